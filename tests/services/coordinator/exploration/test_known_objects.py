"""Objects with a known answer, explored for real (pybullet) through the real store and API.

Every pose is simulated once per session (a shared cache keyed by pose key; an evaluation is
a pure function of the pose, object, gripper and settings), so the second database backend
and the second interleaving replay the same physics through the store.
"""

from __future__ import annotations

import csv
import io
import math
import xml.etree.ElementTree as ET
from concurrent.futures import ProcessPoolExecutor

import pyarrow.parquet as pq
import pytest
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.behaviour import same_behaviour
from graspscape.services.coordinator.manifolds.service import compute_map
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.services.local.run import pybullet_evaluator, run_local
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.objects import ObjectSpec
from PIL import Image
from sqlalchemy import select

CACHES: dict[str, dict] = {}
HANDLE_X_M = 0.055  # the mug's body has a 4.5 cm radius; its handle reaches x ≈ 7 cm


@pytest.fixture(scope="module")
def pool():
    with ProcessPoolExecutor(2) as executor:
        yield executor


def _evaluator(name: str, pool):
    return pybullet_evaluator(ObjectSpec(name=name), pool=pool, cache=CACHES.setdefault(name, {}))


def _explore(sessions, object_id: int, name: str, pool, *, dtheta: float, levels: int,
             workers: int = 2, seed: int = 0):
    spec = ExplorationSpec(
        object_id=object_id,
        grid={"dtheta": math.radians(dtheta), "r_min": 0.01, "r_max": 0.01},
        refinement={"levels": levels, "local_search_rounds": 1},
    )
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=16, max_poses=10**6).id
    run_local(sessions, _evaluator(name, pool), workers=workers, seed=seed)
    with sessions() as s:
        return eid, compute_map(s, eid)


def _at(computed, theta_deg: float, phi_deg: float):
    for p, sample in computed.samples.items():
        if (abs(math.degrees(sample.theta) - theta_deg) < 0.5
                and abs(math.remainder(math.radians(phi_deg) - sample.phi, 2 * math.pi)) < 0.01):
            return p, sample
    raise AssertionError(f"no pose at θ={theta_deg}, φ={phi_deg}")


@pytest.mark.slow
def test_sphere_is_one_manifold_with_near_constant_mu(sessions, named_object, pool) -> None:
    _, c = _explore(sessions, named_object("sphere"), "sphere", pool, dtheta=45, levels=1)
    viable = [p for p, s in c.samples.items() if s.viable]
    assert len(viable) >= 0.9 * len(c.samples)
    biggest = c.map.manifolds[0]
    assert biggest.pose_count >= 0.95 * len(viable)
    assert len(c.map.manifolds) == 1
    assert biggest.mu_s_std < 0.08
    assert biggest.local_maxima and biggest.best.mu_s >= biggest.mu_s_mean


@pytest.mark.slow
def test_sphere_map_is_the_same_for_one_or_two_workers(sessions, named_object, pool) -> None:
    runs = [_explore(sessions, named_object("sphere"), "sphere", pool, dtheta=45, levels=1,
                     workers=w, seed=w) for w in (1, 2)]
    (_, a), (_, b) = runs
    assert {s.key for s in a.samples.values()} == {s.key for s in b.samples.values()}
    assert a.map.model_dump() == b.map.model_dump()


@pytest.mark.slow
def test_cube_shows_face_edge_and_corner_approaches(sessions, named_object, pool) -> None:
    _, c = _explore(sessions, named_object("cube"), "cube", pool, dtheta=45, levels=0)
    faces = [_at(c, t, f) for t, f in ((0, 0), (90, 0), (90, 90), (90, 180), (90, 270), (180, 0))]
    edges = [_at(c, 90, f) for f in (45, 135, 225, 315)]
    corners = [_at(c, t, f) for t in (45, 135) for f in (60, 120, 240, 300)]
    # Face approaches: the palm on the face and the fingers closed alike, all six faces.
    assert all(s.viable and "palm" in s.digits for _, s in faces)
    assert all(same_behaviour(faces[0][1], s) for _, s in faces[1:])
    # Edge approaches close differently: never the face grasp.
    assert all(not same_behaviour(faces[1][1], s) for _, s in edges)
    # Toward a corner the hand pinches with two digits.
    pinches = [s for _, s in corners if s.viable and len(s.digits) == 2]
    assert len(pinches) >= 4
    # Pinches are other manifolds than the face grasps. (Face and edge grasps may chain into
    # one manifold: for this hand the thumb's joints change gradually between them.)
    label = c.label_of
    face_labels = {label[p] for p, _ in faces}
    assert not face_labels & {label.get(p) for p, s in corners if s in pinches}
    described = {m.label: m for m in c.map.manifolds}
    assert all("palm" in described[lab].digits for lab in face_labels)


@pytest.mark.slow
def test_mug_handle_is_its_own_manifold_and_the_api_serves_the_map(
    client, sessions, pool
) -> None:
    response = client.post("/objects", data={"name": "mug"})
    assert response.status_code == 201, response.text
    spec = {
        "object_id": response.json()["id"],
        "grid": {"dtheta": math.radians(30), "r_min": 0.01, "r_max": 0.01},
        "refinement": {"levels": 1, "local_search_rounds": 1},
    }
    created = client.post("/explorations", json=spec)
    assert created.status_code == 201, created.text
    eid = created.json()["id"]
    run_local(sessions, _evaluator("mug", pool), workers=2)
    assert client.get(f"/explorations/{eid}").json()["status"] == "done"

    listed = client.get(f"/explorations/{eid}/manifolds").json()
    assert listed["final"] is True
    table = listed["manifolds"]
    assert [m["name"] for m in table][:3] == ["A", "B", "C"]
    assert [m["volume_cm3"] for m in table] == sorted((m["volume_cm3"] for m in table),
                                                       reverse=True)
    with sessions() as s:
        c = compute_map(s, eid)
        # Certification's jitters: evaluated and exported, off the lattice (no manifold).
        jitters = len(s.scalars(select(PoseRow.id).where(
            PoseRow.exploration_id == eid, PoseRow.certifies.is_not(None))).all())
    head_on, _ = _at(c, 90, 0)  # straight at the handle
    handle = c.label_of[head_on]
    body = 0

    def on_handle(p):
        return any(pos[0] > HANDLE_X_M for pos in c.samples[p].contacts.values())

    members = {lab: [p for p, x in c.label_of.items() if x == lab] for lab in (handle, body)}
    assert handle != body
    assert sum(map(on_handle, members[handle])) >= 0.5 * len(members[handle])
    assert sum(map(on_handle, members[body])) <= 0.1 * len(members[body])

    one = client.get(f"/explorations/{eid}/manifolds/{table[handle]['name']}")
    assert one.status_code == 200 and one.json()["label"] == handle
    assert client.get(f"/explorations/{eid}/manifolds/ZZ").status_code == 404

    best = client.get(f"/explorations/{eid}/best",
                      params={"limit": 3, "rank": "mu_s"}).json()["poses"]
    # (A jitter off the lattice may beat every manifold member.)
    assert len(best) == 3 and best[0]["mu_s"] >= max(m["mu_s_max"] for m in table)
    # From above only (approach direction within 60° of −z), and a low effort cap.
    cone = client.get(f"/explorations/{eid}/best", params={
        "cone_x": 0, "cone_y": 0, "cone_z": -1, "cone_half_angle_deg": 60, "limit": 50}).json()
    assert cone["poses"] and all(p["theta"] <= math.radians(60) + 1e-9 for p in cone["poses"])
    cap = sorted(p["effort_max_nm"] for p in best)[0]
    capped = client.get(f"/explorations/{eid}/best",
                        params={"max_effort_nm": cap, "limit": 100}).json()["poses"]
    assert capped and all(p["effort_max_nm"] <= cap for p in capped)
    per = client.get(f"/explorations/{eid}/best",
                     params={"manifold": "B", "rank": "mu_s"}).json()["poses"]
    assert per and per[0]["pose_key"] == table[1]["best"]["key"]
    assert client.get(f"/explorations/{eid}/best", params={"cone_x": 1}).status_code == 422

    png = client.get(f"/explorations/{eid}/map.png")
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    image = Image.open(io.BytesIO(png.content))
    image.verify()
    assert image.size[0] > 600
    svg = client.get(f"/explorations/{eid}/map.svg", params={"cut": "vertical", "phi0_deg": 0})
    assert svg.status_code == 200 and ET.fromstring(svg.content).tag.endswith("svg")

    rows = list(csv.DictReader(io.StringIO(
        client.get(f"/explorations/{eid}/export/poses.csv").text)))
    assert len(rows) == len(c.samples) + jitters
    assert {r["manifold"] for r in rows if r["viable"] == "True"} >= {"A", "B"}
    parquet = pq.read_table(io.BytesIO(
        client.get(f"/explorations/{eid}/export/poses.parquet").content))
    assert parquet.num_rows == len(rows)
    exported = client.get(f"/explorations/{eid}/export/manifolds.json").json()
    # Large manifolds one row each, then the dust (under 1 % of the viable volume) as one.
    dust = ["dust"] if any(not m["large"] for m in table) else []
    assert [r["label"] for r in exported["table"]] == [m["name"] for m in table
                                                       if m["large"]] + dust


@pytest.mark.slow
def test_symmetry_detected_from_the_mesh() -> None:
    from graspscape.services.coordinator.exploration.symmetry import detect, hand_mirror
    from graspscape.shared.specs.gripper import load_gripper
    from graspscape.workers.sim.evaluate import default_cache_dir
    from graspscape.workers.sim.objects import prepare_object

    def found(name: str) -> set[str]:
        mesh = prepare_object(ObjectSpec(name=name), default_cache_dir() / "objects").mesh
        return {s.describe() for s in detect(mesh)}

    assert found("mug") == {"mirror in the vertical plane at φ = 0.0°"}  # the handle on +x
    cube = found("cube")
    assert {"rotation about z by 90°", "mirror z → −z",
            "mirror in the vertical plane at φ = 45.0°"} <= cube
    assert hand_mirror(load_gripper("robotiq_3f")).fingers == {"A": "A", "B": "C", "C": "B"}


@pytest.mark.parametrize(("name", "symmetry", "given", "stored"), [
    ("cube", False, None, 1),  # a plain run keeps the equal-area lattice
    ("cube", True, None, 4),  # 90° turns and mirrors at 45°
    ("sphere", True, None, 8),  # every candidate: 8 is the largest order used
    pytest.param("mug", True, None, 1,  # one mirror, in the handle's plane at φ = 0
                 marks=pytest.mark.slow),  # the mug's symmetry search: 1.5 s
    ("cube", True, 2, 2),  # as given
])
def test_the_lattice_multiple_is_decided_at_submission_from_the_objects_symmetry(
        sessions, named_object, name: str, symmetry: bool, given: int | None,
        stored: int) -> None:
    spec = ExplorationSpec(
        object_id=named_object(name),
        grid={"dtheta": math.radians(30), "r_min": 0.01, "r_max": 0.01,
              "azimuth_multiple": given},
        shortcuts={"symmetry": symmetry},
    )
    with sessions() as s:
        row = create_exploration(s, spec=spec, tile_target_poses=16, max_poses=10**6)
        assert row.spec["grid"]["azimuth_multiple"] == stored


@pytest.mark.slow
def test_symmetry_shortcut_mirrors_the_cube(sessions, named_object, pool) -> None:
    spec = ExplorationSpec(
        object_id=named_object("cube"),
        grid={"dtheta": math.radians(45), "r_min": 0.01, "r_max": 0.01},
        refinement={"levels": 0},
        shortcuts={"symmetry": True},
    )
    calls: list[str] = []
    thetas: set[float] = set()
    evaluate = _evaluator("cube", pool)

    def counted(poses, match=None):
        calls.extend(p.key() for p in poses)
        thetas.update(round(p.theta, 6) for p in poses)
        return evaluate(poses, match)

    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=16, max_poses=10**6).id
    run_local(sessions, counted, workers=2)
    with sessions() as s:
        c = compute_map(s, eid)
    lattice = c.lattice
    assert len(c.samples) == len(lattice.coarse_points())  # the whole coarse grid is known
    # The lattice was given the cube's 4-fold order, so the 90° turns and the diagonal mirrors
    # map every ring onto itself: 18 directions, 6 orbits.
    assert c.spec.grid.azimuth_multiple == 4
    assert all(lattice.m(K) % 4 == 0 for K in range(1, lattice.n_rings))
    assert len(calls) == len(set(calls)) <= len(c.samples) / 3  # ≥ 3 poses per evaluation
    # z → −z is the cube's symmetry but not the task's (gravity): both poles are simulated.
    assert {0.0, round(math.pi, 6)} <= thetas
    mirrored = {s.key for s in c.samples.values() if s.source == "shortcut:symmetry"}
    assert mirrored and not mirrored & set(calls)
    # A mirrored face approach is the face grasp: palm and the same closure as simulated.
    _, top = _at(c, 0, 0)
    faces = [_at(c, 90, f)[1] for f in (0, 90, 180, 270)]
    assert all(same_behaviour(faces[0], f) for f in faces[1:])
    assert "palm" in top.digits


@pytest.mark.slow
def test_configuration_shortcut_reuses_matching_grasps_alike_for_any_worker_count(
        sessions, named_object, pool) -> None:
    # Sphere approaches along one normal from 0 to 2 cm end in the same grasp: the farther
    # poses reuse the nearer one's trajectory outcome; which ones do is fixed by the tile.
    spec = ExplorationSpec(
        object_id=named_object("sphere"),
        grid={"dtheta": math.radians(60), "r_min": 0.0, "r_max": 0.02, "dr": 0.005},
        refinement={"levels": 0},
        shortcuts={"configuration_inference": True},
    )
    maps = []
    for workers in (1, 2):
        with sessions() as s:
            eid = create_exploration(s, spec=spec, tile_target_poses=30, max_poses=10**6).id
        run_local(sessions, pybullet_evaluator(ObjectSpec(name="sphere"), pool=pool),
                  workers=workers, seed=workers)
        with sessions() as s:
            c = compute_map(s, eid)
            rows = {r.pose_key: r for r in s.scalars(
                select(PoseRow).where(PoseRow.exploration_id == eid))}
        maps.append({k: (r.outcome, r.mu_s, r.inferred_from) for k, r in rows.items()})
        inferred = [s for s in c.samples.values() if s.source == "shortcut:configuration"]
        assert inferred and len(inferred) < len(c.samples)
        for sample in inferred:
            donor = rows[rows[sample.key].inferred_from]
            assert donor.inferred_from is None and donor.theta == sample.theta
            assert donor.phi == sample.phi and donor.r != sample.r
            assert sample.viable == donor.viable and sample.mu_s == donor.mu_s
    assert maps[0] == maps[1]
