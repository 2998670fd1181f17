"""What the default run's certification costs: `graspscape explore <object>` with the defaults,
through the service (coordinator, zenoh, worker processes), then the stored exploration read
back.

The run without certification is the same run up to its first certification evaluation: the
adaptive strategy certifies only once its last search round is over and no tile is open
(exploration/strategies/adaptive.py), so every evaluation stored before the first
certification evaluation is one the run without it makes too. Everything stored after is the
certification's extra: its draws (outcome only), its core claims' N_δ members, and any border
refinement their results called for.

Figures per object: `extra_evaluation_share_default` (extra evaluations ÷ the run without
certification's; the mug's unprefixed, the others `<object>.…`), `extra_cost_share_default`
(the same in the workers' evaluation seconds: a draw costs about a third of a full
evaluation), the draws' and claims' counts, and the spec's `certification.share` it is held
to. Target: ≤ 0.40.

    python benchmarks/bench_certification_share.py --objects mug cube --procs 2
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from graspscape.services.coordinator import db
from graspscape.services.coordinator.exploration.certify_store import (
    certification_plans,
)
from graspscape.services.coordinator.exploration.specs import spec_of
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow
from sqlalchemy import select

from benchmarks._results import write_results

TARGET = 0.40


def explore(name: str, data_dir: Path, procs: int | None) -> tuple[list[str], float]:
    """Runs the default command; returns it and its wall time."""
    command = [sys.executable, "-m", "graspscape.services.local.cli", "explore", name,
               "--data-dir", str(data_dir), "--quiet"]
    if procs:
        command += ["--procs", str(procs)]
    started = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - started
    if run.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({run.returncode}):\n{run.stderr[-3000:]}")
    return command, wall


def share_of(data_dir: Path) -> dict[str, float]:
    """The certification's extra over the run without it, from the stored exploration."""
    engine = db.make_engine(f"sqlite:///{data_dir / 'coordinator.db'}")
    with db.make_sessionmaker(engine)() as session:
        row = session.scalars(select(ExplorationRow).order_by(ExplorationRow.id.desc())).first()
        spec = spec_of(row)
        plans = certification_plans(session, row.id)
        poses = session.execute(select(
            PoseRow.pose_key, PoseRow.worker_id, PoseRow.created_at, PoseRow.eval_time_s,
            PoseRow.sample.is_not(None)).where(PoseRow.exploration_id == row.id)).all()
    engine.dispose()
    evaluated = [p for p in poses if not (p.worker_id or "").startswith("shortcut:")]
    first = min((p.created_at for p in evaluated if p.pose_key in plans), default=None)
    base = [p for p in evaluated if first is None or p.created_at < first]
    extra = [p for p in evaluated if first is not None and p.created_at >= first]
    base_s = sum(p.eval_time_s for p in base)
    return {
        "extra_evaluation_share_default": round(len(extra) / len(base), 4),
        "extra_cost_share_default": round(sum(p.eval_time_s for p in extra) / base_s, 4),
        "evaluations_without_certification": len(base),
        "extra_evaluations": len(extra),
        "draws": sum(1 for p in extra if p[4]),
        "claim_evaluations": sum(1 for p in extra if p.pose_key in plans and plans[p.pose_key]
                                 is None),
        "certification_share_setting": spec.certification.share,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", nargs="+", default=["mug", "cube"])
    parser.add_argument("--procs", type=int, default=None, help="worker processes (default: "
                        "graspscape explore's, the cores)")
    args = parser.parse_args()
    figures: dict[str, float] = {}
    details: dict[str, dict] = {}
    load_before = os.getloadavg()
    for name in args.objects:
        with tempfile.TemporaryDirectory(prefix=f"gs-share-{name}-") as tmp:
            command, wall = explore(name, Path(tmp), args.procs)
            got = share_of(Path(tmp))
        got["wall_s"] = round(wall, 1)
        details[name] = {"command": " ".join(["graspscape", *command[3:]]), **got}
        prefix = "" if name == "mug" else f"{name}."
        for key in ("extra_evaluation_share_default", "extra_cost_share_default"):
            figures[prefix + key] = got[key]
        print(name, got, flush=True)
    figures["extra_evaluation_share_target"] = TARGET
    write_results("certification_share", figures, {
        "load": {"before": [round(x, 2) for x in load_before],
                 "after": [round(x, 2) for x in os.getloadavg()]},
        "details": details})


if __name__ == "__main__":
    main()
