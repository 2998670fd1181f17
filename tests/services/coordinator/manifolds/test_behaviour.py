"""Which digit a gripper link belongs to, and what that means for telling grasp types apart."""

from __future__ import annotations

from graspscape.services.coordinator.manifolds.behaviour import StoredPose, digit, same_behaviour


def test_every_link_of_a_finger_is_that_finger():
    # The scissor base that turns B and C belongs to its finger, like the phalanges; so do a
    # parallel jaw's pads.
    assert {digit(link) for link in ("B_1", "B_2", "B_3", "B_spread")} == {"B"}
    assert digit("L_pad") == "L"
    assert digit("palm") == "palm"


def _sample(key: str, links: tuple[str, ...]) -> StoredPose:
    return StoredPose(key=key, theta=1.0, phi=0.0, r=0.01, roll=0.0, pitch=0.0, yaw=0.0,
                  viable=True, outcome="held", mu_s=0.8,
                  digits=frozenset(digit(link) for link in links),
                  joints={"A_1": 0.3, "B_1": 0.3, "C_1": 0.3})


def test_a_knuckle_touching_too_is_the_same_grasp_type():
    plain = _sample("a", ("A_3", "B_3", "C_3", "palm"))
    knuckle = _sample("b", ("A_3", "B_3", "B_spread", "C_3", "palm"))
    assert same_behaviour(plain, knuckle)
    assert not same_behaviour(plain, _sample("c", ("A_3", "B_3", "palm")))
