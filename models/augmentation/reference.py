"""The literal reference of the paper's augmentations (section 3.1.4): one full-resolution RGB frame at a time,
each step a plain OpenCV call, so the fast batched path (:mod:`models.augmentation.fastaug`) has something exact
to be compared with on the very same draws (:func:`models.augmentation.augment.draw_params`)."""

from __future__ import annotations

import cv2
import numpy as np

from models.augmentation import geometry
from models.augmentation.augment import AugmentSpec, AugParams
from protocol.facts import CAMERAS


def shadows(rgb: np.ndarray, quads: np.ndarray, darkness: float) -> np.ndarray:
    """Darken the union of the quadrilaterals (full-res pixel vertices) by ``darkness``."""
    mask = np.zeros(rgb.shape[:2], np.uint8)
    for quad in quads:
        cv2.fillPoly(mask, [np.asarray(quad, np.int32).reshape(-1, 1, 2)], 1)
    out = rgb.astype(np.float32)
    out[mask.astype(bool)] *= darkness
    return np.rint(out).astype(np.uint8)


def brightness(rgb: np.ndarray, beta: float, mode: str = "add") -> np.ndarray:
    """Eq. 6: add ``beta`` to every pixel and clamp to 0..255; ``mode="scale"``: multiply by 1 + beta.

    Adding U(-100, 100) suits the bright simulator; on a dark frame (mean ~60) it blacks the frame
    out, while a gain keeps its content whatever its brightness.
    """
    x = rgb.astype(np.float32)
    x = x * np.float32(1.0 + beta) if mode == "scale" else x + np.float32(beta)
    return np.rint(np.clip(x, 0, 255)).astype(np.uint8)


def flip(rgb: np.ndarray, steering: float) -> tuple[np.ndarray, float]:
    """Eq. 7 and 8: mirror horizontally, negate the label."""
    return np.ascontiguousarray(rgb[:, ::-1]), -steering


def pan(rgb: np.ndarray, tx: float, ty: float) -> np.ndarray:
    """Eq. 9: shift by (tx, ty) pixels, crop the null area, resize back."""
    h, w = rgb.shape[:2]
    m = np.array([[1.0, 0.0, tx], [0.0, 1.0, ty]])
    shifted = cv2.warpAffine(rgb, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    x0, y0, cw, ch = geometry.pan_crop(w, h, tx, ty)
    return cv2.resize(shifted[y0:y0 + ch, x0:x0 + cw], (w, h), interpolation=cv2.INTER_LINEAR)


def tilt(rgb: np.ndarray, degrees: float) -> np.ndarray:
    """Eq. 10 and 11: rotate about the centre, crop the largest central rectangle, resize back."""
    h, w = rgb.shape[:2]
    rotated = cv2.warpAffine(rgb, geometry.rotation_matrix(w, h, degrees), (w, h), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT)
    x0, y0, cw, ch = geometry.tilt_crop(w, h, degrees)
    return cv2.resize(rotated[y0:y0 + ch, x0:x0 + cw], (w, h), interpolation=cv2.INTER_LINEAR)


def shift(rgb: np.ndarray, tx: float) -> np.ndarray:
    """Horizontal viewpoint shift (nvidia approach): translate, edge pixels repeated."""
    h, w = rgb.shape[:2]
    m = np.array([[1.0, 0.0, tx], [0.0, 1.0, 0.0]])
    return cv2.warpAffine(rgb, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def move(rgb: np.ndarray, lateral_m: float, spec: AugmentSpec) -> np.ndarray:
    """The view of the camera moved ``lateral_m`` to the right: the closed loop's ground-plane re-projection (exact
    on the road, the scenery above the horizon as recorded, the bonnet kept; edge pixels repeated, as ``turn``)."""
    h, w = rgb.shape[:2]
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    src_x, src_y = geometry.offset_sources(w, h, xs.ravel(), ys.ravel(), np.array([lateral_m]), spec.camera_vfov_deg,
                                           spec.camera_pitch_deg, spec.camera_height_m)
    return cv2.remap(rgb, src_x.reshape(h, w).astype(np.float32), src_y.reshape(h, w).astype(np.float32),
                     cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def turn(rgb: np.ndarray, degrees: float, spec: AugmentSpec) -> np.ndarray:
    """The view of the camera turned ``degrees`` to the right (pure rotation; edge pixels repeated)."""
    h, w = rgb.shape[:2]
    pull = geometry.yaw_pullbacks(w, h, np.radians([degrees]), spec.camera_vfov_deg, spec.camera_pitch_deg)[0]
    index = geometry.translate(-0.5, -0.5) @ pull @ geometry.translate(0.5, 0.5)
    return cv2.warpPerspective(rgb, index, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_REPLICATE)


def augment_reference(frames: dict[str, np.ndarray], params: AugParams, i: int,
                      spec: AugmentSpec) -> tuple[np.ndarray, float]:
    """Sample ``i`` of ``params`` applied literally, step by step, to full-resolution RGB frames.

    Slow and simple on purpose: the executable statement of the paper that the fast path is tested
    against. Returns the augmented full-resolution frame and the label.
    """
    img = frames[CAMERAS[int(params.camera[i])]]
    if params.shadow[i]:
        img = shadows(img, params.shadow_xy[i], spec.shadow_darkness)
    if params.brightness[i]:
        img = brightness(img, float(params.beta[i]), spec.brightness_mode)
    # moved first, then turned: the view of the camera moved, then turned (one homography)
    if params.moved[i] and params.offset_m is not None:
        img = move(img, float(params.offset_m[i]), spec)
    if params.turned[i] and params.yaw_deg is not None:
        img = turn(img, float(params.yaw_deg[i]), spec)
    if params.flip[i]:
        img, _ = flip(img, 0.0)
    if params.pan[i]:
        img = pan(img, float(params.pan_xy[i, 0]), float(params.pan_xy[i, 1]))
    if params.shift[i]:
        img = shift(img, float(params.shift_px[i]))
    if params.tilt[i]:
        img = tilt(img, float(params.tilt_deg[i]))
    return img, float(params.steering[i])


