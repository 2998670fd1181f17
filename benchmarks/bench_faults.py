"""Faults beyond one process and how long the system takes to recover from each (issue 19).

The scenarios of `tests/faults/scenarios.py`, run with real processes (root needed):

- link cut: the coordinator in a network namespace of its own, two `--instant` workers in one
  each, joined by veth pairs; worker 0's link is set down while it holds a tile none of whose
  poses is stored (mid-tile) for 4 s (shorter than zenoh's 10 s transport lease) and for 20 s
  (longer), then set up again;
- router restart: the compose deployment (a zenoh router, the coordinator and two workers its
  clients), the router killed -9 and started again on the same port after 3 s;
- PostgreSQL restart: the coordinator on a throwaway cluster on a port of its own (never the
  shared server), stopped with `pg_ctl -m fast` mid-run and started again after 3 s and 15 s.

Each ends with the tally of the stored poses against the plan (rows, unique keys, missing,
foreign); the figures are recovery times in seconds. Writes benchmarks/results/faults.json.

    sudo .venv/bin/python benchmarks/bench_faults.py
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks._results import write_results  # noqa: E402
from tests.faults import scenarios  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", choices=["link", "router", "postgres"], action="append")
    args = parser.parse_args()
    chosen = set(args.only or ["link", "router", "postgres"])
    runs = {
        "link_cut_4s": ("link", lambda work: scenarios.link_cut(work, 4.0)),
        "link_cut_20s": ("link", lambda work: scenarios.link_cut(work, 20.0)),
        "router_restart_3s": ("router", lambda work: scenarios.router_restart(work, 3.0)),
        "postgres_restart_3s": ("postgres", lambda work: scenarios.postgres_restart(work, 3.0)),
        "postgres_restart_15s": ("postgres",
                                 lambda work: scenarios.postgres_restart(work, 15.0)),
    }
    figures: dict[str, float] = {}
    tallies: dict[str, dict] = {}
    load = [os.getloadavg()[0]]
    for name, (kind, scenario) in runs.items():
        if kind not in chosen:
            continue
        started = time.monotonic()
        with tempfile.TemporaryDirectory(prefix=f"gs-{name}-") as work:
            result = scenario(Path(work))
        print(name, result, flush=True)
        for key, value in result["figures"].items():
            figures[f"{name}.{key}"] = value
        figures[f"{name}.complete"] = result["complete"]
        figures[f"{name}.run_s"] = round(time.monotonic() - started, 1)
        tallies[name] = result["tally"]
        load.append(os.getloadavg()[0])
    figures["load_avg_1min_max"] = round(max(load), 2)
    write_results("faults", figures, {
        "tallies": tallies,
        "notes": (
            "Workers are `graspscape worker --instant --instant-pose-s S` (a sleep per pose, "
            "no physics): the faults are in the network, the router and the database. "
            "`*_after_restore_s` / `*_after_restart_s` / `*_after_start_s`: seconds from the "
            "link set up again / the router or PostgreSQL accepting again until the next pose "
            "is stored (by the cut worker for the link), the coordinator's /healthz is 200 "
            "again, and the exploration is done. `tile_released_after_s`: from the cut until "
            "the coordinator had taken the cut worker's tile back (null: it never did, the "
            "transport outlived the cut). `refused_stale_batches`: batches of the cut worker "
            "refused as from an old lease (the tile was done by the other worker meanwhile). "
            "The router is a zenoh session in router mode (eclipse-zenoh, the version of "
            "zenohd in docker-compose.yml), since no zenohd binary is installable here. "
            "Measured on the shared 2-core VM under the other helpers' load (load_avg_1min)."),
    })


if __name__ == "__main__":
    main()
