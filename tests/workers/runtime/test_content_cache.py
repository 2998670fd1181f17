"""The content-addressed cache entry behind meshes and gripper archives: fetched once, kept
only when its bytes hash to its name, a crashed process's half folder replaced whole."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
from graspscape.workers.runtime.content_cache import FetchError, fill_once

DATA = b"solid box\n"
HASH = hashlib.sha256(DATA).hexdigest()


class _Refused(FetchError):
    pass


def _fill(target: Path, fetched: list[bytes], data: bytes = DATA) -> bool:
    def fetch() -> bytes:
        fetched.append(data)
        return data

    def write(body: bytes, tmp: Path) -> None:
        tmp.mkdir()
        (tmp / "mesh.stl").write_bytes(body)
        (tmp / ".done").write_text("")

    return fill_once(target, HASH, whole=(target / ".done").is_file, fetch=fetch, write=write,
                     error=_Refused, what=f"mesh {HASH}")


def test_an_entry_is_fetched_once_over_a_half_folder(tmp_path: Path) -> None:
    target = tmp_path / HASH
    target.mkdir()
    (target / "mesh.stl").write_bytes(b"half")  # a crashed process's, never marked whole
    fetched: list[bytes] = []
    assert _fill(target, fetched) and not _fill(target, fetched)
    assert len(fetched) == 1 and (target / "mesh.stl").read_bytes() == DATA
    assert sorted(p.name for p in tmp_path.iterdir()) == [HASH, f"{HASH}.lock"]


def test_bytes_of_another_hash_are_refused_and_nothing_is_kept(tmp_path: Path) -> None:
    target = tmp_path / HASH
    with pytest.raises(_Refused, match="another hash") as refused:
        _fill(target, [], b"tampered")
    assert not refused.value.transient
    assert [p.name for p in tmp_path.iterdir()] == [f"{HASH}.lock"]
