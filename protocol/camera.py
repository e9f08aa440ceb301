"""The real Udacity simulator's camera rig, and the pinhole and pitch maths every user of it shares.

The numbers are facts of the simulator's car, written here once: the turned-camera augmentation
(:mod:`models.augmentation`), the headless renderer's ``unity`` rig (:mod:`tools.sim.render.camera`) and the
closed loop on recordings (:mod:`tools.drivelog.camera`) all read them from here, so a re-measured camera
changes every one of them together. Numpy and the standard library only.
"""

from __future__ import annotations

import math

import numpy as np

#: Vertical field of view, degrees: Unity cameras are specified by it (``Camera.fieldOfView``, 60 by default,
#: the design card).
VFOV_DEG = 60.0
#: How far the cameras look down, degrees. Fitted to SIFT matches between centre and side frames of real
#: recordings (``rbc drive-log --calibrate``): the horizon at row 65, where the README's crop found row 64.
PITCH_DEG = 6.2
#: The side cameras' offset to each side of the centre one, metres (the design card).
SIDE_OFFSET_M = 0.95
#: Height of the cameras above the road, metres: the calibration found the side cameras 0.68 camera heights
#: out, and they are :data:`SIDE_OFFSET_M` out.
HEIGHT_M = 1.40
#: First row of the car's bonnet in the middle of the centre camera's 320x160 frame (README, "crop rows").
BONNET_ROW = 137
#: Half the car's width, metres (the design card's car is 1.9 m wide).
CAR_HALF_WIDTH_M = 0.95


def focal_px(height_px: int, vfov_deg: float = VFOV_DEG) -> float:
    """Focal length in pixels of a pinhole camera ``height_px`` rows high with that vertical field of view."""
    return (height_px / 2) / math.tan(math.radians(vfov_deg / 2))


def intrinsics(width_px: int, height_px: int, vfov_deg: float = VFOV_DEG) -> np.ndarray:
    """The pinhole's ``K``, its principal point at the frame's middle in corner coordinates."""
    f = focal_px(height_px, vfov_deg)
    return np.array([[f, 0.0, width_px / 2], [0.0, f, height_px / 2], [0.0, 0.0, 1.0]])


def pitch_matrix(deg: float) -> np.ndarray:
    """Rotation of a camera looking ``deg`` down (x right, y down, z forward) from a level one."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def yaw_matrix(rad: float) -> np.ndarray:
    """Rotation about the vertical (y down) of a camera turned ``rad`` to the right."""
    c, s = math.cos(rad), math.sin(rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def horizon_row(height_px: int, vfov_deg: float = VFOV_DEG, pitch_deg: float = PITCH_DEG) -> float:
    """Image row of the horizon (where the ground plane meets infinity) of a camera looking ``pitch_deg`` down."""
    return height_px / 2 - focal_px(height_px, vfov_deg) * math.tan(math.radians(pitch_deg))


def view_homographies(width_px: int, height_px: int, lateral_m: float, yaw_rad: float, forward_m: float = 0.0, *,
                      vfov_deg: float = VFOV_DEG, pitch_deg: float = PITCH_DEG,
                      height_m: float = HEIGHT_M) -> tuple[np.ndarray, np.ndarray]:
    """(ground, far) homographies from a pixel of a new view to the recorded frame (index coordinates).

    The new camera stands ``lateral_m`` to the right and ``forward_m`` ahead of the recorded one, turned
    ``yaw_rad`` to the right. Moving a camera by ``C`` changes what it sees of the ground plane by
    ``H = K R_old (I + C n^T / h) R_new^T K^-1`` (``n``: the ground normal, ``h``: the camera's height), exact for
    everything on the road: ``ground``; above the horizon the scenery is far away and only the turn matters
    (``C`` -> 0): ``far``. The closed loop's view synthesis (:mod:`tools.drivelog.camera`) and the moved-camera
    augmentation (:mod:`models.augmentation`) both use these.
    """
    k = intrinsics(width_px, height_px, vfov_deg)
    k_inv = np.linalg.inv(k)
    r_old = pitch_matrix(pitch_deg)
    r_new = r_old @ yaw_matrix(yaw_rad).T
    centre = np.array([lateral_m, 0.0, forward_m]) / height_m
    ground = k @ r_old @ (np.eye(3) + np.outer(centre, [0.0, 1.0, 0.0])) @ r_new.T @ k_inv
    far = k @ r_old @ r_new.T @ k_inv
    return ground, far


def reproject(xs: np.ndarray, ys: np.ndarray, ground: np.ndarray, far: np.ndarray, horizon: float,
              keep_from_row: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Where in the recorded frame the pixels ``(xs, ys)`` (index coordinates, ``(..., n)``) of a new view sample.

    Rows more than one below the ``horizon`` row show the road: through ``ground``; the others through ``far``
    (:func:`view_homographies`; ``(..., 3, 3)``, broadcast against the points). Rows from ``keep_from_row`` on
    (the car's bonnet, which travels with the camera; None: none) sample themselves, as recorded.
    """
    xs, ys = np.broadcast_arrays(np.asarray(xs, np.float64), np.asarray(ys, np.float64))
    pixels = np.stack([xs, ys, np.ones(xs.shape)], axis=-2)
    maps = []
    for hom in (ground, far):
        p = hom @ pixels
        maps.append(p[..., :2, :] / p[..., 2:, :])
    out = np.where((ys > horizon + 1.0)[..., None, :], maps[0], maps[1])
    if keep_from_row is not None:
        out = np.where((ys >= keep_from_row)[..., None, :], np.stack([xs, ys], axis=-2), out)
    return out[..., 0, :], out[..., 1, :]
