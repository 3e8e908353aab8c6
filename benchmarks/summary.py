"""Print a Markdown table from a pytest-benchmark JSON file.

    python -m pytest benchmarks/ --benchmark-json=bench.json
    python benchmarks/summary.py bench.json
"""

from __future__ import annotations

import json
import sys


def fmt(t: float | None) -> str:
    if t is None or t != t:
        return "-"
    if t < 1e-3:
        return f"{t * 1e6:.1f} us"
    if t < 1:
        return f"{t * 1e3:.2f} ms"
    return f"{t:.2f} s"


def main(path: str) -> None:
    data = json.load(open(path))
    mi = data.get("machine_info", {})
    print(f"Machine: {mi.get('cpu', {}).get('brand_raw', '?')}, "
          f"{mi.get('cpu', {}).get('count', '?')} cores, Python {mi.get('python_version')}, "
          f"{data.get('datetime', '')[:16]}\n")
    print("| benchmark | optkin median | baseline | baseline median | ratio | status | nit | notes |")
    print("|---|---|---|---|---|---|---|---|")
    keep = ("solver", "per_solve_us", "fsolve_per_solve_us", "per_solve_threads2_chunk1024_us",
            "max_residual", "fallback", "postures", "modes", "naive_modes", "types", "curves",
            "aspects", "nlp_build_s", "warm_solve_s", "compile_core_and_tracker_s",
            "compiler_cpu_s", "cached_build_fresh_process_s", "agrees_with_fd",
            "agrees_with_fsolve", "meets_target", "load_average_1min")
    for b in data["benchmarks"]:
        e = b.get("extra_info", {})
        notes = ", ".join(
            f"{k}={fmt(e[k]) if k.endswith('_s') else (f'{e[k]:.3g}' if isinstance(e[k], float) else e[k])}"
            for k in keep if k in e and e[k] is not None
        )
        ratio = e.get("ratio")
        print(f"| {b['name'].removeprefix('test_')} | {fmt(b['stats']['median'])} | {e.get('baseline', '-')} | "
              f"{fmt(e.get('baseline_median_s'))} | "
              f"{'-' if ratio is None else f'{ratio:.1f}x'} | {e.get('status', '-')} | "
              f"{e.get('nit', '-')} | {notes} |")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "bench.json")
