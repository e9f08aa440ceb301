"""The paper's six augmentations (section 3.1.4): label rules, random draws, and a literal reference.

Order (footnote 4: it matters): perspective shift, shadows, brightness, flip, pan, tilt, each applied
with its own probability (Table 5). The random parameters of a whole batch are drawn at once
(``draw_params``) so the literal full-resolution reference (``models.augmentation.reference``) and the fast
batched path (``models.augmentation.fastaug``) can be fed the very same draws and compared. ``shift`` is not in the
paper: it is the horizontal viewpoint shift of the "nvidia" approach (off for the paper's behaviors). Two more are
not in the paper: the car turned (``yaw``) and the car moved sideways (``offset``: DAVE-2's "shifts", the ground-plane
re-projection of the closed loop's view synthesis, :func:`protocol.camera.view_homographies`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from protocol.camera import HEIGHT_M, PITCH_DEG, SIDE_OFFSET_M, VFOV_DEG
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH, MAX_STEERING_DEG

CENTER, LEFT, RIGHT = 0, 1, 2
#: Metres ahead at which a label aims back at the driver's line: Eq. 4/5's recovery distance (gamma = 0.95 m / 10 m)
#: and the moved camera's lookahead.
LOOKAHEAD_M = 10.0


@dataclass(frozen=True)
class AugmentSpec:
    """Probabilities (Table 5) and ranges of the augmentations. Defaults: simplistic driving. A field named like
    a training recipe's key is that key (``TrainConfig.pipeline`` sets it by name) and its default is the key's."""

    perspective: float = 0.5  # left and right half each
    shadow: float = 0.3
    brightness: float = 0.4
    flip: float = 0.5  # centre frames only
    pan: float = 0.1
    tilt: float = 0.05
    shift: float = 0.0  # not in the paper (nvidia approach)
    gamma: float = SIDE_OFFSET_M / LOOKAHEAD_M  # inter-camera distance / recovery distance (Eq. 4/5)
    shadow_count: int = 4
    shadow_darkness: float = 0.65
    shadow_x: tuple[int, int] = (0, FRAME_WIDTH)
    shadow_y: tuple[int, int] = (FRAME_HEIGHT // 2, FRAME_HEIGHT)
    brightness_range: float = 100.0  # "add": grey levels; "scale": fraction of the frame's own values
    brightness_mode: str = "add"  # "add": Eq. 6, p + beta (the paper); "scale": p * (1 + beta), for dark frames
    pan_range: float = 0.05  # fraction of width/height
    tilt_range_deg: float = 1.0
    shift_range_px: float = 0.0  # full-resolution pixels
    shift_steering_per_px: float = 0.0
    # not in the paper: the car turned by psi ~ U(-range, range) degrees, what its camera would then see (an
    # exact homography for a pitched pinhole; camera of the real simulator) and a label that turns back:
    # theta - gain * psi. The closed loop on real frames needs the heading feedback this teaches (README)
    yaw_aug: float = 0.0
    yaw_range: float = 6.0  # degrees
    yaw_gain: float = 1.0
    # not in the paper: the car moved x ~ U(-range, range) metres to the side (+ right; DAVE-2's "shifts"), what
    # its camera would then see (the closed loop's ground-plane re-projection, protocol.camera.view_homographies:
    # exact on the road, the scenery above the horizon left as it is, the bonnet kept) and a label aiming back at
    # the driver's line offset_lookahead ahead: atan(tan(theta) - x / lookahead), the side cameras' Eq. 4/5 at
    # x = +-0.95 m. Centre-camera samples only (a side frame already is a moved one)
    offset_aug: float = 0.0
    offset_range: float = 2.0  # metres
    offset_lookahead: float = LOOKAHEAD_M  # metres
    # not in the paper: a pull towards the road's middle where a camera stands more than edge_margin off it,
    # edge_gain steering per metre beyond the margin, each camera at its own offset (the side cameras
    # side_camera_m to each side); drivers each hold a line of their own within about +-2 m of the middle,
    # so the pull leaves their steering alone and acts where the car nears an edge (0: off)
    edge_gain: float = 0.0
    edge_margin: float = 1.5  # metres
    side_camera_m: float = SIDE_OFFSET_M
    camera_vfov_deg: float = VFOV_DEG  # the real simulator's camera (protocol.camera)
    camera_pitch_deg: float = PITCH_DEG
    camera_height_m: float = HEIGHT_M

    @property
    def uses_side_cameras(self) -> bool:
        return self.perspective > 0.0


@dataclass
class AugParams:
    """Per-sample draws for a batch; ``steering`` is the corrected label."""

    camera: np.ndarray  # int8: CENTER / LEFT / RIGHT
    steering: np.ndarray  # float32, after perspective/flip/shift corrections
    shadow: np.ndarray  # bool
    shadow_xy: np.ndarray  # int32 (n, count, 4, 2): quadrilateral vertices, full-res pixels
    brightness: np.ndarray  # bool
    beta: np.ndarray  # float32
    flip: np.ndarray  # bool (already restricted to centre frames)
    pan: np.ndarray  # bool
    pan_xy: np.ndarray  # float64 (n, 2): shift in full-res pixels
    tilt: np.ndarray  # bool
    tilt_deg: np.ndarray  # float64
    shift: np.ndarray  # bool
    shift_px: np.ndarray  # float64
    yaw: np.ndarray | None = None  # bool; None: no sample turned (a spec without the yaw augmentation)
    yaw_deg: np.ndarray | None = None  # float64, + turned right
    offset: np.ndarray | None = None  # bool; None: no sample moved (a spec without the offset augmentation)
    offset_m: np.ndarray | None = None  # float64, + moved right

    def __len__(self) -> int:
        return len(self.camera)

    @property
    def geometric(self) -> np.ndarray:
        """Samples that need a warp beyond a mirror."""
        return self.pan | self.tilt | self.shift | self.turned | self.moved

    @property
    def turned(self) -> np.ndarray:
        """Samples seen from a turned camera (a projective warp)."""
        return np.zeros(len(self.camera), bool) if self.yaw is None else self.yaw

    @property
    def moved(self) -> np.ndarray:
        """Samples seen from a camera moved sideways (a piecewise projective warp: road and scenery apart)."""
        return np.zeros(len(self.camera), bool) if self.offset is None else self.offset


def correction_angles(theta_rad: np.ndarray | float, gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4 and 5: correction angles (delta for the left camera, phi for the right), radians."""
    t = np.tan(theta_rad)
    delta = np.arctan(gamma / (1.0 + t * t + gamma * t))
    phi = np.arctan(gamma / (1.0 + t * t - gamma * t))
    return delta, phi


def perspective_label(steering: np.ndarray | float, camera: np.ndarray | int, gamma: float) -> np.ndarray:
    """Steering label of a side frame used as the centre frame (normalised, clamped to -1..1).

    The left camera sees the road as if the car had drifted left, so the label steers right
    (positive, as in the simulator): theta + delta (Eq. 4); the right camera: theta - phi (Eq. 5).
    Both equal atan(tan(theta) +- gamma): aiming at the same point ``d`` metres ahead from ``x``
    metres to the side.
    """
    s = np.asarray(steering, dtype=np.float64)
    cam = np.asarray(camera)
    theta = np.radians(s * MAX_STEERING_DEG)
    delta, phi = correction_angles(theta, gamma)
    out = np.where(cam == LEFT, theta + delta, np.where(cam == RIGHT, theta - phi, theta))
    return np.clip(np.degrees(out) / MAX_STEERING_DEG, -1.0, 1.0)


def offset_label(steering: np.ndarray | float, offset_m: np.ndarray | float, lookahead_m: float) -> np.ndarray:
    """Steering label of the centre camera moved ``offset_m`` to the side (+ right; normalised, clamped to -1..1).

    It aims back at the point of the driver's line ``lookahead_m`` ahead: atan(tan(theta) - x / lookahead), so a
    camera moved right steers left; at x = +-0.95 m and 10 m it is the side cameras' Eq. 4/5 (``perspective_label``).
    """
    theta = np.radians(np.asarray(steering, dtype=np.float64) * MAX_STEERING_DEG)
    out = np.arctan(np.tan(theta) - np.asarray(offset_m, np.float64) / lookahead_m)
    return np.clip(np.degrees(out) / MAX_STEERING_DEG, -1.0, 1.0)


def edge_pull(middles: np.ndarray, camera: np.ndarray, spec: AugmentSpec,
              offset_m: np.ndarray | None = None) -> np.ndarray:
    """Steering towards the road's middle for cameras beyond ``spec.edge_margin`` from it (+ right).

    ``middles`` is where the middle lies from the centre camera (m, + right; NaN: unknown, no pull); from
    the left camera it lies ``side_camera_m`` further right, from the right one as much further left, from a
    camera moved ``offset_m`` to the right (the offset augmentation; None: none) that much further left.
    """
    side = np.where(camera == LEFT, spec.side_camera_m, np.where(camera == RIGHT, -spec.side_camera_m, 0.0))
    middle = np.asarray(middles, np.float64) + side
    if offset_m is not None:
        middle = middle - offset_m
    pull = spec.edge_gain * np.sign(middle) * np.maximum(0.0, np.abs(middle) - spec.edge_margin)
    return np.nan_to_num(pull, nan=0.0)  # NaN: a recording without a road file


def draw_params(steering: np.ndarray, has_sides: np.ndarray, spec: AugmentSpec, rng: np.random.Generator,
                middles: np.ndarray | None = None) -> AugParams:
    """Draw every augmentation decision of a batch (Table 5 probabilities), in the paper's order.

    All arrays are drawn whether used or not, so a batch consumes the generator identically; the turn and the
    move (not in the paper) are drawn last and only when used, so runs without them draw as before. ``middles``
    (m, + right, per sample: the road's middle from the centre camera) feeds the edge pull.
    """
    n = len(steering)
    steering = np.asarray(steering, dtype=np.float64)
    u = rng.random(n)
    sides = np.asarray(has_sides, dtype=bool)
    camera = np.where(sides & (u < spec.perspective / 2), LEFT,
                      np.where(sides & (u < spec.perspective), RIGHT, CENTER)).astype(np.int8)

    shadow = rng.random(n) < spec.shadow
    xs = rng.integers(spec.shadow_x[0], spec.shadow_x[1], size=(n, spec.shadow_count, 4), endpoint=True)
    ys = rng.integers(spec.shadow_y[0], spec.shadow_y[1], size=(n, spec.shadow_count, 4), endpoint=True)
    shadow_xy = np.stack([xs, ys], axis=-1).astype(np.int32)

    brightness = rng.random(n) < spec.brightness
    beta = np.where(brightness, rng.uniform(-spec.brightness_range, spec.brightness_range, n), 0.0)

    flip = (rng.random(n) < spec.flip) & (camera == CENTER)

    pan = rng.random(n) < spec.pan
    pan_xy = rng.uniform(-spec.pan_range, spec.pan_range, (n, 2)) * np.array([FRAME_WIDTH, FRAME_HEIGHT])

    tilt = rng.random(n) < spec.tilt
    tilt_deg = rng.uniform(-spec.tilt_range_deg, spec.tilt_range_deg, n)

    shift = rng.random(n) < spec.shift
    shift_px = rng.uniform(-spec.shift_range_px, spec.shift_range_px, n)

    yaw = yaw_deg = offset = offset_m = None
    if spec.yaw_aug > 0:  # drawn last and only when used, so runs without it consume the generator as before
        yaw = rng.random(n) < spec.yaw_aug
        yaw_deg = np.where(yaw, rng.uniform(-spec.yaw_range, spec.yaw_range, n), 0.0)
    if spec.offset_aug > 0:  # likewise, after the turn; centre-camera samples only (a side frame is a moved one)
        offset = (rng.random(n) < spec.offset_aug) & (camera == CENTER)
        offset_m = np.where(offset, rng.uniform(-spec.offset_range, spec.offset_range, n), 0.0)

    # the labels, in the order the views are made: camera (moved), edge pull, flip, shift, turn
    label = perspective_label(steering, camera, spec.gamma)
    if offset is not None and offset_m is not None:  # drawn together
        label = np.where(offset, offset_label(label, offset_m, spec.offset_lookahead), label)
    if spec.edge_gain > 0 and middles is not None:  # before the flip, which mirrors the road too
        label = np.clip(label + edge_pull(middles, camera, spec, offset_m), -1.0, 1.0)
    label = np.where(flip, -label, label) + 0.0  # no -0.0 labels
    label = np.clip(np.where(shift, label + shift_px * spec.shift_steering_per_px, label), -1.0, 1.0)
    if yaw is not None and yaw_deg is not None:  # drawn together
        back = -spec.yaw_gain * yaw_deg / MAX_STEERING_DEG  # the turn is drawn before the flip mirrors it
        label = np.clip(label + np.where(flip, -back, back), -1.0, 1.0) + 0.0

    return AugParams(camera=camera, steering=label.astype(np.float32), shadow=shadow, shadow_xy=shadow_xy,
                     brightness=brightness, beta=beta.astype(np.float32), flip=flip, pan=pan,
                     pan_xy=np.where(pan[:, None], pan_xy, 0.0), tilt=tilt, tilt_deg=np.where(tilt, tilt_deg, 0.0),
                     shift=shift, shift_px=np.where(shift, shift_px, 0.0), yaw=yaw, yaw_deg=yaw_deg, offset=offset,
                     offset_m=offset_m)


def no_augmentation(n: int, steering: np.ndarray) -> AugParams:
    """Parameters that leave frames untouched (validation, previews of the raw data)."""
    z = np.zeros(n, dtype=bool)
    return AugParams(camera=np.zeros(n, np.int8), steering=np.asarray(steering, np.float32), shadow=z,
                     shadow_xy=np.zeros((n, 0, 4, 2), np.int32), brightness=z, beta=np.zeros(n, np.float32),
                     flip=z, pan=z, pan_xy=np.zeros((n, 2)), tilt=z, tilt_deg=np.zeros(n), shift=z,
                     shift_px=np.zeros(n))
