"""First reads of `map.png` drawn on read: the default picture, `cut=vertical` and another φ0,
of a running and of a finished map, the code before a change against the code after it (A/B).

The maps are bench_query.py's (its builders and kept databases: `--keep`, `--pg-db`; built
there with `--build-only` if missing). A finished map is the built one (status done, manifold
table final); a running map is the same rows with the row set back to `running` and its table
not final (as just after a refresh: `manifolds_poses_done == poses_done`, so a read draws the
stored table and refreshes nothing). Before each code's servers the stored pictures are
deleted and the code's own draw-ahead runs where that code has one (the before code: the
finished map's default picture; the code with maps/stored.py's running draw-ahead: the
running map's too), timed apart as `draw_ahead`, as the coordinator does it off the read path.

Each code is served by a fresh `uvicorn` process (bench_query.serve) with that code first on
the path. Per (size, state, code, round): a server asked for the default picture, then
`cut=vertical`, then `cut=vertical&phi0_deg=60` in turn (`seq`: what one viewer paging through
the cuts of one map version gets; `--think-s` seconds after the default one: a viewer looking
at it first), and two more servers asked each for one of the two others
alone (`alone`: the cold first read); each server is asked `--settle-s` after it first answers
(a coordinator that has started, not one still importing; the code after the change draws a
small made-up map then, in a background thread). Figures: wall ms of the request and the
server's CPU ms for it (user + system, /proc). Rounds alternate which code goes first; the
medians over rounds are written, with the rounds' values. Pixels: the decoded PNGs of the two
codes are compared (`pixels_differing_*`). Writes benchmarks/results/map_picture.json.

    .venv/bin/python benchmarks/bench_map_picture.py --before-code DIR [--after-code DIR]
        [--sizes 10k,100k,1m] [--pg-sizes 100k] [--keep DIR] [--pg-db NAME] [--rounds 2]
        [--think-s 0] [--results NAME]
"""

from __future__ import annotations

import argparse
import hashlib
import io
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks import bench_query  # noqa: E402
from benchmarks._results import write_results  # noqa: E402

PICTURES = {"default": "map.png", "vertical": "map.png?cut=vertical",
            "phi60": "map.png?cut=vertical&phi0_deg=60"}
# What a code's draw-ahead does, run in that code (stored.store_default; a running map's
# without the refresh, where that code's store_default takes `ensure`).
_DRAW_AHEAD = """
import inspect, sys, time
from graspscape.services.coordinator import db
from graspscape.services.coordinator.maps import stored
running = sys.argv[2] == "running"
if running and "ensure" not in inspect.signature(stored.store_default).parameters:
    print("none"); sys.exit(0)
engine = db.make_engine(sys.argv[1])
with db.make_sessionmaker(engine)() as s:
    start = time.perf_counter()
    stored.store_default(s, 1, **({"ensure": False} if running else {}))
    s.commit()
    print(round((time.perf_counter() - start) * 1000, 1))
"""


def _env(code: Path) -> dict[str, str]:
    """The environment that puts `code` first as the graspscape package (one shim per code:
    bench_query.Server's one shim per process would serve the first code twice)."""
    tag = hashlib.blake2b(str(code.resolve()).encode(), digest_size=6).hexdigest()
    shim = Path(f"/tmp/graspscape_bench_map_picture_{tag}")
    shim.mkdir(exist_ok=True)
    link = shim / "graspscape"
    if not link.exists():
        link.symlink_to(code.resolve())
    env = dict(os.environ)
    env["PYTHONPATH"] = f"{shim}{os.pathsep}{env.get('PYTHONPATH', '')}"
    return env


class Served(bench_query.Server):
    """bench_query's server, started with `code`'s own shim."""

    def __init__(self, url: str, code: Path) -> None:
        self.port = bench_query._free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.proc = subprocess.Popen(
            [sys.executable, bench_query.__file__, "--serve", url, str(self.port)],
            cwd=code, env=_env(code))


def _sql(url: str, *statements: str) -> None:
    from sqlalchemy import create_engine, text

    engine = create_engine(url)
    try:
        with engine.begin() as conn:
            for statement in statements:
                conn.execute(text(statement))
    finally:
        engine.dispose()


def _set_state(url: str, state: str) -> None:
    status, final = ("running", "false") if state == "running" else ("done", "true")
    _sql(url, f"UPDATE explorations SET status = '{status}', manifolds_final = {final} "
              "WHERE id = 1", "DELETE FROM map_pictures")


def _draw_ahead(url: str, code: Path, state: str) -> float | None:
    out = subprocess.run([sys.executable, "-c", _DRAW_AHEAD, url, state], cwd=code,
                         env=_env(code), check=True, capture_output=True, text=True)
    last = out.stdout.strip().splitlines()[-1]
    return None if last == "none" else float(last)


def _get(server: Served, path: str) -> tuple[float, float, bytes]:
    cpu = server.cpu_s()
    start = time.perf_counter()
    response = httpx.get(f"{server.base}/explorations/1/{path}", timeout=600)
    wall = (time.perf_counter() - start) * 1000
    response.raise_for_status()
    return wall, (server.cpu_s() - cpu) * 1000, response.content


SETTLE_S = 4.0  # --settle-s
THINK_S = 0.0  # --think-s


def _one_code(url: str, code: Path, state: str, out: dict[str, list[float]],
              pngs: dict[str, bytes], prefix: str) -> None:
    _set_state(url, state)
    ahead = _draw_ahead(url, code, state)
    if ahead is not None:
        out.setdefault(f"draw_ahead_ms_{prefix}", []).append(ahead)
    with Served(url, code) as server:
        time.sleep(SETTLE_S)
        cpu0 = server.cpu_s()
        for k, (name, path) in enumerate(PICTURES.items()):
            if k == 1:
                time.sleep(THINK_S)  # a viewer looking at the default picture first
            wall, cpu, png = _get(server, path)
            out.setdefault(f"{name}_seq_ms_{prefix}", []).append(wall)
            out.setdefault(f"{name}_seq_server_cpu_ms_{prefix}", []).append(cpu)
            pngs[name] = png
        # The server's CPU over the three, the think time's included (work done ahead).
        out.setdefault(f"seq_total_server_cpu_ms_{prefix}", []).append(
            (server.cpu_s() - cpu0) * 1000)
    for name in ("vertical", "phi60"):
        with Served(url, code) as server:
            time.sleep(SETTLE_S)
            wall, cpu, _ = _get(server, PICTURES[name])
            out.setdefault(f"{name}_alone_ms_{prefix}", []).append(wall)
            out.setdefault(f"{name}_alone_server_cpu_ms_{prefix}", []).append(cpu)


def _pixels(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGBA"))


def main() -> int:
    global SETTLE_S, THINK_S
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before-code", type=Path, required=True,
                        help="the code before the change (`git archive REV` unpacked)")
    parser.add_argument("--after-code", type=Path, default=REPO,
                        help="the code after it (default: this checkout)")
    parser.add_argument("--sizes", default="10k,100k", help="SQLite sizes (bench_query's)")
    parser.add_argument("--pg-sizes", default="100k", help="PostgreSQL sizes")
    parser.add_argument("--keep", type=Path, default=bench_query.DEFAULT_KEEP)
    parser.add_argument("--pg-db", default=bench_query.PG_DB)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--results", default="map_picture")
    parser.add_argument("--settle-s", type=float, default=SETTLE_S,
                        help="wait this long after a server answers before asking for a "
                        "picture (a started coordinator, not one still starting)")
    parser.add_argument("--think-s", type=float, default=THINK_S,
                        help="in seq, wait this long after the default picture before asking "
                        "for the next (a viewer shown the default picture first; default 0)")
    args = parser.parse_args()
    SETTLE_S, THINK_S = args.settle_s, args.think_s
    bench_query.PG_DB = args.pg_db
    figures: dict[str, float] = {"load_avg_1min_start": bench_query._load(),
                                 "think_s": THINK_S}
    rounds: dict[str, list[float]] = {}
    targets = [(size, f"sqlite:///{args.keep / f'query_{size}.db'}", f"{size}_sqlite")
               for size in filter(None, args.sizes.split(","))]
    targets += [(size, bench_query._pg_url(size, False), f"{size}_pg")
                for size in filter(None, args.pg_sizes.split(","))]
    codes = {"before": args.before_code, "after": args.after_code}
    for _size, url, tag in targets:
        if bench_query._pose_count(url) == 0:
            raise SystemExit(f"{tag}: no finished map at {url}: build it with bench_query.py "
                             "--build-only (same --keep/--pg-db)")
        figures[f"poses_{tag}"] = bench_query._pose_count(url)
        try:
            for state in ("running", "finished"):
                for k in range(args.rounds):
                    order = ["before", "after"] if k % 2 == 0 else ["after", "before"]
                    pngs: dict[str, dict[str, bytes]] = {}
                    for which in order:
                        pngs[which] = {}
                        _one_code(url, codes[which], state, rounds, pngs[which],
                                  f"{tag}_{state}_{which}")
                    for name in PICTURES:
                        a, b = _pixels(pngs["before"][name]), _pixels(pngs["after"][name])
                        differ = -1 if a.shape != b.shape else int((a != b).any(axis=-1).sum())
                        key = f"pixels_differing_{name}_{tag}_{state}"
                        figures[key] = max(figures.get(key, 0), differ)
                    print(tag, state, k, {n: round(v[-1]) for n, v in rounds.items()
                                          if tag in n and state in n and "seq_ms" in n},
                          flush=True)
        finally:
            _set_state(url, "finished")  # as built
        figures[f"load_avg_1min_after_{tag}"] = bench_query._load()
    for name, values in rounds.items():
        figures[name] = round(statistics.median(values), 1)
    figures["load_avg_1min_end"] = bench_query._load()
    write_results(args.results, figures, extra={
        "rounds": {name: [round(v, 1) for v in values] for name, values in rounds.items()},
        "before_code": str(args.before_code), "after_code": str(args.after_code),
        "note": ("first reads of map.png in fresh uvicorn servers (bench_query.serve), "
                 "NAME_seq: default, then (think_s later) cut=vertical, then "
                 "cut=vertical&phi0_deg=60 in one server; NAME_alone: that picture alone in "
                 "a fresh server; server_cpu: the "
                 "server process's user+system CPU for the request; draw_ahead: the code's "
                 "own draw-ahead (off the read path) where it has one; median over rounds, "
                 "rounds alternate which code goes first; a shared 2-core machine (other "
                 "sessions' load: load_avg_*)")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
