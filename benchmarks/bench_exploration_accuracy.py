"""Adaptive exploration against a dense uniform grid at its finest step.

For each object (mug, cube) and each number of roll attitudes (1, 2, 4, 8), the adaptive
exploration (coarse pass Δθ = 30°, r 0–2 cm by 1 cm, one refinement level: finest step 15°
and 0.5 cm) is compared with the dense grid of every finest-level pose:

- manifold agreement: IoU by volume of reference-point cells × attitudes, manifolds matched
  one-to-one by overlap (greedy, largest first); viable-area IoU alongside;
- evaluations used: poses the adaptive run simulated / poses of the dense grid;
- time: CPU seconds of the poses each map needs (measured per pose when simulated) over 2
  processes, plus, for the adaptive run, its measured store and decision time;
- the reference's own reproducibility: the 1-roll dense map against the same grid simulated
  with the object moved 1 µm (IoU as above), the ceiling of any agreement with it.

The dense grid is simulated once per object, at 8 rolls (whose attitudes include those of 1,
2 and 4 rolls), and every adaptive run reads its evaluations from it: an evaluation is a pure
function of pose, object, gripper and settings, so this is what the adaptive run would have
computed, and it keeps the whole benchmark within ~30 min on 2 cores. Each configuration is
run plain, with each shortcut alone, and with all of them. All runs of one object, and its
dense grid, share the lattice that the symmetry shortcut gives the object (ring azimuth
counts a multiple of its symmetry order: 4 for the cube, 1 for the mug).

Run: python -m benchmarks.bench_exploration_accuracy [--objects mug cube] [--rolls 1 2 4 8]
     [--levels 2]  (a second depth: finest 7.5° and 0.25 cm, its own results file)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from graspscape.services.coordinator import db
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.service import compute_map
from graspscape.services.coordinator.manifolds.summary import build_map
from graspscape.services.coordinator.objects.service import create_named
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.services.local.run import pybullet_evaluator, run_local
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.results import PoseResult
from graspscape.workers.sim.configuration_inference import DonorPool, inferred
from sqlalchemy import select

try:
    from benchmarks._results import RESULTS_DIR, write_results
except ModuleNotFoundError:  # run as a script: benchmarks/ itself is on sys.path
    from _results import RESULTS_DIR, write_results

GRID = {"dtheta": math.radians(30), "r_min": 0.0, "r_max": 0.02, "dr": 0.01}
LEVELS = 1  # the default depth; --levels 2 writes exploration_accuracy_levels2.json
PROCESSES = 2


VARIANTS = {  # shortcuts switched on, measured one at a time, then all together
    "plain": {},
    "normal_reuse": {"normal_reuse": True},
    "configuration": {"configuration_inference": True},
    "symmetry": {"symmetry": True},
    "all": {"normal_reuse": True, "configuration_inference": True, "symmetry": True},
}


def azimuth_multiple_of(name: str) -> int:
    """The lattice's azimuth multiple that the symmetry shortcut gives this object; every
    variant, and the dense grid, use it, so that all of them share one lattice."""
    from graspscape.services.coordinator.exploration import symmetry
    from graspscape.services.coordinator.objects.geometry import spec_mesh
    from graspscape.services.local.compose import wire
    from graspscape.shared.specs.gripper import load_gripper

    wire()  # the coordinator sees the object as the workers prepare it
    mesh = spec_mesh(ObjectSpec(name=name))
    usable = symmetry.task_symmetries(symmetry.detect(mesh), load_gripper("robotiq_3f"))
    return symmetry.azimuth_multiple(usable)


def _spec(object_id: int, rolls: int, multiple: int, variant: str = "plain",
          levels: int = LEVELS) -> ExplorationSpec:
    return ExplorationSpec(
        object_id=object_id, label="accuracy",
        grid={**GRID, "attitudes": {"rolls": rolls}, "azimuth_multiple": multiple},
        refinement={"levels": levels, "local_search_rounds": 2},
        shortcuts=VARIANTS[variant],
    )


def _simulator_digest() -> str:
    """A digest of everything a pose's result depends on besides the pose: the simulator's
    code, the gripper configs and the specs, so a kept dense pass is never reused after any
    of them changed."""
    root = Path(__file__).resolve().parent.parent
    digest = hashlib.sha256()
    for folder, pattern in (("workers/sim", "*.py"), ("shared/specs", "*.py"),
                            ("configs/grippers", "*.toml")):
        for file in sorted((root / folder).rglob(pattern)):
            digest.update(file.relative_to(root).as_posix().encode())
            digest.update(file.read_bytes())
    return digest.hexdigest()[:12]


def dense_results(name: str, pool, cache_dir: Path, rolls: int, multiple: int,
                  levels: int = LEVELS) -> tuple[dict[str, PoseResult], float]:
    """Every finest-level pose at `rolls` rolls, simulated once (kept on disk between runs
    of the same simulator)."""
    depth = "" if levels == LEVELS else f"-l{levels}"
    path = cache_dir / f"dense-{name}-q{multiple}{depth}-{_simulator_digest()}.jsonl"
    lattice = Lattice(_spec(1, rolls, multiple).grid, levels)
    poses = [lattice.pose(p) for p in _fine_points(lattice)]
    done: dict[str, PoseResult] = {}
    if path.exists():
        for line in path.read_text().splitlines():
            r = PoseResult.model_validate_json(line)
            done[r.pose_key] = r
    todo = [p for p in poses if p.key() not in done]
    t0 = time.perf_counter()
    evaluate = pybullet_evaluator(ObjectSpec(name=name), pool=pool)
    with path.open("a") as out:
        for start in range(0, len(todo), 200):
            for r in evaluate(todo[start : start + 200]):
                done[r.pose_key] = r
                out.write(r.model_dump_json() + "\n")
            print(f"  dense {name}: {len(done)}/{len(poses)}", flush=True)
    wall = time.perf_counter() - t0
    meta = path.with_suffix(f".{rolls}.wall")
    if todo:
        previous = float(meta.read_text()) if meta.exists() else 0.0
        meta.write_text(str(previous + wall))
    return done, float(meta.read_text()) if meta.exists() else wall


def _fine_points(lattice: Lattice):
    from graspscape.services.coordinator.exploration.lattice import Point

    n_i = (lattice.n_r << lattice.depth) + 1
    return [Point(K, J, i, a) for K, J in lattice.cells(lattice.depth) for i in range(n_i)
            for a in range(len(lattice.attitudes))]


class _Row:
    """A PoseResult seen as a stored row (what StoredPose.from_row reads)."""

    def __init__(self, r: PoseResult) -> None:
        self.pose_key, self.viable, self.outcome = r.pose_key, r.viable, r.outcome.value
        p = r.pose
        self.theta, self.phi, self.r, self.roll, self.pitch, self.yaw = (
            p.theta, p.phi, p.r, p.roll, p.pitch, p.yaw)
        self.mu_s, self.effort_max_nm, self.worker_id = r.mu_s, r.effort_max_nm, "dense"
        self.signature = r.signature.model_dump(mode="json") if r.signature else None
        self.grasp = r.grasp.model_dump(mode="json") if r.grasp else None


def agreement_of(lattice, reference, other) -> tuple[float, float]:
    """`agreement` of two maps' fine labels over the same lattice (points in any order)."""
    index = {p: i for i, p in enumerate(other.points)}
    order = np.array([index[p] for p in reference.points])
    return agreement(lattice, reference.labels, other.labels[order], reference.weights)


def agreement(lattice, dense_labels, adaptive_labels, weights) -> tuple[float, float]:
    """(manifold IoU, viable IoU) by volume over the finest lattice."""
    either = (dense_labels >= 0) | (adaptive_labels >= 0)
    both = (dense_labels >= 0) & (adaptive_labels >= 0)
    viable_iou = weights[both].sum() / max(weights[either].sum(), 1e-30)
    pairs: dict[tuple[int, int], float] = {}
    for d, a, w in zip(dense_labels[both], adaptive_labels[both], weights[both], strict=True):
        pairs[(int(a), int(d))] = pairs.get((int(a), int(d)), 0.0) + w
    matched: dict[int, int] = {}
    used: set[int] = set()
    for (a, d), _ in sorted(pairs.items(), key=lambda kv: -kv[1]):
        if a not in matched and d not in used:
            matched[a] = d
            used.add(d)
    agree = np.array([matched.get(int(a), -2) == int(d)
                      for a, d in zip(adaptive_labels, dense_labels, strict=True)])
    iou = weights[both & agree].sum() / max(weights[either].sum(), 1e-30)
    return float(iou), float(viable_iou)


def differing_pairs(lattice, samples: dict) -> dict[int, tuple[float, float]]:
    """For each level L of the lattice: (share of level-L neighbour pairs of the dense map
    that differ in viability or grasp type, share that differ in viability), over the points
    that exist at level L. Where borders are smooth surfaces this halves from one level to the
    next (border cells grow as area, the grid as volume), which is what lets refinement skip
    most of the grid; where it does not, no border method can."""
    from graspscape.services.coordinator.manifolds.behaviour import differs

    shares = {}
    for level in range(lattice.depth + 1):
        seen: set[frozenset] = set()
        border = viability = 0
        for p, a in samples.items():
            if lattice.birth(p) > level:
                continue
            for _, q in lattice.neighbours(p, level):
                b = samples.get(q)
                if b is None or frozenset((p, q)) in seen:
                    continue
                seen.add(frozenset((p, q)))
                border += differs(a, b)
                viability += a.viable != b.viable
        pairs = len(seen)
        shares[level] = (border / max(pairs, 1), viability / max(pairs, 1))
    return shares


def with_configuration_inference(results: list[PoseResult], match) -> list[PoseResult]:
    """What a worker with shortcut 2 returns for a tile whose plain results are `results`.
    Synthesis is deterministic and the shortcut leaves it alone, so a pose's own synthesized
    grasp is the plain result's; a match takes the donor's outcome, μs and effort, and costs
    the plain evaluation's time less its trajectory and probes."""
    pool = DonorPool(match)
    out = []
    for r in results:
        donor = None if r.grasp is None or r.signature is None else pool.find(
            r.pose, r.grasp, r.signature.links_in_contact)
        if donor is None:
            pool.add(r)
            out.append(r)
            continue
        copy = inferred(r, donor)
        spent = r.eval_time_s - r.phases.trajectory_s - r.phases.sensitivity_s
        out.append(copy.model_copy(update={"eval_time_s": spent}))
    return out


def run_config(name: str, rolls: int, multiple: int, variant: str,
               dense: dict[str, PoseResult], radius, levels: int = LEVELS) -> dict[str, float]:
    url = f"sqlite:///{tempfile.mkdtemp()}/bench.db"
    db.upgrade(url)
    sessions = db.make_sessionmaker(db.make_engine(url))
    with sessions() as s:
        obj, _ = create_named(s, name=name, properties={}, shared_dir=None)
        spec = _spec(obj.id, rolls, multiple, variant, levels)
        eid = create_exploration(s, spec=spec, tile_target_poses=60, max_poses=10**7).id

    def evaluate(poses, match=None):
        if match is None:
            return [dense[p.key()] for p in poses]
        return with_configuration_inference([dense[p.key()] for p in poses], match)

    stats = run_local(sessions, evaluate, workers=2, seed=rolls)
    with sessions() as s:
        computed = compute_map(s, eid)
        rows = s.execute(select(PoseRow.pose_key, PoseRow.worker_id, PoseRow.inferred_from)
                         .where(PoseRow.exploration_id == eid)).all()
    evaluated = [k for k, w, _ in rows if not (w or "").startswith("shortcut:")]
    reused = {k for k, _, source in rows if source}
    lattice = computed.lattice
    fine_pts = _fine_points(lattice)
    dense_samples = {p: StoredPose.from_row(_Row(dense[lattice.pose(p).key()])) for p in fine_pts}
    dense_map, dense_fine, _ = build_map(lattice, dense_samples, radius)
    iou, viable_iou = agreement_of(lattice, dense_fine, computed.fine)
    # A pose that reused a matching grasp's outcome (shortcut 2) was simulated up to its
    # synthesized grasp: it costs that part only, and counts as an evaluation.
    cpu = sum(dense[k].eval_time_s - (dense[k].phases.trajectory_s
                                      + dense[k].phases.sensitivity_s if k in reused else 0.0)
              for k in evaluated)
    dense_cpu = sum(dense[lattice.pose(p).key()].eval_time_s for p in fine_pts)
    return {
        "iou": round(iou, 4),
        "viable_iou": round(viable_iou, 4),
        "evaluations": len(evaluated),
        "inferred": len(rows) - len(evaluated),
        "trajectory_reused": len(reused),
        "dense_poses": len(fine_pts),
        "evaluation_share": round(len(evaluated) / len(fine_pts), 4),
        "manifolds_adaptive": len(computed.map.manifolds),
        "manifolds_dense": len(dense_map.manifolds),
        "adaptive_eval_cpu_s": round(cpu, 1),
        "adaptive_store_wall_s": round(stats.wall_s - stats.eval_s, 1),
        "adaptive_wall_estimate_s": round(cpu / PROCESSES + stats.wall_s - stats.eval_s, 1),
        "dense_eval_cpu_s": round(dense_cpu, 1),
    }


_MOVED: dict[str, object] = {}


def _evaluate_moved(args: tuple[str, list]) -> list[str]:
    """Poses of one object evaluated with the object, and so every pose, moved 1 µm in the
    world (one evaluator per process)."""
    from graspscape.shared.specs.gripper import load_gripper
    from graspscape.workers.sim.evaluate import Evaluator, default_cache_dir
    from graspscape.workers.sim.objects import prepare_object

    name, poses = args
    if name not in _MOVED:
        prepared = prepare_object(ObjectSpec(name=name), default_cache_dir() / "objects")
        _MOVED[name] = Evaluator(prepared, load_gripper("robotiq_3f"),
                                 work_dir=default_cache_dir(), world_offset=(1e-6, 0.0, 0.0))
    return [_MOVED[name].evaluate(p).model_dump_json() for p in poses]


def reproducibility(name: str, pool, multiple: int, dense: dict[str, PoseResult],
                    radius) -> tuple[float, float]:
    """(manifold IoU, viable IoU) of the 1-roll dense map against the same grid simulated
    with the object moved 1 µm: how far the reference itself is reproducible, which bounds
    what any exploration can agree with it."""
    lattice = Lattice(_spec(1, 1, multiple).grid, LEVELS)
    points = _fine_points(lattice)
    poses = [lattice.pose(p) for p in points]
    chunks = [(name, poses[i : i + 50]) for i in range(0, len(poses), 50)]
    moved = {}
    for out in pool.map(_evaluate_moved, chunks):
        for text in out:
            r = PoseResult.model_validate_json(text)
            moved[r.pose_key] = r
    maps = []
    for source in (dense, moved):
        samples = {p: StoredPose.from_row(_Row(source[lattice.pose(p).key()])) for p in points}
        maps.append(build_map(lattice, samples, radius)[1])
    return agreement_of(lattice, *maps)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objects", nargs="+", default=["mug", "cube"])
    parser.add_argument("--rolls", nargs="+", type=int, default=[1, 2, 4, 8])
    parser.add_argument("--levels", type=int, default=LEVELS,
                        help="refinement levels below the 30° coarse pass (the dense grid is "
                        "at the finest); other than 1, the figures go to "
                        "exploration_accuracy_levels<N>.json")
    parser.add_argument("--merge", action="store_true",
                        help="keep the other configurations' rows of the existing results file")
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "gs-bench",
                        help="where the dense pass is kept between runs")
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    from graspscape.services.coordinator.manifolds.service import radius_function
    from graspscape.services.coordinator.objects.geometry import spec_mesh

    figures: dict[str, float] = {}
    table: list[dict] = []
    dense_walls: dict[str, float] = {}
    multiples: dict[str, int] = {}
    levels = args.levels
    results_name = "exploration_accuracy" + ("" if levels == LEVELS else f"_levels{levels}")
    previous = RESULTS_DIR / f"{results_name}.json"
    if args.merge and previous.exists():
        # Keep the rows of configurations this invocation does not recompute.
        old = json.loads(previous.read_text())
        redo = {(o, r) for o in args.objects for r in args.rolls}
        table = [row for row in old.get("table", []) if (row["object"], row["rolls"]) not in redo]
        figures = {k: v for k, v in old.get("figures", {}).items()
                   if (k.split(".")[0], int(k.split(".")[1].removeprefix("rolls"))) not in redo}
        dense_walls = old.get("dense_pass_wall_s_this_invocation", {})
        multiples = dict(old.get("setup", {}).get("azimuth_multiple", {}))
    with ProcessPoolExecutor(PROCESSES) as pool:
        for name in args.objects:
            top = max(args.rolls)
            multiples[name] = multiple = azimuth_multiple_of(name)
            dense, dense_wall = dense_results(name, pool, args.cache, top, multiple, levels)
            if dense_wall > 0.0:  # 0: kept from a run at more rolls; its time stays
                dense_walls[name] = round(dense_wall, 1)
            radius = radius_function(spec_mesh(ObjectSpec(name=name)))
            lattice1 = Lattice(_spec(1, 1, multiple, levels=levels).grid, levels)
            samples1 = {p: StoredPose.from_row(_Row(dense[lattice1.pose(p).key()]))
                        for p in _fine_points(lattice1)}
            for level, (border, viability) in differing_pairs(lattice1, samples1).items():
                step = f"{30.0 / 2**level:g}deg"
                figures[f"{name}.rolls1.dense_pairs_differing_share_at_{step}"] = round(border, 4)
                figures[f"{name}.rolls1.dense_pairs_differing_viability_share_at_{step}"] = round(
                    viability, 4)
            if 1 in args.rolls and levels == LEVELS:  # at depth 2 it would double the run
                iou, viable_iou = reproducibility(name, pool, multiple, dense, radius)
                figures[f"{name}.rolls1.dense_reproducibility_iou_moved_1um"] = round(iou, 4)
                figures[f"{name}.rolls1.dense_reproducibility_viable_iou_moved_1um"] = round(
                    viable_iou, 4)
                print(f"{name}: 1-roll dense map vs moved 1 µm: IoU {iou:.4f}", flush=True)
            for rolls in args.rolls:
                for variant in VARIANTS:
                    row = run_config(name, rolls, multiple, variant, dense, radius, levels)
                    # the dense pass at r rolls is the 8-roll pass's share of its attitudes
                    # Both estimates on one footing: measured CPU seconds over 2 processes
                    # (+ the adaptive run's measured store and decision time).
                    row["dense_wall_estimate_s"] = round(row["dense_eval_cpu_s"] / PROCESSES, 1)
                    row.update(object=name, rolls=rolls, shortcuts=variant)
                    table.append(row)
                    table.sort(key=lambda r: (r["object"], r["rolls"],
                                              list(VARIANTS).index(r["shortcuts"])))
                    tag = f"{name}.rolls{rolls}.{variant}"
                    for key in ("iou", "viable_iou", "evaluation_share",
                                "adaptive_wall_estimate_s", "dense_wall_estimate_s"):
                        figures[f"{tag}.{key}"] = row[key]
                    print(json.dumps(row), flush=True)
                    write_results(results_name, figures, {
                        "setup": {"grid": GRID, "refinement_levels": levels,
                                  "finest_step_deg": 30.0 / 2**levels,
                                  "finest_dr_m": GRID["dr"] / 2**levels,
                                  "processes": PROCESSES, "gripper": "robotiq_3f",
                                  "azimuth_multiple": multiples},
                        "dense_pass_wall_s_this_invocation": dense_walls,
                        "note": "the dense grid is simulated once per object (kept between "
                        "invocations); each configuration reads its attitudes from it. Times: "
                        "CPU seconds of the poses each map needs / 2 processes.",
                        "table": table,
                    })


if __name__ == "__main__":
    main()
