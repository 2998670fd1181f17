"""POST /grippers: a gripper of one's own uploaded over REST, named in a spec by the hash the
answer gives; what is not a gripper is refused with why, and nothing is stored."""

from __future__ import annotations

import io
import shutil
import zipfile
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.api import grippers as route
from graspscape.services.coordinator.store.models import ExplorationRow, GripperRow
from graspscape.shared.specs.gripper import CONFIG_DIR
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker


def _zip(members: dict[str, bytes]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as archive:
        for name, body in members.items():
            archive.writestr(name, body)
    return out.getvalue()


def _count(sessions: sessionmaker[Session]) -> int:
    with sessions() as s:
        return s.scalar(select(func.count()).select_from(GripperRow)) or 0


def test_a_toml_upload_is_named_by_its_hash_and_a_spec_can_use_it(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    toml = (CONFIG_DIR / "parallel_jaw.toml").read_bytes().replace(b'"parallel_jaw"', b'"mine"')
    first = client.post("/grippers", files={"file": ("mine.toml", toml)})
    assert first.status_code == 201, first.text
    body = first.json()
    assert body["kind"] == "toml" and body["name"] == "mine"
    assert body["gripper"] == "sha256:" + body["content_hash"]
    again = client.post("/grippers", files={"file": ("other-name.toml", toml)})
    assert again.status_code == 200 and again.json() == body
    run = client.post("/explorations", json={
        "object_id": object_id, "gripper": body["gripper"],
        "grid": {"dtheta": 1.5, "r_min": 0.01, "r_max": 0.02, "dr": 0.01},
        "refinement": {"levels": 0}})
    assert run.status_code == 201, run.text
    with sessions() as s:
        assert s.get(ExplorationRow, run.json()["id"]).gripper_hash == body["content_hash"]
    unknown = client.post("/explorations", json={"object_id": object_id,
                                                 "gripper": "sha256:" + "0" * 64})
    assert unknown.status_code == 422 and "upload it with POST /grippers" in unknown.text


def test_a_zipped_urdf_folder_is_repacked_to_the_same_hash_however_it_was_zipped(
    client: TestClient, tmp_path: Path
) -> None:
    folder = CONFIG_DIR / "pr2_gripper"
    members = {p.name: p.read_bytes() for p in folder.iterdir()}
    flat = client.post("/grippers", files={"file": ("pr2.zip", _zip(members))})
    assert flat.status_code == 201, flat.text
    nested = _zip({f"pr2_gripper/{k}": v for k, v in reversed(members.items())})
    inside = client.post("/grippers", files={"file": ("pr2-again.zip", nested)})
    assert inside.status_code == 200 and inside.json() == flat.json()
    assert flat.json()["kind"] == "urdf" and flat.json()["name"]


@pytest.mark.parametrize("filename, data, why", [
    ("hand.zip", b"not a zip", "not a zip archive"),
    ("hand.zip", _zip({"../gripper.toml": b"x"}), "only relative paths"),
    ("hand.zip", _zip({"readme.txt": b"x"}), "no gripper.toml at the top"),
    ("hand.urdf", b"<robot/>", "upload a gripper's TOML spec"),
    ("hand.toml", b"name = 'x'", "palm"),
])
def test_what_is_not_a_gripper_is_refused_and_nothing_stored(
    client: TestClient, sessions: sessionmaker[Session], filename: str, data: bytes, why: str
) -> None:
    answer = client.post("/grippers", files={"file": (filename, data)})
    assert answer.status_code == 422 and why in answer.text, answer.text
    assert _count(sessions) == 0


def test_a_urdf_mesh_outside_the_folder_is_refused(client: TestClient, tmp_path: Path) -> None:
    folder = tmp_path / "pr2"
    shutil.copytree(CONFIG_DIR / "pr2_gripper", folder)
    urdf = folder / "pr2_gripper.urdf"
    urdf.write_text(urdf.read_text().replace('"l_finger_tip.stl"', '"/tmp/elsewhere.stl"'))
    members = {p.name: p.read_bytes() for p in folder.iterdir()}
    answer = client.post("/grippers", files={"file": ("pr2.zip", _zip(members))})
    assert answer.status_code == 422 and "outside the gripper's folder" in answer.text


def test_an_oversized_upload_is_refused(client: TestClient, sessions: sessionmaker[Session],
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(route, "MAX_ARCHIVE_BYTES", 1000)
    answer = client.post("/grippers", files={"file": ("big.toml", b"#" * 70_000)})
    assert answer.status_code == 413 and "1000 bytes" in answer.text
    # within the body's slack: refused as the file is read, in the words POST /objects uses
    answer = client.post("/grippers", files={"file": ("big.toml", b"#" * 1001)})
    assert answer.status_code == 413
    assert "the gripper file is larger than the upload limit of 1000 bytes" in answer.text
    assert _count(sessions) == 0
