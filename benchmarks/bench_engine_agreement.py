"""Do pybullet and MuJoCo agree? The same poses in both engines (issue: a second engine).

For each object (the 6 built-ins and the 12 YCB objects of ../shared/objects), one 30° grid
(the accuracy grid: r 0–2 cm by 1 cm, one roll; every pose of the lattice's level 0) is
evaluated in pybullet and in MuJoCo with the default settings otherwise. Figures:

- same_outcome_share: both held, or both did not (the binary outcome a map is made of);
  same_outcome_class_share: the same Outcome value (held, dropped, no_grasp, ...);
- kappa: Cohen's κ of the binary outcome (agreement beyond what the two held shares give by
  chance);
- same_grasp_type_share_where_both_held: the same digits in contact;
- mu_s_spearman_where_both_held: rank correlation of μs;
- the same outcome share over the poses the pybullet map labels robust (s ≥ 0.9 over the
  pose's lattice neighbourhood: services/coordinator/manifolds/robust.py), fragile and futile.

Results are kept per object and engine in a JSON-lines cache (--cache), so a stopped run
resumes; --budget-s stops starting new objects once spent, and the figures say how many poses
were run. Pictures of disagreeing grasps: --pictures N draws N of them in both engines.

    .venv/bin/python benchmarks/bench_engine_agreement.py --budget-s 1500
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.robust import RobustLabel, robust_scores
from graspscape.shared.specs.exploration import PoseGridSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.results import Outcome, PoseResult
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.evaluate import default_cache_dir, evaluate_pose, render_pose
from graspscape.workers.sim.signature import same_grasp_type
from scipy.stats import spearmanr

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_exploration_accuracy import _fine_points, _Row

try:
    from benchmarks._results import write_results
except ModuleNotFoundError:  # run as a script from the repo root
    from _results import write_results

BUILTINS = ("sphere", "cube", "can", "dumbbell", "mug", "spiked_ball")
YCB = ("YcbBanana", "YcbChipsCan", "YcbCrackerBox", "YcbFoamBrick", "YcbGelatinBox",
       "YcbHammer", "YcbMustardBottle", "YcbPottedMeatCan", "YcbPowerDrill", "YcbStrawberry",
       "YcbTennisBall", "YcbTomatoSoupCan")
ENGINES = ("pybullet", "mujoco")
GRID = PoseGridSpec(dtheta=math.radians(30.0), r_min=0.0, r_max=0.02, dr=0.01)


def lattice() -> Lattice:
    return Lattice(GRID, 0)


def object_spec(name: str) -> ObjectSpec:
    return ObjectSpec(name=name if name in BUILTINS else f"ycb:{name}")


def run_object(name: str, cache: Path) -> dict[str, dict[str, PoseResult]]:
    """engine -> pose key -> result, evaluated where not kept in `cache`."""
    lat = lattice()
    poses = [lat.pose(p) for p in _fine_points(lat)]
    out: dict[str, dict[str, PoseResult]] = {}
    for engine in ENGINES:
        path = cache / f"agreement-{name}-{engine}.jsonl"
        done = {}
        if path.exists():
            for line in path.read_text().splitlines():
                r = PoseResult.model_validate_json(line)
                done[r.pose_key] = r
        settings = SimSettings(engine=engine)
        with path.open("a") as f:
            for pose in poses:
                if pose.key() in done:
                    continue
                r = evaluate_pose(pose, obj=object_spec(name), settings=settings)
                done[r.pose_key] = r
                f.write(r.model_dump_json() + "\n")
        out[engine] = done
    return out


def kappa(a: list[bool], b: list[bool]) -> float:
    x, y = np.array(a, dtype=float), np.array(b, dtype=float)
    observed = float(np.mean(x == y))
    chance = float(x.mean() * y.mean() + (1 - x.mean()) * (1 - y.mean()))
    return (observed - chance) / (1 - chance) if chance < 1 else 1.0


def labels(results: dict[str, PoseResult]) -> dict[str, RobustLabel]:
    """pose key -> the robust label of the pybullet map."""
    lat = lattice()
    samples = {p: StoredPose.from_row(_Row(results[lat.pose(p).key()]))
               for p in _fine_points(lat)}
    return {lat.pose(p).key(): s.label for p, s in robust_scores(lat, samples).items()}


def figures_of(by_object: dict[str, dict[str, dict[str, PoseResult]]]) -> tuple[dict, dict]:
    pb, mj, label, disagreeing = [], [], [], []
    for name, runs in by_object.items():
        marks = labels(runs["pybullet"])
        for key, a in runs["pybullet"].items():
            b = runs["mujoco"][key]
            pb.append(a)
            mj.append(b)
            label.append(marks[key])
            if a.viable != b.viable:
                disagreeing.append((name, a, b))
    held_a, held_b = [r.viable for r in pb], [r.viable for r in mj]
    same = [x == y for x, y in zip(held_a, held_b, strict=True)]
    both = [(a, b) for a, b in zip(pb, mj, strict=True) if a.viable and b.viable]
    figures = {
        "objects": len(by_object), "poses": len(pb),
        "same_outcome_share": float(np.mean(same)),
        "same_outcome_class_share": float(np.mean([a.outcome == b.outcome
                                                   for a, b in zip(pb, mj, strict=True)])),
        "kappa": kappa(held_a, held_b),
        "held_share_pybullet": float(np.mean(held_a)),
        "held_share_mujoco": float(np.mean(held_b)),
        "both_held": len(both),
        "same_grasp_type_share_where_both_held": float(np.mean(
            [same_grasp_type(a.signature, b.signature) for a, b in both])) if both else 0.0,
        "mu_s_spearman_where_both_held": float(spearmanr(
            [a.mu_s for a, _ in both], [b.mu_s for _, b in both]).statistic)
        if len(both) > 2 else 0.0,
        "mean_eval_s_pybullet": float(np.mean([r.eval_time_s for r in pb])),
        "mean_eval_s_mujoco": float(np.mean([r.eval_time_s for r in mj])),
    }
    for mark, suffix in ((RobustLabel.ROBUST, "robust"), (RobustLabel.FRAGILE, "fragile"),
                         (RobustLabel.FUTILE, "futile")):
        chosen = [s for s, m in zip(same, label, strict=True) if m == mark]
        figures[f"poses_{suffix}"] = len(chosen)
        figures[f"same_outcome_share_{suffix}"] = float(np.mean(chosen)) if chosen else 0.0
    outcomes = {e: {o.value: sum(r.outcome is o for r in rs) for o in Outcome}
                for e, rs in (("pybullet", pb), ("mujoco", mj))}
    return figures, {"outcomes": outcomes, "disagreeing": [
        {"object": n, "pose": a.pose.model_dump(), "pybullet": a.outcome.value,
         "mujoco": b.outcome.value} for n, a, b in disagreeing]}


def pictures(examples: list[dict], n: int, folder: Path) -> list[str]:
    """Pictures of the first n disagreeing poses in both engines."""
    from graspscape.shared.specs.pose import Pose

    written = []
    for ex in examples[:n]:
        pose = Pose(**ex["pose"])
        for engine in ENGINES:
            stem = f"engines-{ex['object']}-{pose.key()[:8]}-{engine}.png".replace(":", "_")
            path, _ = render_pose(pose, folder / stem, obj=object_spec(ex["object"]),
                                  settings=SimSettings(engine=engine))
            written.append(str(path))
    return written


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", help="comma-separated (default: the 6 built-ins + 12 YCB)")
    parser.add_argument("--budget-s", type=float, default=1500.0,
                        help="start no new object after this many seconds")
    parser.add_argument("--cache", type=Path, default=default_cache_dir() / "agreement")
    parser.add_argument("--pictures", type=int, default=0, metavar="N")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    load_before = os.getloadavg()
    # Built-ins and YCB objects alternate, so a run the budget cuts short still has both kinds.
    mixed = [n for pair in zip(BUILTINS, YCB[:len(BUILTINS)], strict=True) for n in pair]
    names = args.objects.split(",") if args.objects else [*mixed, *YCB[len(BUILTINS):]]
    args.cache.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    by_object = {}
    for name in names:
        if time.perf_counter() - started > args.budget_s:
            print(f"budget spent: {name} and after not run", flush=True)
            break
        by_object[name] = run_object(name, args.cache)
        print(f"{name}: done at {time.perf_counter() - started:.0f} s", flush=True)
    figures, extra = figures_of(by_object)
    figures["objects_asked"] = len(names)
    figures["wall_s"] = time.perf_counter() - started
    extra.update(objects=list(by_object), grid=GRID.model_dump(),
                 load_average_start=list(load_before), load_average_end=list(os.getloadavg()))
    if args.pictures:
        folder = Path(__file__).resolve().parents[1] / "docs" / "img"
        extra["pictures"] = pictures(extra["disagreeing"], args.pictures, folder)
    if args.no_write:
        print(figures)
    else:
        write_results("engine_agreement", figures, extra)


if __name__ == "__main__":
    main()
