"""Does μs rank grasps as a robot would experience them? (issue #16)

Held poses of the mug, cube, can and three YCB objects (seeded random poses until each object
has `--per-object` held ones) are scored by μs and the static metrics μg, μf, μm, and tested by
the robustness margins and the community's grasp tests of workers/sim/robustness.py on the
same synthesized grasp. Reported:

- Spearman rank correlation of each metric with each margin and test, and of the margins with
  one another (signs arranged so that "more robust" is larger: the friction margin enters
  negated, a lower friction being needed);
- on a subset (`--subset` held poses per object): the share of monotone sweeps of the closing
  effort τ_c and of the object's friction (each a full evaluation, the grasp synthesized again,
  as in the paper's Table 1; μs counted 0 where the pose drops; monotone = never falls by more
  than 0.05 as τ_c or friction grows), the μs change when the object is moved by
  (0.5, −0.3, 0.2) m and (10, 10, 1) m, and when window, instants, ε (linear and angular) or
  the characteristic length are halved (mean |Δμs| and rank correlation).

    .venv/bin/python benchmarks/bench_metric_validity.py      # ≈ 15 min on 2 cores
    # writes benchmarks/results/metric_validity.json
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
from graspscape.workers.sim.objects import prepare_object
from scipy.stats import spearmanr

try:
    from benchmarks._results import write_results
    from benchmarks.bench_metric_stability import halved
except ModuleNotFoundError:
    from _results import write_results
    from bench_metric_stability import halved

OBJECTS = ["mug", "cube", "can", "ycb:YcbMustardBottle", "ycb:YcbTomatoSoupCan",
           "ycb:YcbTennisBall"]
METRICS = ["mu_s", "mu_g", "mu_f", "mu_m"]
MARGINS = ["torque_margin_ratio", "neg_friction_margin", "gravity_test_share",
           "force_test_share", "tug_force_n", "shake_survival_s"]
EFFORT_FACTORS = (0.25, 0.5, 1.0, 2.0)  # × the gripper's closing effort
FRICTIONS = (0.2, 0.4, 0.6, 0.8)  # the object's lateral friction coefficient
OFFSETS = {"moved_0p5m": (0.5, -0.3, 0.2), "moved_10m": (10.0, 10.0, 1.0)}
MONOTONE_TOLERANCE = 0.05


def random_poses(seed: int):
    rng = np.random.default_rng(seed)
    while True:
        yield Pose(theta=float(np.arccos(rng.uniform(-1, 1))),
                   phi=float(rng.uniform(0, 2 * np.pi)), r=float(rng.uniform(0.01, 0.03)),
                   roll=float(rng.uniform(0, 2 * np.pi)))


def _evaluator(name: str, settings: SimSettings | None = None, friction: float | None = None,
               offset=(0.0, 0.0, 0.0)) -> Evaluator:
    cache = default_cache_dir()
    prepared = prepare_object(ObjectSpec(name=name, friction=friction), cache / "objects")
    return Evaluator(prepared, load_gripper("robotiq_3f"), settings, work_dir=cache,
                     world_offset=offset)


def _score(result) -> float:
    return result.mu_s if result.viable else 0.0


def _monotone(values: list[float]) -> bool:
    return all(b >= a - MONOTONE_TOLERANCE for a, b in itertools.pairwise(values))


def study_object(args: tuple[str, int, int, int, int]) -> dict:
    name, per_object, subset, max_attempts, seed = args
    started = time.perf_counter()
    rows: list[dict] = []
    attempts = 0
    base = SimSettings()
    with _evaluator(name, base) as evaluator:
        effort = evaluator.gripper.closing_effort
        for pose in random_poses(seed):
            if len(rows) >= per_object or attempts >= max_attempts:
                break
            attempts += 1
            result, report = evaluator.robustness(pose)
            if not result.viable or result.inferred_from:
                continue
            row = {"pose": pose, "mu_s": result.mu_s, "mu_g": result.mu_g or 0.0,
                   "mu_f": result.mu_f or 0.0, "mu_m": result.mu_m or 0.0}
            row.update({k: v for k, v in report.model_dump().items() if v is not None})
            if report.friction_margin is not None:
                row["neg_friction_margin"] = -report.friction_margin
            rows.append(row)
    sample = rows[:subset]
    # Sweeps: full evaluations with τ_c or the object's friction changed.
    for factor in EFFORT_FACTORS:
        policy = base.policy.model_copy(update={"closing_effort": factor * effort})
        with _evaluator(name, base.model_copy(update={"policy": policy})) as ev:
            for row in sample:
                row.setdefault("effort_sweep", []).append(_score(ev.evaluate(row["pose"])))
    for friction in FRICTIONS:
        with _evaluator(name, base, friction=friction) as ev:
            for row in sample:
                row.setdefault("friction_sweep", []).append(_score(ev.evaluate(row["pose"])))
    for label, offset in OFFSETS.items():
        with _evaluator(name, base, offset=offset) as ev:
            for row in sample:
                row[label] = _score(ev.evaluate(row["pose"]))
    metric = base.metric
    variants = halved(metric)
    with _evaluator(name, base) as ev:
        length = ev.length
    variants["length"] = metric.model_copy(update={"characteristic_length": length / 2})
    for label, variant in variants.items():
        with _evaluator(name, base.model_copy(update={"metric": variant})) as ev:
            for row in sample:
                row[f"halved_{label}"] = _score(ev.evaluate(row["pose"]))
    for row in rows:
        row["pose"] = row["pose"].key()
    return {"name": name, "rows": rows, "attempts": attempts,
            "seconds": time.perf_counter() - started}


def _spearman(a: list[float], b: list[float]) -> float:
    if len(a) < 3 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(spearmanr(a, b).statistic)


def summarise(studies: list[dict]) -> dict[str, float]:
    rows = [row for study in studies for row in study["rows"]]
    figures: dict[str, float] = {"held_poses": float(len(rows)),
                                 "held_poses_dropping_when_restored": float(
                                     sum("torque_margin_ratio" not in r for r in rows)),
                                 "attempted_poses": float(sum(s["attempts"] for s in studies))}
    for study in studies:
        key = study["name"].replace("ycb:", "").lower()
        figures[f"{key}.held_poses"] = float(len(study["rows"]))
        figures[f"{key}.seconds"] = study["seconds"]
    # Which cheap metric predicts the margins, and how the margins predict one another.
    for metric in [*METRICS, *MARGINS]:
        for margin in MARGINS:
            if margin == metric:
                continue
            pairs = [(r[metric], r[margin]) for r in rows if margin in r and metric in r]
            figures[f"spearman_{metric}_vs_{margin}"] = _spearman(
                [a for a, _ in pairs], [b for _, b in pairs])
    for margin in MARGINS:
        values = [r[margin] for r in rows if margin in r]
        if values:
            figures[f"mean_{margin}"] = float(np.mean(values))
    sample = [r for r in rows if "effort_sweep" in r]
    figures["sweep_poses"] = float(len(sample))
    if sample:
        figures["monotone_effort_sweep_share"] = float(np.mean(
            [_monotone(r["effort_sweep"]) for r in sample]))
        figures["monotone_friction_sweep_share"] = float(np.mean(
            [_monotone(r["friction_sweep"]) for r in sample]))
        reference = [r["mu_s"] for r in sample]
        for label in [*OFFSETS, "halved_instants", "halved_window", "halved_perturbation",
                      "halved_length"]:
            values = [r[label] for r in sample]
            change = np.abs(np.array(values) - np.array(reference))
            figures[f"mean_abs_mu_s_change_{label}"] = float(change.mean())
            figures[f"rank_correlation_{label}"] = _spearman(values, reference)
            if label in OFFSETS:
                figures[f"max_abs_mu_s_change_{label}"] = float(change.max())
                figures[f"share_mu_s_change_over_0p01_{label}"] = float(np.mean(change > 0.01))
    return {k: (v if not (isinstance(v, float) and math.isnan(v)) else None)
            for k, v in figures.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", nargs="+", default=OBJECTS)
    parser.add_argument("--per-object", type=int, default=35)
    parser.add_argument("--subset", type=int, default=12)
    parser.add_argument("--max-attempts", type=int, default=160)
    parser.add_argument("--procs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=16)
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args()
    jobs = [(name, args.per_object, args.subset, args.max_attempts, args.seed + i)
            for i, name in enumerate(args.objects)]
    started = time.perf_counter()
    with Pool(args.procs) as pool:
        studies = pool.map(study_object, jobs, chunksize=1)
    # Keep the raw rows before summing up: a summary that fails must not cost the run.
    Path("/tmp/metric_validity_rows.json").write_text(json.dumps(studies))
    figures = summarise(studies)
    figures["wall_s"] = time.perf_counter() - started
    if args.no_write:
        print(json.dumps(figures, indent=2))
    else:
        write_results("metric_validity", figures,
                      extra={"rows": {s["name"]: s["rows"] for s in studies}})


if __name__ == "__main__":
    main()
