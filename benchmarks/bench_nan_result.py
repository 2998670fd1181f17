"""A non-finite value in one pose of a real worker loop, end to end (tests/faults/nan_run.py):
`graspscape serve` on SQLite with a 20 s lease and max_attempts 3, one worker process whose
evaluation returns a NaN effort for one pose. Twice: the worker as it is (the pose is stored
as `error`), and the worker without its finite check (the coordinator refuses each batch,
counts it as an attempt, fails the tile). Records the status timeline sampled every 2 s
until the exploration ends, the leases per tile (tile index → epoch), the coordinator's log
lines per refused batch, and the load average.

Writes benchmarks/results/nan_result.json.

    .venv/bin/python benchmarks/bench_nan_result.py
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks._results import write_results  # noqa: E402
from tests.faults.nan_run import nan_run  # noqa: E402


def main() -> None:
    load_before = os.getloadavg()
    runs = {}
    for name, checked in (("checked", True), ("unchecked", False)):
        with tempfile.TemporaryDirectory(prefix="gs-nan-") as work:
            runs[name] = nan_run(Path(work), checked=checked)
    figures: dict[str, float] = {}
    for name, run in runs.items():
        figures[f"{name}_ended_s"] = run["ended_s"]
        figures[f"{name}_lease_s"] = run["lease_s"]
        figures[f"{name}_max_leases_of_a_tile"] = max(run["leases_per_tile"].values())
        figures[f"{name}_refused_batches_logged"] = run["refused_batches_in_log"]
        figures[f"{name}_coordinator_log_lines"] = run["coordinator_log_lines"]
        figures[f"{name}_coordinator_tracebacks"] = run["coordinator_tracebacks"]
        figures[f"{name}_poses_stored"] = run["tally"]["stored_rows"]
        figures[f"{name}_poses_planned"] = run["tally"]["planned"]
    write_results("nan_result", figures, {
        "load_average_before": load_before, "load_average_after": os.getloadavg(),
        "runs": {name: {key: run[key] for key in (
            "status", "timeline", "leases_per_tile", "poisoned_pose", "poisoned_outcome",
            "failed_tiles_reasons", "refused_lines", "worker_dropped_batches")}
            for name, run in runs.items()},
    })


if __name__ == "__main__":
    main()
