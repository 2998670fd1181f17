"""Generates a URDF from a gripper spec (pure: spec in, XML text out).

Collision and visual shapes are boxes. Link names are `palm`, `<finger>_spread` (where the
finger has a spread joint) and `<finger>_<phalanx>`; joint names are the child link's name
with a `_joint` suffix.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from xml.sax.saxutils import quoteattr

from graspscape.shared.specs.gripper import FingerSpec, GripperSpec

_PALM_RGBA = "0.25 0.25 0.28 1"
_FINGER_RGBA = "0.55 0.57 0.62 1"


def _box_inertia(mass: float, x: float, y: float, z: float) -> str:
    ixx = mass * (y * y + z * z) / 12
    iyy = mass * (x * x + z * z) / 12
    izz = mass * (x * x + y * y) / 12
    return f'<inertia ixx="{ixx:.9g}" ixy="0" ixz="0" iyy="{iyy:.9g}" iyz="0" izz="{izz:.9g}"/>'


def _box_link(name: str, size: tuple[float, float, float], center: tuple[float, float, float],
              mass: float, rgba: str) -> str:
    sx, sy, sz = size
    cx, cy, cz = center
    origin = f'<origin xyz="{cx:.9g} {cy:.9g} {cz:.9g}" rpy="0 0 0"/>'
    geometry = f'<geometry><box size="{sx:.9g} {sy:.9g} {sz:.9g}"/></geometry>'
    return (
        f"<link name={quoteattr(name)}>"
        f"<inertial>{origin}<mass value=\"{mass:.9g}\"/>{_box_inertia(mass, sx, sy, sz)}</inertial>"
        f"<visual>{origin}{geometry}<material name={quoteattr(name + '_mat')}>"
        f'<color rgba="{rgba}"/></material></visual>'
        f"<collision>{origin}{geometry}</collision>"
        "</link>"
    )


def _joint(name: str, kind: str, parent: str, child: str, xyz: tuple[float, float, float],
           rpy: tuple[float, float, float], axis: tuple[float, float, float] | None,
           limits: tuple[float, float] | None, effort: float) -> str:
    text = (
        f"<joint name={quoteattr(name)} type=\"{kind}\">"
        f"<parent link={quoteattr(parent)}/><child link={quoteattr(child)}/>"
        f'<origin xyz="{xyz[0]:.9g} {xyz[1]:.9g} {xyz[2]:.9g}" '
        f'rpy="{rpy[0]:.9g} {rpy[1]:.9g} {rpy[2]:.9g}"/>'
    )
    if axis is not None:
        text += f'<axis xyz="{axis[0]:g} {axis[1]:g} {axis[2]:g}"/>'
    if limits is not None:
        text += (
            f'<limit lower="{limits[0]:.9g}" upper="{limits[1]:.9g}" '
            f'effort="{effort:.9g}" velocity="10"/>'
        )
    return text + "</joint>"


def _finger(finger: FingerSpec, effort: float) -> list[str]:
    parts: list[str] = []
    parent = "palm"
    mount_rpy = (0.0, 0.0, finger.mount_yaw)
    if finger.spread is not None:
        # The spread link is a small hub at the knuckle; it rotates the closing plane.
        spread_link = f"{finger.name}_spread"
        parts.append(_box_link(spread_link, (0.02, 0.02, 0.01), (0, 0, -0.005),
                               finger.spread.mass, _FINGER_RGBA))
        parts.append(_joint(f"{spread_link}_joint", "revolute", parent, spread_link,
                            finger.mount_xyz, mount_rpy, (0, 0, 1),
                            (finger.spread.lower, finger.spread.upper), 10 * effort))
        parent, xyz, rpy = spread_link, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    else:
        xyz, rpy = finger.mount_xyz, mount_rpy
    for phalanx in finger.phalanges:
        link = f"{finger.name}_{phalanx.name}"
        parts.append(_box_link(link, (phalanx.thickness, phalanx.width, phalanx.length),
                               (0, 0, phalanx.length / 2), phalanx.mass, _FINGER_RGBA))
        # Revolute phalanges turn about +y, so a positive angle swings +z toward +x (closing).
        axis = (0, 1, 0) if phalanx.joint == "revolute" else (1, 0, 0)
        parts.append(_joint(f"{link}_joint", phalanx.joint, parent, link, xyz, rpy, axis,
                            (phalanx.lower, phalanx.upper), effort))
        parent, xyz, rpy = link, (0.0, 0.0, phalanx.length), (0.0, 0.0, 0.0)
    return parts


def gripper_urdf(spec: GripperSpec) -> str:
    sx, sy, sz = spec.palm.size
    parts = [f"<?xml version=\"1.0\"?><robot name={quoteattr(spec.name)}>"]
    # The palm surface is the base frame's z = 0 plane; the palm box lies below it.
    parts.append(_box_link("palm", (sx, sy, sz), (0, 0, -sz / 2), spec.palm.mass, _PALM_RGBA))
    for finger in spec.fingers:
        parts.extend(_finger(finger, 10 * spec.closing_effort))
    parts.append("</robot>")
    return "\n".join(parts)


def write_gripper_urdf(spec: GripperSpec, directory: Path) -> Path:
    """Writes the URDF under a content-addressed name, so specs never overwrite each other."""
    text = gripper_urdf(spec)
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{spec.name}-{digest}.urdf"
    if not path.exists():
        tmp = path.with_suffix(".tmp")
        tmp.write_text(text)
        tmp.replace(path)
    return path
