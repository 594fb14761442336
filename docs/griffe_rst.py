"""Griffe extension for the documentation site: the reStructuredText markup of the docstrings as Markdown.

The docstrings are Google style (``Args:``, ``Returns:``, ``Attributes:``) with reST markup inside: roles
(``:class:`x```, ``:func:``, ``:math:``), ``.. math::`` blocks, simple tables (``====  ====``), section titles
underlined with ``---``, literal blocks after ``::`` and numbered footnotes. mkdocstrings renders docstrings as
Markdown, so this extension rewrites that markup before the docstrings are parsed:

- roles that name an object become optional cross-references (a link where the object is rendered on the site,
  code otherwise); ``:math:`` becomes ``$...$`` and ``.. math::`` a ``$$`` block (pymdownx.arithmatex);
- simple tables become pipe tables, underlined titles bold lines, ``Foo::`` blocks fenced code;
- the body of a bullet item is indented by four columns (Python-Markdown) instead of two (reST);
- ``[1]_`` / ``.. [1]`` become Markdown footnotes;
- a path of a page of the site (``docs/<page>.md``) becomes a link to it;
- an ``Example:`` section becomes a bold title over its body, and doctest lines (``>>>``) fenced ``pycon`` blocks;
- an ``a, b: text`` item of ``Args:`` or ``Attributes:`` becomes one item per name;
- the ``#:`` comments above an attribute become its docstring, and a submodule's re-export of a name defined in
  another of the packages' modules is not rendered again (the name is documented where it is defined).

Returns sections are read as one block of prose (``returns_multiple_items: false`` in ``mkdocs.yml``). ``quiet``
(an option in ``mkdocs.yml``) names objects whose docstrings griffe parses without warnings.

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


_EXAMPLE_TITLE = re.compile(r"^(\s*)(Example):\s*$")  # "Examples:" is a section of griffe's own


def _open_examples(lines: list[str]) -> list[str]:
    """An ``Example:`` title with its indented body as a bold line and the body at the title's indent (griffe's
    Google parser reads ``Example:`` as plain text, and Markdown would read the indented body as one code block)."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        m = _EXAMPLE_TITLE.match(lines[i])
        end = _block_end(lines, i + 1, len(m[1])) if m else i + 1
        if m and end > i + 1:
            body = textwrap.dedent("\n".join(lines[i + 1:end])).splitlines()
            out += ["", f"{m[1]}**{m[2]}:**", "", *(m[1] + b if b.strip() else "" for b in body)]
            i = end
            continue
        out.append(lines[i])
        i += 1
    return out


def convert_blocks(text: str) -> str:
    """Tables, math blocks, literal blocks, underlined titles, footnote definitions and examples of a docstring."""
    lines = _open_examples(text.splitlines())
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
        if line.lstrip().startswith(">>>"):  # a doctest block: to the next blank line or a smaller indent
            ind = _indent(line)
            end = i + 1
            while end < len(lines) and lines[end].strip() and _indent(lines[end]) >= ind:
                end += 1
            body = [b[ind:] for b in lines[i:end]]
            # under a heading, fenced at the heading's indent (an indented fence there would be a code block
            # holding the fence); elsewhere (a list item, an argument) at its own
            prev = next((b for b in reversed(out) if b.strip()), "")
            pad = " " * (min(ind, _indent(prev)) if prev.lstrip().startswith("#") else ind)
            out += ["", pad + "```pycon", *(pad + b for b in body), pad + "```", ""]
            i = end
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


_ITEM_SECTION = re.compile(r"^(\s*)(Args|Arguments|Params|Parameters|Attributes|Keyword Args|Keyword Arguments|"
                           r"Other Args|Other Arguments|Other Params|Other Parameters):\s*$")
_GROUPED_ITEM = re.compile(r"^(\s*)([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)+)((?:\s*\([^()]*\))?:(?:\s.*)?)$")


def split_grouped_items(text: str) -> str:
    """One item per name in ``Args:`` and ``Attributes:`` sections: ``a, b: text`` becomes ``a: text`` and
    ``b: text`` (with the item's continuation lines), which griffe's Google parser then matches to the signature
    (it reads ``a, b`` as one name)."""
    lines = text.splitlines()
    out: list[str] = []
    section: int | None = None  # the indent of the open section's title
    item = -1  # the indent of its items (its first line's)
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.strip():
            m = _ITEM_SECTION.match(line)
            if m:
                section, item = len(m[1]), -1
            elif section is not None and _indent(line) <= section:
                section = None
            elif section is not None and item < 0:
                item = _indent(line)
            g = _GROUPED_ITEM.match(line) if section is not None and _indent(line) == item else None
            if g:
                end = i + 1
                while end < len(lines) and lines[end].strip() and _indent(lines[end]) > len(g[1]):
                    end += 1
                for name in (n.strip() for n in g[2].split(",")):
                    out += [f"{g[1]}{name}{g[3]}", *lines[i + 1:end]]
                i = end
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


_DOC_PATH = re.compile(r"(?<![\w/`])(``)?docs/([\w/.-]+?)\.md(#[\w-]+)?(?![\w/])(?(1)``)")
_FENCED = re.compile(r"^(\s*)```.*?^\1```[ \t]*$", re.MULTILINE | re.DOTALL)


def _doc_link(m: re.Match[str]) -> str:
    """A ``docs/<page>.md`` path as a link to that page of the site, relative to an API page (``api/<name>/``)."""
    page = m[2]
    page = "" if page == "index" else page.removesuffix("/index")
    url = "../../" + (page + "/" if page else "") + (m[3] or "")
    return f"[`docs/{m[2]}.md{m[3] or ''}`]({url})"


def _link_doc_paths(text: str) -> str:
    """:func:`_doc_link` for every page path outside fenced code blocks (a path in code stays as written)."""
    out, last = [], 0
    for fence in _FENCED.finditer(text):
        out += [_DOC_PATH.sub(_doc_link, text[last:fence.start()]), fence[0]]
        last = fence.end()
    return "".join(out + [_DOC_PATH.sub(_doc_link, text[last:])])


def convert_inline(text: str, obj: griffe.Object) -> str:
    """Roles, math roles, footnote references and paths of the documentation's pages of a docstring."""
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

    text = _link_doc_paths(text)
    text = _MATH_ROLE.sub(lambda m: f"${m[1]}$", text)
    text = _ROLE.sub(role, text)
    return re.sub(r"\[(\d+)\]_", r"[^\1]", text)


def _docstring_from_comments(attr: griffe.Object) -> None:
    """The ``#:`` comment lines right above a module or class attribute (Sphinx's convention for documenting one)
    as its docstring; griffe reads only a string literal after the assignment."""
    path = attr.filepath
    if not attr.lineno or isinstance(path, list) or path not in attr.lines_collection:
        return
    lines = attr.lines_collection[path]
    k = attr.lineno - 2  # the line above the assignment (lineno counts from 1)
    comments: list[str] = []
    while k >= 0 and lines[k].lstrip().startswith("#:"):
        comments.insert(0, lines[k].lstrip()[2:].removeprefix(" "))
        k -= 1
    if comments:
        module_doc = attr.module.docstring
        attr.docstring = griffe.Docstring(
            "\n".join(comments), lineno=k + 2, endlineno=attr.lineno - 1, parent=attr,
            parser=module_doc.parser if module_doc else None,
            parser_options=module_doc.parser_options if module_doc else None)


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
            if obj.is_attribute and obj.docstring is None:
                _docstring_from_comments(obj)
            if obj.docstring is not None:
                text = split_grouped_items(convert_blocks(obj.docstring.value))
                obj.docstring.value = convert_inline(indent_list_items(text), obj)
                if obj.path in self.quiet:
                    options = {**obj.docstring.parser_options, "warnings": False}  # a copy: the loader shares one dict
                    obj.docstring.parser_options = cast(Any, options)
            if obj.is_module and obj.parent is not None:
                # a submodule's re-export of a name defined in another of our modules is documented there once
                # (an explicit ``members:`` list in a page still renders it)
                for member in obj.members.values():
                    if member.is_alias and member.target_path.split(".", 1)[0] in _TOP_PACKAGES:
                        member.public = False
            stack += [m for m in obj.members.values() if not m.is_alias]  # type: ignore[misc]
