"""Pictures of a simulated grasp with pybullet's TinyRenderer (headless, no screen).

`render_scene` draws from a fixed camera around a target (gripper checks). `render_grasp`
chooses the camera from the grasp itself (`grasp_camera`): a fixed camera looks at the back of
the palm whenever the approach comes from its side, hiding the object and the fingers. The
grasp camera looks at the contact centroid (the object's centre of mass without contacts) along
a direction perpendicular to the approach axis, and of GRASP_VIEWS such directions takes the
one whose small test render shows the most object and finger pixels (ties: the first), so the
choice is deterministic and works for any gripper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as p
from PIL import Image

FOV_DEG = 45.0
LIGHT = [0.4, -0.6, 1.0]
GRASP_VIEWS = 8  # candidate directions around the approach axis
PROBE_SIZE = (96, 72)  # test renders that rank the candidates
FRAME_MARGIN = 0.95  # link boxes' corners lie beyond the geometry: frame a little tighter


@dataclass(frozen=True)
class Camera:
    """pybullet's view and projection matrices of one camera."""

    view: tuple[float, ...]
    projection: tuple[float, ...]
    aspect: float


def capture(client: int, camera: Camera, size: tuple[int, int]
            ) -> tuple[np.ndarray, np.ndarray]:
    """RGB (h, w, 3) and the segmentation mask (h, w): body id + (link index + 1) << 24."""
    width, height = size
    _, _, rgba, _, seg = p.getCameraImage(
        width, height, camera.view, camera.projection, renderer=p.ER_TINY_RENDERER,
        lightDirection=LIGHT, flags=p.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX,
        physicsClientId=client)
    image = np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3]
    return image, np.reshape(np.asarray(seg, dtype=np.int64), (height, width))


def _save(image: np.ndarray, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path)
    return path


def render_scene(client: int, target: np.ndarray, path: Path, *, distance: float = 0.35,
                 yaw: float = 45.0, pitch: float = -25.0, size: tuple[int, int] = (640, 480)
                 ) -> Path:
    """A picture from a fixed camera (yaw, pitch in degrees) around `target`."""
    width, height = size
    view = p.computeViewMatrixFromYawPitchRoll(target.tolist(), distance, yaw, pitch, 0.0, 2,
                                               physicsClientId=client)
    projection = p.computeProjectionMatrixFOV(FOV_DEG, width / height, 0.01, 5.0,
                                              physicsClientId=client)
    image, _ = capture(client, Camera(tuple(view), tuple(projection), width / height), size)
    return _save(image, path)


def _boxes(client: int, body: int) -> list[tuple[tuple[float, ...], tuple[float, ...]]]:
    """The axis-aligned box of every link of a body (the base too)."""
    return [p.getAABB(body, link, physicsClientId=client)
            for link in range(-1, p.getNumJoints(body, physicsClientId=client))]


def _look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray, aspect: float,
             client: int) -> Camera:
    view = p.computeViewMatrix(eye.tolist(), target.tolist(), up.tolist(),
                               physicsClientId=client)
    projection = p.computeProjectionMatrixFOV(FOV_DEG, aspect, 0.01, 5.0,
                                              physicsClientId=client)
    return Camera(tuple(view), tuple(projection), aspect)


def _perpendicular_basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to `axis` and to each other: the first as close to world
    up as the axis allows (so view 0 is level), else the world x axis projected."""
    for ref in (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])):
        first = ref - axis * float(ref @ axis)
        if np.linalg.norm(first) > 0.2:
            first /= np.linalg.norm(first)
            return first, np.cross(axis, first)
    raise ValueError("no perpendicular")  # unreachable: z and x cannot both be parallel


def grasp_cameras(client: int, hand_body: int, object_body: int, aspect: float
                  ) -> list[Camera]:
    """The GRASP_VIEWS candidate cameras: on a circle around the approach axis (the hand's
    frame +z, palm → object) through the target, each looking at it, far enough that the hand
    and the object fit."""
    _, hand_orn = p.getBasePositionAndOrientation(hand_body, physicsClientId=client)
    axis = np.asarray(p.getMatrixFromQuaternion(hand_orn), dtype=float).reshape(3, 3)[:, 2]
    contacts = p.getContactPoints(hand_body, object_body, physicsClientId=client)
    if contacts:
        target = np.mean([c[6] for c in contacts], axis=0)  # positionOnB: on the object
    else:
        target = np.asarray(p.getBasePositionAndOrientation(object_body,
                                                            physicsClientId=client)[0])
    # Framed on every link's box (one box round the whole hand would add its empty corners).
    boxes = [*_boxes(client, hand_body), *_boxes(client, object_body)]
    corners = np.array([[x, y, z] for lo, hi in boxes for x in (lo[0], hi[0])
                        for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    radius = float(np.max(np.linalg.norm(corners - target, axis=1)))
    half = math.radians(FOV_DEG) / 2 * min(1.0, aspect)
    distance = FRAME_MARGIN * radius / math.sin(half)
    first, second = _perpendicular_basis(axis)
    cameras = []
    for k in range(GRASP_VIEWS):
        angle = 2 * math.pi * k / GRASP_VIEWS
        out = math.cos(angle) * first + math.sin(angle) * second  # target → eye
        # Up: world z where the view is not near vertical, else the approach axis.
        up = np.array([0.0, 0.0, 1.0]) if abs(out[2]) < 0.9 else axis
        cameras.append(_look_at(target + out * distance, target, up, aspect, client))
    return cameras


def visible_pixels(seg: np.ndarray, hand_body: int, object_body: int) -> tuple[int, int]:
    """(object pixels, finger pixels: hand links other than the palm) of a segmentation mask."""
    body = np.where(seg >= 0, seg & ((1 << 24) - 1), -1)
    link = np.where(seg >= 0, (seg >> 24) - 1, -2)
    return (int(np.count_nonzero(body == object_body)),
            int(np.count_nonzero((body == hand_body) & (link >= 0))))


def grasp_camera(client: int, hand_body: int, object_body: int, aspect: float = 4 / 3
                 ) -> Camera:
    """The candidate camera whose probe render shows the most object and finger pixels."""
    best, best_score = None, -1
    for camera in grasp_cameras(client, hand_body, object_body, aspect):
        _, seg = capture(client, camera, PROBE_SIZE)
        score = sum(visible_pixels(seg, hand_body, object_body))
        if score > best_score:
            best, best_score = camera, score
    assert best is not None
    return best


def render_grasp(client: int, hand_body: int, object_body: int, path: Path, *,
                 size: tuple[int, int] = (640, 480)) -> Path:
    """A picture of the hand on the object from `grasp_camera`."""
    camera = grasp_camera(client, hand_body, object_body, size[0] / size[1])
    image, _ = capture(client, camera, size)
    return _save(image, path)
