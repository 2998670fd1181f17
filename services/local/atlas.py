"""`graspscape atlas`: explore every object beside the checkout and the built-ins with one
setting, then write a static site of the results that opens from disk.

Objects: the built-ins, every YCB folder (one with a `model.urdf`) under `<objects>/ycb` and
every mesh file (.obj .stl .ply .glb) directly in `<objects>`, stored with the setting's
mass. `<objects>` defaults to ../shared/objects next to the checkout, where `ycb:` names
resolve from (shared/specs/object_names.py); another folder is made the `ycb:` root of this
run and of its worker processes.

Resumable: each object's exploration is found by its spec in the data folder's database; a
finished one is skipped, an unfinished one resumed (its failed tiles queued again), so
running the command again after an interruption continues where it stopped and then only
rewrites the site.

Workers: by default this process runs the coordinator's dispatch on loopback and `--procs`
local worker processes, as `explore` does. With `--database-url` of a running coordinator
and `--procs 0`, the explorations are queued in that coordinator's store and whatever workers
are connected to it do the work; this process only waits and writes the site.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from graspscape.services.coordinator.exploration.object_symmetry import resolve_grid
from graspscape.services.coordinator.exploration.service import create_explorations
from graspscape.services.coordinator.exploration.support import resting_specs
from graspscape.services.coordinator.settings import DatabaseSettings, Settings, ZenohSettings
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    ExplorationRow,
    ExplorationStatus,
)
from graspscape.services.coordinator.store.queue import retry_failed_tiles
from graspscape.services.local.compose import open_store, store_object, wire
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec, RefinementSpec
from graspscape.shared.specs.object_names import BUILTIN_NAMES
from graspscape.shared.specs.robustness import TestName
from graspscape.shared.specs.support import (
    DEFAULT_TABLE_FRICTION,
    RestingPose,
    SupportKind,
    SupportSpec,
)
from graspscape.workers.runtime.config import default_procs
from pydantic import BaseModel, Field
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb")
DEFAULT_OBJECTS = Path(__file__).resolve().parents[2].parent / "shared" / "objects"


class AtlasSetting(BaseModel):
    """The one setting every object of an atlas is explored with."""

    model_config = {"frozen": True}

    name: str
    dtheta_deg: float = Field(gt=0.5, le=90)
    r_min: float
    r_max: float
    dr: float
    rolls: Literal[1, 2, 4, 8] = 1
    levels: int = Field(ge=0, le=6)
    robustness: tuple[TestName, ...] = ()
    mesh_mass_kg: float = Field(default=0.2, gt=0, description="mass of loose mesh files")
    support: SupportKind = Field(default="none", description="'plane': each object on a table, "
                                 "one map per chosen resting pose (concepts/support.md)")
    support_friction: float = Field(default=DEFAULT_TABLE_FRICTION, gt=0.0, le=3.0)

    def spec(self, object_id: int, object_name: str) -> ExplorationSpec:
        sim = ExplorationSpec(object_id=object_id).settings
        return ExplorationSpec(
            object_id=object_id,
            grid=PoseGridSpec(dtheta=math.radians(self.dtheta_deg), r_min=self.r_min,
                              r_max=self.r_max, dr=self.dr, attitudes={"rolls": self.rolls}),
            refinement=RefinementSpec(levels=self.levels),
            settings=sim.model_copy(update={"robustness": sim.robustness.model_copy(
                update={"tests": self.robustness})}),
            support=SupportSpec(kind=self.support, friction=self.support_friction),
            label=f"atlas {self.name}: {object_name}",
        )


# reduced: fits in an hour on 2 cores for the 18 objects (built-ins + 12 YCB) — measured in
# benchmarks/results/atlas.json; full: `graspscape explore`'s defaults.
SETTINGS: dict[str, AtlasSetting] = {
    "reduced": AtlasSetting(name="reduced", dtheta_deg=30.0, r_min=0.01, r_max=0.03, dr=0.01,
                            levels=0),
    "full": AtlasSetting(name="full", dtheta_deg=20.0, r_min=0.01, r_max=0.03, dr=0.01,
                         levels=1, robustness=("torque_margin",)),
}


def atlas_objects(objects_dir: Path) -> list[str]:
    """The objects of an atlas: built-ins, then `ycb:<Folder>` names, then mesh files."""
    names = list(BUILTIN_NAMES)
    ycb = objects_dir / "ycb"
    if ycb.is_dir():
        names += sorted(f"ycb:{d.name}" for d in ycb.iterdir() if (d / "model.urdf").is_file())
    if objects_dir.is_dir():
        names += sorted(str(p) for p in objects_dir.iterdir()
                        if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    return names


def short_name(name: str) -> str:
    """The object's name in the site: its file stem for a mesh file."""
    return Path(name).stem if Path(name).suffix.lower() in MESH_SUFFIXES else name


@dataclass
class AtlasEntry:
    name: str
    exploration_id: int
    skipped: bool  # finished before this run
    wall_s: float  # of the exploration (stored start to finish)
    resting: RestingPose | None = None  # on a table: the object's resting pose
    status: str = ""
    poses: int = 0
    notes: list[str] = field(default_factory=list)


class AtlasOptions(BaseModel):
    setting: Literal["reduced", "full"] = "reduced"
    objects_dir: Path = DEFAULT_OBJECTS
    only: tuple[str, ...] = Field(default=(), description="these objects only (names as listed)")
    data_dir: Path = Path("atlas-data")
    out: Path = Path("atlas")
    database_url: str | None = None
    procs: int = Field(default_factory=default_procs, ge=0)
    grid_override_deg: float | None = Field(default=None, gt=0.5, le=90,
                                            description="tests: another Δθ for the setting")
    support: SupportKind | None = Field(default=None, description="another support than the "
                                        "setting's: 'plane' maps each object on a table")
    support_friction: float | None = Field(default=None, gt=0.0, le=3.0)
    pictures: bool = True  # best-grasp pictures in the site (a simulation each)
    quiet: bool = False


def _find_or_create(session: Session, spec: ExplorationSpec, settings: Settings
                    ) -> list[tuple[int, bool, RestingPose | None]]:
    """(id, finished before, resting pose) of each exploration the spec submits (one, or on a
    plane one per chosen resting pose): the newest of each very spec, else new ones."""
    specs = resting_specs(session, spec)
    found = [_find(session, one) for one in specs]
    if any(f is None for f in found):
        rows = create_explorations(session, spec=spec,
                                   tile_target_poses=settings.queue.tile_target_poses,
                                   max_poses=settings.queue.max_poses_per_exploration)
        found = [(row.id, False) for row in rows]
    return [(eid, finished, one.support.resting)
            for (eid, finished), one in zip(found, specs, strict=True)]  # type: ignore[misc]


def _find(session: Session, spec: ExplorationSpec) -> tuple[int, bool] | None:
    """(id, finished before) of the newest exploration of this very spec, if any."""
    wanted = resolve_grid(session, spec).model_dump(mode="json")
    for row in session.scalars(select(ExplorationRow).order_by(ExplorationRow.id.desc())):
        if row.spec != wanted or row.status == ExplorationStatus.CANCELLED:
            continue
        if row.status in (ExplorationStatus.INCOMPLETE, ExplorationStatus.FAILED):
            retry_failed_tiles(session, exploration_id=row.id)
            return row.id, False
        return row.id, row.status in FINISHED_STATUSES
    return None


def _wait(sessions: sessionmaker[Session], exploration_id: int, poll: Callable[[], None],
          say: Callable[[str], None]) -> ExplorationRow:
    last = -1
    while True:
        poll()
        with sessions() as session:
            row = session.get(ExplorationRow, exploration_id)
            assert row is not None
            if row.poses_done != last:
                last = row.poses_done
                say(f"  {row.poses_done}/{row.poses_total} poses")
            if row.status in FINISHED_STATUSES:
                session.expunge(row)
                return row
        time.sleep(0.5)


class _LocalWorkers:
    """The coordinator's dispatch on loopback and local worker processes, started on demand."""

    def __init__(self, settings: Settings, sessions: sessionmaker[Session], endpoint: str,
                 procs: int) -> None:
        self.settings, self.sessions, self.endpoint, self.procs = (settings, sessions,
                                                                   endpoint, procs)
        self.dispatcher: Any = None
        self.supervisor: Any = None

    def start(self) -> None:
        from graspscape.services.coordinator.dispatch.service import Dispatcher
        from graspscape.workers.runtime.config import WorkerConfig
        from graspscape.workers.runtime.supervisor import Supervisor

        if self.dispatcher is not None:
            return
        self.dispatcher = Dispatcher(self.settings, self.sessions)
        self.dispatcher.start()
        if not self.dispatcher.ready:
            self.dispatcher.stop()
            raise RuntimeError(f"could not open the zenoh peer on {self.endpoint}")
        self.supervisor = Supervisor(WorkerConfig(connect=[self.endpoint], procs=self.procs,
                                                  name="atlas"), log_level="warning")
        self.supervisor.start()

    def poll(self) -> None:
        if self.supervisor is not None:
            self.supervisor.poll()

    def stop(self) -> None:
        if self.supervisor is not None:
            self.supervisor.shutdown()  # while the dispatch runs, so releases are acknowledged
        if self.dispatcher is not None:
            self.dispatcher.stop()


def _wall_s(row: ExplorationRow) -> float:
    if row.started_at is None or row.finished_at is None:
        return 0.0
    return (row.finished_at - row.started_at).total_seconds()


def run_atlas(opts: AtlasOptions) -> int:
    """Explore what is not explored yet, then write the site; 0 when every object is done."""
    say = (lambda _msg: None) if opts.quiet else (lambda msg: print(msg, file=sys.stderr))
    setting = SETTINGS[opts.setting]
    if opts.grid_override_deg is not None:
        setting = setting.model_copy(update={"dtheta_deg": opts.grid_override_deg})
    for key in ("support", "support_friction"):
        if getattr(opts, key) is not None:
            setting = setting.model_copy(update={key: getattr(opts, key)})
    objects_dir = opts.objects_dir.resolve()
    # `ycb:` names resolve here for this process and the worker processes it starts.
    previous = os.environ.get("GRASPSCAPE_YCB_DIR")
    os.environ["GRASPSCAPE_YCB_DIR"] = str(objects_dir / "ycb")
    try:
        return _run(opts, setting, objects_dir, say)
    finally:
        if previous is None:
            os.environ.pop("GRASPSCAPE_YCB_DIR", None)
        else:
            os.environ["GRASPSCAPE_YCB_DIR"] = previous


def _run(opts: AtlasOptions, setting: AtlasSetting, objects_dir: Path,
         say: Callable[[str], None]) -> int:
    from graspscape.services.local.atlas_site import write_site
    from graspscape.services.local.explore import _free_port

    names = atlas_objects(objects_dir)
    if opts.only:
        names = [n for n in names if n in opts.only or short_name(n) in opts.only]
        missing = set(opts.only) - {n for n in names} - {short_name(n) for n in names}
        if missing:
            raise ValueError(f"not among the atlas objects: {', '.join(sorted(missing))}")
    data_dir = opts.data_dir.resolve()
    data_dir.mkdir(parents=True, exist_ok=True)
    url = opts.database_url or f"sqlite:///{(data_dir / 'coordinator.db').as_posix()}"
    local = opts.procs > 0
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    settings = Settings(database=DatabaseSettings(data_dir=data_dir, url=url),
                        zenoh=ZenohSettings(enabled=local, mode="peer", listen=[endpoint],
                                            connect=[]))
    wire()
    engine, sessions = open_store(url)
    workers = _LocalWorkers(settings, sessions, endpoint, opts.procs) if local else None
    entries: list[AtlasEntry] = []
    started = time.monotonic()
    try:
        for i, name in enumerate(names, 1):
            with sessions() as session:
                mass = setting.mesh_mass_kg if Path(name).suffix.lower() in MESH_SUFFIXES \
                    else None
                object_id = store_object(session, name, mass_kg=mass)
                found = _find_or_create(session, setting.spec(object_id, short_name(name)),
                                        settings)
            for eid, finished, resting in found:
                # On a table, one page per resting pose, as the group's explorations.
                shown = short_name(name) + ("" if resting is None else f" rest{resting.index}")
                say(f"[{i}/{len(names)}] {shown}: exploration {eid}"
                    + (" (done before, skipped)" if finished else ""))
                if not finished and workers is not None:
                    workers.start()  # only once something is left to explore
                row = _wait(sessions, eid, workers.poll if workers else (lambda: None), say)
                entries.append(AtlasEntry(name=shown, exploration_id=eid, skipped=finished,
                                          wall_s=_wall_s(row), status=row.status,
                                          poses=row.poses_done, resting=resting))
    finally:
        if workers is not None:
            workers.stop()
    explored_s = time.monotonic() - started
    say(f"explored {len(entries)} objects in {explored_s:.0f} s; writing the site ...")
    index = write_site(sessions, entries, opts.out.resolve(), setting, pictures=opts.pictures)
    engine.dispose()
    print(f"atlas: {index} ({len(entries)} objects, setting {setting.name}); open it in a "
          "browser, no server needed")
    failed = [e.name for e in entries if e.status != ExplorationStatus.DONE]
    if failed:
        print(f"not done: {', '.join(failed)}", file=sys.stderr)
        return 2
    return 0
