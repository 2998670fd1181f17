"""A vendor's URDF made into a gripper the Hand can drive (pure: files in, a URDF file out).

What the rewrite does, in order (docs/howto/add-gripper.md):
- keeps the subtree under the description's base link (a hand on an arm: the arm is dropped);
- refuses any joint that moves and that the description does not name (it would swing free);
- re-roots the base link at the palm frame, so pybullet's base frame is the gripper frame the
  rest of Graspscape uses (origin at the palm surface centre, z along the palm normal);
- turns every joint that closes toward smaller values around (axis and limits negated), so
  every finger joint closes as its value grows, as the Hand's sequencing assumes;
- renames links and joints to the Graspscape convention (`palm`, `<finger>_<k>`,
  `<finger>_spread`, joints `<link>_joint`): digits are read from link names
  (manifolds/behaviour.py); the vendor's names are kept in `PreparedUrdf.vendor_names`;
- resolves every mesh inside the gripper's folder only (`package://` maps to the folder), and
  replaces each collision mesh by its convex hull (a convex mesh) or its V-HACD parts (a
  concave one), cached by the mesh's content hash as objects are (objects/decompose.py).
"""

from __future__ import annotations

import hashlib
import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from graspscape.shared.specs.gripper import (
    UrdfGripperSpec,
)
from graspscape.shared.specs.gripper_files import GripperFileError, resolve_inside
from graspscape.workers.sim.objects.decompose import params_key, vhacd_parts
from graspscape.workers.sim.objects.meshio import atomic_write, write_parts_obj
from scipy.spatial.transform import Rotation

# A collision mesh whose convex hull holds at most this much more volume is used as its hull.
CONVEX_VOLUME_RATIO = 1.05
MOVING = ("revolute", "prismatic", "continuous", "planar", "floating")


@dataclass(frozen=True)
class JointLayout:
    """A finger's joints for the Hand, in Graspscape names and closing-positive values."""

    finger: str
    spread_joint: str | None
    spread_sign: float
    joints: tuple[str, ...]  # actuated ones, in closing order
    open_values: tuple[float, ...]
    uppers: tuple[float, ...]
    shares: tuple[float, ...]


@dataclass(frozen=True)
class Coupling:
    """follower = ratio · driver + offset (Graspscape joint names, closing-positive values)."""

    follower: str
    driver: str
    ratio: float
    offset: float


@dataclass(frozen=True)
class PreparedUrdf:
    path: Path
    fingers: tuple[JointLayout, ...]
    couplings: tuple[Coupling, ...]
    vendor_names: dict[str, str]  # Graspscape link or joint name → the URDF's


# --- files --------------------------------------------------------------------------------
def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def collision_mesh(path: Path, cache: Path) -> Path:
    """The collision geometry pybullet gets for a mesh: its hull if it is convex, else its
    V-HACD parts (a multi-object OBJ pybullet loads as a compound). Cached by content."""
    out = cache / f"{_sha(path)[:20]}-{params_key()}.obj"
    if out.is_file():
        return out
    mesh = trimesh.load(path, force="mesh", process=True)
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise GripperFileError(f"mesh {path.name}: no triangles in it")
    hull = mesh.convex_hull
    convex = mesh.is_watertight and mesh.volume > 0 and (
        hull.volume <= CONVEX_VOLUME_RATIO * mesh.volume)
    if convex:
        write_parts_obj([np.asarray(hull.vertices)], out)
    else:
        vhacd_parts(mesh, out, path.name)
    return out


# --- frames -------------------------------------------------------------------------------
def _floats(text: str | None, n: int = 3) -> np.ndarray:
    values = [float(v) for v in (text or "").split()]
    return np.array(values if len(values) == n else [0.0] * n)


def _origin(parent: ET.Element) -> np.ndarray:
    element = parent.find("origin")
    t = np.eye(4)
    if element is not None:
        t[:3, :3] = Rotation.from_euler("xyz", _floats(element.get("rpy"))).as_matrix()
        t[:3, 3] = _floats(element.get("xyz"))
    return t


def _set_origin(parent: ET.Element, t: np.ndarray) -> None:
    element = parent.find("origin")
    if element is None:
        element = ET.Element("origin")
        parent.insert(0, element)
    with warnings.catch_warnings():  # gimbal lock: any of the equivalent angles will do
        warnings.simplefilter("ignore")
        rpy = Rotation.from_matrix(t[:3, :3]).as_euler("xyz")
    element.set("xyz", " ".join(f"{v:.12g}" for v in t[:3, 3]))
    element.set("rpy", " ".join(f"{v:.12g}" for v in rpy))


_INERTIA = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def _unrotate_inertial(inertial: ET.Element) -> None:
    """The root link's inertial frame turned parallel to the link frame (tensor rotated to
    match): pybullet reports a body's base pose as its inertial frame, and the Hand takes the
    base frame as the gripper frame shifted by the inertial offset only."""
    t = _origin(inertial)
    tensor = inertial.find("inertia")
    if tensor is not None:
        v = {k: float(tensor.get(k, 0.0)) for k in _INERTIA}
        m = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
                      [v["ixz"], v["iyz"], v["izz"]]])
        m = t[:3, :3] @ m @ t[:3, :3].T
        for k, (i, j) in zip(_INERTIA, [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)],
                             strict=True):
            tensor.set(k, f"{m[i, j]:.12g}")
    t[:3, :3] = np.eye(3)
    _set_origin(inertial, t)


def palm_transform(spec: UrdfGripperSpec) -> np.ndarray:
    """The palm frame in the base link's frame (x made orthogonal to the normal)."""
    z = np.array(spec.palm.normal, dtype=float)
    z /= np.linalg.norm(z)
    x = np.array(spec.palm.x_axis, dtype=float)
    x = x - z * float(x @ z)
    if np.linalg.norm(x) < 1e-9:
        raise GripperFileError("palm.x_axis is parallel to palm.normal")
    x /= np.linalg.norm(x)
    t = np.eye(4)
    t[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    t[:3, 3] = spec.palm.origin
    return t


# --- the rewrite --------------------------------------------------------------------------
def _subtree(links: dict[str, ET.Element], joints: list[ET.Element], base: str) -> set[str]:
    if base not in links:
        raise GripperFileError(f"base link {base!r} is not in the URDF "
                               f"(links: {', '.join(sorted(links))})")
    keep, grew = {base}, True
    while grew:
        grew = False
        for joint in joints:
            parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
            if parent in keep and child not in keep:
                keep.add(child)
                grew = True
    return keep


def _limits(joint: ET.Element, name: str) -> tuple[float, float]:
    limit = joint.find("limit")
    if joint.get("type") not in ("revolute", "prismatic") or limit is None:
        raise GripperFileError(f"joint {name!r}: a finger or spread joint must be revolute or "
                               "prismatic with <limit lower upper>")
    return float(limit.get("lower", 0.0)), float(limit.get("upper", 0.0))


def _parse(source: str, label: str) -> ET.Element:
    """The URDF's root. Files made for other tools use namespace prefixes they never declare
    (Drake's `<drake:collision_filter_group>`), which ROS's and pybullet's parsers let pass:
    such prefixes are declared here so the file parses (those elements are dropped anyway)."""
    declared = set(re.findall(r"xmlns:([\w.-]+)=", source))
    used = set(re.findall(r"</?([A-Za-z_][\w.-]*):[A-Za-z_]", source)) - declared - {"xml"}
    if used:
        names = " ".join(f'xmlns:{prefix}="urn:undeclared:{prefix}"' for prefix in sorted(used))
        source = re.sub(r"<robot\b", f"<robot {names}", source, count=1)
    try:
        return ET.fromstring(source)
    except ET.ParseError as exc:
        raise GripperFileError(f"{label}: not valid XML ({exc})") from None


def _prune(robot: ET.Element, links: dict[str, ET.Element], base_link: str) -> set[str]:
    """Drops every link and joint outside the base link's subtree; returns the links kept."""
    keep = _subtree(links, robot.findall("joint"), base_link)
    for element in list(robot):
        if element.tag == "link" and element.get("name") in keep:
            continue
        if element.tag == "joint" and element.find("parent").get("link") in keep:
            continue
        if element.tag != "material":
            robot.remove(element)
    return keep


def _names(spec: UrdfGripperSpec, joints: dict[str, ET.Element], keep: set[str],
           ) -> tuple[dict[str, str], dict[str, str], dict[str, int]]:
    """Graspscape names and directions of the joints the description names: (link renames,
    joint renames, closing sign by vendor joint)."""
    rename: dict[str, str] = {spec.base_link: "palm"}  # links
    joint_names: dict[str, str] = {}
    sign: dict[str, int] = {}
    for finger in spec.fingers:
        if finger.spread is not None:
            joint_names[finger.spread.joint] = f"{finger.name}_spread_joint"
            sign[finger.spread.joint] = 1
        for k, item in enumerate(finger.joints, start=1):
            joint_names[item.joint] = f"{finger.name}_{k}_joint"
            sign[item.joint] = item.closing
    for vendor, ours in joint_names.items():
        if vendor not in joints:
            raise GripperFileError(f"joint {vendor!r} is not in the gripper's subtree of "
                                   f"{spec.urdf}")
        _limits(joints[vendor], vendor)
        rename[joints[vendor].find("child").get("link")] = ours.removesuffix("_joint")
    free = sorted(n for n, j in joints.items() if j.get("type") in MOVING and n not in joint_names)
    if free:
        raise GripperFileError(f"joints {', '.join(free)} move but are in no finger of the "
                               "description: name them (as a finger joint, a spread joint or a "
                               "mimic) or make them fixed")
    taken = set(rename.values())
    for name in keep - set(rename):  # fixed links (pybullet merges them into their parent)
        rename[name] = name if name not in taken else f"{name}_fixed"
    return rename, joint_names, sign


def _reroot(spec: UrdfGripperSpec, base: ET.Element, joints: dict[str, ET.Element]) -> None:
    """Re-root at the palm frame."""
    to_palm = np.linalg.inv(palm_transform(spec))
    for tag in ("inertial", "visual", "collision"):
        for element in base.findall(tag):
            _set_origin(element, to_palm @ _origin(element))
    for inertial in base.findall("inertial"):
        _unrotate_inertial(inertial)
    for joint in joints.values():
        if joint.find("parent").get("link") == spec.base_link:
            _set_origin(joint, to_palm @ _origin(joint))


def _orient(joints: dict[str, ET.Element], joint_names: dict[str, str], sign: dict[str, int],
            rename: dict[str, str]) -> dict[str, tuple[float, float]]:
    """Closing-positive joints, names, no <mimic> (pybullet ignores it; couplings do its job).
    Returns each vendor joint's (lower, upper) limits after the flip."""
    values: dict[str, tuple[float, float]] = {}
    for vendor, joint in joints.items():
        lower, upper = _limits(joint, vendor) if vendor in joint_names else (0.0, 0.0)
        if sign.get(vendor) == -1:
            axis = joint.find("axis")
            flipped = -_floats(axis.get("xyz") if axis is not None else "1 0 0")
            if axis is None:
                axis = ET.SubElement(joint, "axis")
            axis.set("xyz", " ".join(f"{v:.12g}" for v in flipped))
            lower, upper = -upper, -lower
            joint.find("limit").set("lower", f"{lower:.12g}")
            joint.find("limit").set("upper", f"{upper:.12g}")
        values[vendor] = (lower, upper)
        for mimic in joint.findall("mimic"):
            joint.remove(mimic)
        joint.set("name", joint_names.get(vendor, f"{vendor}_fixed"))
        for end in ("parent", "child"):
            joint.find(end).set("link", rename[joint.find(end).get("link")])
    return values


def _layout(spec: UrdfGripperSpec, joint_names: dict[str, str], sign: dict[str, int],
            values: dict[str, tuple[float, float]],
            ) -> tuple[list[JointLayout], list[Coupling]]:
    """Each finger's actuated joints in closing order, and the mimic joints as couplings."""
    fingers, couplings = [], []
    for finger in spec.fingers:
        actuated = [j for j in finger.joints if j.mimic is None]
        for item in finger.joints:
            if item.mimic is None:
                continue
            if item.mimic.joint not in joint_names:
                raise GripperFileError(f"joint {item.joint!r} mimics {item.mimic.joint!r}, "
                                       "which no finger names")
            s_f, s_d = sign[item.joint], sign[item.mimic.joint]
            couplings.append(Coupling(joint_names[item.joint], joint_names[item.mimic.joint],
                                      s_f * s_d * item.mimic.ratio, s_f * item.mimic.offset))
        if not actuated:
            continue
        fingers.append(JointLayout(
            finger=finger.name,
            spread_joint=joint_names[finger.spread.joint] if finger.spread else None,
            spread_sign=finger.spread.sign if finger.spread else 1.0,
            joints=tuple(joint_names[j.joint] for j in actuated),
            open_values=tuple(sign[j.joint] * j.open for j in actuated),
            uppers=tuple(values[j.joint][1] for j in actuated),
            shares=tuple(j.torque_share for j in actuated)))
        for j in actuated:
            low, high = values[j.joint]
            if not low <= sign[j.joint] * j.open <= high:
                raise GripperFileError(f"joint {j.joint!r}: open value {j.open} is outside "
                                       "its limits")
    return fingers, couplings


def rewrite(spec: UrdfGripperSpec, source: str, mesh_cache: Path) -> tuple[str, PreparedUrdf]:
    """The rewritten URDF text and the layout the Hand needs (path left empty)."""
    folder = Path(spec.folder)
    urdf_dir = resolve_inside(folder, spec.urdf).parent
    robot = _parse(source, spec.urdf)
    links = {link.get("name"): link for link in robot.findall("link")}
    keep = _prune(robot, links, spec.base_link)
    joints = {j.get("name"): j for j in robot.findall("joint")}
    rename, joint_names, sign = _names(spec, joints, keep)

    # A link without <inertial> has no mass in the URDF standard, but pybullet gives it 1 kg:
    # give it a gram instead (a massless link of a moving multibody is not simulable).
    for link in robot.findall("link"):
        if link.find("inertial") is None:
            ET.SubElement(link, "inertial").extend([
                ET.fromstring('<mass value="0.001"/>'),
                ET.fromstring('<inertia ixx="1e-8" ixy="0" ixz="0" iyy="1e-8" iyz="0" '
                              'izz="1e-8"/>')])
    _reroot(spec, links[spec.base_link], joints)
    values = _orient(joints, joint_names, sign, rename)
    for link in robot.findall("link"):
        link.set("name", rename[link.get("name")])

    # Meshes: inside the folder only; collision meshes convex or decomposed.
    for link in robot.findall("link"):
        for tag in ("visual", "collision"):
            for mesh in link.findall(f"{tag}/geometry/mesh"):
                path = resolve_inside(folder, mesh.get("filename", ""), urdf_dir)
                if tag == "collision":
                    path = collision_mesh(path, mesh_cache)
                mesh.set("filename", str(path))

    fingers, couplings = _layout(spec, joint_names, sign, values)
    vendor_names = {rename[v]: v for v in rename} | {ours: v for v, ours in joint_names.items()}
    text = ET.tostring(robot, encoding="unicode")
    return text, PreparedUrdf(Path(), tuple(fingers), tuple(couplings), vendor_names)


def prepare_urdf(spec: UrdfGripperSpec, directory: Path) -> PreparedUrdf:
    """Rewrites the gripper's URDF into `directory` under a content-addressed name (collision
    meshes cached in `directory`/meshes)."""
    source_path = resolve_inside(Path(spec.folder), spec.urdf)
    text, prepared = rewrite(spec, source_path.read_text(), directory / "meshes")
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    path = directory / f"{spec.name}-{digest}.urdf"
    if not path.exists():
        atomic_write(path, text.encode())
    return PreparedUrdf(path, prepared.fingers, prepared.couplings, prepared.vendor_names)
