"""Objects at rest on a table against the free-floating object: what a table leaves of a map.

For each object: its stable resting poses with their probabilities (all found, and those an
exploration on a plane explores), then one map of the free object and one on the table per
chosen resting pose, on one coarse lattice (so every pose of one map is a pose of the others),
in this process (`run_local`, pybullet). Per resting pose:

- `viable_share_on_table`: of the free map's viable poses, the share still viable on the
  table (lattice poses weighted equally);
- `large_manifolds_surviving`: of the free map's large manifolds, the share with at least one
  member pose still viable on the table;
- `evaluations_vs_free`: poses simulated on the table (a start in the table is counted, not
  simulated) per pose simulated for the free map;
- the best grasp on the table by the default ranking of `/best` (P(success) where the
  certification drew around a pose, then the robust map), with its μs, and the best μs; the
  outcome counts. The mug's best grasp at its most probable resting pose is drawn to
  docs/img/mug_best_grasp_table.png (the grasp simulated again on the table).

The object-level figures weight the resting poses by their probabilities. Run:
`nice -n 10 .venv/bin/python benchmarks/bench_support.py` (about 10 minutes on 2 loaded cores;
object names as arguments run those only).
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks._results import write_results

ROOT = Path(__file__).resolve().parents[1]

OBJECTS = ("mug", "cube", "ycb:YcbMustardBottle", "ycb:YcbFoamBrick", "ycb:YcbTomatoSoupCan")
# Coarse: 45° between approach directions, three start gaps up to 10 cm (the 3F's open
# fingertips reach 12.7 cm past the palm, so on a table a start from above clears the table
# only from r ≈ 12.7 cm − the object's height), and two rolls.
GRID = {"dtheta": math.radians(45.0), "r_min": 0.02, "r_max": 0.10, "dr": 0.04,
        "attitudes": {"rolls": 2}}


def _poses(session, exploration_id: int) -> dict[str, tuple[str, bool, float, int | None]]:
    from graspscape.services.coordinator.store.models import PoseRow
    from sqlalchemy import select

    rows = session.execute(select(PoseRow.pose_key, PoseRow.outcome, PoseRow.viable,
                                  PoseRow.mu_s, PoseRow.manifold_id)
                           .where(PoseRow.exploration_id == exploration_id))
    return {key: (outcome, viable, mu, manifold) for key, outcome, viable, mu, manifold in rows}


def _large_members(session, exploration_id: int,
                   poses: dict[str, tuple[str, bool, float, int | None]]) -> dict[int, set[str]]:
    from graspscape.services.coordinator.store.models import ManifoldRow
    from sqlalchemy import select

    large = set(session.scalars(select(ManifoldRow.id).where(
        ManifoldRow.exploration_id == exploration_id, ManifoldRow.large)))
    members: dict[int, set[str]] = {m: set() for m in large}
    for key, (_, _, _, manifold) in poses.items():
        if manifold in members:
            members[manifold].add(key)
    return members


def _object(name: str, sessions, object_id: int) -> dict:
    from graspscape.services.coordinator.exploration.service import create_explorations
    from graspscape.services.coordinator.manifolds.service import ensure_manifolds
    from graspscape.services.coordinator.objects.geometry import object_mesh
    from graspscape.services.local.run import pybullet_evaluator, run_local
    from graspscape.shared.specs.exploration import ExplorationSpec
    from graspscape.shared.specs.objects import ObjectSpec
    from graspscape.shared.specs.resting import stable_poses
    from graspscape.shared.specs.sim import SimSettings

    obj = ObjectSpec(name=name)
    with sessions() as s:
        found = stable_poses(object_mesh(s, object_id))
        free_row = create_explorations(s, spec=ExplorationSpec(object_id=object_id, grid=GRID),
                                       tile_target_poses=50, max_poses=10**7)[0]
        free_id = free_row.id
        table_rows = create_explorations(
            s, spec=ExplorationSpec(object_id=object_id, grid=GRID, support={"kind": "plane"}),
            tile_target_poses=50, max_poses=10**7)
        tables = {r.id: ExplorationSpec.model_validate(r.spec) for r in table_rows}
    evaluators = {i: pybullet_evaluator(obj, settings=SimSettings(table=spec.settings.table))
                  for i, spec in tables.items()}
    t0 = time.perf_counter()
    run_local(sessions, pybullet_evaluator(obj), evaluators=evaluators)
    wall = time.perf_counter() - t0
    with sessions() as s:
        ensure_manifolds(s, free_id)
        free = _poses(s, free_id)
        members = _large_members(s, free_id, free)
        on_table = {i: _poses(s, i) for i in tables}
        best_ranked = {i: _best_by_default(s, i) for i in tables}
    viable_free = {k for k, v in free.items() if v[1]}
    simulated_free = sum(1 for v in free.values() if v[0] != "infeasible_table")
    rests = []
    for i, spec in tables.items():
        poses = on_table[i]
        viable = {k for k, v in poses.items() if v[1]}
        resting = spec.support.resting
        best = max(((v[2], k) for k, v in poses.items() if v[1]), default=(0.0, None))
        counts = Counter(v[0] for v in poses.values())
        rests.append({
            "index": resting.index, "probability": resting.probability,
            "up_in_object_frame": [round(float(x), 4) for x in resting.up()],
            "height_m": round(resting.position[2], 4),
            "viable_share_on_table": len(viable & viable_free) / max(1, len(viable_free)),
            "viable_on_table_not_free": len(viable - viable_free),
            "large_manifolds_surviving": (sum(1 for keys in members.values() if keys & viable)
                                          / max(1, len(members))),
            "evaluations_vs_free": ((len(poses) - counts["infeasible_table"])
                                    / max(1, simulated_free)),
            "outcomes": dict(counts), "best_mu_s": best[0], "best_mu_s_pose_key": best[1],
            "best": best_ranked[i],
        })
    weight = sum(r["probability"] for r in rests) or 1.0

    def weighted(field: str) -> float:
        return sum(r["probability"] * r[field] for r in rests) / weight

    return {
        "stable_poses_found": [round(p, 4) for _, p in found],
        "resting_poses": rests, "free_poses": len(free), "free_viable": len(viable_free),
        "free_large_manifolds": len(members), "wall_s": round(wall, 1),
        "viable_share_on_table": weighted("viable_share_on_table"),
        "large_manifolds_surviving": weighted("large_manifolds_surviving"),
        "evaluations_vs_free": weighted("evaluations_vs_free"),
        "evaluations_group_vs_free": sum(r["evaluations_vs_free"] for r in rests),
        "exploration_ids": list(tables),
    }


def _best_by_default(session, exploration_id: int) -> dict | None:
    """The pose `/best` answers by default (its rank, no filter), with its numbers."""
    from graspscape.services.coordinator.manifolds import best as ranking
    from graspscape.services.coordinator.manifolds.service import ensure_manifolds

    ensure_manifolds(session, exploration_id)
    found = ranking.best_poses(session, exploration_id, limit=1,
                               rank=ranking.BEST_DEFAULT_RANK)
    if not found:
        return None
    pose = found[0]
    drawn = ranking.estimates(session, exploration_id).get(pose.pose_key)
    return {"rank": str(ranking.BEST_DEFAULT_RANK.value), "pose_id": pose.id,
            "pose_key": pose.pose_key, "theta_deg": round(math.degrees(pose.theta), 1),
            "phi_deg": round(math.degrees(pose.phi), 1), "r_m": round(pose.r, 4),
            "mu_s": pose.mu_s, "torque_margin_nm": pose.torque_margin_nm,
            "p_success": None if drawn is None else {"k": drawn.k, "n": drawn.n,
                                                     "p": drawn.p, "lower": drawn.lower}}


def _picture(sessions, found: dict, path: Path) -> str | None:
    """The best grasp (default ranking) at the most probable resting pose with one, drawn
    as the viewer draws it (the pose simulated again, on the table)."""
    from graspscape.services.coordinator.web.grasp import grasp_png

    for eid, rest in zip(found["exploration_ids"], found["resting_poses"], strict=True):
        if rest["best"] is None:
            continue
        with sessions() as s:
            path.write_bytes(grasp_png(s, eid, rest["best"]["pose_id"]))
        return f"{path.relative_to(ROOT).as_posix()} (resting pose {rest['index']})"
    return None


def main() -> None:
    from graspscape.services.local.compose import open_store, store_object, wire

    wire()
    load_before = os.getloadavg()
    started = time.perf_counter()
    details, figures = {}, {}
    only = sys.argv[1:] or OBJECTS
    with tempfile.TemporaryDirectory() as tmp:
        engine, sessions = open_store(f"sqlite:///{tmp}/support.db")
        for name in only:
            with sessions() as s:
                object_id = store_object(s, name)
            found = _object(name, sessions, object_id)
            if name == "mug":
                found["best_picture"] = _picture(sessions, found,
                                                 ROOT / "docs" / "img" / "mug_best_grasp_table.png")
            details[name] = found
            short = name.split(":")[-1].lower()
            for field in ("viable_share_on_table", "large_manifolds_surviving",
                          "evaluations_vs_free"):
                figures[f"{field}_{short}"] = round(found[field], 4)
            print(name, {k: v for k, v in found.items() if k != "resting_poses"}, flush=True)
        engine.dispose()
    write_results("support", figures, {
        "load": {"before": list(load_before), "after": list(os.getloadavg())},
        "wall_s": round(time.perf_counter() - started, 1),
        "grid": {**GRID, "dtheta_deg": 45.0}, "details": details})


if __name__ == "__main__":
    main()
