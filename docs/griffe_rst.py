"""Griffe extension for the documentation site: the reStructuredText markup of the docstrings as Markdown.

The docstrings are Google style (``Args:``, ``Returns:``, ``Attributes:``) with reST markup inside: roles
(``:class:`x```, ``:func:``, ``:math:``), ``.. math::`` blocks, simple tables (``====  ====``), section titles
underlined with ``---``, literal blocks after ``::`` and numbered footnotes. mkdocstrings renders docstrings as
Markdown, so this extension rewrites that markup before the docstrings are parsed:

- roles that name an object become optional cross-references (a link where the object is rendered on the site,
  code otherwise); ``:math:`` becomes ``$...$`` and ``.. math::`` a ``$$`` block (pymdownx.arithmatex);
- simple tables become pipe tables, underlined titles bold lines, ``Foo::`` blocks fenced code;
- the body of a bullet item is indented by four columns (Python-Markdown) instead of two (reST);
- ``[1]_`` / ``.. [1]`` become Markdown footnotes.

``quiet`` (an option in ``mkdocs.yml``) names objects whose docstrings griffe parses without warnings.

Loaded by ``mkdocs.yml`` (``plugins: mkdocstrings: handlers: python: options: extensions``); part of the docs
build only, never imported by the packages.
"""

from __future__ import annotations

import re
import textwrap
from typing import Any, cast

import griffe

_BORDER = re.compile(r"^(\s*)(=+)((?:\s+=+)+)\s*$")
_MATH_DIRECTIVE = re.compile(r"^(\s*)\.\. math::\s*(.*)$")
_FOOTNOTE_DEF = re.compile(r"^(\s*)\.\. \[(\d+)\]\s+(.*)$")
_UNDERLINE = re.compile(r"^\s*([-=~^])\1{2,}\s*$")
_LITERAL = re.compile(r"^(\s*)(.*[^:\s]):(:)\s*$")
_ROLE = re.compile(r":(class|func|meth|attr|mod|data|exc|obj|const):`(~?)([^`]+)`")
_MATH_ROLE = re.compile(r":math:`([^`]+)`")
_TITLED = re.compile(r"^(.*\S)\s*<([^<>]+)>$")
_TOP_PACKAGES = ("cascgp", "jaco_env", "cascgp_experiments", "scripts")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


# --------------------------------------------------------------------------- tables
def _columns(border: str) -> list[int]:
    return [m.start() for m in re.finditer(r"=+", border)]


def _cells(line: str, starts: list[int]) -> list[str]:
    """Split a table row at the column starts; a word that overflows its column moves the boundary to its end."""
    bounds = list(starts)
    for k in range(1, len(bounds)):
        b = max(bounds[k], bounds[k - 1] + 1)
        while 0 < b < len(line) and line[b - 1] != " " and line[b] != " ":
            b += 1
        bounds[k] = b
    bounds.append(max(len(line), bounds[-1]))
    return [line[bounds[k]:bounds[k + 1]].strip() for k in range(len(starts))]


def _table(lines: list[str], i: int) -> tuple[list[str], int] | None:
    """The pipe table for the simple table starting at ``lines[i]`` and the index after it, or ``None``."""
    indent = _BORDER.match(lines[i])[1]  # type: ignore[index]
    starts = _columns(lines[i])
    borders = [i]
    j = i + 1
    while j < len(lines) and len(borders) < 3:
        if _BORDER.match(lines[j]) and _indent(lines[j]) == len(indent):
            borders.append(j)
        elif not lines[j].strip():
            break
        j += 1
    if len(borders) < 2:
        return None
    if len(borders) == 2:
        header: list[str] = []
        body = lines[borders[0] + 1:borders[1]]
    else:
        header = lines[borders[0] + 1:borders[1]]
        body = lines[borders[1] + 1:borders[2]]

    def rows(block: list[str]) -> list[list[str]]:
        out: list[list[str]] = []
        for line in block:
            if not line.strip():
                continue
            cells = _cells(line, starts)
            # a continuation line: an empty first column (reST), or, in a table of 3+ columns, empty middle columns
            # under a row that has them (a long first or last cell wrapped by hand)
            middle_empty = len(cells) > 2 and not any(cells[1:-1]) and out and all(out[-1][1:-1])
            if out and (not cells[0] or middle_empty):
                out[-1] = [f"{a} {b}".strip() for a, b in zip(out[-1], cells)]
            else:
                out.append(cells)
        return out

    def row(cells: list[str]) -> str:
        return indent + "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

    head = rows(header)
    head_cells = [" ".join(col).strip() for col in zip(*head)] if head else [""] * len(starts)
    out = ["", row(head_cells), indent + "|" + "---|" * len(starts)]
    out += [row(r) for r in rows(body)]
    out.append("")
    return out, borders[-1] + 1


# --------------------------------------------------------------------------- blocks
def _block_end(lines: list[str], i: int, indent: int) -> int:
    """Index after the block of lines indented more than ``indent`` that starts at ``lines[i]`` (blank lines inside)."""
    j = i
    while j < len(lines) and (not lines[j].strip() or _indent(lines[j]) > indent):
        j += 1
    while j > i and not lines[j - 1].strip():
        j -= 1
    return j


def convert_blocks(text: str) -> str:
    """Tables, math blocks, literal blocks, underlined titles and footnote definitions of a docstring."""
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if _BORDER.match(line):
            table = _table(lines, i)
            if table is not None:
                out += table[0]
                i = table[1]
                continue
        m = _MATH_DIRECTIVE.match(line)
        if m:
            pad = m[1]
            end = _block_end(lines, i + 1, len(pad))
            body = textwrap.dedent("\n".join(lines[i + 1:end])).strip("\n").splitlines()
            if m[2].strip():
                body.insert(0, m[2].strip())
            out += ["", pad + "$$", *(pad + b if b.strip() else "" for b in body), pad + "$$", ""]
            i = end
            continue
        m = _FOOTNOTE_DEF.match(line)
        if m:
            out.append(f"{m[1]}[^{m[2]}]: {m[3]}")
            i += 1
            continue
        m = _LITERAL.match(line)
        if m and not line.lstrip().startswith(".."):
            pad = m[1]
            end = _block_end(lines, i + 1, len(pad))
            body = textwrap.dedent("\n".join(lines[i + 1:end])).strip("\n").splitlines()
            if body:
                out += [pad + m[2] + ":", "", pad + "```text", *(pad + b if b.strip() else "" for b in body),
                        pad + "```", ""]
                i = end
                continue
        if (i + 1 < len(lines) and line.strip() and _UNDERLINE.match(lines[i + 1])
                and len(lines[i + 1].strip()) >= len(line.strip()) and _indent(lines[i + 1]) == _indent(line)):
            out += ["", " " * _indent(line) + f"**{line.strip()}**", ""]
            i += 2
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


_BULLET = re.compile(r"^(\s*)[*+-] \S")


def indent_list_items(text: str) -> str:
    """Indent the body of every bullet item by four columns instead of reST's two.

    Python-Markdown keeps a paragraph, a nested list or a ``$$`` block inside a list item only when it is indented
    by four columns; reST needs two. An item whose body holds a blank line is also closed by a blank line, so that
    the next item does not run into its last paragraph.
    """
    out: list[str] = []
    stack: list[list[Any]] = []  # [content column (reST), body has a blank line] of the open items, innermost last
    blank = False
    for line in text.splitlines():
        if not line.strip():
            blank = True
            out.append(line)
            continue
        ind = _indent(line)
        closed_loose = False
        while stack and ind < stack[-1][0]:
            closed_loose |= stack.pop()[1]
        if blank and stack:
            for item in stack:
                item[1] = True
        blank = False
        m = _BULLET.match(line)
        if m and closed_loose and out and out[-1].strip():
            out.append("")
        out.append(" " * (2 * len(stack)) + line)
        if m:
            stack.append([ind + 2, False])
    return "\n".join(out)


# --------------------------------------------------------------------------- inline markup
def _resolver(obj: griffe.Object) -> Any:
    def exists(path: str) -> bool:
        try:
            obj.modules_collection.get_member(path)
        except (KeyError, ValueError, griffe.AliasResolutionError, griffe.CyclicAliasError):
            return False
        return True

    def resolve(name: str) -> str | None:
        name = name.lstrip(".")
        if name.split(".", 1)[0] in _TOP_PACKAGES:
            return name
        first, _, rest = name.partition(".")
        scope: Any = obj
        while scope is not None:
            if first in scope.members:
                path = f"{scope.path}.{name}"
                return path if exists(path) else None
            if getattr(scope, "is_module", False) and first in scope.imports:
                path = scope.imports[first] + (f".{rest}" if rest else "")
                return path if path.split(".", 1)[0] in _TOP_PACKAGES else None
            scope = scope.parent
        return None

    return resolve


def convert_inline(text: str, obj: griffe.Object) -> str:
    """Roles, math roles and footnote references of a docstring."""
    resolve = _resolver(obj)

    def role(m: re.Match[str]) -> str:
        short, target = m[2] == "~", m[3].strip()
        titled = _TITLED.match(target)
        title = titled[1] if titled else None
        if titled:
            target = titled[2]
        target = target.lstrip("~")
        if title is None:
            title = target.rsplit(".", 1)[-1] if short else target
        if m[1] in ("func", "meth") and not title.endswith(")"):
            title += "()"
        path = resolve(target)
        code = f"<code>{title}</code>"
        return f'<autoref identifier="{path}" optional>{code}</autoref>' if path else f"`{title}`"

    text = _MATH_ROLE.sub(lambda m: f"${m[1]}$", text)
    text = _ROLE.sub(role, text)
    return re.sub(r"\[(\d+)\]_", r"[^\1]", text)


class RstToMarkdown(griffe.Extension):
    """Rewrite every docstring of a loaded package (see the module docstring).

    Args:
        quiet: paths of objects whose docstrings are parsed without griffe's warnings (known deviations from the
            Google style that would otherwise fail ``mkdocs build --strict``).
    """

    def __init__(self, quiet: list[str] | None = None) -> None:
        super().__init__()
        self.quiet = set(quiet or ())

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        seen: set[int] = set()
        stack: list[griffe.Object] = [pkg]
        while stack:
            obj = stack.pop()
            if id(obj) in seen:
                continue
            seen.add(id(obj))
            if obj.docstring is not None:
                obj.docstring.value = convert_inline(indent_list_items(convert_blocks(obj.docstring.value)), obj)
                if obj.path in self.quiet:
                    options = {**obj.docstring.parser_options, "warnings": False}  # a copy: the loader shares one dict
                    obj.docstring.parser_options = cast(Any, options)
            stack += [m for m in obj.members.values() if not m.is_alias]  # type: ignore[misc]
