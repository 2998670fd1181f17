"""The ingest benchmarks' exploration: a sphere mapped by the Robotiq 3F on a ~190k-pose grid,
more poses than any timed run stores (bench_ingest, bench_batch_cpu).

graspscape is imported when called, not at import, so that a benchmark which swaps in an older
tree first (bench_batch_cpu's `--baseline`) creates the exploration with that tree's code."""

from __future__ import annotations

from typing import Any


def create_sphere_exploration(sessions: Any, *, tile_target_poses: int) -> int:
    """A new exploration (and its object row) in `sessions`' database; its id."""
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.store.models import ObjectRow
    from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec

    grid = PoseGridSpec(dtheta=0.04, r_min=0.0, r_max=0.05, dr=0.01, attitudes={"rolls": 4})
    with sessions() as s:
        obj = ObjectRow(kind="named", name="sphere", properties={})
        s.add(obj)
        s.commit()
        spec = ExplorationSpec(object_id=obj.id, gripper="robotiq_3f", grid=grid)
        return create_exploration(s, spec=spec, tile_target_poses=tile_target_poses,
                                  max_poses=10**7).id


def store_only(ingest_results: Any) -> dict[str, Any]:
    """`ingest_results`' arguments for storing without the manifold keeper's refresh (a
    benchmark that builds a map and writes or times the table itself); none for a tree from
    before the keeper."""
    import inspect

    return {"keeper": None} if "keeper" in inspect.signature(ingest_results).parameters else {}
