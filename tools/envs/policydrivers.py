"""Every policy as a driver of the simulator's own runs, so that every policy is scored as ``rbc eval`` scores a model.

A policy here is an ONNX steering model (behavioral cloning, DAgger: ``rbc eval``'s own in-process driver,
:class:`tools.sim.driving.drivers.OnnxDriver`, unchanged), a Stable-Baselines3 policy trained on
``rbc/Drive-v0`` (PPO's ``model.zip``: :class:`SB3Driver`) or the environment's expert (:class:`ExpertDriver`).
:func:`tools.dagger.rlcompare.run_policy_task` drives one of ``rbc eval``'s tasks (a world or a track, one lap,
seed 0) with it and returns the same run record, so the referee (take-over, the car put back,
driving goes on), the scenario and the degree of autonomy are the simulator's own for all of them.

Why drivers of the referee's runs rather than episodes of ``rbc/Drive-v0`` with ``terminate_on_takeover=False``:
an ONNX model scored through the environment would not give ``rbc eval``'s figure. The environment applies an
action in the step it was asked for (``action_delay=0``), where ``rbc eval`` keeps two frames in flight as Unity
does; it never starts a run at seed 0 (the nominal spawn), and it draws its own run seed. Driving the SB3 policy
as one more driver of :func:`tools.sim.driving.session.run_scenario` keeps the BC and DAgger rows ``rbc eval``'s
runs to the last digit and puts the PPO row on the same runs: :class:`SB3Driver` rebuilds the observation the
policy learnt from the frame on the wire (``observation="model"``: the JPEG decoded and cropped by the
environment's contract; ``speed=True``: the telemetry's speed in km/h) and turns its mean action into a command
as the environment does (:func:`tools.envs.config.steer_command`). What it costs: the SB3 policy drives with the
one-step command delay every model has in ``rbc eval``; a policy trained with ``action_delay=0`` (the PPO
recipe's default) meets that delay first here.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from protocol import SteerCommand, parse_number, to_kmh
from protocol.errors import BadValue
from protocol.jpeg import decode_image
from tools.sim.driving.drivers import LocalDriver

if TYPE_CHECKING:
    from drive_server.serving.control import ControlLaw
    from tools.envs.config import DriveEnvConfig
    from tools.envs.policy import Observation
    from tools.sim.driving.autopilot import Autopilot
    from tools.sim.driving.drivers import Frame, Scene
    from tools.sim.driving.scenario import ScenarioConfig

log = logging.getLogger(__name__)

#: What a policy of the comparison is: an ONNX model, an SB3 PPO policy, or the environment's expert.
KINDS = ("onnx", "ppo", "expert")


@dataclass(frozen=True)
class PolicySpec:
    """One policy of a comparison: its name in the table, its kind (:data:`KINDS`) and its file (PPO: the run folder
    with ``model.zip`` and ``recipe.json``, or the ``model.zip``; the expert has none)."""

    name: str
    kind: str
    path: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise BadValue(f"policy kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        if (self.path is None) != (self.kind == "expert"):
            raise BadValue(f"{self.name}: the expert has no file, every other policy one")

    @property
    def model_file(self) -> Path | None:
        """The file the policy's identity is read from (PPO's ``model.zip``, the ONNX model)."""
        if self.path is None:
            return None
        path = Path(self.path)
        return path / "model.zip" if self.kind == "ppo" and path.is_dir() else path


def ppo_env_config(run: str | Path) -> DriveEnvConfig:
    """The ``rbc/Drive-v0`` settings a PPO run trained with (its ``recipe.json``; without one, the recipe's
    defaults): what :class:`SB3Driver` observes and how its actions become commands."""
    from tools.envs.config import config_from_kwargs
    from tools.envs.ppo import PPORecipe

    run = Path(run)
    recipe_file = (run if run.is_dir() else run.parent) / "recipe.json"
    fields = json.loads(recipe_file.read_text(encoding="utf-8")) if recipe_file.is_file() else {}
    kwargs = PPORecipe(**{k: v for k, v in fields.items() if k in PPORecipe.__dataclass_fields__}).make_kwargs()
    for key in ("track", "worlds", "spawn", "max_episode_steps"):  # the evaluation's, not the training's
        kwargs.pop(key, None)
    config = config_from_kwargs(kwargs)
    if config.cameras != 1:
        raise BadValue(f"{run}: a policy of {config.cameras} cameras cannot be driven: the simulator's runs send the "
                       "centre camera only")
    return config


class Predictor(Protocol):
    """What SB3's policies and algorithms answer: the action for an observation (and any recurrent state)."""

    def predict(self, observation: Observation, *, deterministic: bool = ...) -> tuple[np.ndarray, object]: ...


class SB3Driver(LocalDriver):
    """A Stable-Baselines3 policy (anything with SB3's ``predict``) driving the simulator's runs: each frame becomes
    the observation ``rbc/Drive-v0`` made with ``config`` would give, the mean action becomes the command."""

    def __init__(self, policy: Predictor, config: DriveEnvConfig, law: ControlLaw, speed_unit: str = "mph",
                 name: str = "sb3") -> None:
        from drive_server.serving.preprocess import jpeg_reduction

        super().__init__()
        assert config.contract is not None  # DriveEnvConfig always sets one
        self.policy, self.config, self.law, self.speed_unit, self.name = policy, config, law, speed_unit, name
        self.reduce = jpeg_reduction(config.contract) if config.observation == "model" else 1

    def observation(self, frame: Frame) -> Observation:
        """The observation of this frame: the environment's ``_observe`` on the frame's JPEG and speed."""
        from drive_server.serving.preprocess import frame_to_network_image
        from tools.envs.drive_env import MAX_SPEED_KMH

        telemetry = frame.telemetry()
        image = decode_image(telemetry.image_b64, self.reduce)
        if self.config.observation == "model":
            assert self.config.contract is not None
            image = frame_to_network_image(image, self.config.contract)
        if not self.config.speed:
            return image
        speed = min(max(to_kmh(telemetry.speed, self.speed_unit), 0.0), MAX_SPEED_KMH)
        return {"center": image, "speed": np.array([speed], np.float32)}

    def steer(self, frame: Frame) -> SteerCommand:
        from tools.envs.config import steer_command

        action, _ = self.policy.predict(self.observation(frame), deterministic=True)
        a = np.clip(np.asarray(action, np.float64).reshape(-1), -1.0, 1.0)
        return steer_command(float(a[0]), float(a[1]) if len(a) > 1 else None, self.config.control, self.law,
                             to_kmh(frame.telemetry().speed, self.speed_unit))


class ExpertDriver(LocalDriver):
    """The environment's expert (``DriveEnv.expert_action``, :class:`tools.envs.ExpertPolicy`): the autopilot's
    pure-pursuit steering from the ground truth, Eq. 14's throttle on the telemetry speed (``control="steer"``)."""

    name = "expert"

    def __init__(self, law: ControlLaw, speed_unit: str = "mph") -> None:
        super().__init__()
        self.law, self.speed_unit = law, speed_unit
        self.autopilot: Autopilot | None = None

    def start(self, scene: Scene) -> None:
        from tools.sim.driving.autopilot import Autopilot, AutopilotParams

        super().start(scene)  # as the environment's client makes its expert at every reset
        self.autopilot = Autopilot(scene.track, scene.direction, scene.cones,
                                   replace(AutopilotParams(), speed_kmh=self.law.speed_limit_kmh), scene.vehicle,
                                   seed=scene.seed)

    def steer(self, frame: Frame) -> SteerCommand:
        from tools.envs.config import steer_command

        if self.autopilot is None:
            raise RuntimeError("ExpertDriver.start() was not called")
        steering = float(self.autopilot.wanted_steering(frame.truth))
        speed = parse_number(frame.payload["speed"], "speed")  # the frame has no image: the expert renders none
        return steer_command(steering, None, "steer", self.law, to_kmh(speed, self.speed_unit))


_DRIVERS: dict[tuple[PolicySpec, float, str], LocalDriver] = {}


def policy_driver(policy: PolicySpec, scenario: ScenarioConfig) -> LocalDriver:
    """The driver of a PPO policy or the expert, one per worker process (and per speed limit and unit)."""
    from drive_server.serving.control import ControlLaw

    key = (policy, scenario.speed_limit_kmh, scenario.speed_unit)
    if key not in _DRIVERS:
        if policy.kind == "ppo":
            import torch
            from stable_baselines3 import PPO

            torch.set_num_threads(1)  # one run per core, as the ONNX drivers
            assert policy.path is not None
            config = ppo_env_config(policy.path)
            law = replace(config.law, speed_limit_kmh=scenario.speed_limit_kmh)
            _DRIVERS[key] = SB3Driver(PPO.load(str(policy.model_file), device="cpu"), config, law,
                                      scenario.speed_unit, name=f"ppo:{policy.name}")
        elif policy.kind == "expert":
            _DRIVERS[key] = ExpertDriver(ControlLaw(speed_limit_kmh=scenario.speed_limit_kmh), scenario.speed_unit)
        else:
            raise BadValue(f"{policy.name}: an {policy.kind} policy is driven by rbc eval's own driver")
    return _DRIVERS[key]
