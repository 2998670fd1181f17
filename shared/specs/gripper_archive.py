"""A gripper's description as one archive, so that it can travel to workers like a mesh.

The coordinator packs the gripper a spec names (a TOML spec file, or a URDF gripper's folder
with its meshes) into a zip whose bytes depend only on the files' names and contents (sorted
entries, fixed dates and modes), stores it under the SHA-256 of those bytes, and workers fetch
it by that hash (workers/runtime/grippers.py). A TOML gripper's archive holds one member,
`spec.toml`; a URDF gripper's holds its folder's files with `gripper.toml` at the top.

Unpacking trusts nothing: members with absolute paths, `..`, backslashes or links are
refused, and so are archives over the size limits (a zip bomb included), with a message that
says which limit.
"""

from __future__ import annotations

import io
import os
import re
import stat
import tomllib
import zipfile
from pathlib import Path, PurePosixPath
from typing import Literal

from graspscape.shared.specs.gripper import (
    URDF_DESCRIPTION,
    GripperSpec,
    MjcfGripperSpec,
    find_gripper,
    load_urdf_gripper,
    unknown_gripper_message,
)
from graspscape.shared.specs.gripper_files import GripperFileError, resolve_inside
from pydantic import ValidationError

GripperKind = Literal["toml", "urdf"]
TOML_MEMBER = "spec.toml"  # the one member of a TOML gripper's archive
MAX_ARCHIVE_BYTES = 32 * 1024 * 1024  # the archive as stored and sent
MAX_UNPACKED_BYTES = 128 * 1024 * 1024  # all members unpacked
MAX_MEMBERS = 512
_DATE = (1980, 1, 1, 0, 0, 0)  # the earliest date zip can hold: no clock in the bytes
_MESH_FILE = re.compile(r"""<mesh\b[^>]*?\bfilename\s*=\s*(["'])(.*?)\1""", re.S)


class GripperArchiveError(ValueError):
    """An archive that is not a usable gripper; the message says why."""


def pack(files: dict[str, bytes]) -> bytes:
    """The archive of these members (POSIX relative names): the same files give the same
    bytes."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(files):
            info = zipfile.ZipInfo(_safe_name(name), date_time=_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (stat.S_IFREG | 0o644) << 16
            archive.writestr(info, files[name])
    data = out.getvalue()
    if len(data) > MAX_ARCHIVE_BYTES:
        raise GripperArchiveError(f"the gripper's archive is {len(data)} bytes, more than the "
                                  f"limit of {MAX_ARCHIVE_BYTES}")
    return data


def _safe_name(name: str) -> str:
    path = PurePosixPath(name)
    if (not name or "\\" in name or "\x00" in name or path.is_absolute() or ":" in path.parts[0]
            or any(part in ("", ".", "..") for part in name.split("/"))):
        raise GripperArchiveError(f"archive member {name!r}: only relative paths inside the "
                                  "gripper's folder are allowed (no absolute path, no '..')")
    return name


def unpack(data: bytes) -> dict[str, bytes]:
    """The members of an archive, every name and size checked before anything is read."""
    if len(data) > MAX_ARCHIVE_BYTES:
        raise GripperArchiveError(f"the gripper's archive is {len(data)} bytes, more than the "
                                  f"limit of {MAX_ARCHIVE_BYTES}")
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except (zipfile.BadZipFile, ValueError) as exc:
        raise GripperArchiveError(f"not a zip archive: {exc}") from exc
    with archive:
        infos = [i for i in archive.infolist() if not i.is_dir()]
        if len(infos) > MAX_MEMBERS:
            raise GripperArchiveError(f"the archive has {len(infos)} files, more than "
                                      f"{MAX_MEMBERS}")
        if sum(i.file_size for i in infos) > MAX_UNPACKED_BYTES:
            raise GripperArchiveError(f"the archive unpacks to more than {MAX_UNPACKED_BYTES} "
                                      "bytes")
        files: dict[str, bytes] = {}
        for info in infos:
            name = _safe_name(info.filename)
            if stat.S_ISLNK(info.external_attr >> 16):
                raise GripperArchiveError(f"archive member {name!r} is a link; put the file "
                                          "itself in the folder")
            if name in files:
                raise GripperArchiveError(f"archive member {name!r} appears twice")
            try:
                with archive.open(info) as fh:  # read at most the declared size, plus one
                    body = fh.read(info.file_size + 1)
            except (zipfile.BadZipFile, OSError, EOFError, ValueError) as exc:
                raise GripperArchiveError(f"archive member {name!r} cannot be read: {exc}"
                                          ) from exc
            if len(body) != info.file_size:
                raise GripperArchiveError(f"archive member {name!r} is not the size it says")
            files[name] = body
    return files


def kind_of(files: dict[str, bytes]) -> GripperKind:
    if URDF_DESCRIPTION in files:
        return "urdf"
    if list(files) == [TOML_MEMBER]:
        return "toml"
    raise GripperArchiveError(f"the archive holds neither a {URDF_DESCRIPTION} at its top (a "
                              f"URDF gripper's folder) nor one {TOML_MEMBER} (a TOML gripper)")


def folder_files(folder: Path) -> dict[str, bytes]:
    """Every file of a URDF gripper's folder, by its path relative to the folder. Hidden
    files and folders are left out; a link pointing out of the folder is refused."""
    root = folder.resolve()
    files: dict[str, bytes] = {}
    for dirpath, dirnames, filenames in os.walk(root, followlinks=False):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
        for filename in sorted(f for f in filenames if not f.startswith(".")):
            path = Path(dirpath) / filename
            if not path.resolve().is_relative_to(root):
                raise GripperFileError(f"{path} links outside the gripper's folder {root}; "
                                       "copy the file into the folder")
            if path.is_file():
                files[path.relative_to(root).as_posix()] = path.read_bytes()
    return files


def check_urdf_folder(folder: Path) -> None:
    """The description parses, the URDF is in the folder, and no mesh it names points out of
    the folder (the rule the worker applies, checked here so that a submit is refused, not a
    tile). A mesh that is missing is the worker's to report: it may belong to a link the
    gripper drops (an arm's, above the base link)."""
    spec = load_urdf_gripper(folder)
    if isinstance(spec, MjcfGripperSpec):
        _check_mjcf(folder, spec)
        return
    urdf = resolve_inside(folder, spec.urdf)
    # The mesh names only: the worker's parser (workers/sim/gripper/urdf_import.py) is the one
    # that reads the file, and takes files other tools wrote with undeclared XML prefixes.
    for filename in _MESH_FILE.findall(urdf.read_text(errors="replace")):
        resolve_inside(folder, filename[1], urdf.parent, must_exist=False)


# The attributes by which an MJCF reaches files: its assets and the folders they are read from.
_MJCF_FILE = re.compile(r"""\b(file|meshdir|texturedir|assetdir)\s*=\s*["']([^"']+)["']""")


def _check_mjcf(folder: Path, spec: MjcfGripperSpec) -> None:
    """An MJCF gripper's folder (it travels as a folder, like a URDF's): the MJCF lies in the
    folder and no file or asset folder it names points out of it."""
    mjcf = resolve_inside(folder, spec.mjcf)
    for _, filename in _MJCF_FILE.findall(mjcf.read_text(errors="replace")):
        resolve_inside(folder, filename, mjcf.parent, must_exist=False)


def archive_of(found: Path) -> tuple[GripperKind, bytes]:
    """The kind and archive of a found gripper (find_gripper's answer), checked as a worker
    would load it."""
    if found.is_dir():
        check_urdf_folder(found)
        return "urdf", pack(folder_files(found))
    data = found.read_bytes()
    GripperSpec.model_validate(tomllib.loads(data.decode()))
    return "toml", pack({TOML_MEMBER: data})


def archive_of_name(name_or_path: str) -> tuple[GripperKind, bytes]:
    """archive_of for a spec's gripper string; ValueError (with what to pass) when it names
    nothing or its files are not a usable gripper."""
    found = find_gripper(name_or_path)
    if found is None:
        raise GripperFileError(unknown_gripper_message(name_or_path))
    try:
        return archive_of(found)
    except (ValidationError, tomllib.TOMLDecodeError, UnicodeDecodeError, OSError) as exc:
        raise GripperFileError(f"gripper {name_or_path}: {_first_line(exc)}") from exc


def write_members(files: dict[str, bytes], folder: Path) -> None:
    """Write unpacked members under `folder` (names checked by unpack: none leaves it)."""
    root = folder.resolve()
    for name, body in files.items():
        path = (root / _safe_name(name)).resolve()
        if not path.is_relative_to(root):
            raise GripperArchiveError(f"archive member {name!r} leaves the folder")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(body)


def local_path(folder: Path, kind: GripperKind) -> Path:
    """What find_gripper is given for an unpacked archive: the TOML file, or the folder."""
    return folder / TOML_MEMBER if kind == "toml" else folder


def _first_line(exc: Exception) -> str:
    text = str(exc)
    return text.splitlines()[0] if isinstance(exc, OSError) else " ".join(text.split())
