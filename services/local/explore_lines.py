"""The lines `graspscape explore` closes with: how the run ended and why, and the best grasp
of each large manifold by P(success) with its evidence."""

from __future__ import annotations

from graspscape.services.coordinator.exploration.certify_store import RobustSummary, format_best
from graspscape.services.coordinator.exploration.service import failure_summary
from graspscape.services.coordinator.store.models import ExplorationRow, ExplorationStatus
from sqlalchemy.orm import Session


def outcome_line(session: Session, exploration_id: int, stored: int, elapsed_s: float) -> str:
    """The command's last line: status, poses stored of those planned, failed tiles and why."""
    row = session.get(ExplorationRow, exploration_id)
    assert row is not None
    session.refresh(row)
    line = f"{row.status}: {stored} of {row.poses_total} poses stored in {elapsed_s:.0f} s"
    failures = failure_summary(session, exploration_id=exploration_id)
    if failures.tiles:
        reasons = "; ".join(
            f"{_short(r.reason or 'no reason recorded')} ({r.tiles} tiles)"
            for r in failures.reasons[:3])
        more = len(failures.reasons) - 3
        line += (f"; {failures.tiles} tiles failed: {reasons}"
                 f"{f'; and {more} other reasons' if more > 0 else ''}")
        if row.status != ExplorationStatus.CANCELLED:
            line += "; run the same command again to retry them"
    if failures.poses_with_errors:
        line += (f"; {failures.poses_with_errors} poses raised in simulation (stored with "
                 "outcome error and the message)")
    return line


def robust_lines(robust: RobustSummary) -> str:
    """The pick of each large manifold by P(success) (docs/design/exploration.md, "Certification"):
    volume and robust core, s_δ, the pose, k/n with the 95 % bounds, and the claim."""
    lines = ["best grasp by P(success) per large manifold (≥ 1 % of the viable volume):"]
    lines += [format_best(b) for b in robust.bests]
    if robust.dust_count:
        lines.append(f"  dust: {robust.dust_count} smaller manifolds, "
                     f"{robust.dust_volume_cm3:.1f} cm³ in all")
    return "\n".join(lines)


def _short(text: str, limit: int = 200) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 1] + "…"
