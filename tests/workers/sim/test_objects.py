"""Objects: every named object prepares and spawns, physics agrees with the mesh, the mug's
handle hole survives decomposition, decompositions are cached, bad meshes raise their error.

Real pybullet (DIRECT) and real meshes; one session-scoped cache so V-HACD runs once.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as p
import pybullet_data
import pytest
import trimesh
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.workers.sim.objects import (
    EmptyMesh,
    NonFiniteVertices,
    NotWatertight,
    ObjectError,
    PreparedObject,
    TooManyFaces,
    UnknownObject,
    UnreadableMesh,
    ZeroVolume,
    describe,
    forget_client,
    list_builtin_objects,
    prepare_object,
    source_axes_orientation,
    spawn_object,
)
from graspscape.workers.sim.objects.catalog import ycb_root
from graspscape.workers.sim.objects.prepare import INERTIA_ALIGN_THRESHOLD

BUILTINS = ["sphere", "cube", "can", "dumbbell", "mug", "spiked_ball"]
PYBULLET_DATA = ["pb:mug", "pb:bunny", "pb:duck", "pb:teddy"]
YCB = ["ycb:YcbPowerDrill", "ycb:YcbHammer"]
needs_ycb = pytest.mark.skipif(not ycb_root().is_dir(), reason="YCB folder not present")


@pytest.fixture(scope="session")
def cache_dir(object_cache: Path) -> Path:
    return object_cache


@pytest.fixture(scope="session")
def prepared(cache_dir: Path) -> dict[str, PreparedObject]:
    names = BUILTINS + PYBULLET_DATA + (YCB if ycb_root().is_dir() else [])
    return {n: prepare_object(ObjectSpec(name=n), cache_dir) for n in names}


@pytest.fixture
def client() -> Iterator[int]:
    cid = p.connect(p.DIRECT)
    yield cid
    forget_client(cid)
    p.disconnect(physicsClientId=cid)


def _world_point(cid: int, body: int, local: np.ndarray) -> np.ndarray:
    pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
    rot = np.asarray(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
    return rot @ local + np.asarray(pos)


def _ray_hits(cid: int, start: np.ndarray, end: np.ndarray) -> bool:
    return p.rayTest(start.tolist(), end.tolist(), physicsClientId=cid)[0][0] >= 0


def _src(prep: PreparedObject, point: tuple[float, float, float]) -> np.ndarray:
    """A source-file point expressed in the prepared object's frame."""
    return trimesh.transform_points(np.array([point]), prep.object_from_source)[0]


# ---------------------------------------------------------------- registry


def test_registry_lists_and_describes_every_named_object() -> None:
    names = list_builtin_objects()
    assert set(BUILTINS + PYBULLET_DATA) <= set(names)
    if ycb_root().is_dir():
        assert len([n for n in names if n.startswith("ycb:")]) == 12
    mug = describe("mug")
    assert mug["mass_kg"] == pytest.approx(0.3)
    assert mug["dimensions_m"]["outer_radius"] == pytest.approx(0.04)
    # Sized for the hand: nothing wider than its ~15 cm span plus a margin.
    for n in BUILTINS:
        d = describe(n)
        assert 0 < d["mass_kg"] < 1 and 0 < d["friction"] <= 1.5
    with pytest.raises(UnknownObject, match="teapot"):
        describe("teapot")


# ---------------------------------------------------------------- every object


@pytest.mark.parametrize("name", BUILTINS + PYBULLET_DATA + YCB)
def test_object_prepares_in_com_frame_and_spawns_with_its_mass(
    name: str, prepared: dict[str, PreparedObject], client: int
) -> None:
    if name.startswith("ycb:") and name not in prepared:
        pytest.skip("YCB folder not present")
    prep = prepared[name]
    mesh = prep.mesh
    assert mesh.is_watertight and mesh.volume > 0
    # The pose space is defined around the centre of mass: it is the origin.
    assert np.linalg.norm(mesh.center_mass) < 1e-6 * max(1.0, prep.bounding_radius)
    assert 0.02 < prep.bounding_radius < 0.25  # hand-sized objects
    assert len(prep.collision_parts) >= 1 and prep.collision_path.is_file()
    assert prep.inertia_dropped <= INERTIA_ALIGN_THRESHOLD  # pybullet's diagonal is near exact

    body = spawn_object(client, prep, position=(0.3, -0.2, 1.0))
    info = p.getDynamicsInfo(body, -1, physicsClientId=client)
    assert info[0] == pytest.approx(prep.mass_kg)
    assert info[1] == pytest.approx(prep.friction)
    assert np.allclose(info[2], prep.inertia_diag, rtol=1e-6)
    assert np.allclose(info[3], 0.0)  # inertial frame = body frame = COM frame
    # Collision geometry sits where the query mesh says (same frame, no offset).
    lo, hi = (np.asarray(v) for v in p.getAABB(body, physicsClientId=client))
    centre = np.array([0.3, -0.2, 1.0])
    assert np.allclose(lo - centre, mesh.bounds[0], atol=0.006)
    assert np.allclose(hi - centre, mesh.bounds[1], atol=0.006)
    # In zero gravity with no contacts an untouched body stays put and does not turn.
    for _ in range(240):
        p.stepSimulation(physicsClientId=client)
    pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
    assert np.allclose(pos, centre, atol=1e-9) and np.allclose(orn, (0, 0, 0, 1), atol=1e-9)


def test_rays_agree_between_query_mesh_and_physics(
    prepared: dict[str, PreparedObject], client: int
) -> None:
    """A ray toward the COM meets pybullet's collision where it meets prepared.mesh."""
    rng = np.random.default_rng(0)
    compared = 0
    for name in ["mug", "dumbbell", "pb:bunny", "pb:mug"]:
        prep = prepared[name]
        body = spawn_object(client, prep)
        for d in rng.normal(size=(6, 3)):
            d /= np.linalg.norm(d)
            start = d * (prep.bounding_radius + 0.05)
            hit = p.rayTest(start.tolist(), [0, 0, 0], physicsClientId=client)[0]
            locs, _, _ = prep.mesh.ray.intersects_location([start], [-d])
            if hit[0] != body or len(locs) == 0:
                continue  # ray through the open mug mouth to a COM in the cavity
            first = locs[np.argmin(np.linalg.norm(locs - start, axis=1))]
            # Hulls may bridge small concavities, so physics meets the object no later.
            assert np.linalg.norm(np.asarray(hit[3]) - start) <= np.linalg.norm(
                first - start
            ) + 1e-3
            compared += 1
        p.removeBody(body, physicsClientId=client)
    assert compared >= 16


def test_mug_rests_upright_on_a_table_at_its_com_height(
    prepared: dict[str, PreparedObject], client: int
) -> None:
    """Physical COM check: standing on a plane, the body origin settles at the height of the
    COM above the mug's base, and the mug neither tips nor drifts."""
    p.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=client)
    p.loadURDF("plane.urdf", physicsClientId=client)
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    for name in ["mug", "can"]:
        prep = prepared[name]
        height = -prep.mesh.bounds[0][2]
        body = spawn_object(client, prep, position=(0, 0, height + 0.002))
        for _ in range(480):
            p.stepSimulation(physicsClientId=client)
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=client)
        assert pos[2] == pytest.approx(height, abs=0.002)
        assert abs(pos[0]) < 0.002 and abs(pos[1]) < 0.002
        assert np.allclose(orn, (0, 0, 0, 1), atol=0.01)
        p.removeBody(body, physicsClientId=client)


# ---------------------------------------------------------------- concavities


def _assert_hole_open(
    client: int, prep: PreparedObject, centre: np.ndarray, axis: np.ndarray, probe_r: float
) -> None:
    body = spawn_object(client, prep)
    reach = prep.bounding_radius + 0.05
    # A ray through the hole passes; the same ray moved onto the cup body is stopped.
    assert not _ray_hits(client, centre - reach * axis, centre + reach * axis)
    assert _ray_hits(client, -reach * axis, reach * axis)
    # A finger-sized probe in the hole touches nothing.
    probe_shape = p.createCollisionShape(p.GEOM_SPHERE, radius=probe_r, physicsClientId=client)
    probe = p.createMultiBody(0, probe_shape, basePosition=centre.tolist(), physicsClientId=client)
    close = p.getClosestPoints(probe, body, 0.05, physicsClientId=client)
    assert close and min(c[8] for c in close) > 0.0
    p.removeBody(probe, physicsClientId=client)
    p.removeBody(body, physicsClientId=client)


def test_pybullet_mug_decomposition_keeps_the_handle_hole(
    prepared: dict[str, PreparedObject], client: int
) -> None:
    prep = prepared["pb:mug"]
    assert prep.decomposition == "vhacd" and len(prep.collision_parts) > 1
    # The handle on +y spans y 0.04..0.077, z 0.017..0.084 in mug.obj; hole centre below.
    centre = _src(prep, (0.0, 0.056, 0.05))
    axis = prep.object_from_source[:3, :3] @ np.array([1.0, 0.0, 0.0])
    # The test is meaningful: a single convex hull of the same mesh closes the hole.
    hull = p.createCollisionShape(
        p.GEOM_MESH, vertices=prep.mesh.vertices.tolist(), physicsClientId=client
    )
    hull_mug = p.createMultiBody(0.3, hull, physicsClientId=client)
    assert _ray_hits(client, centre - 0.2 * axis, centre + 0.2 * axis)
    p.removeBody(hull_mug, physicsClientId=client)
    _assert_hole_open(client, prep, centre, axis, probe_r=0.008)


def test_builtin_mug_handle_hole_fits_a_finger(
    prepared: dict[str, PreparedObject], client: int
) -> None:
    prep = prepared["mug"]
    dims = describe("mug")["dimensions_m"]
    centre = _src(prep, (dims["outer_radius"] + dims["handle_hole_depth"] / 2, 0.0, 0.0))
    axis = prep.object_from_source[:3, :3] @ np.array([0.0, 1.0, 0.0])
    _assert_hole_open(client, prep, centre, axis, probe_r=0.009)


def test_dumbbell_waist_is_concave_in_physics(
    prepared: dict[str, PreparedObject], client: int
) -> None:
    prep = prepared["dumbbell"]
    body = spawn_object(client, prep)
    # Between the balls, beside the bar: free space a convex hull would fill.
    probe = p.createCollisionShape(p.GEOM_SPHERE, radius=0.005, physicsClientId=client)
    pb = p.createMultiBody(0, probe, basePosition=[0, 0, 0.022], physicsClientId=client)
    assert min(c[8] for c in p.getClosestPoints(pb, body, 0.05, physicsClientId=client)) > 0
    assert spawn_object(client, prep) != body  # same prepared, second body, shared shapes


# ---------------------------------------------------------------- cache and hashing


def test_decomposition_cache_is_hit_on_second_load(tmp_path: Path) -> None:
    spec = ObjectSpec(name="pb:mug")
    t0 = time.perf_counter()
    first = prepare_object(spec, tmp_path)
    t1 = time.perf_counter()
    second = prepare_object(spec, tmp_path)
    t2 = time.perf_counter()
    print(
        f"\npb:mug prepare: first {t1 - t0:.3f} s (V-HACD, {len(first.collision_parts)} hulls), "
        f"second {t2 - t1:.3f} s (cache)"
    )
    assert not first.decomposition_cached and second.decomposition_cached
    assert first.collision_path == second.collision_path
    assert len(list(tmp_path.rglob("collision-vhacd-*.obj"))) == 1
    assert [len(a) for a in first.collision_parts] == [len(a) for a in second.collision_parts]
    assert (t2 - t1) < 0.5 * (t1 - t0)


def test_content_hash_is_stable_and_scale_sensitive(cache_dir: Path) -> None:
    a = prepare_object(ObjectSpec(name="pb:bunny"), cache_dir)
    b = prepare_object(ObjectSpec(name="pb:bunny", mass_kg=1.0), cache_dir)
    c = prepare_object(ObjectSpec(name="pb:bunny", scale=1.1), cache_dir)
    assert a.content_hash == b.content_hash != c.content_hash
    assert len(a.content_hash) == 64
    assert b.mass_kg == 1.0 and np.allclose(np.asarray(b.inertia_diag) * 0.15,
                                            np.asarray(a.inertia_diag) * 1.0)
    assert c.extents[0] == pytest.approx(a.extents[0] * 1.1, rel=1e-6)


# ---------------------------------------------------------------- user meshes


def test_user_stl_round_trip(tmp_path: Path, cache_dir: Path, client: int) -> None:
    box = trimesh.creation.box(extents=(0.05, 0.04, 0.03))
    box.apply_translation((0.5, -0.2, 0.1))  # off-centre in the file: prepare re-centres it
    path = tmp_path / "brick.stl"
    box.export(path)
    prep = prepare_object(
        ObjectSpec(mesh_path=str(path), mass_kg=0.2, friction=0.6), cache_dir
    )
    assert prep.decomposition == "convex" and len(prep.collision_parts) == 1
    assert np.allclose(prep.extents, (0.05, 0.04, 0.03), atol=1e-9)
    assert np.allclose(prep.com_in_source, (0.5, -0.2, 0.1), atol=1e-9)
    m = 0.2
    expected = m / 12 * np.array([0.04**2 + 0.03**2, 0.05**2 + 0.03**2, 0.05**2 + 0.04**2])
    assert np.allclose(prep.inertia_diag, expected, rtol=1e-6)
    body = spawn_object(client, prep)
    assert p.getDynamicsInfo(body, -1, physicsClientId=client)[1] == pytest.approx(0.6)


def test_user_glb_round_trip(tmp_path: Path, cache_dir: Path) -> None:
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    path = tmp_path / "ball.glb"
    ball.export(path)
    prep = prepare_object(ObjectSpec(mesh_path=str(path), mass_kg=0.1), cache_dir)
    assert prep.decomposition == "convex"
    assert prep.bounding_radius == pytest.approx(0.03, rel=1e-6)


def test_user_concave_obj_is_decomposed_and_keeps_its_notch(
    tmp_path: Path, cache_dir: Path, client: int
) -> None:
    # An L: a 6 cm square with the +x/+z quarter cut away.
    full = trimesh.creation.box(extents=(0.06, 0.03, 0.06))
    cut = trimesh.creation.box(bounds=((0.0, -0.1, 0.0), (0.1, 0.1, 0.1)))
    shape = trimesh.boolean.difference([full, cut], engine="manifold")
    path = tmp_path / "ell.obj"
    shape.export(path)
    prep = prepare_object(
        ObjectSpec(mesh_path=str(path), mass_kg=0.3, inertia_diag=(1e-4, 2e-4, 3e-4)),
        cache_dir,
    )
    assert prep.decomposition == "vhacd" and len(prep.collision_parts) >= 2
    assert prep.inertia_diag == (1e-4, 2e-4, 3e-4)  # user inertia wins
    body = spawn_object(client, prep)
    assert np.allclose(p.getDynamicsInfo(body, -1, physicsClientId=client)[2], (1e-4, 2e-4, 3e-4))
    notch = _src(prep, (0.02, 0.0, 0.02))  # inside the cut-away quarter
    probe = p.createCollisionShape(p.GEOM_SPHERE, radius=0.004, physicsClientId=client)
    pb = p.createMultiBody(0, probe, basePosition=notch.tolist(), physicsClientId=client)
    assert min(c[8] for c in p.getClosestPoints(pb, body, 0.05, physicsClientId=client)) > 0


# ---------------------------------------------------------------- bad meshes


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


CUBE_V = "".join(
    f"v {x} {y} {z}\n" for x in (0, 0.05) for y in (0, 0.05) for z in (0, 0.05)
)
CUBE_F = [
    "f 1 3 4", "f 1 4 2", "f 5 6 8", "f 5 8 7", "f 1 2 6", "f 1 6 5",
    "f 3 7 8", "f 3 8 4", "f 1 5 7", "f 1 7 3", "f 2 4 8", "f 2 8 6",
]


@pytest.mark.parametrize(
    ("filename", "content", "error", "words"),
    [
        ("empty.obj", "# nothing here\n", EmptyMesh, "empty"),
        ("nan.obj", CUBE_V.replace("v 0 0 0", "v nan 0 0") + "\n".join(CUBE_F), NonFiniteVertices,
         "NaN"),
        ("flat.obj", "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0.1 0.1 0\nf 1 2 3\nf 2 4 3\n", ZeroVolume,
         "flat"),
        ("open.obj", CUBE_V + "\n".join(CUBE_F[:-2]), NotWatertight, "watertight"),
        ("garbage.glb", "\x00\x01 this is not a mesh at all", UnreadableMesh, "garbage.glb"),
        ("notes.txt", "v 0 0 0\n", UnreadableMesh, "unsupported"),
    ],
)
def test_bad_mesh_raises_its_error(
    tmp_path: Path, cache_dir: Path, filename: str, content: str, error: type, words: str
) -> None:
    path = _write(tmp_path / filename, content)
    with pytest.raises(error, match=words) as info:
        prepare_object(ObjectSpec(mesh_path=str(path), mass_kg=0.1), cache_dir)
    assert isinstance(info.value, ObjectError)


def test_closed_mesh_of_zero_volume_raises(tmp_path: Path, cache_dir: Path) -> None:
    # Two triangles back to back: closed, but encloses nothing (and is flat).
    path = _write(tmp_path / "sliver.obj", "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\nf 1 3 2\n")
    with pytest.raises(ZeroVolume):
        prepare_object(ObjectSpec(mesh_path=str(path), mass_kg=0.1), cache_dir)


def test_too_many_faces_and_missing_file_and_unknown_names(
    tmp_path: Path, cache_dir: Path
) -> None:
    path = tmp_path / "dense.ply"
    trimesh.creation.icosphere(subdivisions=4, radius=0.04).export(path)  # 5120 faces
    with pytest.raises(TooManyFaces, match="5120"):
        prepare_object(ObjectSpec(mesh_path=str(path), mass_kg=0.1), cache_dir, max_faces=1000)
    assert prepare_object(ObjectSpec(mesh_path=str(path), mass_kg=0.1), cache_dir).mass_kg == 0.1
    with pytest.raises(UnreadableMesh, match="not found"):
        prepare_object(ObjectSpec(mesh_path=str(tmp_path / "nope.obj"), mass_kg=0.1), cache_dir)
    for name in ["teapot", "pb:teapot", "ycb:NoSuchThing", "ycb:../ycb"]:
        with pytest.raises(UnknownObject, match="unknown object"):
            prepare_object(ObjectSpec(name=name), cache_dir)


def test_errors_never_reach_pybullet(tmp_path: Path, cache_dir: Path, client: int) -> None:
    """A bad mesh fails in prepare, so a client that saw it keeps working."""
    path = _write(tmp_path / "nan.obj", "v nan nan nan\nv 0 1 0\nv 1 0 0\nf 1 2 3\n")
    with pytest.raises(ObjectError):
        prepare_object(ObjectSpec(mesh_path=str(path), mass_kg=0.1), cache_dir)
    assert p.isConnected(physicsClientId=client)
    assert spawn_object(client, prepare_object(ObjectSpec(name="sphere"), cache_dir)) >= 0


@needs_ycb
def test_ycb_mass_and_friction_come_from_its_urdf(prepared: dict[str, PreparedObject]) -> None:
    drill = prepared["ycb:YcbPowerDrill"]
    assert drill.mass_kg == pytest.approx(0.895) and drill.friction == pytest.approx(0.9)
    # The URDF's 1e-3 placeholder inertia is replaced by the mesh's at that mass.
    assert all(1e-4 < v < 1e-2 for v in drill.inertia_diag)
    assert drill.inertia_diag != pytest.approx((1e-3, 1e-3, 1e-3))


def test_turned_frame_maps_back_to_the_source_axes(
    prepared: dict[str, PreparedObject], client: int
) -> None:
    """The duck's frame is turned onto its principal axes; spawning with
    source_axes_orientation shows it as its file has it."""
    duck = prepared["pb:duck"]
    assert not np.allclose(duck.object_from_source[:3, :3], np.eye(3))
    src_hulls = Path(pybullet_data.getDataPath()) / "duck_vhacd.obj"
    src = trimesh.load(src_hulls, force="mesh")
    src.apply_scale(0.06)
    com = np.asarray(duck.com_in_source)
    body = spawn_object(client, duck, position=com, orientation=source_axes_orientation(duck))
    # Points of the file's surface, placed where the file has them, lie on the body's surface.
    probe = p.createCollisionShape(p.GEOM_SPHERE, radius=0.001, physicsClientId=client)
    for point in src.vertices[:: max(1, len(src.vertices) // 12)]:
        pb = p.createMultiBody(0, probe, basePosition=point.tolist(), physicsClientId=client)
        d = min(c[8] for c in p.getClosestPoints(pb, body, 0.05, physicsClientId=client))
        assert abs(d + 0.001) < 0.002
        p.removeBody(pb, physicsClientId=client)
    assert source_axes_orientation(prepared["mug"]) == pytest.approx((0, 0, 0, 1))


def test_spawn_recovers_after_reset_simulation(
    prepared: dict[str, PreparedObject], client: int
) -> None:
    spawn_object(client, prepared["mug"])
    p.resetSimulation(physicsClientId=client)  # drops the cached shapes in pybullet
    body = spawn_object(client, prepared["mug"])
    assert p.getNumBodies(physicsClientId=client) == 1
    assert p.getDynamicsInfo(body, -1, physicsClientId=client)[0] == pytest.approx(0.3)
