"""Where the default test suite's time goes: wall and CPU seconds of `python -m pytest`, by
phase (collection, setup, call, teardown) and by fixture.

    python benchmarks/bench_test_suite.py [--checkout DIR] [--baseline DIR] [--repeat N]
                                          [--name NAME] [-- PYTEST_ARGS]

Runs the README's default test command in DIR (default: this checkout) N times, one after
another, with the `_suite_timing` plugin (benchmarks/_suite_timing.py), and writes
benchmarks/results/NAME.json: per run and as the median over runs, the wall seconds, the CPU
seconds of pytest and every process it waited for (os.wait4's rusage), collection wall and
CPU, the phase sums, the fixtures with the most setup wall time, the tests that start
subprocesses, and the load average at each run's start and end. The machine is shared: wall
seconds move with the load, CPU seconds much less (the database server's CPU is not in them).
`--checkout` measures another commit's tests (a `git worktree`) against the same installed
code; `--baseline DIR` alternates runs of DIR's tests with the checkout's (baseline first) and
writes the baseline's figures as `baseline.*`, for a before/after under the same load.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _results import write_results  # noqa: E402

TOP_FIXTURES = 8


def _load() -> float:
    return os.getloadavg()[0]


def run_once(checkout: Path, pytest_args: list[str]) -> dict[str, Any]:
    """One default-suite run in `checkout`: the plugin's report plus wall, CPU and load."""
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "timing.json"
        env = {**os.environ, "GS_SUITE_TIMING_OUT": str(report),
               "PYTHONPATH": os.pathsep.join(
                   p for p in (str(HERE), os.environ.get("PYTHONPATH", "")) if p)}
        load_start = _load()
        start = time.perf_counter()
        process = subprocess.Popen(
            [sys.executable, "-m", "pytest", "-q", "-p", "_suite_timing",
             "-p", "no:cacheprovider", *pytest_args],
            cwd=checkout, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        assert process.stdout is not None
        tail = process.stdout.read().decode(errors="replace").strip().splitlines()[-1:]
        _, status, usage = os.wait4(process.pid, 0)
        process.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - start
        data = json.loads(report.read_text())
    data.update(wall_s=wall, cpu_user_s=usage.ru_utime, cpu_sys_s=usage.ru_stime,
                load_start=load_start, load_end=_load(), exit_code=process.returncode,
                summary=tail[0] if tail else "")
    return data


def _commit(checkout: Path) -> str:
    out = subprocess.run(["git", "-C", str(checkout), "rev-parse", "--short", "HEAD"],
                         capture_output=True, text=True)
    return out.stdout.strip() or "unknown"


def figures_of(runs: list[dict[str, Any]]) -> dict[str, float]:
    """Medians over the runs (the load decides each run's wall time)."""

    def median(get: Any) -> float:
        return round(statistics.median(get(r) for r in runs), 2)

    figures: dict[str, float] = {
        "runs": len(runs),
        "wall_s": median(lambda r: r["wall_s"]),
        "cpu_s": median(lambda r: r["cpu_user_s"] + r["cpu_sys_s"]),
        "collection_wall_s": median(lambda r: r["collection"]["wall_s"]),
        "collection_cpu_s": median(lambda r: r["collection"]["cpu_s"]),
        "setup_wall_s": median(lambda r: r["phases_s"].get("setup", 0.0)),
        "call_wall_s": median(lambda r: r["phases_s"].get("call", 0.0)),
        "teardown_wall_s": median(lambda r: r["phases_s"].get("teardown", 0.0)),
        "tests_passed": median(lambda r: r["outcomes"].get("passed", 0)),
        "tests_failed": median(lambda r: r["outcomes"].get("failed", 0)),
        "tests_starting_subprocesses": median(
            lambda r: sum(1 for k in r["subprocesses"] if not k.startswith("<"))),
        "load_1min_start_min": round(min(r["load_start"] for r in runs), 2),
        "load_1min_end_max": round(max(r["load_end"] for r in runs), 2),
    }
    totals: dict[str, float] = {}
    for r in runs:
        for name, f in r["fixtures"].items():
            totals[name] = totals.get(name, 0.0) + f["setup_wall_s"] / len(runs)
    for name in sorted(totals, key=totals.__getitem__, reverse=True)[:TOP_FIXTURES]:
        key = name.split(" ")[0]
        figures[f"fixture.{key}.setup_wall_s"] = median(
            lambda r, n=name: r["fixtures"].get(n, {}).get("setup_wall_s", 0.0))
        figures[f"fixture.{key}.setup_cpu_s"] = median(
            lambda r, n=name: r["fixtures"].get(n, {}).get("setup_cpu_s", 0.0))
        figures[f"fixture.{key}.setups"] = median(
            lambda r, n=name: r["fixtures"].get(n, {}).get("count", 0))
    return figures


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkout", type=Path, default=HERE.parent)
    parser.add_argument("--baseline", type=Path, help="another checkout, run alternately")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--name", default="test_suite")
    parser.add_argument("pytest_args", nargs="*", help="extra pytest arguments (after --)")
    args = parser.parse_args(argv)
    sides = {"": args.checkout.resolve()}
    if args.baseline is not None:
        sides = {"baseline.": args.baseline.resolve(), **sides}
    runs: dict[str, list[dict[str, Any]]] = {prefix: [] for prefix in sides}
    for i in range(args.repeat):
        for prefix, checkout in sides.items():
            run = run_once(checkout, args.pytest_args)
            print(f"{prefix or 'checkout.'}run {i + 1}: {run['wall_s']:.1f} s wall, "
                  f"{run['cpu_user_s'] + run['cpu_sys_s']:.1f} s CPU, load "
                  f"{run['load_start']:.1f} -> {run['load_end']:.1f}: {run['summary']}")
            runs[prefix].append(run)
    figures: dict[str, float] = {}
    extra: dict[str, Any] = {}
    for prefix, checkout in sides.items():
        figures.update({f"{prefix}{k}": v for k, v in figures_of(runs[prefix]).items()})
        extra[f"{prefix}checkout_commit"] = _commit(checkout)
        extra[f"{prefix}runs"] = [{k: v for k, v in r.items() if k != "fixtures"}
                                  for r in runs[prefix]]
    write_results(args.name, figures, extra)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
