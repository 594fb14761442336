"""The documentation site renders the docstrings' markup: the griffe extension ``docs/griffe_rst.py`` on its own
(examples, grouped items, page paths) and the built site (no example, list or section left as plain text).

Needs the ``docs`` extra (griffe, MkDocs); skipped without it.
"""

from __future__ import annotations

import html
import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
pytest.importorskip("griffe")


def _hook():
    spec = importlib.util.spec_from_file_location("griffe_rst", REPO / "docs" / "griffe_rst.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def test_an_example_section_becomes_a_title_over_fenced_doctests():
    text = "Summary.\n\nExample:\n    >>> x = 1\n    >>> x + 1\n    2\n\n    Text after the example.\n"
    out = _hook().convert_blocks(text)
    assert "**Example:**" in out
    assert "```pycon\n>>> x = 1\n>>> x + 1\n2\n```" in out  # at the title's indent: not an indented code block
    assert "\nText after the example." in out


def test_a_doctest_under_a_heading_is_fenced_at_the_heading_s_indent():
    out = _hook().convert_blocks("## Example\n    >>> 1 + 1\n    2\n")
    assert "\n```pycon\n>>> 1 + 1\n2\n```" in out


def test_grouped_names_become_one_item_each():
    text = ("Args:\n    q, qd: joint positions and\n        velocities.\n    tau (float): torque.\n\n"
            "Returns:\n    a, b: not an item list.\n")
    out = _hook().split_grouped_items(text)
    assert out.splitlines()[:6] == ["Args:", "    q: joint positions and", "        velocities.",
                                    "    qd: joint positions and", "        velocities.", "    tau (float): torque."]
    assert "    a, b: not an item list." in out  # Returns is prose


def test_a_page_path_becomes_a_link_relative_to_an_api_page():
    link = _hook()._link_doc_paths
    assert link("see docs/studies/index.md.") == "see [`docs/studies/index.md`](../../studies/)."
    assert link("in ``docs/sensing-sources.md``)") == "in [`docs/sensing-sources.md`](../../sensing-sources/))"
    assert link("``docs/performance.md#the-fit``") == "[`docs/performance.md#the-fit`](../../performance/#the-fit)"
    assert link("docs/reindex.md") == "[`docs/reindex.md`](../../reindex/)"
    # code stays as written: a code span, a fenced block, a URL
    for text in ("`docs/a.md`", "```text\ndocs/a.md\n```", "https://example.org/docs/a.md"):
        assert link(text) == text


def test_a_doctest_in_a_list_item_or_an_argument_keeps_its_indent():
    hook = _hook()
    assert "\n  ```pycon\n  >>> f(1)\n  2\n  ```" in hook.convert_blocks("* item, e.g.\n\n  >>> f(1)\n  2\n* next")
    out = hook.convert_blocks("Args:\n    x: the value, e.g.\n\n        >>> x = 1\n")
    assert "\n        ```pycon\n        >>> x = 1\n        ```" in out
    assert "**Examples:**" not in hook.convert_blocks("Examples:\n    >>> 1\n")  # griffe's own section


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(out)], cwd=REPO,
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def _paragraphs(page: Path) -> list[str]:
    return [html.unescape(re.sub(r"<[^>]+>", "", p)) for p in re.findall(r"<p>(.*?)</p>", page.read_text(), re.S)]


def test_the_site_leaves_no_example_list_or_fence_as_plain_text(site):
    pages = sorted(site.rglob("index.html"))
    assert len(pages) > 30
    for page in pages:
        name = page.relative_to(site).parent
        for p in _paragraphs(page):
            assert ">>>" not in p, f"{name}: a doctest rendered as text: {p[:120]!r}"
            items = [line for line in p.split("\n")[1:] if re.match(r"\s*([-*+]|\d+\.) \S", line)]
            assert not items, f"{name}: a list rendered as one paragraph: {p[:120]!r}"
        assert "<code>```" not in page.read_text(), f"{name}: a fence inside a code block"


def test_the_api_pages_document_the_constants_the_readme_uses(site):
    api = "".join(p.read_text() for p in (site / "api").rglob("index.html"))
    for name in ("jaco_env.NOMINAL_URDF", "jaco_env.gains.DEFAULT_KP", "jaco_env.gains.DEFAULT_KD",
                 "jaco_env.robot.TORQUE_LIMITS", "jaco_env.sensors.OBS_Q", "cascgp.models.MODEL_NAMES"):
        assert f'id="{name}"' in api, name
    # a re-export is documented once, where it is defined
    assert 'id="cascgp.derivatives.differentiate"' in api and 'id="cascgp.data.differentiate"' not in api
    # every line of a multi-line Returns section stays in one row (one row per line before)
    page = (site / "api" / "gp" / "index.html").read_text()
    start = page.index('id="cascgp.fit_audit.audit_model"')
    title = page.index("Returns:", start)
    returns = page[title:page.index("</table>", title)]
    assert returns.count("<tr") == 2  # the header and one row
