"""The real simulator's centre camera as a pinhole over flat ground, and the views it would see from elsewhere.

Moving the camera sideways by ``e`` and turning it by ``psi`` changes what it sees of the ground plane
by a homography, ``H = K R_old (I + C n^T / h) R_new^T K^-1`` (``C``: the new camera centre in the old
one's level frame, ``n``: the ground normal, ``h``: the camera height), which is exact for everything on
the road; above the horizon the scenery is far away and only the turn matters (``C`` -> 0). That maths is
:mod:`protocol.camera`'s (``view_homographies``, ``reproject``), shared with the moved-camera augmentation. The car's
bonnet moves with the camera, so its rows are kept as recorded. This is the view synthesis of NVIDIA's
DAVE-2 evaluation; :mod:`tools.drivelog.calibrate` measures the camera's numbers (:mod:`protocol.camera`)
on real frames.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from protocol import camera as rig
from protocol.camera import pitch_matrix
from protocol.errors import BadValue
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH


@dataclass(frozen=True)
class UnityCamera:
    """Centre camera of the Udacity simulator's car. Angles in degrees, lengths in metres.

    Defaults: the real simulator's rig (:mod:`protocol.camera`, where each number says where it comes from);
    ``rbc drive-log --calibrate`` fits ``pitch_deg`` and the side offset in camera heights again on a log.
    ``bonnet_row``: first row of the bonnet in the middle of the frame.
    """

    vfov_deg: float = rig.VFOV_DEG
    pitch_deg: float = rig.PITCH_DEG
    height_m: float = rig.HEIGHT_M
    side_offset_m: float = rig.SIDE_OFFSET_M
    bonnet_row: int = rig.BONNET_ROW
    width: int = FRAME_WIDTH
    height: int = FRAME_HEIGHT

    @property
    def focal_px(self) -> float:
        return rig.focal_px(self.height, self.vfov_deg)

    def intrinsics(self) -> np.ndarray:
        return rig.intrinsics(self.width, self.height, self.vfov_deg)

    @property
    def horizon_row(self) -> float:
        """Image row of the horizon (where the ground plane meets infinity)."""
        return rig.horizon_row(self.height, self.vfov_deg, self.pitch_deg)


#: The camera of every closed loop unless calibrated otherwise.
DEFAULT_CAMERA = UnityCamera()


def ground_to_pixels(camera: UnityCamera, x_m: np.ndarray, z_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel (column, row) of the ground points ``x_m`` to the right and ``z_m`` ahead of the camera."""
    x = np.asarray(x_m, np.float64)
    p = np.stack([x.ravel(), np.full(x.size, camera.height_m), np.asarray(z_m, np.float64).ravel()])
    q = camera.intrinsics() @ pitch_matrix(camera.pitch_deg) @ p
    return (q[0] / q[2]).reshape(x.shape), (q[1] / q[2]).reshape(x.shape)


def view_homographies(camera: UnityCamera, lateral_m: float, yaw_rad: float,
                      forward_m: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(ground, far) homographies from a pixel of the new view to the recorded frame.

    The new camera stands ``lateral_m`` to the right and ``forward_m`` ahead of the recorded one, turned
    ``yaw_rad`` to the right; ``ground`` maps the road, ``far`` (rotation only) what lies above the horizon
    (the maths is :func:`protocol.camera.view_homographies`, shared with the moved-camera augmentation).
    """
    return rig.view_homographies(camera.width, camera.height, lateral_m, yaw_rad, forward_m, vfov_deg=camera.vfov_deg,
                                 pitch_deg=camera.pitch_deg, height_m=camera.height_m)


class ViewSynthesizer:
    """Re-projects recorded frames to other poses; keeps its pixel grid between calls (one per frame size)."""

    def __init__(self, camera: UnityCamera = DEFAULT_CAMERA) -> None:
        self.camera = camera
        h, w = camera.height, camera.width
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        self._xs, self._ys = xs.ravel(), ys.ravel()
        self._bonnet = int(camera.bonnet_row)

    def view(self, frame: np.ndarray, lateral_m: float, yaw_rad: float, forward_m: float = 0.0,
             bonnet: np.ndarray | None = None, pitch_deg: float | None = None) -> np.ndarray:
        """What the centre camera would see from the given offset (frame: full-size RGB uint8).

        ``bonnet``: the frame whose bottom rows are kept (a side camera's frame shows the bonnet from the
        side: re-projecting one to the centre camera keeps the centre frame's bonnet instead). ``pitch_deg``:
        the ground ahead seen at this pitch (a hill: :mod:`tools.drivelog.pitch`; None: the camera's).
        """
        h, w = self.camera.height, self.camera.width
        if frame.shape[:2] != (h, w):
            raise BadValue(f"expected a {w}x{h} frame, got {frame.shape[1]}x{frame.shape[0]}")
        camera = self.camera
        if pitch_deg is not None and pitch_deg != camera.pitch_deg:
            camera = replace(camera, pitch_deg=pitch_deg)
        ground, far = view_homographies(camera, lateral_m, yaw_rad, forward_m)
        map_x, map_y = rig.reproject(self._xs, self._ys, ground, far, camera.horizon_row)
        out = cv2.remap(frame, map_x.reshape(h, w).astype(np.float32), map_y.reshape(h, w).astype(np.float32),
                        cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out[self._bonnet:] = (frame if bonnet is None else bonnet)[self._bonnet:]  # it travels with the camera
        return out
