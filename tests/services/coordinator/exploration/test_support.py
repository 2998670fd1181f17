"""An object on a table, as submitted: one exploration per chosen resting pose, grouped, each
storing its resting pose; the workers are told the table through the settings."""

from __future__ import annotations

import numpy as np
import pytest
from graspscape.services.coordinator.dispatch.catalog import WorkContexts
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.shared.specs.exploration import ExplorationSpec

COARSE = {"dtheta": 1.2, "r_min": 0.02, "r_max": 0.02}


def test_a_plane_submits_one_exploration_per_resting_pose(client, named_object, sessions):
    mug = named_object("mug")
    spec = {"object_id": mug, "grid": COARSE, "support": {"kind": "plane"}}
    created = client.post("/explorations", json=spec)
    assert created.status_code == 201, created.text
    group = created.json()["group"]
    assert 1 <= len(group) <= 4 and created.json()["id"] == group[0]
    rows = [client.get(f"/explorations/{i}").json() for i in group]
    probabilities = [row["resting_probability"] for row in rows]
    assert all(p >= 0.05 for p in probabilities)
    assert probabilities == sorted(probabilities, reverse=True)
    assert {row["support_group"] for row in rows} == {group[0]}
    assert [row["resting_index"] for row in rows] == list(range(len(group)))
    ups = []
    for row in rows:
        spec_i = ExplorationSpec.model_validate(row["spec"])
        resting = spec_i.support.resting
        assert resting is not None and spec_i.settings.table.resting == resting
        ups.append(resting.up())
    # Different resting poses: the table's up differs in the object's frame.
    assert min(np.linalg.norm(a - b) for i, a in enumerate(ups) for b in ups[i + 1:]) > 0.1
    with sessions() as s:
        created_at = s.get(ExplorationRow, group[1]).created_at
        context = WorkContexts().context(s, group[1], created_at)
    assert context.settings.table is not None
    assert context.settings.table.friction == 0.5


def test_a_free_object_is_no_group(client, object_id):
    created = client.post("/explorations", json={"object_id": object_id, "grid": COARSE})
    assert created.status_code == 201
    assert created.json()["group"] == []
    assert client.get(f"/explorations/{created.json()['id']}").json()["support_group"] is None


def test_a_plane_on_mujoco_is_refused_naming_the_engine(client, object_id):
    spec = {"object_id": object_id, "support": {"kind": "plane"},
            "settings": {"engine": "mujoco"}}
    refused = client.post("/explorations", json=spec)
    assert refused.status_code == 422
    assert "pybullet" in refused.text


def test_best_and_the_group_route_select_a_resting_pose(client, named_object):
    cube = named_object("cube")
    created = client.post("/explorations", json={"object_id": cube, "grid": COARSE,
                                                 "support": {"kind": "plane"}}).json()
    group = client.get(f"/explorations/{created['group'][-1]}/group").json()
    assert [g["id"] for g in group] == created["group"]
    assert [g["resting_index"] for g in group] == list(range(len(group)))
    last = len(group) - 1
    best = client.get(f"/explorations/{created['id']}/best", params={"resting": last})
    assert best.status_code == 200, best.text
    assert best.json()["exploration_id"] == group[last]["id"]
    missing = client.get(f"/explorations/{created['id']}/best", params={"resting": 99})
    assert missing.status_code == 404 and "group" in missing.text


def test_exports_state_the_resting_pose(client, named_object):
    cube = named_object("cube")
    created = client.post("/explorations", json={"object_id": cube, "grid": COARSE,
                                                 "support": {"kind": "plane"}}).json()
    second = created["group"][1]
    table = client.get(f"/explorations/{second}/export/manifolds.json").json()
    resting = table["resting_pose"]
    assert resting["index"] == 1 and resting["friction"] == 0.5
    matrix = np.array(resting["object_in_table"])
    # A cube face down: the centre of mass 3 cm over the table, the axes a rotation.
    assert matrix[2, 3] == pytest.approx(0.03, abs=1e-6)
    assert np.allclose(matrix[:3, :3] @ matrix[:3, :3].T, np.eye(3), atol=1e-9)
    graspgen = client.get(f"/explorations/{second}/export/graspgen.json").json()
    assert graspgen["table"] == resting
    free = client.post("/explorations", json={"object_id": cube, "grid": COARSE}).json()
    assert "resting_pose" not in client.get(
        f"/explorations/{free['id']}/export/manifolds.json").json()


def test_a_free_map_seeds_the_table_with_its_viable_poses_not_under_it(
        client, named_object, sessions):
    from graspscape.services.coordinator.exploration.scheduler import ingest_results
    from graspscape.services.coordinator.store.models import PoseRow
    from graspscape.services.coordinator.store.queue import lease_tiles
    from graspscape.shared.specs.placement import place_gripper
    from graspscape.shared.specs.pose import Pose
    from sqlalchemy import select

    from tests.factories import oracle_result

    cube = named_object("cube")
    grid = {"dtheta": 0.8, "r_min": 0.02, "r_max": 0.02}
    free = client.post("/explorations", json={"object_id": cube, "grid": grid}).json()["id"]
    with sessions() as s:  # the free map, made up
        while tiles := lease_tiles(s, worker_id="w", n=8, lease_seconds=60):
            for tile in tiles:
                ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                               worker_id="w", results=[oracle_result(p) for p in tile.poses()],
                               keeper=None)
        seed_keys = set(s.scalars(select(PoseRow.pose_key).where(
            PoseRow.exploration_id == free, PoseRow.viable)))
    created = client.post("/explorations", json={
        "object_id": cube, "grid": grid,
        "support": {"kind": "plane", "seed_exploration": free}}).json()
    mesh = prepare_cube_mesh()
    with sessions() as s:
        leased = lease_tiles(s, worker_id="v", n=1000, lease_seconds=60)
    skipped_somewhere = False
    for eid in created["group"]:  # each resting pose skips the starts under its own table
        row = client.get(f"/explorations/{eid}").json()
        resting = ExplorationSpec.model_validate(row["spec"]).support.resting
        up, height = resting.up(), resting.position[2]
        planned = {p.key() for tile in leased if tile.exploration_id == eid
                   for p in tile.poses()}
        assert planned and planned <= seed_keys
        assert row["poses_total"] == len(planned)
        for key in seed_keys - planned:  # skipped: the palm under the table
            theta, phi, r, roll, pitch, yaw = (float(x) for x in key.split("/"))
            pose = Pose(theta=theta, phi=phi, r=r, roll=roll, pitch=pitch, yaw=yaw)
            assert up @ place_gripper(mesh, pose).position <= -height
            skipped_somewhere = True
    assert skipped_somewhere
    wrong = client.post("/explorations", json={
        "object_id": cube, "grid": {**grid, "dtheta": 0.7},
        "support": {"kind": "plane", "seed_exploration": free}})
    assert wrong.status_code == 422 and "seed exploration" in wrong.text


def prepare_cube_mesh():
    from graspscape.services.coordinator.objects.geometry import spec_mesh
    from graspscape.shared.specs.objects import ObjectSpec

    return spec_mesh(ObjectSpec(name="cube"))


def test_the_map_picture_draws_the_table(client, named_object, sessions):
    import matplotlib.pyplot as plt
    from graspscape.services.coordinator.maps.table import table_in_cut

    mug = named_object("mug")
    created = client.post("/explorations", json={"object_id": mug, "grid": COARSE,
                                                 "support": {"kind": "plane"}}).json()
    with_table = client.get(f"/explorations/{created['id']}/map.png",
                            params={"cut": "vertical"})
    assert with_table.status_code == 200
    assert with_table.content[:8] == b"\x89PNG\r\n\x1a\n"
    # The trace: a line at the table's height under the centre of mass, in the cut's plane.
    fig, ax = plt.subplots()
    grid = np.linspace(-0.1, 0.1, 5)
    field = {"X": np.tile(grid, (5, 1)), "Y": np.tile(grid, (5, 1)).T,
             "e1": np.array([1.0, 0.0, 0.0]), "e2": np.array([0.0, 0.0, 1.0])}
    table_in_cut(ax, field, (np.array([0.0, 0.0, 1.0]), 0.04))
    (line,) = ax.lines
    assert np.allclose(line.get_ydata(), -0.04)
    plt.close(fig)
