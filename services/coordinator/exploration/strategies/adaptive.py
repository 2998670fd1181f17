"""The adaptive strategy (the paper's): coarse pass, border refinement, shortcuts, search.

Decisions come from `refine` (pure); this module loads what they read and turns what they
decide into planned poses (evaluated once each) and inferred results. The scheduler calls it
inside the ingest transaction, after the exploration's counter update, whose row lock makes
the batches of one exploration take turns: each sees every result committed before it, so a
pair of neighbours is always judged by whichever of its two results arrives last. When no
tile is open any more, a round of local search in the large manifolds is planned, then rounds
of certification of the best grasps and of core claims (exploration/certify.py), or, after the
last, the manifolds are computed for good.
"""

from __future__ import annotations

from collections.abc import Callable

from graspscape.services.coordinator.exploration import certify, symmetry
from graspscape.services.coordinator.exploration.certify_store import (
    certification_plans,
    certification_round,
    mark_certifies,
)
from graspscape.services.coordinator.exploration.lattice import Point
from graspscape.services.coordinator.exploration.object_symmetry import (
    hand_mirror,
    symmetry_orbits,
)
from graspscape.services.coordinator.exploration.planning import store_inferred
from graspscape.services.coordinator.exploration.refine import (
    Inference,
    Proposal,
    border_proposals,
    local_maxima,
    lookup_points,
    normal_decisions,
    search_proposals,
)
from graspscape.services.coordinator.exploration.samples import (
    lattice_of,
    load_samples,
    point_or_none,
)
from graspscape.services.coordinator.exploration.strategies.base import Batch, Planned, Stage
from graspscape.services.coordinator.exploration.symmetry import Orbits
from graspscape.services.coordinator.exploration.tiling import (
    TilePlan,
    coarse_tiles,
    count_poses,
    group_tiles,
)
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.service import refresh_manifolds
from graspscape.services.coordinator.store import explorations
from graspscape.services.coordinator.store.models import PosePlanRow, TileRow
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import func, select
from sqlalchemy.orm import Session


class AdaptiveStrategy:
    def __init__(self, spec: ExplorationSpec) -> None:
        self.spec = spec
        self.lattice = lattice_of(spec)
        # Coarse pass only, no shortcuts: no batch can lead to more work, and the manifolds
        # are computed on request; ingest stays at the store's own speed.
        self.reacts = self.lattice.depth > 0 or spec.shortcuts.normal_reuse or \
            spec.shortcuts.symmetry
        # A coarse-only exploration has no search rounds. The manifold table is the keeper's
        # (manifolds/keeper.py, after each committed batch), except where a round reads it.
        self.has_rounds = self.lattice.depth > 0
        self._samples: dict[Point, StoredPose] | None = None  # read by next_round, for progress
        self._refreshed = False  # next_round stored the manifolds of these samples

    # --- the coarse pass -----------------------------------------------------------------
    def planned_poses(self) -> int:
        return count_poses(self.spec.grid)

    def initial_work(self, session: Session, *, target_poses: int) -> list[TilePlan]:
        """Level-0 tiles. With normal reuse only the two r ends of each normal are evaluated
        first; the levels between are inferred or bisected as the ends come in. With
        symmetry, only one pose of each orbit is evaluated; the others are mirrored from it."""
        spec, lattice = self.spec, self.lattice
        normal = spec.shortcuts.normal_reuse and len(spec.grid.r_levels()) > 2
        orbits = symmetry_orbits(session, spec)
        if not normal and orbits is None:
            return coarse_tiles(spec.grid, target_poses=target_poses)
        top = lattice.n_r * lattice.scale(0)
        points = [p for p in lattice.coarse_points()
                  if not normal or p.r_index in (0, top)]
        if orbits is not None:
            points = [p for p in points if orbits.representative(p) == p]
        return group_tiles([lattice.pose(p) for p in points], target_poses=target_poses)

    # --- after every batch ---------------------------------------------------------------
    def after_batch(self, batch: Batch) -> list[Planned]:
        """Refine borders, apply shortcuts: the poses the batch's results call for."""
        spec, lattice, session = self.spec, self.lattice, batch.session
        points = [(r.pose_key, point_or_none(lattice, r.pose)) for r in batch.results]
        new_points = sorted(p for _, p in points if p is not None)
        off_lattice = [key for key, p in points if p is None]
        if off_lattice:  # jitters of the certification: name the pose each one certifies
            mark_certifies(session, batch.exploration_id, off_lattice)
        if not new_points:
            return []
        orbits = symmetry_orbits(session, spec)
        wanted: set[Point] = set(new_points)
        for p in new_points:
            wanted |= lookup_points(lattice, p)
        samples = self._load(batch, wanted)
        proposals: list[Proposal] = []
        todo = [p for p in new_points if p in samples]
        mu_step = spec.refinement.mu_step_max
        if spec.shortcuts.normal_reuse:
            inferences: list[Inference] = []
            for p in todo:
                props, infs = normal_decisions(lattice, p, samples.get, mu_step)
                proposals += props
                inferences += [i for i in infs if i.point not in samples]
            inferences = sorted({i.point: i for i in inferences}.values(), key=lambda i: i.point)
            # Inferred points neighbour others; their own lookups may need more rows.
            extra = set()
            for inf in inferences:
                extra |= lookup_points(lattice, inf.point)
            extra -= wanted
            wanted |= extra
            samples.update(self._load(batch, extra))
            self._infer(batch, inferences, samples)
            todo += [i.point for i in inferences]
        if orbits is not None:
            # Every image's neighbours must be at hand: a pair missed now is missed for good.
            extra = set()
            for p in todo:
                for q in orbits.orbit(p):
                    extra |= {q} | lookup_points(lattice, q)
            extra -= wanted
            wanted |= extra
            samples.update(self._load(batch, extra))
            todo += self._mirror(batch, todo, orbits, samples)
        for p in todo:
            proposals += border_proposals(lattice, p, samples.get, mu_step)
        proposals = self._canonical(proposals, orbits)
        proposals = [q for q in proposals if q.point not in samples]
        budget = spec.refinement.max_poses - self._plans(batch)
        refine = [q for q in proposals if q.reason == "refine"]
        keep = [q for q in proposals if q.reason != "refine"] + sorted(
            refine, key=lambda q: (q.level, q.point))[: max(0, budget)]
        # Normal-reuse levels are coarse poses: level-0 tiles, counted at submission.
        return self._planned(keep, lambda q: 0 if q.reason == "normal" else q.level)

    # --- when no tile is open ------------------------------------------------------------
    def next_round(self, batch: Batch) -> list[Planned]:
        """The next round of local search from each manifold's best maxima; once that is
        over, the next round of certification (exploration/certify.py); or nothing."""
        session, spec = batch.session, self.spec
        rounds_done = session.scalar(
            select(func.count(func.distinct(TileRow.round))).where(
                TileRow.exploration_id == batch.exploration_id, TileRow.round > 0)
        ) or 0
        samples = self._samples = load_samples(session, batch.exploration_id, self.lattice)
        orbits = symmetry_orbits(session, spec)
        certifying = bool(certification_plans(session, batch.exploration_id))
        if rounds_done < spec.refinement.local_search_rounds and not certifying:
            # Search in the large manifolds only (≥ 1 % of the viable volume, the map's
            # `large`): on a map with structure at every scale most manifolds are dust of one
            # or a few poses, each with its own maxima, and searching them all cost the cube
            # 40-68 % of its dense grid (docs/design/exploration.md, "Local search").
            computed = refresh_manifolds(session, batch.exploration_id, spec, self.lattice,
                                         samples=samples)
            self._refreshed = True
            large = {m.label for m in computed.map.manifolds if m.large}
            members: dict[int, list[Point]] = {}
            for p, label in sorted(computed.label_of.items()):
                if label in large:
                    members.setdefault(label, []).append(p)
            proposals: list[Proposal] = []
            for _, comp in sorted(members.items()):
                maxima = local_maxima(self.lattice, comp, samples.get,
                                      top=spec.refinement.local_search_starts)
                proposals += search_proposals(self.lattice, maxima, samples.get)
            proposals = self._canonical(proposals, orbits)
            firsts: dict[Point, Proposal] = {}  # in order: the first proposal of a point
            for q in proposals:
                if q.point not in samples:
                    firsts.setdefault(q.point, q)
            proposals = list(firsts.values())
            # `refinement.max_poses` caps the search too (its poses are planned poses like
            # refinement's): the largest manifolds' best maxima first.
            proposals = proposals[: max(0, spec.refinement.max_poses - self._plans(batch))]
            if proposals:
                # Search round k is the exploration's round k (1, 2, …): its tiles are leased
                # after every tile of the rounds before, refinement included.
                return self._planned(proposals, lambda q: q.level, round_=rounds_done + 1)
        if (spec.certification.share <= 0
                or rounds_done >= spec.refinement.local_search_rounds + certify.MAX_ROUNDS):
            return []
        # Certification reads the current manifolds, so they are stored now (the progress
        # report of a new round then has nothing to add).
        computed = refresh_manifolds(session, batch.exploration_id, spec, self.lattice,
                                     samples=samples)
        self._refreshed = True
        return certification_round(session, batch.exploration_id, spec, computed, orbits,
                                   rounds_done + 1)

    def progress(self, batch: Batch, stage: Stage) -> None:
        """The manifold table is the keeper's, after the commit (manifolds/keeper.py); only
        where next_round stored the manifolds of these very samples and planned nothing more
        are they the finished exploration's (what the keeper's final refresh would note)."""
        if stage == Stage.FINISHED and self._refreshed:
            explorations.mark_table_final(batch.session, batch.exploration_id)

    # --- helpers -------------------------------------------------------------------------
    def _plans(self, batch: Batch) -> int:
        """Poses planned beyond the coarse pass so far (refinement, search, certification)."""
        return batch.session.scalar(
            select(func.count()).select_from(PosePlanRow)
            .where(PosePlanRow.exploration_id == batch.exploration_id)) or 0

    def _load(self, batch: Batch, points: set[Point]) -> dict[Point, StoredPose]:
        return load_samples(batch.session, batch.exploration_id, self.lattice,
                            [self.lattice.pose(q).key() for q in points])

    def _planned(self, proposals: list[Proposal], tile_level: Callable[[Proposal], int],
                 round_: int = 0) -> list[Planned]:
        """Proposals as planned poses, ordered by (level, point): the first proposal of a
        pose is the one planned. Refinement and normal reuse belong to round 0, the lattice
        pass, whenever they are planned."""
        return [
            Planned(self.lattice.pose(q.point), plan_level=q.level, tile_level=tile_level(q),
                    round=round_, reason=q.reason, counted=q.reason != "normal")
            for q in sorted(proposals, key=lambda q: (q.level, q.point))
        ]

    def _canonical(self, proposals: list[Proposal], orbits: Orbits | None) -> list[Proposal]:
        """With symmetry, each proposal becomes its orbit's representative (evaluated once,
        mirrored onto the rest when it arrives)."""
        if orbits is None:
            return proposals
        out = []
        for prop in proposals:
            rep = orbits.representative(prop.point)
            out.append(Proposal(rep, self.lattice.birth(rep) if prop.reason != "search"
                                else prop.level, prop.reason))
        return out

    def _infer(self, batch: Batch, inferences: list[Inference], samples: dict[Point, StoredPose],
               paths: dict[Point, tuple[symmetry.Symmetry, ...]] | None = None) -> None:
        """Store copies of the sources' results; later decisions of this batch read them."""
        lattice = self.lattice
        copies = [(lattice.pose(i.point), samples[i.source].key, i.reason,
                   lattice.birth(i.point) > 0) for i in inferences]
        rows = store_inferred(
            batch.session, batch.exploration_id, copies, batch.now,
            None if paths is None else [paths.get(i.point, ()) for i in inferences],
            hand_mirror(self.spec) if paths is not None else None)
        for inf, row in zip(inferences, rows, strict=True):
            samples[inf.point] = StoredPose.from_row(row)

    def _mirror(self, batch: Batch, points: list[Point], orbits: Orbits,
                samples: dict[Point, StoredPose]) -> list[Point]:
        """Shortcut 3: copy each new result onto the rest of its orbit; returns the new
        points."""
        todo: dict[Point, Inference] = {}
        paths: dict[Point, tuple[symmetry.Symmetry, ...]] = {}
        for p in points:
            for q, path in orbits.orbit(p).items():
                if q != p and q not in samples and q not in todo:
                    todo[q] = Inference(q, p, "symmetry")
                    paths[q] = path
        inferences = sorted(todo.values(), key=lambda i: i.point)
        self._infer(batch, inferences, samples, paths)
        return [i.point for i in inferences]
