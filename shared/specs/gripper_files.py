"""A gripper's files: the rule that every file a gripper description names lies inside its
folder (a URDF's meshes, an MJCF's assets), checked where a gripper is packed and where it is
loaded."""

from __future__ import annotations

import os
from pathlib import Path


class GripperFileError(ValueError):
    """A gripper's files cannot be used as they are; the message says why and what to do."""


def resolve_inside(folder: Path, filename: str, relative_to: Path | None = None, *,
                   must_exist: bool = True) -> Path:
    """The file a URDF names, which must lie inside the gripper's folder. `package://PKG/a/b`
    is looked up as `a/b` and as `PKG/a/b` under the folder, a plain name relative to
    `relative_to` (the URDF's folder); absolute paths, `..` out of the folder and links
    pointing out of it are refused. `must_exist=False`: only that rule, for a mesh of a link
    that may be dropped (an arm's, above the hand's base link)."""
    root = folder.resolve()
    start = root
    if filename.startswith("package://"):
        rest = filename.removeprefix("package://")
        candidates = [rest.split("/", 1)[1], rest] if "/" in rest else [rest]
    else:
        candidates = [filename.removeprefix("file://")]
        start = (relative_to or root).resolve()
    for name in candidates:
        path = (start / name).resolve()
        if os.path.isabs(name) or not path.is_relative_to(root):
            raise GripperFileError(
                f"mesh {filename!r} lies outside the gripper's folder {root}: copy the file "
                "into the folder and name it relative to it (package:// maps to the folder)")
        if path.is_file() or not must_exist:
            return path
    raise GripperFileError(f"mesh {filename!r} is not in the gripper's folder {root}")
