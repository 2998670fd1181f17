"""The gripper spec formats: a palm and fingers made of phalanges (a TOML of boxes, generic
enough for any serial-finger gripper: the Robotiq 3-finger hand, a parallel-jaw gripper, ...),
or a vendor's URDF plus a short description of it (`UrdfGripperSpec`, docs/howto/add-gripper.md),
or a vendor's MJCF plus the same kind of description (`MjcfGripperSpec`: MuJoCo engine only).

Frames: the gripper base frame has its origin at the centre of the palm surface and +z along
the palm normal, pointing out of the palm toward where the fingers reach. Each finger has a
mount frame (its knuckle) given by a position on the palm and a yaw about the palm normal; in
the mount frame the finger extends along +z and closes toward +x.
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

# The shipped grippers: configs/grippers/ of the checkout, which an installed copy carries as
# graspscape/configs/grippers/ (setup.py), at the same place relative to this file.
CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "grippers"
# Folders of one's own grippers, searched before the shipped ones (os.pathsep-separated).
GRIPPER_PATH_ENV = "GRASPSCAPE_GRIPPER_PATH"


class PalmSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    size: tuple[float, float, float] = Field(description="x, y, thickness (m)")
    mass: float = Field(gt=0)


class PhalanxSpec(BaseModel):
    """One link of a finger and the joint that carries it."""

    model_config = ConfigDict(frozen=True)

    name: str
    joint: Literal["revolute", "prismatic"] = "revolute"
    length: float = Field(gt=0, description="along the finger (+z of its joint frame), m")
    width: float = Field(gt=0, description="across the finger (y), m")
    thickness: float = Field(gt=0, description="in the closing direction (x), m")
    mass: float = Field(gt=0)
    lower: float = Field(description="joint limit: rad (revolute) or m (prismatic)")
    upper: float
    open: float = Field(description="joint value of the open hand")
    torque_share: float = Field(
        default=1.0, gt=0, le=1.0, description="share of the finger's closing effort"
    )

    @model_validator(mode="after")
    def _limits(self) -> PhalanxSpec:
        if not self.lower < self.upper or not self.lower <= self.open <= self.upper:
            raise ValueError(f"phalanx {self.name}: need lower < upper and open within them")
        return self


class SpreadSpec(BaseModel):
    """A joint about the palm normal that turns a finger's closing plane (Robotiq scissor)."""

    model_config = ConfigDict(frozen=True)

    lower: float
    upper: float
    mass: float = Field(default=0.05, gt=0)


class FingerSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str
    mount_xyz: tuple[float, float, float]
    mount_yaw: float = Field(description="rotation of the mount frame about the palm normal")
    spread: SpreadSpec | None = None
    spread_sign: float = Field(default=1.0, description="how this finger follows the spread mode")
    phalanges: tuple[PhalanxSpec, ...] = Field(min_length=1)


class GripperSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str
    description: str = ""
    palm: PalmSpec
    fingers: tuple[FingerSpec, ...] = Field(min_length=1)
    closing_effort: float = Field(
        gt=0, description="default closing torque (N·m) or force (N) per finger actuator"
    )
    spread_modes: dict[str, float] = Field(
        default_factory=lambda: {"basic": 0.0}, description="named spread angles, rad"
    )

    @model_validator(mode="after")
    def _unique_names(self) -> GripperSpec:
        names = [f.name for f in self.fingers]
        links = [f"{f.name}_{p.name}" for f in self.fingers for p in f.phalanges]
        if len(set(names)) != len(names) or len(set(links)) != len(links):
            raise ValueError("finger and phalanx names must be unique")
        return self

    def reach(self) -> float:
        """How far the open hand reaches past the palm surface along its normal, m."""
        import math

        best = 0.0
        for finger in self.fingers:
            z, angle = finger.mount_xyz[2], 0.0
            for phalanx in finger.phalanges:
                if phalanx.joint == "revolute":
                    angle += phalanx.open
                z += phalanx.length * math.cos(angle)
            best = max(best, z)
        return best


# A finger's name is the digit its links are counted under (manifolds/behaviour.py reads the
# digit as the letters before "_1", "_2", ... of a link name), so letters only.
_FINGER_NAME = re.compile(r"^[A-Za-z]+$")
URDF_DESCRIPTION = "gripper.toml"  # the description file inside a URDF gripper's folder


class MimicSpec(BaseModel):
    """A joint that follows another one, q = ratio · q_driver + offset (a URDF <mimic>, a
    coupling linkage): realised with a pybullet gear constraint, not a motor."""

    model_config = ConfigDict(frozen=True)

    joint: str = Field(description="the driving joint, as the URDF names it")
    ratio: float = 1.0
    offset: float = 0.0


class UrdfJointSpec(BaseModel):
    """One joint of a finger, in closing order. Values are in the URDF's own convention."""

    model_config = ConfigDict(frozen=True)

    joint: str = Field(description="the joint's name in the URDF")
    open: float = Field(description="joint value of the open hand (URDF convention)")
    closing: Literal[1, -1] = Field(
        default=1, description="+1: the joint closes as its value grows; -1: as it shrinks")
    torque_share: float = Field(default=1.0, gt=0, le=1.0)
    mimic: MimicSpec | None = None


class UrdfSpreadSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    joint: str
    sign: float = Field(default=1.0, description="how this finger follows the spread mode")


class UrdfFingerSpec(BaseModel):
    model_config = ConfigDict(frozen=True)

    name: str
    joints: tuple[UrdfJointSpec, ...] = Field(min_length=1)
    spread: UrdfSpreadSpec | None = None

    @model_validator(mode="after")
    def _name(self) -> UrdfFingerSpec:
        if not _FINGER_NAME.match(self.name):
            raise ValueError(f"finger name {self.name!r}: letters only (it names a digit)")
        return self

    @property
    def actuated(self) -> bool:
        """A finger whose joints all mimic others has no actuator of its own."""
        return any(j.mimic is None for j in self.joints)


class PalmFrameSpec(BaseModel):
    """The gripper frame in the base link's frame: origin at the palm surface centre, z along
    the palm normal (toward where the fingers reach), x toward the side that placement's
    reference attitude turns up (shared/specs/placement.py)."""

    model_config = ConfigDict(frozen=True)

    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    x_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)


class UrdfGripperSpec(BaseModel):
    """A gripper from its URDF plus this description (the folder's gripper.toml)."""

    model_config = ConfigDict(frozen=True)

    kind: Literal["urdf"] = "urdf"
    name: str
    description: str = ""
    source: str = Field(default="", description="where the URDF and meshes come from")
    licence: str = Field(default="", description="their licence (a file in the folder)")
    folder: Path = Field(description="the gripper's folder; every file it uses lies inside")
    urdf: str = Field(description="the URDF file, relative to the folder")
    base_link: str = Field(description="root of the gripper's subtree; links above are dropped")
    palm: PalmFrameSpec = PalmFrameSpec()
    fingers: tuple[UrdfFingerSpec, ...] = Field(min_length=1)
    closing_effort: float = Field(gt=0, description="N·m or N per finger actuator")
    spread_modes: dict[str, float] = Field(default_factory=lambda: {"basic": 0.0})
    reach_m: float = Field(gt=0, description="how far the open hand reaches past the palm "
                           "surface (`graspscape gripper check` measures it)")
    inertia: Literal["file", "geometry"] = Field(
        default="file", description="the URDF's inertia tensors, or pybullet's from the "
        "collision shapes (for files whose tensors are placeholders)")

    @model_validator(mode="after")
    def _unique(self) -> UrdfGripperSpec:
        names = [f.name for f in self.fingers]
        joints = [j.joint for f in self.fingers for j in f.joints]
        if len(set(names)) != len(names) or len(set(joints)) != len(joints):
            raise ValueError("finger names and joint names must be unique")
        if not any(f.actuated for f in self.fingers):
            raise ValueError("no finger has an actuated joint")
        return self

    def reach(self) -> float:
        return self.reach_m


class MjcfFingerSpec(BaseModel):
    """One finger of an MJCF gripper: the joints the closing sequence commands, and the joints
    the model's own constraints move (a linkage's passive joints), which count for this digit."""

    model_config = ConfigDict(frozen=True)

    name: str
    joints: tuple[UrdfJointSpec, ...] = Field(min_length=1)
    passive: tuple[str, ...] = Field(default=(), description="joints moved by the MJCF's "
                                     "equality constraints, tendons or springs")

    @model_validator(mode="after")
    def _checked(self) -> MjcfFingerSpec:
        if not _FINGER_NAME.match(self.name):
            raise ValueError(f"finger name {self.name!r}: letters only (it names a digit)")
        if any(j.mimic is not None for j in self.joints):
            raise ValueError(f"finger {self.name}: an MJCF couples joints itself (equality "
                             "constraints, tendons); mimic is for URDF grippers")
        return self


class MjcfGripperSpec(BaseModel):
    """A gripper from a vendor's MJCF (MuJoCo Menagerie's, say) plus this description (the
    folder's gripper.toml, with kind = "mjcf"). Only the MuJoCo engine loads it."""

    model_config = ConfigDict(frozen=True)

    kind: Literal["mjcf"] = "mjcf"
    name: str
    description: str = ""
    source: str = Field(default="", description="where the MJCF and meshes come from")
    licence: str = Field(default="", description="their licence (a file in the folder)")
    folder: Path = Field(description="the gripper's folder; every file it uses lies inside")
    mjcf: str = Field(description="the MJCF file, relative to the folder")
    base_body: str = Field(description="the hand's root body; the palm frame is given in it")
    actuator: str = Field(description="the MJCF's actuator that closes the hand (its "
                          "transmission, a joint or a tendon, is kept; its gains are the "
                          "closing sequence's)")
    palm: PalmFrameSpec = PalmFrameSpec()
    fingers: tuple[MjcfFingerSpec, ...] = Field(min_length=1)
    closing_effort: float = Field(gt=0, description="N·m or N on each finger joint")
    spread_modes: dict[str, float] = Field(default_factory=lambda: {"basic": 0.0})
    reach_m: float = Field(gt=0)

    @model_validator(mode="after")
    def _unique(self) -> MjcfGripperSpec:
        names = [f.name for f in self.fingers]
        joints = [j.joint for f in self.fingers for j in f.joints] + [
            j for f in self.fingers for j in f.passive]
        if len(set(names)) != len(names) or len(set(joints)) != len(joints):
            raise ValueError("finger names and joint names must be unique")
        return self

    def reach(self) -> float:
        return self.reach_m


AnyGripperSpec = GripperSpec | UrdfGripperSpec | MjcfGripperSpec

# A gripper stored on the coordinator (POST /grippers, or packed at submit): the spec names it
# by the content hash of its archive (shared/specs/gripper_archive.py).
STORED_PREFIX = "sha256:"
STORED_GRIPPER = re.compile(r"^sha256:[0-9a-f]{64}$")


def is_shipped(found: Path) -> bool:
    """Whether a found gripper file or folder is one of the shipped ones (every worker has
    those; any other is shipped to workers by the coordinator)."""
    return found.resolve().is_relative_to(CONFIG_DIR.resolve())


def gripper_dirs() -> list[Path]:
    """Where a gripper name is looked up: GRASPSCAPE_GRIPPER_PATH's folders, then the shipped
    grippers."""
    given = os.environ.get(GRIPPER_PATH_ENV, "")
    return [Path(p).expanduser() for p in given.split(os.pathsep) if p] + [CONFIG_DIR]


def _urdf_folder(path: Path) -> Path | None:
    if path.is_dir() and (path / URDF_DESCRIPTION).is_file():
        return path
    if path.name == URDF_DESCRIPTION and path.is_file():
        return path.parent
    return None


def find_gripper(name_or_path: str) -> Path | None:
    """The file or folder a gripper names: a path to a TOML spec or a URDF gripper's folder
    (or its gripper.toml), or a name looked up in `gripper_dirs()` (NAME.toml, or a folder
    NAME/ with gripper.toml); None if none exists."""
    path = Path(name_or_path).expanduser()
    if path.suffix == ".toml" and path.is_file() and path.name != URDF_DESCRIPTION:
        return path
    folder = _urdf_folder(path)
    if folder is not None:
        return folder
    if path.suffix or len(path.parts) != 1:  # a path, and nothing there
        return None
    for directory in gripper_dirs():
        if (directory / f"{name_or_path}.toml").is_file():
            return directory / f"{name_or_path}.toml"
        if (directory / name_or_path / URDF_DESCRIPTION).is_file():
            return directory / name_or_path
    return None


def unknown_gripper_message(name_or_path: str) -> str:
    """Why `name_or_path` names no gripper, and what to pass instead."""
    path = Path(name_or_path)
    if path.suffix.lower() in (".urdf", ".xacro", ".sdf"):
        folder = path.parent if str(path.parent) not in ("", ".") else Path(".")
        has = (folder / URDF_DESCRIPTION).is_file()
        return (f"{name_or_path} is a robot description, not a gripper: pass its folder "
                f"({folder}){' which has' if has else ', with'} a {URDF_DESCRIPTION} that "
                "says which links are the palm and fingers (docs/howto/add-gripper.md, 'A URDF "
                "gripper')")
    if path.suffix or len(path.parts) != 1:
        return (f"no gripper at {name_or_path}: a TOML spec file, or a folder with "
                f"{URDF_DESCRIPTION}, is expected")
    where = ", ".join(str(d) for d in gripper_dirs())
    return (f"unknown gripper {name_or_path!r}; known: {', '.join(list_grippers())} "
            f"(searched {where}; add folders with {GRIPPER_PATH_ENV})")


def load_urdf_gripper(folder: Path) -> UrdfGripperSpec | MjcfGripperSpec:
    """A gripper folder's description: a URDF's, or an MJCF's (kind = "mjcf")."""
    with (folder / URDF_DESCRIPTION).open("rb") as fh:
        data = tomllib.load(fh)
    cls = MjcfGripperSpec if data.get("kind") == "mjcf" else UrdfGripperSpec
    return cls.model_validate({**data, "folder": folder.resolve()})


def load_gripper(name_or_path: str) -> AnyGripperSpec:
    """A gripper by name (NAME.toml or a URDF gripper's folder NAME/, in GRASPSCAPE_GRIPPER_PATH
    then the shipped configs/grippers), by path to a TOML spec, or by path to a URDF gripper's
    folder."""
    found = find_gripper(name_or_path)
    if found is None:
        raise ValueError(unknown_gripper_message(name_or_path))
    if found.is_dir():
        return load_urdf_gripper(found)
    with found.open("rb") as fh:
        return GripperSpec.model_validate(tomllib.load(fh))


def list_grippers() -> list[str]:
    """The names of the grippers found in `gripper_dirs()`."""
    names: set[str] = set()
    for directory in gripper_dirs():
        names.update(p.stem for p in directory.glob("*.toml"))
        names.update(p.parent.name for p in directory.glob(f"*/{URDF_DESCRIPTION}"))
    return sorted(names)


def engine_problem(name_or_path: str, engines: Iterable[str]) -> str | None:
    """Why the gripper cannot be simulated in every one of `engines` (an MJCF description
    loads in MuJoCo only), or None; a gripper that does not load is left to the check that
    names it."""
    others = sorted(set(engines) - {"mujoco"})
    if not others:
        return None
    try:
        spec = load_gripper(name_or_path)
    except (ValueError, OSError, tomllib.TOMLDecodeError):
        return None
    if isinstance(spec, MjcfGripperSpec):
        return (f"gripper {name_or_path} is described by an MJCF, which only the MuJoCo engine "
                f"loads (asked for: {', '.join(others)}): use the engine mujoco")
    return None
