"""How much the recorded car turned, read off its own frames: the effective wheelbase of the path model.

Between two consecutive frames the far scenery (above the horizon) shifts sideways by about
``f * dpsi`` pixels when the car turns by ``dpsi``; phase correlation of that band measures it. Against
the kinematic prediction ``v dt tan(delta) / L`` the fit gives the wheelbase ``L`` the recorded car
behaves as if it had. Unity's car understeers, more at speed: measured on public recordings, 2.8 m for
a mouse driver at moderate speed up to 5.1 m for keyboard drivers at full speed, where the geometric
wheelbase would be about 2.6 m. The same frames show when the steering acts: the image turn follows the
recorded steering with no lag (the correlation peaks at a shift of 0 frames), so the recorded value is
the wheel angle of that frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from protocol.errors import BadValue
from protocol.jpeg import read_jpeg_file
from tools.drivelog.camera import DEFAULT_CAMERA, UnityCamera
from tools.drivelog.path import RecordedDrive, curvature

#: Pairs with a weaker phase-correlation peak than this are not trusted (blur, a pause, a new session).
MIN_RESPONSE = 0.2
#: Below this speed (m/s) the car barely turns: the pair says nothing about the wheelbase.
MIN_SPEED_MPS = 3.0
#: Wheelbases outside this range mean the fit failed (too few curves, frames that do not match).
PLAUSIBLE_M = (1.5, 12.0)


@dataclass(frozen=True)
class WheelbaseFit:
    wheelbase_m: float
    pairs: int
    r: float  # correlation of the image turn with the kinematic prediction


def _band(rgb: np.ndarray, camera: UnityCamera) -> np.ndarray:
    top, bottom = 4, max(12, int(camera.horizon_row) - 4)
    return cv2.cvtColor(rgb[top:bottom], cv2.COLOR_RGB2GRAY).astype(np.float64)


def image_yaw(drive: RecordedDrive, camera: UnityCamera = DEFAULT_CAMERA, max_pairs: int = 1500
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frame index, turn in radians to the next frame, peak response) for up to ``max_pairs`` pairs spread
    over the drive (consecutive frames of one session)."""
    candidates = np.flatnonzero((drive.dt > 0) & (drive.speed >= MIN_SPEED_MPS))
    if len(candidates) > max_pairs:
        candidates = candidates[np.linspace(0, len(candidates) - 1, max_pairs).astype(int)]
    yaw, response = np.zeros(len(candidates)), np.zeros(len(candidates))
    window = None
    for k, i in enumerate(candidates):
        a, b = (_band(read_jpeg_file(drive.frames[j]), camera) for j in (i, i + 1))
        if window is None:
            window = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_64F)
        (dx, _), response[k] = cv2.phaseCorrelate(a, b, window)
        yaw[k] = -math.atan(dx / camera.focal_px)  # the scenery moves left when the car turns right
    return candidates, yaw, response


def fit_wheelbase(drive: RecordedDrive, camera: UnityCamera = DEFAULT_CAMERA, max_pairs: int = 1500) -> WheelbaseFit:
    """Least-squares ``L`` in ``image turn = v dt tan(delta) / L`` over the trusted pairs."""
    idx, yaw, response = image_yaw(drive, camera, max_pairs)
    ok = response >= MIN_RESPONSE
    predicted = (drive.speed * drive.dt * curvature(drive.steering, 1.0))[idx][ok]
    measured = yaw[ok]
    if len(measured) < 20 or not np.any(predicted) or float(predicted @ measured) <= 0:
        raise BadValue(f"only {len(measured)} usable frame pairs with turning: cannot fit the wheelbase")
    wheelbase = float(predicted @ predicted / (predicted @ measured))
    if not PLAUSIBLE_M[0] <= wheelbase <= PLAUSIBLE_M[1]:
        raise BadValue(f"fitted wheelbase {wheelbase:.1f} m is implausible: the frames do not follow the steering")
    r = float(np.corrcoef(predicted, measured)[0, 1])
    return WheelbaseFit(wheelbase, int(len(measured)), r)


def wheelbase_or_default(drive: RecordedDrive) -> tuple[float, WheelbaseFit | None]:
    """The fitted effective wheelbase, or the default car's (with a warning) where the frames cannot say."""
    import logging

    from tools.drivelog.path import WHEELBASE_M

    try:
        fit = fit_wheelbase(drive)
    except ValueError as exc:
        logging.getLogger("rbc").warning("%s; using %.1f m", exc, WHEELBASE_M)
        return WHEELBASE_M, None
    return fit.wheelbase_m, fit
