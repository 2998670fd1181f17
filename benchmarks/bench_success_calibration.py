"""Does P(success) predict fresh survival? Calibration of the sequential, raced certification.

Per object: one default `graspscape explore` run (20°, r 1–3 cm, one refinement level, one
roll, the exploration's torque margin on every held pose) with its certification stage off
(the uncertified run). Per uncertainty model (`lab`, `field`): in each large manifold, the
robust map's best candidates (robust order: label, q_δ, μs) race for draws
(mapspace/success.py: Clopper–Pearson bounds, Bonferroni spending over the looks 12/24/48/96,
LUCB racing); a draw is an outcome-only simulation (workers/sim/samples.py) of the start pose
moved by one draw of the model, with the model's friction, mass and effort scales; success =
held with the centre's grasp type. The poses scored: the top 3 per large manifold by each
ranking (p_success: the raced lower bound; robust; mu_s; torque_margin) and `--random` random
held poses; every one gets the sequential rule's estimate (draws beyond the race are for the
measurement only, not counted as the run's cost), and a fresh check of `--fresh` new draws of
the same model from another stream ("fresh", never used by the run).

Figures (per object and model, and pooled): top-1 / top-3 fresh survival per ranking, the
calibration error (|k/n − fresh frequency|, mean over poses with n ≥ 30), the Brier score, the
AUC of each score for fresh survival ≥ 0.9, the share of certified claims whose fresh survival
is below the level, the race's draws over the uncertified run's evaluations, wall time.
"""

from __future__ import annotations

import argparse
import math
import os
import random
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from graspscape.services.coordinator import db
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.behaviour import digit
from graspscape.services.coordinator.manifolds.grouping import FALLBACK_RADIUS, surface_radii
from graspscape.services.coordinator.manifolds.service import compute_map
from graspscape.services.coordinator.manifolds.summary import robust_order
from graspscape.services.coordinator.mapspace import success
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.services.local.compose import store_object
from graspscape.services.local.defaults import DEFAULT_DTHETA_DEG, DEFAULT_LEVELS, DEFAULT_R
from graspscape.services.local.run import pybullet_evaluator, run_local
from graspscape.shared.specs.exploration import (
    EXPLORATION_ROBUSTNESS,
    CertificationSpec,
    ExplorationSpec,
    PoseGridSpec,
    RefinementSpec,
)
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.specs.uncertainty import UncertaintyModel, draws, perturbed
from sqlalchemy import select

from benchmarks._results import write_results
from benchmarks.success_figures import figures_of, reliability_png

RANKINGS = ("p_success", "robust", "mu_s", "torque_margin")
CANDIDATES = 4  # per large manifold, the robust map's best, raced


def _draw_one(args: tuple) -> tuple[bool, bool]:
    """(held at all, held with the centre's grasp type) of one draw."""
    from graspscape.workers.sim.evaluate import _evaluator
    from graspscape.workers.sim.samples import sample
    name, pose, digits, scales = args
    ev = _evaluator(ObjectSpec(name=name), "robotiq_3f",
                    SimSettings(robustness=EXPLORATION_ROBUSTNESS),
                    Path(tempfile.gettempdir()) / "gs-i32-cal")
    s = sample(ev, pose, friction_scale=scales[0], mass_scale=scales[1], effort_scale=scales[2])
    return s.held, s.held and frozenset(digit(x) for x in s.links) == digits


class Drawer:
    """Draws of one object's poses under one model, simulated in the pool, counted."""

    def __init__(self, name: str, model: UncertaintyModel, pool, radius, info) -> None:
        self.name, self.model, self.pool, self.radius, self.info = name, model, pool, radius, info
        self.outcomes: dict[tuple[str, str], list[tuple[bool, bool]]] = {}
        self.spent = {"run": 0, "fresh": 0, "measure": 0}

    def extend(self, wanted: dict[str, int], stream: str, purpose: str) -> None:
        """Brings every pose key's draws of `stream` up to the wanted count."""
        jobs, owners = [], []
        for key, n in wanted.items():
            have = self.outcomes.setdefault((key, stream), [])
            pose, digits = self.info[key]
            for d in draws(key, self.model, n - len(have), start=len(have), stream=stream):
                jobs.append((self.name, perturbed(pose, d, self.radius(pose)), digits,
                             (d.friction_scale, d.mass_scale, d.effort_scale)))
                owners.append(key)
        for key, out in zip(owners, self.pool.map(_draw_one, jobs, chunksize=4), strict=True):
            self.outcomes[(key, stream)].append(out)
        self.spent[purpose] += len(jobs)

    def estimate(self, key: str) -> success.Estimate:
        return success.estimate([ok for _, ok in self.outcomes.get((key, "run"), [])])

    def run_rule(self, keys: list[str], purpose: str) -> None:
        """The sequential rule on each key until it is done."""
        while True:
            todo = {}
            for k in keys:
                e = self.estimate(k)
                nxt = success.next_look(e.n)
                if not e.done and nxt is not None:
                    todo[k] = nxt
            if not todo:
                return
            self.extend(todo, "run", purpose)

    def race(self, keys: list[str], room: int) -> None:
        """LUCB steps until the race is decided or `room` draws are spent (a look cut short
        by the budget counts only once complete: `success.estimate`)."""
        start = self.spent["run"]
        while True:
            chosen = success.race([self.estimate(k) for k in keys])
            left = room - (self.spent["run"] - start)
            if not chosen or left <= 0:
                return
            wanted = {}
            for i in chosen:
                have = self.estimate(keys[i]).n
                take = min(success.next_look(have) - have, left)
                if take > 0:
                    wanted[keys[i]] = have + take
                    left -= take
            self.extend(wanted, "run", "run")


def sample_cost(name: str, n: int) -> dict[str, float]:
    """CPU time of an outcome-only draw against a full evaluation as an exploration runs it
    (μs probes and the torque margin on held poses), over the same n poses, in this process."""
    from graspscape.workers.sim.evaluate import _evaluator
    from graspscape.workers.sim.samples import sample
    ev = _evaluator(ObjectSpec(name=name), "robotiq_3f",
                    SimSettings(robustness=EXPLORATION_ROBUSTNESS),
                    Path(tempfile.gettempdir()) / "gs-i32-cal")
    rng = random.Random(5)
    poses = [Pose(theta=math.acos(rng.uniform(-1, 1)), phi=rng.uniform(0, 2 * math.pi),
                  r=rng.choice(DEFAULT_R[:2]), roll=0.0, pitch=0.0, yaw=0.0) for _ in range(n)]
    t = time.process_time()
    full = [ev.evaluate(q) for q in poses]
    full_s = time.process_time() - t
    t = time.process_time()
    fast = [sample(ev, q) for q in poses]
    fast_s = time.process_time() - t
    same = sum(a.outcome == b.outcome for a, b in zip(full, fast, strict=True)) / n
    return {"full_evaluation_cpu_ms": round(1000 * full_s / n, 1),
            "sample_cpu_ms": round(1000 * fast_s / n, 1),
            "sample_cost_share": round(fast_s / full_s, 3),
            "sample_outcome_agreement_share": round(same, 3),
            "sample_cost_poses": n,
            "sample_cost_held_share": round(sum(r.viable for r in full) / n, 3)}


def explore(name: str, pool, dtheta_deg: float, levels: int) -> tuple[dict, dict]:
    """The uncertified default run: its map's poses and its counts."""
    url = f"sqlite:///{tempfile.mkdtemp()}/bench.db"
    db.upgrade(url)
    sessions = db.make_sessionmaker(db.make_engine(url))
    with sessions() as s:
        oid = store_object(s, name)
        r0, r1, dr = DEFAULT_R
        spec = ExplorationSpec(
            object_id=oid, grid=PoseGridSpec(dtheta=math.radians(dtheta_deg),
                                             r_min=r0, r_max=r1, dr=dr),
            refinement=RefinementSpec(levels=levels),
            certification=CertificationSpec(share=0.0), label="success-calibration")
        eid = create_exploration(s, spec=spec, tile_target_poses=60, max_poses=10**7).id
    evaluate = pybullet_evaluator(ObjectSpec(name=name), settings=spec.settings, pool=pool)
    t0 = time.perf_counter()
    run_local(sessions, evaluate, workers=2, seed=0)
    wall = time.perf_counter() - t0
    with sessions() as s:
        computed = compute_map(s, eid)
        m = computed.map
        torque = dict(s.execute(select(PoseRow.pose_key, PoseRow.torque_margin_ratio).where(
            PoseRow.exploration_id == eid)).all())
        workers = dict(s.execute(select(PoseRow.pose_key, PoseRow.worker_id).where(
            PoseRow.exploration_id == eid)).all())
    evaluated = sum(1 for w in workers.values() if not (w or "").startswith("shortcut:"))
    mesh = computed.mesh
    by_key = {sp.key: sp for sp in computed.samples.values()}
    return ({"samples": by_key, "label": m.assignment, "robust": m.robust, "torque": torque,
             "large": [x.label for x in m.manifolds if x.large], "mesh": mesh},
            {"evaluations": evaluated, "explore_wall_s": round(wall, 1)})


def score_object(name: str, run: dict, counts: dict, model_name: str, pool, fresh: int,
                 n_random: int, seed: int, share: float) -> dict:
    model = UncertaintyModel(preset=model_name)
    samples, robust, torque = run["samples"], run["robust"], run["torque"]
    mesh = run["mesh"]

    def radius(pose: Pose) -> float:
        st = math.sin(pose.theta)
        u = np.array([[st * math.cos(pose.phi), st * math.sin(pose.phi), math.cos(pose.theta)]])
        return float(surface_radii(mesh, u, FALLBACK_RADIUS)[0])

    info = {k: (Pose(theta=s.theta, phi=s.phi, r=s.r, roll=s.roll, pitch=s.pitch, yaw=s.yaw),
                s.digits) for k, s in samples.items() if s.viable}
    drawer = Drawer(name, model, pool, radius, info)
    t0 = time.perf_counter()
    members: dict[int, list[str]] = {}
    for key, label in run["label"].items():
        if key in info and label in run["large"]:
            members.setdefault(label, []).append(key)
    orders = {
        "robust": lambda k: robust_order(samples[k], robust[k]) if k in robust
        else (9, 0, -samples[k].mu_s, k),
        "mu_s": lambda k: (-samples[k].mu_s, k),
        "torque_margin": lambda k: (-(torque.get(k) or 0.0), -samples[k].mu_s, k),
    }
    picks: dict[str, dict[int, list[str]]] = {r: {} for r in RANKINGS}
    budget = math.floor(share * counts["evaluations"])
    for i, (label, keys) in enumerate(sorted(members.items())):
        cands = sorted(keys, key=orders["robust"])[:CANDIDATES]
        room = -(-(budget - drawer.spent["run"]) // (len(members) - i))  # an even share
        drawer.race(cands, room)  # the certification's own draws: the run's cost
        picks["p_success"][label] = sorted(cands, key=lambda k: (
            -drawer.estimate(k).lower, -drawer.estimate(k).p, k))[:3]
        for r in ("robust", "mu_s", "torque_margin"):
            picks[r][label] = sorted(keys, key=orders[r])[:3]
    race_s = time.perf_counter() - t0
    every = [k for keys in members.values() for k in keys]
    raced = [k for ks in picks["p_success"].values() for k in ks[:1]]
    overall = {r: min(every, key=orders[r]) if every else None for r in orders}
    overall["p_success"] = min(raced, key=lambda k: (
        -drawer.estimate(k).lower, -drawer.estimate(k).p, k)) if raced else None
    held = sorted(info)
    rng = random.Random(seed)
    randoms = rng.sample(held, min(n_random, len(held)))
    scored = sorted({k for r in picks.values() for ks in r.values() for k in ks} | set(randoms))
    drawer.run_rule(scored, "measure")
    drawer.extend({k: fresh for k in scored}, "fresh", "fresh")
    rows = []
    for k in scored:
        e = drawer.estimate(k)
        f = drawer.outcomes[(k, "fresh")]
        sc = robust.get(k)
        rows.append({
            "key": k, "manifold": run["label"].get(k), "k": e.k, "n": e.n, "p": e.p,
            "lower": e.lower, "upper": e.upper, "certified": e.certified,
            "fresh_survival": sum(ok for _, ok in f) / len(f), "fresh_n": len(f),
            "fresh_held_at_all": sum(h for h, _ in f) / len(f),
            "robust_s": None if sc is None else sc.s, "robust_q": None if sc is None else sc.q,
            "mu_s": samples[k].mu_s, "torque_margin": torque.get(k),
            "random": k in randoms,
        })
    return {"object": name, "model": model.describe(), "rows": rows, "picks": picks,
            "overall": overall,
            "draws": dict(drawer.spent), "evaluations": counts["evaluations"],
            "explore_wall_s": counts["explore_wall_s"], "score_wall_s": round(
                time.perf_counter() - t0, 1), "race_wall_s": round(race_s, 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", nargs="+",
                        default=["mug", "cube", "ycb:YcbMustardBottle", "ycb:YcbTomatoSoupCan",
                                 "ycb:YcbFoamBrick"])
    parser.add_argument("--models", nargs="+", default=["lab", "field"])
    parser.add_argument("--fresh", type=int, default=100, help="fresh draws per scored pose")
    parser.add_argument("--random", type=int, default=30, help="random held poses scored")
    parser.add_argument("--share", type=float, default=0.4,
                        help="the race's draws: at most this share of the run's evaluations")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="success_calibration")
    parser.add_argument("--dtheta-deg", type=float, default=DEFAULT_DTHETA_DEG,
                        help="the exploration's grid step (default: `graspscape explore`'s)")
    parser.add_argument("--levels", type=int, default=DEFAULT_LEVELS,
                        help="refinement levels (default: `graspscape explore`'s)")
    parser.add_argument("--sample-cost", type=int, default=40,
                        help="poses of the first object timed for the draw's cost (0: none)")
    args = parser.parse_args()
    os.environ.setdefault("GRASPSCAPE_YCB_DIR", str(Path("/work/shared/objects/ycb")))
    load_start = os.getloadavg()
    t0 = time.perf_counter()
    results: list[dict] = []
    cost = sample_cost(args.objects[0], args.sample_cost) if args.sample_cost else {}
    print(f"cost: {cost}", flush=True)
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for name in args.objects:
            run, counts = explore(name, pool, args.dtheta_deg, args.levels)
            print(f"{name}: explored, {counts}", flush=True)
            for model in args.models:
                res = score_object(name, run, counts, model, pool, args.fresh, args.random,
                                   seed=20261205, share=args.share)
                results.append(res)
                print(f"{name} {model}: {res['draws']} {res['score_wall_s']} s", flush=True)
                # Written after every object and model: a run cut short keeps what it did.
                _write(args, results, cost, load_start, time.perf_counter() - t0)


def _sizing(args: argparse.Namespace) -> str:
    """What this run left out of the full design, and why, in words."""
    parts = []
    if args.fresh < 100:
        parts.append(f"{args.fresh} fresh draws per scored pose instead of 100")
    if args.random < 30:
        parts.append(f"{args.random} random held poses instead of 30")
    if not parts:
        return "the full design"
    return ("; ".join(parts) + ": sized so that the run fits in about half an hour on a "
            "shared 2-core machine (a fresh draw costs one outcome-only simulation, ~42 ms CPU); "
            "a fresh survival from 30 draws has a standard error up to 0.09, so single-pose "
            "fresh figures are rough and the false-certification share counts a claim false "
            "where its 30 fresh draws fall below the level by chance too")


def _write(args: argparse.Namespace, results: list[dict], cost: dict, load_start: tuple,
           wall: float) -> None:
    figures, detail = figures_of(results, RANKINGS)
    figures.update(cost)
    png = Path(__file__).resolve().parents[1] / "docs" / "img" / "success_reliability.png"
    reliability_png(results, png)
    figures["wall_s"] = round(wall, 1)
    write_results(args.out, figures, extra={
        "per_object_model": detail,
        "setup": {"objects": args.objects, "dtheta_deg": args.dtheta_deg,
                  "levels": args.levels, "models": args.models, "fresh_draws": args.fresh,
                  "random_held": args.random, "share": args.share,
                  "candidates_per_manifold": CANDIDATES,
                  "looks": list(success.LOOKS), "level": success.LEVEL,
                  "confidence": success.CONFIDENCE, "workers": args.workers,
                  "done": [f"{r['object']} {r['model']}" for r in results]},
        "sizing": _sizing(args),
        "load_average_start": load_start, "load_average_end": os.getloadavg(),
        "reliability_png": str(png.relative_to(png.parents[2])),
        "scored": [{k: v for k, v in r.items() if k != "rows"} | {"rows": r["rows"]}
                   for r in results],
    })


if __name__ == "__main__":
    main()
