"""How long another writer waits on SQLite while a map's default picture is drawn ahead and
stored (maps/stored.store_default), the code before a change against the code after it (A/B).

On SQLite a transaction's first write takes the database's write lock until its commit. A
draw-ahead that wrote before drawing held it for the whole draw (seconds at 1M poses), and
every ingest, lease and refresh of every exploration on that database waited behind it. Per
(code, round): the stored pictures are deleted (so both codes read the poses: a like-for-like
draw), then, in a process running that code, a thread draws and stores the default picture of
bench_query's finished map while the main thread makes a one-row write every 0.25 s in its own
transaction, timed from its start to its commit. Figures: the draw-ahead's wall ms and the
longest and median write waits (ms), medians over rounds. Writes
benchmarks/results/draw_ahead_lock.json.

    .venv/bin/python benchmarks/bench_draw_ahead_lock.py --before-code DIR [--after-code DIR]
        [--size 1m] [--keep DIR] [--rounds 2] [--results NAME]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks import bench_map_picture, bench_query  # noqa: E402
from benchmarks._results import write_results  # noqa: E402

_MEASURE = """
import json, statistics, sys, threading, time
from graspscape.services.coordinator import db
from graspscape.services.coordinator.maps import render, stored
from sqlalchemy import text
render.warm_up()
engine = db.make_engine(sys.argv[1])
sessions = db.make_sessionmaker(engine)
drawn = []
def draw():
    with sessions() as s:
        start = time.perf_counter()
        stored.store_default(s, 1)
        s.commit()
        drawn.append((time.perf_counter() - start) * 1000)
thread = threading.Thread(target=draw)
thread.start()
waits = []
while thread.is_alive():
    time.sleep(0.25)
    start = time.perf_counter()
    with engine.begin() as conn:
        conn.execute(text("UPDATE explorations SET updated_at = updated_at WHERE id = 1"))
    waits.append((time.perf_counter() - start) * 1000)
thread.join()
print(json.dumps({"draw_ms": drawn[0], "writes": len(waits), "max_wait_ms": max(waits),
                  "median_wait_ms": statistics.median(waits)}))
"""


def measure(url: str, code: Path) -> dict[str, float]:
    bench_map_picture._set_state(url, "finished")  # no stored picture: both codes draw
    out = subprocess.run([sys.executable, "-c", _MEASURE, url], cwd="/tmp",
                         env=bench_map_picture._env(code), check=True, capture_output=True,
                         text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before-code", type=Path, required=True,
                        help="a tree of the code before (git archive of a commit)")
    parser.add_argument("--after-code", type=Path, default=REPO)
    parser.add_argument("--size", default="1m", help="bench_query's SQLite size")
    parser.add_argument("--keep", type=Path, default=bench_query.DEFAULT_KEEP)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--results", default="draw_ahead_lock")
    args = parser.parse_args()
    path = args.keep / f"query_{args.size}.db"
    if not path.exists():
        raise SystemExit(f"{path} missing: build it with `bench_query.py --sizes {args.size} "
                         "--pg-sizes '' --build-only`")
    url = f"sqlite:///{path}"
    figures: dict[str, float] = {"load_avg_1min_start": round(os.getloadavg()[0], 2)}
    runs: dict[str, list[dict[str, float]]] = {"before": [], "after": []}
    for k in range(args.rounds):
        order = ("before", "after") if k % 2 == 0 else ("after", "before")
        for which in order:
            code = args.before_code if which == "before" else args.after_code
            got = measure(url, code)
            print(which, k, got, flush=True)
            runs[which].append(got)
    for which, got in runs.items():
        for name in ("draw_ms", "max_wait_ms", "median_wait_ms"):
            figures[f"{name.removesuffix('_ms')}_ms_{args.size}_sqlite_{which}"] = round(
                statistics.median(g[name] for g in got), 1)
        figures[f"writes_{args.size}_sqlite_{which}"] = statistics.median(
            g["writes"] for g in got)
    figures["load_avg_1min_end"] = round(os.getloadavg()[0], 2)
    write_results(args.results, figures, {"rounds": runs})


if __name__ == "__main__":
    main()
