"""An ONNX model from ``rbc train`` as a policy of ``rbc/Drive-v0``, through drive_server's own pipeline.

The model sees exactly what drive_server would feed it: the centre frame's JPEG (``info["jpeg"]``) decoded by
THE decode at the model's reduced scale, THE preprocessing of its contract, its output checked and clamped,
and the steering smoothing its metadata asks for, one smoother per episode as one per client.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from drive_server.serving.control import ControlLaw
from drive_server.serving.smoothing import SteeringSmoother
from protocol import SpeedUnit
from protocol.errors import BadValue
from protocol.jpeg import decode_jpeg
from tools.envs.config import CONTROLS
from tools.sim.driving.model_rig import model_rig

#: What the env observes: the centre camera's frame, or a dict of frames by camera (``cameras=...``).
Observation = np.ndarray | dict[str, np.ndarray]


class OnnxPolicy:
    """``policy(obs, info) -> action`` for an environment made with the same ``control`` (and, for
    ``steer_throttle``, the same ``law``, Eq. 14; None: the default) and ``camera=policy.camera_rig``. Without
    ``info["jpeg"]`` (``jpeg=False``) the model reads the full-size frame, resized by its contract: within a few
    grey levels of what drive_server would feed it."""

    def __init__(self, path: str | Path, control: str = "steer", smoothing: float | None = None, threads: int = 1,
                 law: ControlLaw | None = None, gain: float | None = None) -> None:
        if control not in CONTROLS:
            raise BadValue(f"control must be one of {', '.join(CONTROLS)}, got {control!r}")
        # here, not at the top: importing rbc/Drive-v0 does not load onnxruntime (about 20 MB in every process)
        from drive_server.serving.model import InferenceConfig, SteeringModel
        from drive_server.serving.pipeline import DriveConfig, DrivePipeline

        model = SteeringModel(Path(path), InferenceConfig(threads=threads))
        model.warm_up()
        self.control = control
        self.pipeline = DrivePipeline(model, DriveConfig(law=law or ControlLaw(), speed_unit=SpeedUnit.KMH,
                                                         smoothing=smoothing, gain=gain))
        self.smoother: SteeringSmoother | None = self.pipeline.smoother()
        #: the camera rig the model learnt (its record; ``rbc sim --model`` shows it the same): make the env with it
        self.camera_rig = model_rig(path)

    def reset(self) -> None:
        """Forget the smoothing state (a new client); done by itself when ``info["step"]`` is 0."""
        self.smoother = self.pipeline.smoother()

    def steering(self, obs: Observation, info: dict[str, Any] | None = None) -> float:
        """The model's smoothed steering (-1..1) for one observation."""
        info = info or {}
        if info.get("step") == 0:
            self.reset()
        data = info.get("jpeg")
        if data:
            rgb = decode_jpeg(data, self.pipeline.reduce)
        else:
            rgb = obs["center"] if isinstance(obs, dict) else np.asarray(obs)
        return self.pipeline.steer(rgb, self.smoother)

    def __call__(self, obs: Observation, info: dict[str, Any] | None = None) -> np.ndarray:
        steering = self.steering(obs, info)
        if self.control == "steer":
            return np.array([steering], np.float32)
        if not info or "speed_kmh" not in info:
            raise BadValue("control='steer_throttle' needs the step's info (its speed_kmh) for Eq. 14's throttle")
        throttle = self.pipeline.control(steering, info["speed_kmh"]).throttle
        return np.array([steering, throttle], np.float32)
