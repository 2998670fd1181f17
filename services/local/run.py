"""Run an exploration in-process: lease, evaluate with pybullet, ingest — no network.

For tests, benchmarks and `graspscape map run` on one machine, composed as `explore` is
(`compose.wire`). `workers` simulated workers lease one tile
each per round; their reports are ingested in an order drawn from `seed`, and each tile's
results may arrive in several partial batches, so that one spec can be driven through many
interleavings (what different numbers of real workers would produce). Evaluations go through
`evaluate`, by default pybullet in this process or in a process pool; it gets a tile's poses
and, when the exploration asks for shortcut 2, its tolerance (what a worker's lease carries).
A tile of draws (wire TileSample) goes to `draw` where given (`drawer`: outcome only, as a
worker runs it), else to `evaluate` like any other tile.
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

from graspscape.services.coordinator.dispatch.catalog import configuration_match_of
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.specs import stored_spec
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.services.local.compose import wire
from graspscape.shared.specs.exploration import ConfigurationMatch
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PoseResult
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire.messages import TileSample
from sqlalchemy.orm import Session, sessionmaker

Evaluate = Callable[[Sequence[Pose], ConfigurationMatch | None], list[PoseResult]]
Draw = Callable[[Sequence[Pose], TileSample], list[PoseResult]]


@dataclass
class RunStats:
    tiles: int = 0
    evaluated: int = 0
    wall_s: float = 0.0
    eval_s: float = 0.0


def _eval_one(args: tuple[Pose, ObjectSpec, str, SimSettings]) -> PoseResult:
    from graspscape.workers.sim.evaluate import evaluate_pose

    pose, obj, gripper, settings = args
    return evaluate_pose(pose, obj=obj, gripper=gripper, settings=settings)


def _eval_normal(args: tuple[list[Pose], ObjectSpec, str, SimSettings, ConfigurationMatch]
                 ) -> list[PoseResult]:
    """The poses of one normal in tile order, with shortcut 2 among them (donors never come
    from another normal, so this equals one donor pool for the whole tile)."""
    from graspscape.workers.sim.configuration_inference import DonorPool
    from graspscape.workers.sim.evaluate import evaluate_pose

    poses, obj, gripper, settings, match = args
    donors = DonorPool(match)
    return [evaluate_pose(p, obj=obj, gripper=gripper, settings=settings, donors=donors)
            for p in poses]


def _draw_one(args: tuple[Pose, ObjectSpec, str, SimSettings, TileSample]) -> PoseResult:
    from graspscape.workers.sim.samples import sample_result

    pose, obj, gripper, settings, tile = args
    return sample_result(pose, obj=obj, gripper=gripper, settings=settings,
                         engines=list(tile.engines), scales=tile.scales.get(pose.key()))


def drawer(obj: ObjectSpec, gripper: str = "robotiq_3f", settings: SimSettings | None = None,
           *, pool: Executor | None = None) -> Draw:
    """Evaluate a tile of draws outcome only, in each of its engines (in a pool if given)."""
    settings = settings or SimSettings()

    def run(poses: Sequence[Pose], tile: TileSample) -> list[PoseResult]:
        args = [(p, obj, gripper, settings, tile) for p in poses]
        return list(pool.map(_draw_one, args) if pool is not None else map(_draw_one, args))

    return run


def pybullet_evaluator(
    obj: ObjectSpec,
    gripper: str = "robotiq_3f",
    settings: SimSettings | None = None,
    *,
    pool: Executor | None = None,
    cache: dict[str, PoseResult] | None = None,
) -> Evaluate:
    """Evaluate poses with pybullet (in a pool if given). `cache` (pose key → result) lets
    tests drive one spec through several interleavings without simulating a pose twice; an
    evaluation is a pure function of pose, object, gripper and settings, so this changes
    nothing but the time."""
    settings = settings or SimSettings()

    def run(poses: Sequence[Pose], match: ConfigurationMatch | None = None
            ) -> list[PoseResult]:
        # With shortcut 2 a result depends on the poses evaluated before it on its normal:
        # such results are cached apart from plain ones.
        prefix = "" if match is None else f"configuration:{match.model_dump_json()}:"
        todo = [p for p in poses if cache is None or prefix + p.key() not in cache]
        def mapper(fn, items, chunksize=1):
            return pool.map(fn, items, chunksize=chunksize) if pool is not None else map(fn, items)

        if match is None:
            done = list(mapper(_eval_one, [(p, obj, gripper, settings) for p in todo], 4))
        else:
            normals: dict[tuple[float, ...], list[Pose]] = {}
            for p in todo:
                normals.setdefault(p.normal(), []).append(p)
            args = [(group, obj, gripper, settings, match) for group in normals.values()]
            done = [r for group in mapper(_eval_normal, args) for r in group]
        if cache is None:
            by_key = {r.pose_key: r for r in done}
            return [by_key[p.key()] for p in poses]
        for r in done:
            cache[prefix + r.pose_key] = r
        return [cache[prefix + p.key()] for p in poses]

    return run


def run_local(
    sessions: sessionmaker[Session],
    evaluate: Evaluate,
    *,
    workers: int = 1,
    seed: int = 0,
    split: int = 1,
    max_tiles: int = 100_000,
    evaluators: Mapping[int, Evaluate] | None = None,
    draw: Draw | None = None,
    engines: Sequence[str] = ("pybullet",),
) -> RunStats:
    """Drive every queued tile to done. `split` > 1 sends each tile's results in that many
    batches (the last one final); batches of all leased tiles are shuffled by `seed`.
    `evaluators`: an exploration's own evaluation, by id, where its settings differ (a table
    at each resting pose); the others use `evaluate`."""
    evaluators = evaluators or {}
    wire()
    rng = random.Random(seed)
    stats = RunStats()
    started = time.perf_counter()
    while stats.tiles < max_tiles:
        leased = []
        with sessions() as session:
            for w in range(workers):
                leased += [(f"local-{w}", t) for t in
                           lease_tiles(session, worker_id=f"local-{w}", n=1,
                                                   lease_seconds=3600, engines=engines)]
        if not leased:
            break
        with sessions() as session:
            matches = {
                eid: configuration_match_of(stored_spec(session, eid))
                for eid in {t.exploration_id for _, t in leased}
            }
        batches = []
        for worker, tile in leased:
            t0 = time.perf_counter()
            if tile.sample is not None and draw is not None:
                results = draw(tile.poses(), tile.sample)
            else:
                results = evaluators.get(tile.exploration_id, evaluate)(
                    tile.poses(), matches.get(tile.exploration_id))
            stats.eval_s += time.perf_counter() - t0
            stats.evaluated += len(results)
            order = list(results)
            rng.shuffle(order)
            n = max(1, min(split, len(order)))
            chunks = [order[i::n] for i in range(n)]
            for i, chunk in enumerate(chunks):
                batches.append((worker, tile, chunk, i == n - 1))
        # Partial batches in any order, but a tile's final batch after its partial ones.
        rng.shuffle(batches)
        batches.sort(key=lambda b: b[3])
        for worker, tile, chunk, final in batches:
            with sessions() as session:
                ingest_results(session, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                               worker_id=worker, results=chunk, final=final)
        stats.tiles += len(leased)
    stats.wall_s = time.perf_counter() - started
    return stats
