"""`graspscape explore OBJECT`: one machine, one command. The embedded default deployment.

Runs the coordinator's store (SQLite under the data folder) and dispatch in this process and
N local worker processes that connect to it over loopback zenoh, exactly as remote workers
would; shows a progress bar and prints where the results are, the robust best grasp of each
large manifold with its certification evidence, and last the outcome (done, incomplete or
failed, with the reasons of failed tiles), which the exit status follows.
Running the same command again resumes an unfinished exploration of the same spec instead of
starting over; one that ended incomplete or failed has its failed tiles queued again.
"""

from __future__ import annotations

import csv
import math
import signal
import socket
import sys
import time
from pathlib import Path
from typing import Literal

from graspscape.services.coordinator.dispatch.leases import requeue_lost
from graspscape.services.coordinator.dispatch.service import Dispatcher
from graspscape.services.coordinator.exploration.certify_store import (
    robust_summary,
)
from graspscape.services.coordinator.exploration.object_symmetry import resolve_grid
from graspscape.services.coordinator.exploration.service import (
    create_exploration,
)
from graspscape.services.coordinator.exploration.support import resting_specs
from graspscape.services.coordinator.maps.picture import write_map_files
from graspscape.services.coordinator.settings import (
    DatabaseSettings,
    Settings,
    ZenohSettings,
)
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    POSE_METRIC_COLUMNS,
    ExplorationRow,
    ExplorationStatus,
    PoseRow,
    TileRow,
    TileState,
)
from graspscape.services.coordinator.store.queue import retry_failed_tiles
from graspscape.services.local.compose import open_store, store_object, wire
from graspscape.services.local.defaults import DEFAULT_DTHETA_DEG, DEFAULT_LEVELS, DEFAULT_R
from graspscape.services.local.explore_lines import outcome_line, robust_lines
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec, RefinementSpec
from graspscape.shared.specs.objects import LengthUnit
from graspscape.shared.specs.robustness import TestName
from graspscape.shared.specs.sim import EngineName
from graspscape.shared.specs.support import SupportKind, SupportSpec
from graspscape.shared.specs.uncertainty import UncertaintyModel
from graspscape.workers.runtime.config import WorkerConfig, default_procs
from graspscape.workers.runtime.supervisor import Supervisor
from pydantic import BaseModel, Field
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker


class ExploreOptions(BaseModel):
    object: str
    gripper: str = "robotiq_3f"
    dtheta_deg: float = Field(default=DEFAULT_DTHETA_DEG, gt=0.5, le=90)
    r_min: float = DEFAULT_R[0]
    r_max: float = DEFAULT_R[1]
    dr: float = DEFAULT_R[2]
    rolls: int = 1
    levels: int = Field(default=DEFAULT_LEVELS, ge=0, le=6)
    procs: int = Field(default_factory=default_procs, ge=1)
    data_dir: Path = Path("data")
    mass_kg: float | None = None
    friction: float | None = None
    scale: float | None = None
    units: LengthUnit | None = None
    engine: EngineName | None = Field(
        default=None, description="physics engine; None: the spec's default (pybullet)")
    robustness: tuple[TestName, ...] | None = Field(
        default=None, description="robustness tests on every held pose; None: the spec's default")
    quiet: bool = False
    new: bool = Field(default=False, description="explore again where this very exploration "
                      "is done")
    uncertainty: Literal["none", "lab", "field"] = "lab"
    support: SupportKind = "none"
    support_friction: float | None = Field(default=None, gt=0.0, le=3.0)
    draw_engines: tuple[EngineName, ...] | None = Field(
        default=None, description="engines each P(success) draw runs in; None: pybullet")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# Exit statuses of `graspscape explore`.
EXIT_DONE, EXIT_FAILED, EXIT_INCOMPLETE, EXIT_INTERRUPTED = 0, 1, 2, 130
_UNFINISHED = (ExplorationStatus.QUEUED, ExplorationStatus.RUNNING)
_RETRYABLE = (ExplorationStatus.INCOMPLETE, ExplorationStatus.FAILED)


def _exploration(session: Session, spec: ExplorationSpec, settings: Settings,
                 new: bool = False) -> tuple[int, str, int]:
    """The exploration of this very spec: a done one (unless `new`), an unfinished one
    (resumed; one that ended incomplete or failed has its failed tiles queued again), or a new
    one. (id, how: "done", "resuming" or "exploration", tiles retried)"""
    # As stored: with the grid's azimuth multiple decided at submission (else no stored spec
    # ever equals the one asked for, and nothing was resumed).
    # On a plane, the group is found by its first exploration (the most probable resting pose).
    wanted = resolve_grid(session, resting_specs(session, spec)[0]).model_dump(mode="json")
    reusable = _UNFINISHED + _RETRYABLE + (() if new else (ExplorationStatus.DONE,))
    for row in session.scalars(
        select(ExplorationRow)
        .where(ExplorationRow.status.in_(reusable))
        .order_by(ExplorationRow.status != ExplorationStatus.DONE,
                  ExplorationRow.status.in_(_RETRYABLE), ExplorationRow.id.desc())
    ):
        # Read as a spec: a row stored before a field was added (support) reads with its
        # default, and is the same exploration.
        if row.spec == wanted or _as_spec(row.spec) == wanted:
            if row.status == ExplorationStatus.DONE:
                return row.id, "done", 0
            retried = 0
            if row.status in _RETRYABLE:
                retried = retry_failed_tiles(session, exploration_id=row.id)
            return row.id, "resuming", retried
    row = create_exploration(session, spec=spec, tile_target_poses=settings.queue.tile_target_poses,
                             max_poses=settings.queue.max_poses_per_exploration)
    return row.id, "exploration", 0


def _as_spec(stored: dict) -> dict | None:
    try:
        return ExplorationSpec.model_validate(stored).model_dump(mode="json")
    except ValueError:  # a spec this version no longer reads is not the one asked for
        return None


def exit_status(status: str) -> int:
    return {ExplorationStatus.DONE: EXIT_DONE,
            ExplorationStatus.INCOMPLETE: EXIT_INCOMPLETE}.get(status, EXIT_FAILED)


def _bar(done: int, total: int, viable: int, rate: float, failed: int = 0,
         width: int = 30) -> str:
    frac = done / total if total else 1.0
    filled = int(frac * width)
    eta = f"{(total - done) / rate:5.0f} s" if rate > 0 else "    ? s"
    failed_text = f"  {failed} tiles failed" if failed else ""
    return (f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} poses "
            f"{100 * frac:5.1f} %  viable {viable}  {rate:5.1f} poses/s  ETA {eta}"
            f"{failed_text}")


def _export_csv(session: Session, exploration_id: int, path: Path) -> int:
    columns = ("pose_key", "theta", "phi", "r", "roll", "pitch", "yaw", "outcome", "viable",
               "mu_s", "effort_max_nm", "eval_time_s", *POSE_METRIC_COLUMNS)
    rows = session.execute(
        select(*(getattr(PoseRow, c) for c in columns))
        .where(PoseRow.exploration_id == exploration_id)
        .order_by(PoseRow.pose_key)
    ).all()
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        writer.writerows(rows)
    return len(rows)


def _spec(opts: ExploreOptions) -> ExplorationSpec:
    spec = ExplorationSpec(
        object_id=1,  # replaced once the object is stored
        gripper=opts.gripper,
        grid=PoseGridSpec(dtheta=math.radians(opts.dtheta_deg), r_min=opts.r_min,
                          r_max=opts.r_max, dr=opts.dr, attitudes={"rolls": opts.rolls}),
        refinement=RefinementSpec(levels=opts.levels),
        uncertainty=UncertaintyModel(preset=opts.uncertainty, **(
            {"engines": opts.draw_engines} if opts.draw_engines else {})),
        label=f"graspscape explore {opts.object}",
        support=SupportSpec(kind=opts.support, **({} if opts.support_friction is None else
                                                  {"friction": opts.support_friction})),
    )
    if opts.engine is not None:
        spec = spec.model_copy(update={"settings": spec.settings.model_copy(
            update={"engine": opts.engine})})
    if opts.robustness is not None:
        sim = spec.settings
        spec = spec.model_copy(update={"settings": sim.model_copy(update={
            "robustness": sim.robustness.model_copy(update={"tests": opts.robustness})})})
    return spec


def _plan(opts: ExploreOptions, sessions: sessionmaker[Session],
          settings: Settings) -> tuple[int, str, int, int]:
    """Store the object, find or create the exploration: (id, how, tiles retried, poses)."""
    with sessions() as session:
        object_id = store_object(session, opts.object, mass_kg=opts.mass_kg,
                                 friction=opts.friction, scale=opts.scale, units=opts.units)
        spec = _spec(opts).model_copy(update={"object_id": object_id})
        exploration_id, how, retried = _exploration(session, spec, settings, opts.new)
        # Every worker of this command starts now, so any lease still held is an orphan of
        # an earlier, interrupted run.
        requeue_lost(session, alive=[], max_attempts=settings.queue.max_attempts)
        total = session.scalar(
            select(ExplorationRow.poses_total).where(ExplorationRow.id == exploration_id))
    return exploration_id, how, retried, total or 0


def _progress(session: Session, exploration_id: int) -> tuple[str, int, int, int, int]:
    """(status, poses done, poses planned, viable, tiles failed)"""
    row = session.get(ExplorationRow, exploration_id)
    assert row is not None
    failed = session.scalar(
        select(func.count()).select_from(TileRow).where(
            TileRow.exploration_id == exploration_id, TileRow.state == TileState.FAILED)) or 0
    return row.status, row.poses_done, row.poses_total, row.viable_count, failed


def _drive(opts: ExploreOptions, sessions: sessionmaker[Session], settings: Settings,
           endpoint: str, exploration_id: int) -> bool:
    """Run the dispatch and the workers until the exploration finishes; True if interrupted."""
    dispatcher = Dispatcher(settings, sessions)
    dispatcher.start()
    if not dispatcher.ready:
        dispatcher.stop()
        raise RuntimeError(f"could not open the zenoh peer on {endpoint}")
    supervisor = Supervisor(
        WorkerConfig(connect=[endpoint], procs=opts.procs, name="explore"), log_level="warning"
    )
    try:
        supervisor.start()
        first_done: tuple[float, int] | None = None
        while True:
            supervisor.poll()
            with sessions() as session:
                status, done, total, viable, failed = _progress(session, exploration_id)
            now = time.monotonic()
            if first_done is None and done > 0:
                first_done = (now, done)  # rate from the first result: start-up excluded
            rate = ((done - first_done[1]) / (now - first_done[0])
                    if first_done and now > first_done[0] else 0.0)
            if not opts.quiet:
                print(_bar(done, total, viable, rate, failed), end="", file=sys.stderr,
                      flush=True)
            if status in FINISHED_STATUSES:
                return False
            time.sleep(0.5)
    except KeyboardInterrupt:
        if not opts.quiet:
            print("\ninterrupted: workers finish their pose and hand the rest back ...",
                  file=sys.stderr)
        return True
    finally:
        # A second Ctrl-C must not cut the clean-up short: an open zenoh session would keep
        # the interpreter from exiting, and unreleased tiles would wait for expiry.
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            supervisor.shutdown()  # while the dispatch runs, so releases are acknowledged
        finally:
            dispatcher.stop()
            signal.signal(signal.SIGINT, previous)


def _report(sessions: sessionmaker[Session], data_dir: Path, exploration_id: int,
            interrupted: bool, elapsed: float) -> str:
    """Write the CSV, map and table; print where they are and the robust bests; return the
    exploration's status."""
    with sessions() as session:
        csv_path = data_dir / f"exploration-{exploration_id}.csv"
        n = _export_csv(session, exploration_id, csv_path)
        map_path = data_dir / f"exploration-{exploration_id}-map.png"
        table_path = data_dir / f"exploration-{exploration_id}-manifolds.json"
        manifolds = robust = None
        if n and not interrupted:
            manifolds, _ = write_map_files(session, exploration_id, map_path, table_path)
            robust = robust_summary(session, exploration_id)
        outcome = (f"interrupted: {n} poses stored in {elapsed:.0f} s; run the same command "
                   "again to resume" if interrupted
                   else outcome_line(session, exploration_id, n, elapsed))
        status = session.scalar(
            select(ExplorationRow.status).where(ExplorationRow.id == exploration_id))
    print(f"results: {csv_path}")
    if manifolds is not None:
        print(f"map: {map_path} ({manifolds} behavioral manifolds; table: {table_path})")
    if robust is not None and robust.bests:
        print(robust_lines(robust))
    print(f"database: {data_dir / 'coordinator.db'} (exploration {exploration_id}); browse with "
          f"`graspscape serve --data-dir {data_dir}` and GET "
          f"/explorations/{exploration_id}/poses")
    # Last, on stdout even with --quiet: what became of the exploration; the exit status says
    # the same (0 done, 2 incomplete, 1 failed or cancelled, 130 interrupted).
    print(outcome)
    return status or ExplorationStatus.FAILED


def run_explore(opts: ExploreOptions) -> int:
    from graspscape.workers.sim.engine import available_engines

    missing = sorted(set(opts.draw_engines or ()) - set(available_engines()))
    if missing:  # its draws would wait for a worker that never comes
        print(f"graspscape explore: --draw-engines {', '.join(missing)}: not installed here",
              file=sys.stderr)
        return 1
    data_dir = opts.data_dir.resolve()
    data_dir.mkdir(parents=True, exist_ok=True)
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    settings = Settings(
        database=DatabaseSettings(
            data_dir=data_dir, url=f"sqlite:///{(data_dir / 'coordinator.db').as_posix()}"),
        zenoh=ZenohSettings(enabled=True, mode="peer", listen=[endpoint], connect=[]),
    )
    wire()
    engine, sessions = open_store(settings.database.resolved_url)
    first_id, how, retried, _ = _plan(opts, sessions, settings)
    statuses = []
    try:
        for exploration_id in _group(sessions, first_id):
            statuses.append(_explore_one(opts, sessions, settings, endpoint,
                                         exploration_id, how, retried))
            if statuses[-1] == EXIT_INTERRUPTED:
                break
    finally:
        engine.dispose()
    return max(statuses, key=lambda code: (code == EXIT_INTERRUPTED, code != EXIT_DONE))


def _group(sessions: sessionmaker[Session], exploration_id: int) -> list[int]:
    """The exploration, or on a table every exploration of its group (one per resting pose)."""
    with sessions() as session:
        group = session.scalar(select(ExplorationRow.support_group)
                               .where(ExplorationRow.id == exploration_id))
        if group is None:
            return [exploration_id]
        return list(session.scalars(select(ExplorationRow.id).where(
            ExplorationRow.support_group == group).order_by(ExplorationRow.id)))


def _explore_one(opts: ExploreOptions, sessions: sessionmaker[Session], settings: Settings,
                 endpoint: str, exploration_id: int, how: str, retried: int) -> int:
    """Drive one exploration to its end and report it; the command's exit status for it."""
    say = (lambda *a: None) if opts.quiet else (lambda msg: print(msg, file=sys.stderr))
    data_dir = settings.database.data_dir
    with sessions() as session:
        total = session.get(ExplorationRow, exploration_id).poses_total
    if how == "done":
        say(f"exploration {exploration_id} of {opts.object} with {opts.gripper} is done: its "
            "stored results (--new explores again)")
    else:
        say(f"{how} {exploration_id}: {total} poses of {opts.object} with {opts.gripper}, "
            f"{opts.procs} worker processes"
            + (f"; {retried} failed tiles queued again" if retried else ""))
    started = time.monotonic()
    interrupted = (how != "done"
                   and _drive(opts, sessions, settings, endpoint, exploration_id))
    elapsed = time.monotonic() - started
    say("")
    status = _report(sessions, data_dir, exploration_id, interrupted, elapsed)
    return EXIT_INTERRUPTED if interrupted else exit_status(status)
