"""Grasp-type signatures and how alike two of them are (pure functions).

A signature says which gripper links touch the object, where (one force-weighted contact
centroid per link, in the object frame) and the final joint angles. Two grasps are of one type
when the same links touch roughly the same places with the hand closed roughly alike.
"""

from __future__ import annotations

import math

from graspscape.shared.specs.results import ContactPoint, GraspSignature

# Scales of "roughly": 2 cm between contact centroids, 0.3 rad of joint angle.
CONTACT_SCALE_M = 0.02
ANGLE_SCALE_RAD = 0.3
WEIGHTS = {"links": 0.5, "contacts": 0.3, "angles": 0.2}
SAME_TYPE_THRESHOLD = 0.7


def build_signature(raw_contacts: list[tuple[str, tuple[float, float, float], float]],
                    joint_angles: dict[str, float]) -> GraspSignature:
    """raw_contacts: (link name, position in the object frame, normal force) per contact."""
    per_link: dict[str, list[tuple[tuple[float, float, float], float]]] = {}
    for link, position, force in raw_contacts:
        per_link.setdefault(link, []).append((position, force))
    contacts = []
    for link in sorted(per_link):
        items = per_link[link]
        total = sum(max(f, 0.0) for _, f in items)
        weights = [max(f, 0.0) / total if total > 0 else 1.0 / len(items) for _, f in items]
        centroid = tuple(
            round(sum(w * pos[i] for (pos, _), w in zip(items, weights, strict=True)), 6)
            for i in range(3)
        )
        contacts.append(ContactPoint(link=link, position_object=centroid,
                                     normal_force_n=round(total, 6)))
    return GraspSignature(links_in_contact=tuple(sorted(per_link)), contacts=tuple(contacts),
                          joint_angles={k: round(v, 6) for k, v in sorted(joint_angles.items())})


def similarity(a: GraspSignature, b: GraspSignature) -> float:
    """In [0, 1]: 1 for identical grasps, 0 for grasps that share nothing."""
    links_a, links_b = set(a.links_in_contact), set(b.links_in_contact)
    union = links_a | links_b
    if not union:
        return 1.0
    link_score = len(links_a & links_b) / len(union)
    shared = links_a & links_b
    if shared:
        pa = {c.link: c.position_object for c in a.contacts}
        pb = {c.link: c.position_object for c in b.contacts}
        contact_score = sum(math.exp(-math.dist(pa[k], pb[k]) / CONTACT_SCALE_M)
                            for k in shared) / len(shared)
    else:
        contact_score = 0.0
    joints = set(a.joint_angles) & set(b.joint_angles)
    if joints:
        mean_diff = sum(abs(a.joint_angles[j] - b.joint_angles[j]) for j in joints) / len(joints)
        angle_score = math.exp(-mean_diff / ANGLE_SCALE_RAD)
    else:
        angle_score = 0.0
    return (WEIGHTS["links"] * link_score + WEIGHTS["contacts"] * contact_score
            + WEIGHTS["angles"] * angle_score)


def same_grasp_type(a: GraspSignature, b: GraspSignature,
                    threshold: float = SAME_TYPE_THRESHOLD) -> bool:
    return similarity(a, b) >= threshold
