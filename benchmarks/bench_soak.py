"""The soak (issue 19): one exploration of many small tiles (3 poses each) through `graspscape
serve` (SQLite) and a `graspscape worker --instant --procs 3`, a simulation process killed -9
every few simulated minutes (process 0 never), memory sampled every second.

Reports whether the exploration ended done with every planned pose stored once, the RSS of
the coordinator, the worker's supervisor and its never-killed process 0 (first vs last
quartile of the samples after the first 10 % of tiles; "flat" = within 10 %), the
coordinator's open files and threads first vs last, and at the end its established zenoh
connections against the live worker processes (no session left behind by a killed one).
The workers are instant, so no pybullet client is opened in this run.

The issue asks for 20,000 tiles, the default (`--tiles N` for a shorter run; the file says
which count ran). It runs in a mount namespace with a private /dev/shm, so the zenoh
shared-memory segments left at the end are this run's alone.

Writes benchmarks/results/soak.json.

    sudo .venv/bin/python benchmarks/bench_soak.py [--tiles 20000] [--procs 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks._results import write_results  # noqa: E402
from tests.faults.soak import soak_isolated  # noqa: E402

FULL_TILES = 20_000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tiles", type=int, default=FULL_TILES,
                        help=f"tiles of the exploration (the issue's count: {FULL_TILES})")
    parser.add_argument("--procs", type=int, default=3)
    parser.add_argument("--simulated-minutes", type=float, default=3.0,
                        help="simulated time between two kills")
    parser.add_argument("--timeout-s", type=float, default=3600)
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="gs-soak-") as work:
        result = soak_isolated(Path(work), tiles=args.tiles, procs=args.procs,
                      simulated_minutes=args.simulated_minutes, timeout_s=args.timeout_s)
    rss = result.pop("rss")
    figures = {
        "tiles": result["tiles"],
        "poses": result["poses"],
        "complete": result["complete"],
        "elapsed_s": result["elapsed_s"],
        "tiles_per_s": result["tiles_per_s"],
        "kills": result["kills"],
        "kill_every_tiles": result["kill_every_tiles"],
        "kill_every_simulated_min": result["kill_every_simulated_min"],
        "simulated_hours": result["simulated_hours"],
        **{f"rss_{name}_{key}": value for name, values in rss.items()
           for key, value in values.items()},
        "coordinator_fds_first": result["coordinator_fds_first_last"][0],
        "coordinator_fds_last": result["coordinator_fds_first_last"][1],
        "coordinator_threads_first": result["coordinator_threads_first_last"][0],
        "coordinator_threads_last": result["coordinator_threads_first_last"][1],
        "worker_processes_alive_at_end": result["worker_processes_alive_at_end"],
        "coordinator_zenoh_connections_at_end": result["coordinator_zenoh_connections_at_end"],
        "zenoh_shm_segments_left": result["zenoh_shm_segments_left"],
        "zenoh_shm_bytes_left": result["zenoh_shm_bytes_left"],
        "worker_restarts_logged": result["worker_restarts_logged"],
        "load_avg_1min_before": round(load_before, 2),
        "load_avg_1min_after": round(os.getloadavg()[0], 2),
    }
    write_results("soak", figures, {
        "full_count": FULL_TILES,
        "ran_full_count": result["tiles"] >= FULL_TILES * 0.95,
        "tally": result["tally"],
        "kill_log": result["kill_log"],
        "notes": (
            "Simulated time: a tile of 3 poses stands for 3 / 3.7 s of physics per process "
            "(eval_pose.json's rate on this VM), over the worker's processes. RSS quartiles "
            "leave out the first 10 % of tiles (start-up). Measured on the shared 2-core VM "
            "under the other helpers' load (load_avg_1min)."),
    })


if __name__ == "__main__":
    main()
