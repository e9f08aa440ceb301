"""The fast, batched augmentation path used for training: same draws, same semantics, network resolution.

Frames come from the ``FrameCache`` (decoded once, already at the network's size), so augmenting a
sample never touches a 320x160 image. Why that is equivalent to the literal full-resolution chain
(``reference.augment_reference`` followed by the network resize), and where it is only approximately so:

* Perspective shift picks another cached camera frame: exact.
* Flip, pan, tilt (and the nvidia shift) are affine maps. "Transform, crop the null area, resize back"
  and the final resize to the network size compose into ONE affine map (``models.augmentation.geometry``), applied
  to the cached frame with a single ``cv2.warpAffine``; the matrices of a batch are built at once. A
  flip alone is an exact mirror of the cached frame (the area resize is symmetric). What differs is
  interpolation only: the reference interpolates at full resolution and then box-filters, the warp
  interpolates the box-filtered frame, slightly softer (on the 15 % of samples that pan or tilt:
  ~4/255 mean absolute difference on real frames, against 10-14/255 for not transforming at all).
* The camera moved sideways (``offset``, not in the paper) is no single homography: the road moves through the
  ground plane's, the scenery above the horizon stays (``geometry.offset_sources``). Its samples are warped with
  ``cv2.remap`` through a per-pixel map (the sample's turn, flip, pan, shift and tilt composed point by point with
  it), and their shadows are drawn before the warp, on the cached frame, as the reference does.
* Shadows are applied after the warp: darkening commutes with moving pixels, so their quadrilaterals
  are mapped through the same affine map and drawn anti-aliased at network resolution (the coverage
  stands in for the box filter's partial darkening along their edges), as ``p - round(p * 0.35 * cover)``
  in saturating uint8 arithmetic.
* Brightness (Eq. 6) is a pointwise add-and-clamp, done with a per-image lookup table; after the
  resize it differs only where a resize window mixes clamped and unclamped pixels.

``tests/test_augment.py`` checks the agreement on real frames. Colour: the cache holds frames in the
contract's colour; for YUV, darkening scales Y and the chroma offsets, and brightness adds to Y only
(exactly what adding to R, G and B does before clamping).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Protocol

import cv2
import numpy as np

from drive_server.serving.contract import PreprocessContract
from drive_server.serving.preprocess import to_input_tensor
from models.augmentation import geometry
from models.augmentation.augment import CENTER, LEFT, RIGHT, AugmentSpec, AugParams, draw_params
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

_SUBPIXEL_BITS = 4


class CachedFrames(Protocol):
    """What the augmenter reads of a frame cache (:class:`models.data.framecache.FrameCache`): said here, not
    imported, because the data's batches use this augmenter (the data sits above the augmentation)."""

    frames: np.ndarray  # (cameras, n, height, width, 3) uint8, the contract's colour
    cameras: tuple[str, ...]
    contract: PreprocessContract


class FastAugmenter:
    """Applies ``AugParams`` to cached network-size frames, a batch at a time."""

    def __init__(self, cache: CachedFrames, spec: AugmentSpec) -> None:
        self.cache = cache
        self.spec = spec
        c = cache.contract
        self.contract = c
        self.size = (c.width, c.height)
        # network corner coordinates -> full-resolution corner coordinates
        crop_h = c.crop_bottom - c.crop_top
        self._to_full = geometry.translate(0.0, c.crop_top) @ geometry.scale(FRAME_WIDTH / c.width, crop_h / c.height)
        self._from_full = np.linalg.inv(self._to_full)
        slot = {name: i for i, name in enumerate(cache.cameras)}
        self._slot = np.full(3, -1, np.int64)
        for cam, name in ((CENTER, "center"), (LEFT, "left"), (RIGHT, "right")):
            self._slot[cam] = slot.get(name, -1)
        self._yuv = c.color == "yuv"
        self.interpolation = cv2.INTER_LINEAR
        #: seconds per stage, accumulated when set to a dict (``rbc train-bench`` reads it)
        self.timings: dict[str, float] | None = None

    def lap(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        if self.timings is not None:
            self.timings[stage] = self.timings.get(stage, 0.0) + now - since
        return now

    def chain(self, params: AugParams, which: np.ndarray) -> np.ndarray:
        """Pullbacks (k, 3, 3), full-res corner coordinates, of turn, flip, pan, shift and tilt, in that order."""
        n = len(which)
        flip = np.where(params.flip[which, None, None], geometry.flip_pullback(FRAME_WIDTH), np.eye(3))
        pan = geometry.pan_pullbacks(FRAME_WIDTH, FRAME_HEIGHT, params.pan_xy[which, 0], params.pan_xy[which, 1])
        shift = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        shift[:, 0, 2] = -params.shift_px[which]
        tilt = geometry.tilt_pullbacks(FRAME_WIDTH, FRAME_HEIGHT, params.tilt_deg[which])
        if params.yaw_deg is None:
            return flip @ pan @ shift @ tilt
        turn = geometry.yaw_pullbacks(FRAME_WIDTH, FRAME_HEIGHT, np.radians(params.yaw_deg[which]),
                                      self.spec.camera_vfov_deg, self.spec.camera_pitch_deg)
        return turn @ flip @ pan @ shift @ tilt

    def images(self, idx: np.ndarray, params: AugParams) -> np.ndarray:
        """Augmented uint8 network images (n, h, w, 3) in the contract's colour."""
        t = time.perf_counter()
        slots = self._slot[params.camera]
        if (slots < 0).any():
            raise ValueError("augmentation asked for a camera that is not in the frame cache")
        frames = self.cache.frames
        out = frames[slots, idx]
        geometric = params.geometric
        for i in np.flatnonzero(params.flip & ~geometric):
            out[i] = cv2.flip(out[i], 1)
        t = self.lap("gather+mirror", t)
        shadowed = np.flatnonzero(params.shadow)
        # output network corner coordinates -> source full-resolution corner coordinates, per shadowed sample
        to_full = np.where(params.flip[shadowed, None, None], geometry.flip_pullback(FRAME_WIDTH) @ self._to_full,
                           self._to_full)
        warped = np.flatnonzero(geometric)
        moved = params.moved
        if moved.any():  # their shadows are drawn before their warp (below), not after
            shadowed, to_full = shadowed[~moved[shadowed]], to_full[~moved[shadowed]]
        if len(warped):
            pulls = self.chain(params, warped) @ self._to_full
            maps = geometry.translate(-0.5, -0.5) @ self._from_full @ pulls @ geometry.translate(0.5, 0.5)
            turned = params.turned
            if moved.any():
                self._moved(out, idx, params, warped, pulls)
            for k, i in enumerate(warped):
                if moved[i]:
                    continue
                warp = cv2.warpPerspective if turned[i] else cv2.warpAffine
                out[i] = warp(frames[slots[i], idx[i]], maps[k] if turned[i] else maps[k, :2], self.size,
                              flags=self.interpolation | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
            both = np.isin(shadowed, warped)
            to_full[both] = pulls[np.searchsorted(warped, shadowed[both])]
        t = self.lap("pan/tilt warps", t)
        if len(shadowed):
            self._shadows(out, shadowed, params.shadow_xy[shadowed], np.linalg.inv(to_full),
                          params.turned[shadowed])
        t = self.lap("shadows", t)
        self._brightness(out, params)
        self.lap("brightness", t)
        return out

    def _moved(self, out: np.ndarray, idx: np.ndarray, params: AugParams, warped: np.ndarray,
               pulls: np.ndarray) -> None:
        """Warp the samples seen from a moved camera: shadows drawn on the cached frame, then one ``cv2.remap``
        through the per-pixel map (``pulls``: the chain's, network corner -> full-res corner, per warped sample)."""
        offset_m = params.offset_m
        if offset_m is None:  # a spec without the offset augmentation: no sample moved
            return
        which = np.flatnonzero(params.moved)
        slots = self._slot[params.camera[which]]
        src = self.cache.frames[slots, idx[which]]  # a copy
        dark = np.flatnonzero(params.shadow[which])
        if len(dark):
            forward = np.broadcast_to(self._from_full, (len(dark), 3, 3))
            self._shadows(src, dark, params.shadow_xy[which[dark]], forward, np.zeros(len(dark), bool))
        w, h = self.size
        gx, gy = np.meshgrid(np.arange(w, dtype=np.float64) + 0.5, np.arange(h, dtype=np.float64) + 0.5)
        grid = np.stack([gx.ravel(), gy.ravel(), np.ones(w * h)])
        q = pulls[np.searchsorted(warped, which)] @ grid  # full-res corner coordinates of the moved view
        sx, sy = geometry.offset_sources(FRAME_WIDTH, FRAME_HEIGHT, q[:, 0] / q[:, 2] - 0.5, q[:, 1] / q[:, 2] - 0.5,
                                         offset_m[which], self.spec.camera_vfov_deg,
                                         self.spec.camera_pitch_deg, self.spec.camera_height_m)
        f = self._from_full  # affine: full-res corner -> network corner, then network index
        nx = (f[0, 0] * (sx + 0.5) + f[0, 2] - 0.5).astype(np.float32).reshape(-1, h, w)
        ny = (f[1, 1] * (sy + 0.5) + f[1, 2] - 0.5).astype(np.float32).reshape(-1, h, w)
        for k, i in enumerate(which):
            out[i] = cv2.remap(src[k], nx[k], ny[k], self.interpolation, borderMode=cv2.BORDER_REPLICATE)

    def _shadows(self, out: np.ndarray, which: np.ndarray, quads: np.ndarray, forward: np.ndarray,
                 projective: np.ndarray) -> None:
        """Darken the quadrilaterals, mapped to output coordinates and drawn anti-aliased (partial coverage).

        ``projective``: samples whose map is a homography (a turned camera), the others' maps are affine."""
        # vertices are pixel indices at full resolution: their centres are at +0.5 in corner coordinates
        pts = np.einsum("kij,kqvj->kqvi", forward[:, :2, :2], quads + 0.5) + forward[:, None, None, :2, 2] - 0.5
        if projective.any():  # a straight edge stays straight under a homography: mapping the vertices is exact
            homog = np.einsum("kij,kqvj->kqvi", forward[projective], np.concatenate(
                [quads[projective] + 0.5, np.ones(quads[projective].shape[:-1] + (1,))], axis=-1))
            pts[projective] = homog[..., :2] / homog[..., 2:] - 0.5
        fixed = np.rint(pts * (1 << _SUBPIXEL_BITS)).astype(np.int32)
        strength = 1.0 - self.spec.shadow_darkness
        mask = np.empty((self.contract.height, self.contract.width, 3), np.uint8)
        for k, i in enumerate(which):
            mask.fill(0)
            for quad in fixed[k]:
                cv2.fillPoly(mask, [quad.reshape(-1, 1, 2)], (255, 255, 255), lineType=cv2.LINE_AA,
                             shift=_SUBPIXEL_BITS)
            if self._yuv:  # darken luma and chroma offsets around 128
                x = out[i].astype(np.float32)
                f = 1.0 - strength / 255.0 * mask.astype(np.float32)
                x[..., 1:] -= 128.0
                x *= f
                x[..., 1:] += 128.0
                out[i] = np.rint(np.clip(x, 0, 255)).astype(np.uint8)
            else:  # img - round(img * 0.35 * coverage), saturating uint8 arithmetic
                out[i] = cv2.subtract(out[i], cv2.multiply(out[i], mask, scale=strength / 255.0))

    def _brightness(self, out: np.ndarray, params: AugParams) -> None:
        """Eq. 6 as a per-image lookup table: clamp(p + round(beta)), or clamp(p * (1 + beta)) (luma only for YUV)."""
        which = np.flatnonzero(params.brightness)
        if not len(which):
            return
        ramp = np.arange(256, dtype=np.int32)
        betas = np.rint(params.beta[which]).astype(np.int32)
        if self.spec.brightness_mode == "scale":
            luts = np.clip(np.rint(ramp[None, :] * (1.0 + params.beta[which, None].astype(np.float64))), 0, 255)
            luts = luts.astype(np.uint8)
        else:
            luts = np.clip(ramp[None, :] + betas[:, None], 0, 255).astype(np.uint8)
        for k, i in enumerate(which):
            lut = luts[k]
            if self._yuv:
                lut = np.stack([lut, ramp.astype(np.uint8), ramp.astype(np.uint8)], axis=-1)[None]
            out[i] = cv2.LUT(out[i], lut)


def training_contract(contract: PreprocessContract) -> PreprocessContract:
    """The same pixel contract in NCHW: the networks convolve NCHW fastest on CPU and take it directly
    in training, while the exported model keeps the contract's layout (it permutes internally)."""
    return replace(contract, layout="nchw")


def augment_batch(augmenter: FastAugmenter, idx: np.ndarray, steering: np.ndarray, has_sides: np.ndarray,
                  rng: np.random.Generator, middles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One training batch: draw, augment, preprocess. Returns (x float32 NCHW, y float32 (n, 1)).

    ``idx`` are frame-cache positions; ``steering``, ``has_sides`` and ``middles`` (the road's middle,
    for the edge pull; None: none) belong to those samples.
    """
    t = time.perf_counter()
    params = draw_params(steering, has_sides, augmenter.spec, rng, middles)
    t = augmenter.lap("draw", t)
    images = augmenter.images(idx, params)
    t = time.perf_counter()
    # transpose the uint8 batch (4x less memory than float) and hand the shared preprocessing an NHWC
    # view of it: its float result is then already NCHW-contiguous
    planar = np.ascontiguousarray(images.transpose(0, 3, 1, 2)).transpose(0, 2, 3, 1)
    x = to_input_tensor(planar, training_contract(augmenter.contract))
    augmenter.lap("to float NCHW", t)
    return x, params.steering.reshape(-1, 1)
