"""POST/GET /objects through the real app on both databases, every validation error included:
the one object validation (shared/specs/object_checks.py) refuses at upload what every worker
would refuse, and returns and stores its warnings (issue #19, finding 6)."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh
from fastapi.testclient import TestClient
from graspscape.services.coordinator.settings import Settings
from pydantic import SecretStr
from sqlalchemy.orm import Session

from tests import object_meshes as meshes
from tests.factories import box_stl
from tests.services.coordinator.conftest import RefusalApi

TETRA_OBJ = b"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def test_named_object_is_stored_once(client: TestClient) -> None:
    first = client.post("/objects", data={"name": "mug", "mass_kg": "0.3", "friction": "0.8"})
    assert first.status_code == 201, first.text
    body = first.json()
    assert (body["kind"], body["name"], body["content_hash"]) == ("named", "mug", None)
    assert body["properties"] == {"mass_kg": 0.3, "friction": 0.8, "scale": 1.0}
    again = client.post("/objects", data={"name": "mug", "mass_kg": "0.3", "friction": "0.8"})
    assert again.status_code == 200 and again.json()["id"] == body["id"]
    other = client.post("/objects", data={"name": "mug", "mass_kg": "0.5"})
    assert other.status_code == 201 and other.json()["id"] != body["id"]
    assert client.post("/objects", data={"name": "ycb:YcbPowerDrill"}).status_code == 201


def test_mesh_upload_is_validated_hashed_and_listed(client: TestClient) -> None:
    data = box_stl()
    response = client.post(
        "/objects",
        files={"file": ("box.stl", data, "application/octet-stream")},
        data={"mass_kg": "0.4", "inertia_diag": "0.001,0.001,0.0005"},
    )
    assert response.status_code == 201, response.text
    body = response.json()
    assert body["kind"] == "upload" and body["mesh_format"] == "stl"
    assert len(body["content_hash"]) == 64
    assert body["mesh_info"]["watertight"] is True
    assert body["mesh_info"]["volume_m3"] == pytest.approx(0.05 * 0.05 * 0.1, rel=1e-3)
    assert body["properties"]["inertia_diag"] == [0.001, 0.001, 0.0005]
    assert body["mesh_info"]["bodies"] == 1 and body["warnings"] == []
    obj = client.post("/objects", files={"file": ("t.obj", TETRA_OBJ)}, data={"mass_kg": "0.1"})
    assert obj.status_code == 201, obj.text
    listing = client.get("/objects", params={"limit": 1, "offset": 1}).json()
    assert listing["total"] == 2 and [o["id"] for o in listing["items"]] == [obj.json()["id"]]
    assert client.get(f"/objects/{body['id']}").json() == body


def test_shared_folder_objects(client: TestClient, settings: Settings) -> None:
    folder = settings.api.shared_objects_dir
    assert folder is not None
    folder.mkdir(parents=True)
    (folder / "tetra.obj").write_bytes(TETRA_OBJ)
    ok = client.post("/objects", data={"name": "shared:tetra.obj", "mass_kg": "0.1"})
    assert ok.status_code == 201, ok.text
    assert ok.json()["kind"] == "shared" and ok.json()["mesh_info"]["faces"] == 4
    missing = client.post("/objects", data={"name": "shared:nope.obj"})
    assert missing.status_code == 422 and "does not exist" in str(missing.json()["detail"])
    escape = client.post("/objects", data={"name": "shared:../secret.obj"})
    assert escape.status_code == 422 and "outside the shared folder" in str(escape.json()["detail"])


def _flat_obj() -> bytes:
    return b"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0.1 0.1 0\nf 1 2 3\nf 2 4 3\n"


def _nan_obj() -> bytes:
    return TETRA_OBJ.replace(b"v 0.1 0 0", b"v nan 0 0")


def _coplanar_open_obj() -> bytes:
    # Open surface whose points all lie in one slanted plane: no solid at all.
    return b"v 0 0 0\nv 0.1 0.1 0\nv 0 0 0.1\nv 0.1 0.1 0.1\nf 1 2 3\nf 2 4 3\n"


@pytest.mark.parametrize(
    ("files", "data", "status", "fragment"),
    [
        (None, {}, 422, "give a mesh file"),
        ({"file": ("box.stl", box_stl())}, {"name": "sphere"}, 422, "not both"),
        (None, {"name": "teapot"}, 422, "unknown object 'teapot'"),
        (None, {"name": "pb:teapot"}, 422, "unknown object 'pb:teapot'"),
        (None, {"name": "cube", "scale": "1e-12"}, 422, "too small"),
        (None, {"name": "cube", "units": "mm"}, 422, "units apply to mesh files"),
        (None, {"name": "cube", "units": "inch"}, 422, "units"),
        (None, {"name": "sphere", "mass_kg": "-1"}, 422, "mass_kg"),
        (None, {"name": "sphere", "mass_kg": "abc"}, 422, "mass_kg"),
        (None, {"name": "sphere", "friction": "9"}, 422, "friction"),
        (None, {"name": "sphere", "scale": "0"}, 422, "scale"),
        (None, {"name": "sphere", "inertia_diag": "1,2"}, 422, "inertia_diag"),
        (None, {"name": "sphere", "inertia_diag": "1,-2,3"}, 422, "inertia_diag"),
        (None, {"name": "sphere", "inertia_diag": "1,nan,3"}, 422, "inertia_diag"),
        (None, {"name": "shared:a\x01b.obj"}, 422, "control characters"),
        ({"file": ("box.step", b"solid")}, {}, 415, "unsupported format"),
        ({"file": ("noext", b"solid")}, {}, 415, "unsupported format"),
        ({"file": ("empty.stl", b"")}, {}, 422, "mesh file is empty"),
        ({"file": ("junk.stl", b"this is not a mesh at all")}, {}, 422, "mesh"),
        ({"file": ("flat.obj", _flat_obj())}, {}, 422, "flat"),
        ({"file": ("nan.obj", _nan_obj())}, {}, 422, "non-finite"),
        ({"file": ("plane.obj", _coplanar_open_obj())}, {}, 422, "not watertight"),
        ({"file": ("box.stl", box_stl((50.0, 50.0, 100.0)))}, {}, 422, "metres"),
        ({"file": ("box.stl", box_stl())}, {}, 422, "give mass_kg"),
        ({"file": ("big.stl", b"x" * (80 * 1024))}, {}, 413, "upload limit"),
    ],
)
def test_object_validation_errors(
    refusals: RefusalApi, files: dict | None, data: dict, status: int, fragment: str
) -> None:
    before = refusals.client.get("/objects").json()["total"]
    response = refusals.client.post("/objects", files=files, data=data)
    assert response.status_code == status, response.text
    assert fragment in str(response.json()["detail"])
    assert refusals.client.get("/objects").json()["total"] == before


def test_millimetre_mesh_with_scale_is_accepted(client: TestClient) -> None:
    mm_box = trimesh.creation.box(extents=(50.0, 50.0, 100.0)).export(file_type="stl")
    response = client.post(
        "/objects", files={"file": ("mm.stl", mm_box)}, data={"scale": "0.001", "mass_kg": "0.2"}
    )
    assert response.status_code == 201, response.text
    assert response.json()["mesh_info"]["extents_m"] == pytest.approx([0.05, 0.05, 0.1])


# ------------------------------------------------- issue #19, finding 6: each fails before


def _upload(client: TestClient, name: str, data: bytes, **form: str):
    return client.post("/objects", files={"file": (name, data)}, data={"mass_kg": "0.2", **form})


def test_two_bodies_far_apart_are_accepted_with_a_stored_warning(client: TestClient) -> None:
    response = _upload(client, "two.stl", meshes.stl_bytes(meshes.two_bodies()))
    assert response.status_code == 201, response.text
    body = response.json()
    assert body["mesh_info"]["bodies"] == 2
    (warning,) = body["warnings"]
    assert "2 bodies up to 0.3 m apart" in warning and "one rigid object" in warning
    # Stored with the object: the listing and the object show it again.
    assert client.get(f"/objects/{body['id']}").json()["warnings"] == [warning]
    assert client.get("/objects").json()["items"][0]["warnings"] == [warning]


@pytest.mark.parametrize(
    ("mesh", "fragments"),
    [
        (meshes.open_tube(), ["not watertight (64 open edges)", "close its holes"]),
        (meshes.box(10_000.0), ["too large: 1e+04 m across", "gripper reaches 0.126 m",
                                "units"]),
        (meshes.box(1e-6), ["too small: 1e-06 m across", "units"]),
    ],
    ids=["open-tube", "10-km", "1-um"],
)
def test_bad_objects_are_refused_at_upload_saying_what_to_do(
    client: TestClient, mesh: trimesh.Trimesh, fragments: list[str]
) -> None:
    response = _upload(client, "bad.stl", meshes.stl_bytes(mesh))
    assert response.status_code == 422, response.text
    detail = str(response.json()["detail"])
    assert all(f in detail for f in fragments), detail
    assert "zero volume" not in detail
    assert client.get("/objects").json()["total"] == 0


def test_a_mesh_in_other_units_is_refused_until_its_units_are_given(client: TestClient) -> None:
    raw = _upload(client, "bunny.obj", meshes.RAW_BUNNY.read_bytes())
    assert raw.status_code == 422 and "too large: 1.97 m across" in str(raw.json()["detail"])
    in_mm = meshes.bunny_in_mm()
    refused = _upload(client, "bunny_mm.obj", in_mm)
    assert refused.status_code == 422 and "'mm'" in str(refused.json()["detail"])
    ok = _upload(client, "bunny_mm.obj", in_mm, units="mm")
    assert ok.status_code == 201, ok.text
    assert max(ok.json()["mesh_info"]["extents_m"]) == pytest.approx(0.0987, abs=0.001)
    assert ok.json()["properties"]["units"] == "mm"


def test_a_named_object_scaled_past_the_gripper_is_warned_and_the_warning_kept(
    client: TestClient,
) -> None:
    response = client.post("/objects", data={"name": "mug", "scale": "8"})
    assert response.status_code == 201, response.text
    body = response.json()
    assert body["mesh_info"] is None
    (warning,) = body["warnings"]
    assert "0.912 m across at scale 8" in warning
    assert client.get(f"/objects/{body['id']}").json()["warnings"] == [warning]
    assert client.post("/objects", data={"name": "mug", "scale": "20"}).status_code == 422


def test_ycb_names_are_checked_against_this_machines_folder(
    client: TestClient, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "ycb"
    (folder / "YcbThing").mkdir(parents=True)
    (folder / "YcbThing" / "model.urdf").write_text("<robot/>")
    monkeypatch.setenv("GRASPSCAPE_YCB_DIR", str(folder))
    ok = client.post("/objects", data={"name": "ycb:YcbThing"})
    assert ok.status_code == 201 and ok.json()["warnings"] == []
    missing = client.post("/objects", data={"name": "ycb:NoSuchThing"})
    assert missing.status_code == 422
    assert "unknown object 'ycb:NoSuchThing': use one of sphere" in missing.text
    assert "ycb:YcbThing" in missing.text
    # A coordinator without the YCB set cannot check: accepted, and it says so.
    monkeypatch.setenv("GRASPSCAPE_YCB_DIR", str(tmp_path / "absent"))
    unchecked = client.post("/objects", data={"name": "ycb:NoSuchThing"})
    assert unchecked.status_code == 201
    assert "no YCB folder on this machine" in unchecked.json()["warnings"][0]


def test_the_face_limit_is_the_workers(session: Session) -> None:
    """More faces than the worker takes (200,000) is refused at upload, not on every worker."""
    from graspscape.services.coordinator.errors import InvalidInput
    from graspscape.services.coordinator.objects.service import create_uploaded

    dense = trimesh.creation.icosphere(subdivisions=7, radius=0.04)  # 327,680 faces
    with pytest.raises(InvalidInput, match="327680 faces exceed the limit of 200000"):
        create_uploaded(session, filename="dense.stl", data=meshes.stl_bytes(dense),
                        properties={"mass_kg": 0.2})


def test_unknown_object_is_404(client: TestClient) -> None:
    response = client.get("/objects/12345")
    assert response.status_code == 404 and "object 12345" in response.json()["detail"]
    assert client.get("/objects/0").status_code == 422


def test_bearer_token_guards_mutating_routes(settings: Settings, tmp_path: Path) -> None:
    from graspscape.services.coordinator.app import create_app

    guarded = settings.model_copy(
        update={"api": settings.api.model_copy(update={"token": SecretStr("s3cret")})})
    with TestClient(create_app(guarded)) as c:
        assert c.post("/objects", data={"name": "cube"}).status_code == 401
        wrong = c.post("/objects", data={"name": "cube"}, headers={"Authorization": "Bearer nope"})
        assert wrong.status_code == 401 and wrong.headers["www-authenticate"] == "Bearer"
        ok = c.post("/objects", data={"name": "cube"}, headers={"Authorization": "Bearer s3cret"})
        assert ok.status_code == 201
        assert c.get("/objects").status_code == 200  # reads stay open
        assert (
            c.post("/explorations", json={"object_id": 1, "gripper": "robotiq_3f"}).status_code
            == 401
        )
        assert c.post("/explorations/1/cancel").status_code == 401
        assert c.post("/explorations/1/retry").status_code == 401
        assert c.delete("/explorations/1").status_code == 401
