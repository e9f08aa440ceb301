"""The real simulator's centre camera as a pinhole over flat ground, and the views it would see from elsewhere.

Moving the camera sideways by ``e`` and turning it by ``psi`` changes what it sees of the ground plane
by a homography, ``H = K R_old (I + C n^T / h) R_new^T K^-1`` (``C``: the new camera centre in the old
one's level frame, ``n``: the ground normal, ``h``: the camera height), which is exact for everything on
the road; above the horizon the scenery is far away and only the turn matters (``C`` -> 0). The car's
bonnet moves with the camera, so its rows are kept as recorded. This is the view synthesis of NVIDIA's
DAVE-2 evaluation; :mod:`tools.drivelog.calibrate` measures the numbers below on real frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH


@dataclass(frozen=True)
class UnityCamera:
    """Centre camera of the Udacity simulator's car. Angles in degrees, lengths in metres.

    ``vfov_deg``: Unity cameras are specified by their vertical field of view, 60 by default (the design
    card). ``pitch_deg`` (looking down) and the side cameras' offset in camera heights were fitted to
    SIFT matches between centre and side frames of real recordings (``rbc drive-log --calibrate``:
    6.2 deg, i.e. the horizon at row 65 where the README's crop found row 64; sides at 0.68 h).
    ``height_m`` follows from that ratio and the side cameras' 0.95 m (design card): 1.40 m.
    ``bonnet_row``: first row of the bonnet in the middle of the frame (README, "crop rows").
    """

    vfov_deg: float = 60.0
    pitch_deg: float = 6.2
    height_m: float = 1.40
    side_offset_m: float = 0.95
    bonnet_row: int = 137
    width: int = FRAME_WIDTH
    height: int = FRAME_HEIGHT

    @property
    def focal_px(self) -> float:
        return (self.height / 2) / math.tan(math.radians(self.vfov_deg / 2))

    def intrinsics(self) -> np.ndarray:
        f = self.focal_px
        return np.array([[f, 0.0, self.width / 2], [0.0, f, self.height / 2], [0.0, 0.0, 1.0]])

    @property
    def horizon_row(self) -> float:
        """Image row of the horizon (where the ground plane meets infinity)."""
        return self.height / 2 - self.focal_px * math.tan(math.radians(self.pitch_deg))


#: The camera of every closed loop unless calibrated otherwise.
DEFAULT_CAMERA = UnityCamera()


def _pitch(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _yaw(rad: float) -> np.ndarray:
    c, s = math.cos(rad), math.sin(rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def ground_to_pixels(camera: UnityCamera, x_m: np.ndarray, z_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel (column, row) of the ground points ``x_m`` to the right and ``z_m`` ahead of the camera."""
    x = np.asarray(x_m, np.float64)
    p = np.stack([x.ravel(), np.full(x.size, camera.height_m), np.asarray(z_m, np.float64).ravel()])
    q = camera.intrinsics() @ _pitch(camera.pitch_deg) @ p
    return (q[0] / q[2]).reshape(x.shape), (q[1] / q[2]).reshape(x.shape)


def view_homographies(camera: UnityCamera, lateral_m: float, yaw_rad: float,
                      forward_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(ground, far) homographies from a pixel of the new view to the recorded frame.

    The new camera stands ``lateral_m`` to the right and ``forward_m`` ahead of the recorded one, turned
    ``yaw_rad`` to the right; ``ground`` maps the road, ``far`` (rotation only) what lies above the horizon.
    """
    k = camera.intrinsics()
    k_inv = np.linalg.inv(k)
    r_old = _pitch(camera.pitch_deg)
    r_new = r_old @ _yaw(yaw_rad).T
    centre = np.array([lateral_m, 0.0, forward_m]) / camera.height_m
    ground = k @ r_old @ (np.eye(3) + np.outer(centre, [0.0, 1.0, 0.0])) @ r_new.T @ k_inv
    far = k @ r_old @ r_new.T @ k_inv
    return ground, far


class ViewSynthesizer:
    """Re-projects recorded frames to other poses; keeps its pixel grid between calls (one per frame size)."""

    def __init__(self, camera: UnityCamera = DEFAULT_CAMERA) -> None:
        self.camera = camera
        h, w = camera.height, camera.width
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        self._pixels = np.stack([xs.ravel(), ys.ravel(), np.ones(h * w)])
        self._below = (ys.ravel() > camera.horizon_row + 1.0).reshape(h, w)
        self._bonnet = int(camera.bonnet_row)

    def view(self, frame: np.ndarray, lateral_m: float, yaw_rad: float, forward_m: float = 0.0,
             bonnet: np.ndarray | None = None) -> np.ndarray:
        """What the centre camera would see from the given offset (frame: full-size RGB uint8).

        ``bonnet``: the frame whose bottom rows are kept (a side camera's frame shows the bonnet from the
        side: re-projecting one to the centre camera keeps the centre frame's bonnet instead).
        """
        h, w = self.camera.height, self.camera.width
        if frame.shape[:2] != (h, w):
            raise ValueError(f"expected a {w}x{h} frame, got {frame.shape[1]}x{frame.shape[0]}")
        ground, far = view_homographies(self.camera, lateral_m, yaw_rad, forward_m)
        maps = []
        for hom in (ground, far):
            p = hom @ self._pixels
            maps.append((p[:2] / p[2]).reshape(2, h, w))
        xy = np.where(self._below[None], maps[0], maps[1]).astype(np.float32)
        out = cv2.remap(frame, xy[0], xy[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out[self._bonnet:] = (frame if bonnet is None else bonnet)[self._bonnet:]  # it travels with the camera
        return out
