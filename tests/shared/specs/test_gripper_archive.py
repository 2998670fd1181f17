"""A gripper's archive: the same files give the same bytes; unsafe or oversized archives are
refused with a message that says why; a URDF mesh outside its folder is refused at packing."""

from __future__ import annotations

import io
import shutil
import zipfile

import pytest
from graspscape.shared.specs import gripper_archive as ga
from graspscape.shared.specs.gripper import CONFIG_DIR, find_gripper, load_gripper
from graspscape.shared.specs.gripper_files import GripperFileError


def _zip(members: dict[str, bytes]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as archive:
        for name, body in members.items():
            archive.writestr(name, body)
    return out.getvalue()


def test_a_toml_gripper_packs_to_the_same_bytes_and_unpacks_to_a_loadable_spec(tmp_path):
    source = tmp_path / "my_jaw.toml"
    shutil.copy(CONFIG_DIR / "parallel_jaw.toml", source)
    kind, first = ga.archive_of(source)
    assert kind == "toml" and ga.archive_of(source)[1] == first
    files = ga.unpack(first)
    assert ga.kind_of(files) == "toml"
    ga.write_members(files, tmp_path / "out")
    path = ga.local_path(tmp_path / "out", "toml")
    assert find_gripper(str(path)) == path
    assert load_gripper(str(path)) == load_gripper(str(source))


def test_a_urdf_folder_packs_its_files_and_nothing_hidden(tmp_path):
    folder = tmp_path / "pr2"
    shutil.copytree(CONFIG_DIR / "pr2_gripper", folder)
    (folder / ".git").mkdir()
    (folder / ".git" / "HEAD").write_text("ref")
    kind, data = ga.archive_of(folder)
    files = ga.unpack(data)
    assert kind == "urdf" and ga.kind_of(files) == "urdf"
    assert set(files) == {p.name for p in (CONFIG_DIR / "pr2_gripper").iterdir()}


def test_a_urdf_mesh_outside_the_folder_is_refused_when_packing(tmp_path):
    folder = tmp_path / "pr2"
    shutil.copytree(CONFIG_DIR / "pr2_gripper", folder)
    urdf = folder / "pr2_gripper.urdf"
    urdf.write_text(urdf.read_text().replace('filename="l_finger_tip.stl"',
                                             'filename="../elsewhere.stl"'))
    assert "../elsewhere.stl" in urdf.read_text()
    with pytest.raises(GripperFileError, match="outside the gripper's folder"):
        ga.archive_of(folder)


@pytest.mark.parametrize("name", ["/etc/passwd", "../up.toml", "a/../../b", "a\\b", "C:x"])
def test_members_leaving_the_folder_are_refused(name: str):
    with pytest.raises(ga.GripperArchiveError, match="only relative paths"):
        ga.unpack(_zip({name: b"x"}))


def test_malformed_and_oversized_archives_are_refused(monkeypatch: pytest.MonkeyPatch):
    with pytest.raises(ga.GripperArchiveError, match="not a zip archive"):
        ga.unpack(b"PK\x03\x04 not really")
    with pytest.raises(ga.GripperArchiveError, match="neither"):
        ga.kind_of(ga.unpack(_zip({"readme.txt": b"hi"})))
    bomb = _zip({"spec.toml": b"0" * 5000})
    monkeypatch.setattr(ga, "MAX_UNPACKED_BYTES", 4000)
    with pytest.raises(ga.GripperArchiveError, match="unpacks to more than 4000"):
        ga.unpack(bomb)
    monkeypatch.setattr(ga, "MAX_ARCHIVE_BYTES", 100)
    with pytest.raises(ga.GripperArchiveError, match="more than the limit of 100"):
        ga.unpack(bomb)


def test_every_shipped_gripper_packs_and_loads_from_its_unpacked_archive(tmp_path):
    from graspscape.shared.specs.gripper import list_grippers

    for name in list_grippers():
        kind, data = ga.archive_of(find_gripper(name))
        out = tmp_path / name
        ga.write_members(ga.unpack(data), out)
        assert load_gripper(str(ga.local_path(out, kind))).name == load_gripper(name).name
