"""POST/GET /objects through the real app on both databases, every validation error included."""

from __future__ import annotations

from pathlib import Path

import pytest
import trimesh
from fastapi.testclient import TestClient
from graspscape.services.coordinator.settings import Settings
from pydantic import SecretStr

from tests.factories import box_stl

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
    obj = client.post("/objects", files={"file": ("t.obj", TETRA_OBJ)})
    assert obj.status_code == 201, obj.text
    listing = client.get("/objects", params={"limit": 1, "offset": 1}).json()
    assert listing["total"] == 2 and [o["id"] for o in listing["items"]] == [obj.json()["id"]]
    assert client.get(f"/objects/{body['id']}").json() == body


def test_shared_folder_objects(client: TestClient, settings: Settings) -> None:
    folder = settings.api.shared_objects_dir
    assert folder is not None
    folder.mkdir(parents=True)
    (folder / "tetra.obj").write_bytes(TETRA_OBJ)
    ok = client.post("/objects", data={"name": "shared:tetra.obj"})
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
        (None, {"name": "teapot"}, 422, "unknown object name 'teapot'"),
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
        ({"file": ("plane.obj", _coplanar_open_obj())}, {}, 422, "zero volume"),
        ({"file": ("box.stl", box_stl((50.0, 50.0, 100.0)))}, {}, 422, "metres"),
        ({"file": ("big.stl", b"x" * (80 * 1024))}, {}, 413, "upload limit"),
    ],
)
def test_object_validation_errors(
    client: TestClient, files: dict | None, data: dict, status: int, fragment: str
) -> None:
    response = client.post("/objects", files=files, data=data)
    assert response.status_code == status, response.text
    assert fragment in str(response.json()["detail"])
    assert client.get("/objects").json()["total"] == 0


def test_millimetre_mesh_with_scale_is_accepted(client: TestClient) -> None:
    mm_box = trimesh.creation.box(extents=(50.0, 50.0, 100.0)).export(file_type="stl")
    response = client.post("/objects", files={"file": ("mm.stl", mm_box)}, data={"scale": "0.001"})
    assert response.status_code == 201, response.text
    assert response.json()["mesh_info"]["extents_m"] == pytest.approx([0.05, 0.05, 0.1])


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
