"""Which object names exist, known to both sides without the workers' geometry code.

The coordinator refuses an unknown name at upload and checks a named object's size at its
scale before any worker sees it; it must not import the workers, so the names and each
named object's size live here. The workers' catalogue (workers/sim/objects/catalog.py)
builds the geometry; a test keeps its entries and sizes equal to these.
"""

from __future__ import annotations

import os
from pathlib import Path

BUILTIN_NAMES = ("sphere", "cube", "can", "dumbbell", "mug", "spiked_ball")
PB_NAMES = ("mug", "bunny", "duck", "teddy")  # after 'pb:'

# Largest axis-aligned extent (m) of each built-in and pybullet_data entry at scale 1, as
# prepared (object frame). Used to check `scale` at upload without building the geometry.
NAMED_SIZE_M: dict[str, float] = {
    "sphere": 0.080,
    "cube": 0.060,
    "can": 0.120,
    "dumbbell": 0.160,
    "mug": 0.114,
    "spiked_ball": 0.094,
    "pb:mug": 0.122,
    "pb:bunny": 0.099,
    "pb:duck": 0.099,
    "pb:teddy": 0.093,
}


def ycb_root() -> Path:
    """YCB folder: $GRASPSCAPE_YCB_DIR, else ../shared/objects/ycb next to the repository."""
    env = os.environ.get("GRASPSCAPE_YCB_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2].parent / "shared" / "objects" / "ycb"


def ycb_names() -> list[str]:
    """'ycb:<Folder>' for every folder of this machine's YCB set that has a model.urdf."""
    root = ycb_root()
    if not root.is_dir():
        return []
    return sorted(f"ycb:{d.name}" for d in root.iterdir() if (d / "model.urdf").is_file())


def known_names() -> list[str]:
    """Every name ObjectSpec.name accepts on this machine: built-ins, 'pb:', then 'ycb:'."""
    return [*BUILTIN_NAMES, *(f"pb:{n}" for n in PB_NAMES), *ycb_names()]


def ycb_folder(name: str) -> Path | None:
    """The folder of a 'ycb:<Folder>' name on this machine, None if it has no such folder."""
    folder = name.removeprefix("ycb:")
    if not folder or "/" in folder or "\\" in folder or folder in (".", ".."):
        return None
    path = ycb_root() / folder
    return path if (path / "model.urdf").is_file() else None


def unknown_name_message(name: str) -> str:
    return (
        f"unknown object '{name}': use one of {', '.join(known_names())}, or give a mesh file"
    )
