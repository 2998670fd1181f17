"""Figures of the robust map benchmark's dense grids (split from bench_robust_map.py, which
imports them): what r became (start gap), the differing-pair shares and α, and the digest of
the simulator code that keys the kept grids."""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable
from pathlib import Path

from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.shared.specs.results import Outcome, PoseResult

try:
    from benchmarks import bench_exploration_accuracy as accuracy
except ModuleNotFoundError:  # run as a script: benchmarks/ itself is on sys.path
    import bench_exploration_accuracy as accuracy  # type: ignore[no-redef]


# Poses are written per batch: a stopped run loses at most one batch.
BATCH = 100

LatticeOf = Callable[[int, int, int], Lattice]  # (rolls, azimuth multiple, levels) → lattice


def load_kept(path: Path) -> dict[str, PoseResult]:
    """The poses kept in a dense grid's file, by pose key."""
    done: dict[str, PoseResult] = {}
    if not path.exists():
        return done
    lines = path.read_text().splitlines()
    for i, line in enumerate(lines):
        try:
            r = PoseResult.model_validate_json(line)
        except ValueError:
            # A --dense-only run may be appending to the file this moment: its last line can
            # be half written (it is read again next time); any other is damage.
            if i == len(lines) - 1:
                break
            raise
        done[r.pose_key] = r
    return done


def coarser_grids(rolls: int, levels: int) -> list[tuple[int, int]]:
    """The (levels, rolls) grids nested in this one, itself included: roll counts halving down
    to 1, refinement levels down to 1, coarsest first."""
    counts = sorted({r for r in (2**k for k in range(rolls.bit_length())) if rolls % r == 0}
                    | {rolls})
    return sorted((lv, r) for lv in range(1, levels + 1) for r in counts)


def nested_rank(lattice_of: LatticeOf, rolls: int, multiple: int,
                levels: int) -> dict[str, tuple[int, int]]:
    """Pose key → the coarsest nested grid holding it, so the dense grid is filled coarsest
    grid first and one stopped midway still holds whole coarser grids to score (the 8-roll
    grid holds the 1-, 2- and 4-roll ones; the 7.5° grid the 15° one)."""
    rank: dict[str, tuple[int, int]] = {}
    for lv, r in coarser_grids(rolls, levels):
        lattice = lattice_of(r, multiple, lv)
        for p in accuracy._fine_points(lattice):
            rank.setdefault(lattice.pose(p).key(), (lv, r))
    return rank


def complete_grids(lattice_of: LatticeOf, done: dict, rolls: int, multiple: int, levels: int,
                   dtheta: float) -> str:
    """Which nested grids the kept poses hold whole (for the progress line)."""
    whole = []
    for lv, r in coarser_grids(rolls, levels):
        lattice = lattice_of(r, multiple, lv)
        if all(lattice.pose(p).key() in done for p in accuracy._fine_points(lattice)):
            whole.append(f"{r} roll(s) {math.degrees(dtheta) / 2**lv:g}°")
    return ", ".join(whole) or "none"


def start_gap_figures(lattice: Lattice, results: dict[str, PoseResult]) -> dict[str, float]:
    """What r became on a dense grid: per nominal r, the median effective r (the palm gap the
    start used), the share started further out than r (backed off or cleared), the share
    infeasible; and how many distinct starts the r levels of one direction and attitude make."""
    out: dict[str, float] = {}
    by_r: dict[float, list[PoseResult]] = {}
    for p in accuracy._fine_points(lattice):
        r = results[lattice.pose(p).key()]
        by_r.setdefault(round(r.pose.r, 4), []).append(r)
    for nominal, rs in sorted(by_r.items()):
        placed = [r.effective_r for r in rs if r.effective_r is not None]
        tag = f"r{nominal * 100:g}cm"
        out[f"median_effective_r_m_at_{tag}"] = round(statistics.median(placed), 4)
        out[f"share_started_beyond_r_at_{tag}"] = round(
            sum(e > nominal + 0.001 for e in placed) / len(rs), 4)
        out[f"share_infeasible_at_{tag}"] = round(
            sum(r.outcome is Outcome.INFEASIBLE for r in rs) / len(rs), 4)
        out[f"share_held_at_{tag}"] = round(sum(r.viable for r in rs) / len(rs), 4)
    # Distinct starts: along one normal (direction, attitude), how many different palm gaps
    # (to 1 mm) its r levels start at, as a share of its r levels.
    normals: dict[tuple, list[float]] = {}
    for p in accuracy._fine_points(lattice):
        r = results[lattice.pose(p).key()]
        if r.effective_r is not None:
            normals.setdefault((p.ring, p.azimuth, p.attitude), []).append(r.effective_r)
    distinct = [len({round(g, 3) for g in gaps}) / len(gaps) for gaps in normals.values()]
    out["distinct_start_share_per_normal_mean"] = round(statistics.fmean(distinct), 4)
    return out


def differing_figures(lattice: Lattice, samples: dict, dtheta: float) -> dict[str, float]:
    """Differing-pair shares per step and α between successive steps (bench_exploration_
    accuracy's count, on this grid)."""
    out: dict[str, float] = {}
    shares = accuracy.differing_pairs(lattice, samples)
    for level, (border, viability) in shares.items():
        step = f"{math.degrees(dtheta) / 2**level:g}deg"
        out[f"pairs_differing_share_at_{step}"] = round(border, 4)
        out[f"pairs_differing_viability_share_at_{step}"] = round(viability, 4)
    for level in range(1, len(shares)):
        coarse, fine = shares[level - 1][0], shares[level][0]
        if coarse > 0 and fine > 0:
            coarse_deg = math.degrees(dtheta) / 2 ** (level - 1)
            out[f"alpha_{coarse_deg:g}_to_{coarse_deg / 2:g}deg"] = round(
                math.log2(coarse / fine), 3)
    return out


def simulator_digest() -> str:
    """A digest of what a pose result depends on: the source of every graspscape module the
    evaluation loads (the simulator and the specs it reads, found by importing it, not a
    folder: other work adds grippers and tools there that no robotiq_3f result depends on)
    and the gripper's config, so a kept dense grid is never reused after any of them
    changed."""
    import hashlib
    import sys

    import graspscape.workers.sim.evaluate  # noqa: F401

    root = Path(__file__).resolve().parent.parent
    # The exploration spec is loaded with the specs but no pose result reads it; the URDF
    # import runs only for URDF grippers (robotiq_3f is a TOML one).
    files = {Path(m.__file__).resolve() for name, m in list(sys.modules.items())
             if name.startswith(("graspscape.workers.sim", "graspscape.shared.specs"))
             and name != "graspscape.shared.specs.exploration"
             and not name.startswith("graspscape.workers.sim.gripper.urdf")
             and getattr(m, "__file__", None)}
    files |= set((root / "configs/grippers").glob("robotiq_3f.*"))
    digest = hashlib.sha256()
    for file in sorted(files):
        digest.update(file.relative_to(root).as_posix().encode())
        digest.update(file.read_bytes())
    return digest.hexdigest()[:12]
