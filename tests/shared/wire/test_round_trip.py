"""The two data-carrying messages (a tile lease, a result batch) sent through a real zenoh
session on loopback, the way coordinator and workers send them, arrive equal to what was sent:
every field, nested models and floats included."""

from __future__ import annotations

import math
import socket
import threading
from datetime import UTC, datetime

import pytest
import zenoh
from graspscape.shared.specs.exploration import ConfigurationMatch
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    ContactPoint,
    GraspConfiguration,
    GraspSignature,
    Outcome,
    PhaseTimes,
    PoseResult,
    RobustnessReport,
)
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode, encode
from graspscape.shared.wire.messages import ObjectRef, ResultBatch, TileLease
from graspscape.shared.wire.session import zenoh_config

SESSION_KEY = "5e55" * 8  # a worker session's key (any 32 hex digits)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _held(pose: Pose) -> PoseResult:
    joints = {"finger_1_joint_1": 0.61, "finger_1_joint_2": 1.0e-3, "palm_finger_1_joint": -0.1}
    return PoseResult(
        pose=pose, pose_key=pose.key(), outcome=Outcome.HELD, viable=True,
        mu_s=0.123456789012345, effective_r=0.0725, effort_max_nm=1.75,
        contacts_per_link={"finger_1_link_3": 2, "palm": 1},
        grasp=GraspConfiguration(base_position=(0.01, -0.2, 0.3),
                                 base_orientation=(0.0, 0.7071067811865476, 0.0,
                                                   0.7071067811865476),
                                 joint_angles=joints),
        signature=GraspSignature(
            links_in_contact=("finger_1_link_3", "palm"),
            contacts=(ContactPoint(link="palm", position_object=(1e-9, -0.05, 0.02),
                                   normal_force_n=3.5),),
            joint_angles=joints),
        eval_time_s=0.75, inferred_from=None,
        phases=PhaseTimes(reset_s=0.01, approach_s=0.1, closing_s=0.2, trajectory_s=0.3,
                          sensitivity_s=0.1, approach_steps=120, closing_steps=240,
                          trajectory_steps=96, sensitivity_steps=24),
        mu_g=0.2, mu_f=0.0, mu_m=1.5e-5, min_closing_effort=0.4,
        robustness=RobustnessReport(torque_margin_nm=0.3, torque_margin_ratio=0.25,
                                    friction_margin=0.6, gravity_test_share=5 / 6,
                                    force_test_share=1.0, tug_force_n=12.5,
                                    shake_survival_s=2.0),
    )


def _dropped(pose: Pose) -> PoseResult:
    return PoseResult(pose=pose, pose_key=pose.key(), outcome=Outcome.DROPPED, viable=False,
                      mu_s=0.0, inferred_from="0.100000/0.000000/0.010000/0.000000/0.000000/"
                      "0.000000")


def _messages() -> list[TileLease | ResultBatch]:
    poses = [Pose(theta=math.pi / 3, phi=5.9, r=0.01, roll=math.pi / 4, pitch=0.1, yaw=-0.2),
             Pose(theta=0.0, phi=0.0, r=0.0)]
    lease = TileLease(
        tile_id=2**31 - 1, exploration_id=7, level=2, index=41, lease_epoch=3,
        lease_expires_at=datetime(2026, 12, 1, 20, 15, 30, 123456, tzinfo=UTC),
        cells=[(math.pi / 3, 5.9), (0.0, 0.0)], r_levels=[0.0, 0.005, 0.01],
        attitudes=[(0.0, 0.0, 0.0), (math.pi / 4, 0.1, -0.2)],
        object=ObjectRef(object_id=5, name=None, content_hash="c" * 64, mesh_format="obj",
                         properties={"mass_kg": 0.3, "friction": 0.8, "scale": [1.0, 1.0, 2.0]}),
        gripper="robotiq_3f",
        settings=SimSettings(policy_name="haptic"),
        configuration_match=ConfigurationMatch(),
    )
    batch = ResultBatch(session_key=SESSION_KEY,
                        worker_id="host-1:p0@9", tile_id=2**31 - 1, lease_epoch=3,
                        results=[_held(poses[0]), _dropped(poses[1])], final=False,
                        release=False, error=None)
    return [lease, batch]


@pytest.fixture
def loopback():
    port = _free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    server = zenoh.open(zenoh_config(mode="peer", listen=[endpoint]))
    client = zenoh.open(zenoh_config(mode="client", connect=[endpoint], connect_timeout_ms=5000))
    yield server, client
    client.close()
    server.close()


def test_lease_and_batch_arrive_equal_through_zenoh(loopback) -> None:
    server, client = loopback
    received: list[bytes] = []
    lock = threading.Lock()

    def answer(query: zenoh.Query) -> None:
        data = query.payload.to_bytes()
        with lock:
            received.append(data)
        query.reply(str(query.key_expr), data)  # echo: the reply path is checked as well

    queryable = server.declare_queryable(keys.RESULTS_QUERYABLE, answer)
    try:
        for message in _messages():
            replies = list(client.get(keys.results_key(1, 1), payload=encode(message),
                                      timeout=10.0))
            assert len(replies) == 1 and replies[0].ok is not None
            echoed = decode(replies[0].ok.payload.to_bytes())
            assert echoed == message
            assert type(echoed) is type(message)
            assert echoed.model_dump() == message.model_dump()  # every field, nested ones too
    finally:
        queryable.undeclare()
    assert [decode(d) for d in received] == _messages()
