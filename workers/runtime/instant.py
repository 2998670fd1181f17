"""`graspscape worker --instant`: a made-up result per pose, no physics, for measuring the
dispatch and ingest ceiling with messages and rows the size of real ones. A pose of a tile of
draws gets a made-up draw shaped as workers/sim/samples.py's `sample_result` makes it (outcome
only, a `sample` record per engine), so the store sees what real workers send."""

from __future__ import annotations

from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    ContactPoint,
    DrawScales,
    EngineOutcome,
    GraspConfiguration,
    GraspSignature,
    Outcome,
    PoseResult,
    SampleRecord,
)
from graspscape.shared.wire.messages import TileSample


def instant_result(pose: Pose, sample: TileSample | None = None) -> PoseResult:
    """A made-up held grasp the size of a real one (contacts, joint angles), for measuring
    the dispatch and ingest ceiling with realistic messages and rows; for a pose of a tile
    of draws (`sample`, the lease's), a made-up held draw in each of its engines."""
    if sample is not None:
        return _instant_draw(pose, sample)
    # Built as evaluate_pose builds its results: model_copy()s of one template took 60 %
    # longer to serialize, a cost real workers never pay.
    return PoseResult(**_INSTANT, pose=pose, pose_key=pose.key(), effective_r=pose.r)


def _instant_draw(pose: Pose, sample: TileSample) -> PoseResult:
    """As sample_result's record: held in every engine, with the template's links in
    contact, under the scales the lease gives this pose."""
    key = pose.key()
    held = EngineOutcome(outcome=Outcome.HELD, links=_LINKS)
    record = SampleRecord(scales=sample.scales.get(key) or DrawScales(),
                          engines=dict.fromkeys(sample.engines, held))
    return PoseResult(pose=pose, pose_key=key, outcome=Outcome.HELD, viable=True, mu_s=0.0,
                      eval_time_s=0.0, sample=record)


_LINKS = ("finger_1_link_1", "finger_2_link_1", "finger_middle_link_1", "palm")


def _instant_template() -> PoseResult:
    pose = Pose(theta=0.0, phi=0.0, r=0.0)
    joints = {f"joint_{i}": 0.1 * i for i in range(10)}
    links = _LINKS
    return PoseResult(
        pose=pose, pose_key=pose.key(), outcome=Outcome.HELD, viable=True, mu_s=0.5,
        effective_r=pose.r, effort_max_nm=1.0, contacts_per_link=dict.fromkeys(links, 1),
        grasp=GraspConfiguration(base_position=(0.0, 0.0, 0.1),
                                 base_orientation=(0.0, 0.0, 0.0, 1.0), joint_angles=joints),
        signature=GraspSignature(
            links_in_contact=links,
            contacts=tuple(ContactPoint(link=link, position_object=(0.01, 0.02, 0.03),
                                        normal_force_n=2.0) for link in links),
            joint_angles=joints,
        ),
    )


_INSTANT = {name: value for name, value in _instant_template() if name not in
            ("pose", "pose_key", "effective_r")}
