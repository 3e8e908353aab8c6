"""The README's Python tour runs as written (so the README stays true)."""

from __future__ import annotations

import pathlib
import re

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_readme_tour_runs(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) >= 2
    monkeypatch.chdir(tmp_path)  # pictures land here
    namespace: dict = {}
    exec(compile("\n".join(blocks), str(README), "exec"), namespace)  # noqa: S102
    assert namespace["r"].success
    assert len(namespace["modes"]) >= 1
    assert list(tmp_path.glob("*.png"))


def test_readme_shows_the_two_commands():
    text = README.read_text()
    assert "python -m pip install -e . && optkin run problems/" in text
    assert 'python -m pip install -e ".[test]" && python -m pytest -n 2' in text
    ci = (README.parent / ".ci" / "run").read_text()
    assert 'python -m pip install -e ".[test]" && python -m pytest -n 2' in ci
    assert "optkin run problems/" in ci
