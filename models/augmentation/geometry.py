"""Geometry of the paper's flip, pan and tilt as composable affine maps.

Every map here is a *pullback* in continuous corner coordinates: a 3x3 matrix taking a point of the
output image to the point of the input image it samples (pixel ``i`` spans ``[i, i + 1)``). In these
coordinates OpenCV's resize is a pure scale, a crop a pure offset, so the paper's "transform, crop the
null area, resize back" chain and the final resize to the network's input compose into ONE matrix
(``models.augmentation.fastaug`` warps the cached network-size frame with it, once).
``models.augmentation.augment`` performs the same chain literally, step by step at full resolution, as the reference.
"""

from __future__ import annotations

import math

import numpy as np

from protocol.camera import BONNET_ROW, horizon_row, intrinsics, pitch_matrix, reproject, view_homographies
from protocol.facts import FRAME_HEIGHT

Matrix = np.ndarray  # (3, 3) float64


def translate(dx: float, dy: float) -> Matrix:
    return np.array([[1.0, 0.0, dx], [0.0, 1.0, dy], [0.0, 0.0, 1.0]])


def scale(sx: float, sy: float) -> Matrix:
    return np.array([[sx, 0.0, 0.0], [0.0, sy, 0.0], [0.0, 0.0, 1.0]])


def flip_pullback(width: float) -> Matrix:
    """Eq. 7 (dst[i] = src[w - 1 - i]) in corner coordinates: X -> w - X."""
    return np.array([[-1.0, 0.0, width], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def crop_resize_pullback(x0: float, y0: float, crop_w: float, crop_h: float, out_w: float, out_h: float) -> Matrix:
    """Crop ``[x0, x0 + crop_w) x [y0, y0 + crop_h)`` and resize it to ``out_w x out_h``."""
    return translate(x0, y0) @ scale(crop_w / out_w, crop_h / out_h)


def pan_crop(width: int, height: int, tx: float, ty: float) -> tuple[int, int, int, int]:
    """Integer crop ``(x0, y0, w, h)`` that removes the null area left by shifting the image by (tx, ty)."""
    cx, cy = math.ceil(abs(tx) - 1e-9), math.ceil(abs(ty) - 1e-9)
    return (cx if tx > 0 else 0), (cy if ty > 0 else 0), width - cx, height - cy


def pan_pullback(width: int, height: int, tx: float, ty: float) -> Matrix:
    """Eq. 9 shift by (tx, ty) pixels, null area cropped, resized back to ``width x height``."""
    x0, y0, cw, ch = pan_crop(width, height, tx, ty)
    return translate(-tx, -ty) @ crop_resize_pullback(x0, y0, cw, ch, width, height)


def rotation_matrix(width: int, height: int, degrees: float) -> np.ndarray:
    """Eq. 10: the forward 2x3 matrix rotating about (w/2, h/2) in pixel-index coordinates (as OpenCV)."""
    p = math.radians(degrees)
    c, s = math.cos(p), math.sin(p)
    return np.array([[c, s, width / 2 * (1 - c) - height / 2 * s],
                     [-s, c, width / 2 * s + height / 2 * (1 - c)]])


def max_inscribed_rect(width: float, height: float, degrees: float) -> tuple[float, float]:
    """Eq. 11: size of the largest axis-aligned central rectangle inside the rotated ``width x height`` frame."""
    if width <= 0 or height <= 0:
        return 0.0, 0.0
    a = math.radians(abs(degrees))
    sin_a, cos_a = abs(math.sin(a)), abs(math.cos(a))
    if sin_a < 1e-12:
        return float(width), float(height)
    long_side, short_side = (width, height) if width >= height else (height, width)
    if short_side <= 2.0 * sin_a * cos_a * long_side or abs(sin_a - cos_a) < 1e-10:
        # half-constrained: two corners on the longer side, two on the midline of the shorter sides
        x = 0.5 * short_side
        return (x / sin_a, x / cos_a) if width >= height else (x / cos_a, x / sin_a)
    cos_2a = cos_a * cos_a - sin_a * sin_a  # fully constrained: all four corners on the sides
    return (width * cos_a - height * sin_a) / cos_2a, (height * cos_a - width * sin_a) / cos_2a


#: The tilt crop is taken this many pixels inside Eq. 11's rectangle, so bilinear sampling at its
#: corners never blends in the null area (at 320x160 that is 0.6 % of the width).
TILT_INSET_PX = 1


def tilt_crop(width: int, height: int, degrees: float) -> tuple[int, int, int, int]:
    """Integer central crop ``(x0, y0, w, h)`` inside Eq. 11's rectangle."""
    w_roi, h_roi = max_inscribed_rect(width, height, degrees)
    inset = TILT_INSET_PX if degrees else 0
    x0 = math.ceil((width - w_roi) / 2 - 1e-9) + inset
    y0 = math.ceil((height - h_roi) / 2 - 1e-9) + inset
    x1 = math.floor((width + w_roi) / 2 + 1e-9) - inset
    y1 = math.floor((height + h_roi) / 2 + 1e-9) - inset
    return x0, y0, x1 - x0, y1 - y0


def warp_pullback(forward_index: np.ndarray) -> Matrix:
    """Pullback (corner coordinates) of ``cv2.warpAffine(src, forward_index)`` (2x3, pixel-index coordinates)."""
    m = np.vstack([forward_index, [0.0, 0.0, 1.0]])
    return translate(0.5, 0.5) @ np.linalg.inv(m) @ translate(-0.5, -0.5)


def tilt_pullback(width: int, height: int, degrees: float) -> Matrix:
    """Eq. 10 rotation, Eq. 11 crop, resized back to ``width x height``."""
    x0, y0, cw, ch = tilt_crop(width, height, degrees)
    return warp_pullback(rotation_matrix(width, height, degrees)) @ crop_resize_pullback(x0, y0, cw, ch, width, height)


def to_index_inverse_map(pullback: Matrix) -> np.ndarray:
    """2x3 matrix for ``cv2.warpAffine(..., flags=WARP_INVERSE_MAP)``: output index -> input index."""
    return (translate(-0.5, -0.5) @ pullback @ translate(0.5, 0.5))[:2]


def apply_points(matrix: Matrix, points: np.ndarray) -> np.ndarray:
    """Apply a 3x3 affine matrix to points (..., 2)."""
    return points @ matrix[:2, :2].T + matrix[:2, 2]


# ---- the same maps for a whole batch at once, (n, 3, 3): the training path avoids per-sample Python ----

def _stack(n: int) -> np.ndarray:
    return np.broadcast_to(np.eye(3), (n, 3, 3)).copy()


def pan_pullbacks(width: int, height: int, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
    """Batched ``pan_pullback``: X -> x0 - tx + X * crop_w / w (and likewise for y)."""
    m = _stack(len(tx))
    for axis, t, size in ((0, np.asarray(tx, float), width), (1, np.asarray(ty, float), height)):
        cut = np.ceil(np.abs(t) - 1e-9)
        m[:, axis, axis] = (size - cut) / size
        m[:, axis, 2] = np.where(t > 0, cut, 0.0) - t
    return m


def max_inscribed_rects(width: float, height: float, degrees: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched ``max_inscribed_rect`` (Eq. 11)."""
    a = np.radians(np.abs(np.asarray(degrees, float)))
    s, c = np.abs(np.sin(a)), np.abs(np.cos(a))
    long_side, short_side = (width, height) if width >= height else (height, width)
    with np.errstate(divide="ignore", invalid="ignore"):
        half = (short_side <= 2.0 * s * c * long_side) | (np.abs(s - c) < 1e-10)
        x = 0.5 * short_side
        half_w, half_h = (x / s, x / c) if width >= height else (x / c, x / s)
        cos_2a = c * c - s * s
        full_w, full_h = (width * c - height * s) / cos_2a, (height * c - width * s) / cos_2a
        w = np.where(s < 1e-12, float(width), np.where(half, half_w, full_w))
        h = np.where(s < 1e-12, float(height), np.where(half, half_h, full_h))
    return w, h


def tilt_pullbacks(width: int, height: int, degrees: np.ndarray) -> np.ndarray:
    """Batched ``tilt_pullback``: Eq. 10 rotation, Eq. 11 crop (inset as ``tilt_crop``), resize back."""
    deg = np.asarray(degrees, float)
    p = np.radians(deg)
    c, s = np.cos(p), np.sin(p)
    forward = _stack(len(deg))
    forward[:, 0, :] = np.stack([c, s, width / 2 * (1 - c) - height / 2 * s], axis=-1)
    forward[:, 1, :] = np.stack([-s, c, width / 2 * s + height / 2 * (1 - c)], axis=-1)
    rotate = translate(0.5, 0.5) @ np.linalg.inv(forward) @ translate(-0.5, -0.5)
    w_roi, h_roi = max_inscribed_rects(width, height, deg)
    inset = np.where(deg != 0, TILT_INSET_PX, 0)
    x0 = np.ceil((width - w_roi) / 2 - 1e-9) + inset
    y0 = np.ceil((height - h_roi) / 2 - 1e-9) + inset
    x1 = np.floor((width + w_roi) / 2 + 1e-9) - inset
    y1 = np.floor((height + h_roi) / 2 + 1e-9) - inset
    crop = _stack(len(deg))
    crop[:, 0, 0], crop[:, 0, 2] = (x1 - x0) / width, x0
    crop[:, 1, 1], crop[:, 1, 2] = (y1 - y0) / height, y0
    return rotate @ crop


def yaw_pullbacks(width: int, height: int, yaw_rad: np.ndarray, vfov_deg: float, pitch_deg: float) -> np.ndarray:
    """What a pitched pinhole camera sees when the car turns by ``yaw_rad`` (+ right) about the vertical.

    A pure rotation of the camera is an exact homography for everything in view, near or far (no depth
    needed): ``K R_pitch R_yaw R_pitch^T K^-1`` from a pixel of the turned view to the recorded frame,
    the same map as the closed loop's view synthesis above the horizon (``tools.drivelog.camera``); the pinhole
    and pitch maths are :mod:`protocol.camera`'s.
    Returned as pullbacks in corner coordinates, like every map here (``(n, 3, 3)``, projective).
    """
    k = intrinsics(width, height, vfov_deg)
    pitch = pitch_matrix(pitch_deg)
    a = np.asarray(yaw_rad, float)
    yaw = _stack(len(a))
    yaw[:, 0, 0], yaw[:, 0, 2], yaw[:, 2, 0], yaw[:, 2, 2] = np.cos(a), np.sin(a), -np.sin(a), np.cos(a)
    # index coordinates (pixel centres at integers) -> corner coordinates: +0.5
    rotate = k @ pitch @ yaw @ pitch.T @ np.linalg.inv(k)
    return translate(0.5, 0.5) @ rotate @ translate(-0.5, -0.5)


def offset_sources(width: int, height: int, xs: np.ndarray, ys: np.ndarray, lateral_m: np.ndarray, vfov_deg: float,
                   pitch_deg: float, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Where in the recorded frame (index coordinates) the pixels ``(xs, ys)`` (``(n,)`` or ``(k, n)``) of the view
    from the camera moved ``lateral_m[k]`` (+ right) sideways sample, ``(k, n)`` each.

    The closed loop's view synthesis (:func:`protocol.camera.view_homographies` and ``reproject``): the road
    through the exact ground-plane homography, the scenery above the horizon as recorded (far away: a sideways
    move does not shift it), the bonnet's rows kept (it travels with the camera). Not one homography: the
    sample's other maps are composed with it point by point (``models.augmentation.fastaug``).
    """
    homs = [view_homographies(width, height, float(x), 0.0, vfov_deg=vfov_deg, pitch_deg=pitch_deg, height_m=height_m)
            for x in np.atleast_1d(lateral_m)]
    ground = np.stack([g for g, _ in homs])
    far = np.stack([f for _, f in homs])
    xs, ys = np.asarray(xs, np.float64), np.asarray(ys, np.float64)
    if xs.ndim == 1:
        xs, ys = xs[None], ys[None]
    return reproject(xs, ys, ground, far, horizon_row(height, vfov_deg, pitch_deg), BONNET_ROW * height / FRAME_HEIGHT)
