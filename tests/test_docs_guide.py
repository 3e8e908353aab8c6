"""The getting-started page and the user guide run as written (docs/getting_started.md,
docs/guide/*.md): every ```python block of a page, in order, in one namespace, in a
temporary working directory (pictures are written there). Blocks shown but not run use the
MyST ``{code-block}`` directive."""

from __future__ import annotations

import pathlib
import re

import pytest

DOCS = pathlib.Path(__file__).resolve().parents[1] / "docs"
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def _pages() -> list[pathlib.Path]:
    """getting_started, then the guide in the order of the index's toctree."""
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    names = re.findall(r"^(getting_started|guide/\w+)\s*$", index, flags=re.M)
    return [DOCS / f"{name}.md" for name in names]


PAGES = _pages()


def _blocks(page: pathlib.Path) -> list[tuple[int, str]]:
    """(line number of the first line, code) of every ```python block."""
    text = page.read_text(encoding="utf-8")
    return [(text.count("\n", 0, m.start(1)), m.group(1)) for m in BLOCK.finditer(text)]


def test_every_page_of_the_toctree_is_tested():
    assert [p.name for p in PAGES[:1]] == ["getting_started.md"]
    guide = {p.name for p in (DOCS / "guide").glob("*.md")}
    assert {p.name for p in PAGES[1:]} == guide and len(guide) == 11
    for page in PAGES:
        assert page.exists(), page
        assert _blocks(page), f"{page.name} has no python block"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.stem)
def test_page_code_runs(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__docs__"}
    for line, code in _blocks(page):
        # padded so that a traceback names the line of the page
        exec(compile("\n" * line + code, str(page), "exec"), namespace)  # noqa: S102


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.stem)
def test_page_images_exist(page):
    text = page.read_text(encoding="utf-8")
    images = re.findall(r"^```\{image\} (\S+)", text, flags=re.M)
    for image in images:
        made = re.fullmatch(r"(?:\.\./)*gallery/images/sphx_glr_(\w+?)_\d{3}\.png", image)
        if made:  # a picture the gallery makes during the build: its script must exist
            script = DOCS.parent / "examples" / f"{made.group(1)}.py"
            assert script.is_file(), f"{page.name}: {image}: no {script.name} in examples/"
        else:
            assert (page.parent / image).is_file(), f"{page.name}: {image} not found"
