"""The documentation's doctests run (docs/*.md ```{doctest} blocks), so the conventions the
site states are checked against scipy on every test run; and the site's sources are whole
(every page named in a toctree exists)."""

from __future__ import annotations

import doctest
import pathlib
import re

import pytest

DOCS = pathlib.Path(__file__).resolve().parents[1] / "docs"
PAGES = sorted(p for p in DOCS.rglob("*.md") if "_build" not in p.parts and "gallery" not in p.parts)


def _doctest_blocks(text: str) -> list[str]:
    return re.findall(r"```\{doctest\}\n(.*?)```", text, flags=re.S)


@pytest.mark.parametrize("page", [p for p in PAGES if _doctest_blocks(p.read_text())],
                         ids=lambda p: str(p.relative_to(DOCS)))
def test_doctests_of_the_page(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    source = "\n".join(_doctest_blocks(page.read_text()))
    test = doctest.DocTestParser().get_doctest(source, {}, page.name, str(page), 0)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.attempted > 0 and result.failed == 0, f"{result.failed} doctest(s) failed in {page}"


def test_the_conventions_page_checks_the_pose_conventions_against_scipy():
    blocks = "\n".join(_doctest_blocks((DOCS / "conventions.md").read_text()))
    assert "Rotation.from_euler(\"ZYX\"" in blocks and "as_quat" in blocks


def test_every_toctree_entry_exists():
    for page in PAGES:
        for block in re.findall(r"```\{toctree\}\n(.*?)```", page.read_text(), flags=re.S):
            for line in block.splitlines():
                entry = line.strip()
                if not entry or entry.startswith(":"):
                    continue
                target = page.parent / entry
                found = [target.with_suffix(s) for s in (".md", ".rst")] + [
                    target / "index.md", target / "index.rst"]
                generated = entry in ("gallery/index", "problem_schema", "options")  # made by the build
                assert generated or any(f.exists() for f in found), f"{page.name}: {entry}"


def test_the_options_page_lists_every_defaults_dict():
    import sys

    sys.path.insert(0, str(DOCS))
    try:
        from _options_page import TABLES, options_markdown
    finally:
        sys.path.remove(str(DOCS))
    found = set()
    for src in (DOCS.parent / "optkin").rglob("*.py"):
        found |= set(re.findall(r"^([A-Z][A-Z0-9_]*_DEFAULTS)\b.*=", src.read_text(), flags=re.M))
    assert found == {name for _, name, _ in TABLES}
    text = options_markdown()
    assert "| `tol` | `1e-10` | max \\|Phi\\| for a converged start |" in text  # a comment kept
