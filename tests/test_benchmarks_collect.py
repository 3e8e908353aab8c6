"""The benchmark suite stays runnable: ``python -m pytest benchmarks/`` is not part of the
default test run, and once a renamed optkin function broke one benchmark's imports unseen,
which stopped the whole suite at collection (``benchmarks/test_inverse.py``, 2026-12-06)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_every_benchmark_module_imports_and_collects():
    pytest.importorskip("pytest_benchmark")
    files = sorted(str(p) for p in (ROOT / "benchmarks").glob("*.py")
                   if p.name.startswith(("test_", "bench_")))
    assert len(files) >= 10
    r = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-m", "",
                        "-p", "no:cacheprovider", *files], cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "error" not in r.stdout.lower().split("collected")[-1], r.stdout[-2000:]
