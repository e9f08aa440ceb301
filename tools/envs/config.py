"""What defines a ``rbc/Drive-v0`` environment, and the reward's constants, each in one place.

Every bad argument is a :class:`protocol.errors.BadValue` naming the argument, so ``gymnasium.make`` fails at
once with a sentence rather than on the first step. Procedural worlds follow ``rbc collect``'s rule: an
environment made for training refuses world seeds outside the training range unless told it is for evaluation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from drive_server.serving.contract import PreprocessContract
from drive_server.serving.control import ControlLaw
from protocol import SteerCommand
from protocol.errors import BadValue
from tools.envs.client import StepReport
from tools.envs.worlds import WorldDistribution
from tools.sim.driving.scenario import ScenarioConfig
from tools.sim.render.camera import RIGS
from tools.sim.vehicle.kinematic import VEHICLE_KINDS

CONTROLS = ("steer", "steer_throttle")
OBSERVATIONS = ("frame", "model")
#: observation="model"'s default contract per camera rig: generalist.onnx's for the real simulator's camera
#: (rows 64-136, below the horizon and above the bonnet, to 64x64 RGB; JPEG decoded at half size), the
#: paper's whole frame to 64x64 for the classic rig
MODEL_CONTRACTS = {"unity": PreprocessContract(crop_top=64, crop_bottom=136, decode_reduce=2),
                   "classic": PreprocessContract()}
PURPOSES = ("train", "eval")
SPAWNS = ("start", "random")


@dataclass(frozen=True)
class RewardConfig:
    """The reward per step, as data (``gymnasium.make("rbc/Drive-v0", reward={...})``, an rl-zoo ``env_kwargs``):

    reward = progress_per_m * metres driven along the lap in the step
             - out_of_lane_per_s * seconds of the step with the car's body over its lane's edge
             - takeover (once, on the step of a take-over, which ends the episode by default)
             + lane_per_m * the integral over the step of (1 - |cte| / max_cte_m) * speed dt
             + speed_per_m * metres driven over the ground in the step (in any direction)

    ``lane_per_m`` is gym-donkeycar's ``(1 - |cte| / max_cte) * speed`` per second (cte from the car's line;
    a cost beyond ``max_cte_m``), ``speed_per_m`` the same without the lane's factor. The default is progress
    only: about 1,003 per lap of the lake (its length in metres), 0.46 a step at 25 km/h; a step fully out of
    the lane costs about a third of what it earns, and a take-over (leaving the road, hitting a cone, spinning
    out, driving the wrong way, standing still) the progress of 10 m.
    """

    progress_per_m: float = 1.0
    out_of_lane_per_s: float = 2.5
    takeover: float = 10.0
    lane_per_m: float = 0.0
    max_cte_m: float = 2.0  # where the lane term reaches 0 (half the lake's lane)
    speed_per_m: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
                raise BadValue(f"reward {f.name} must be a finite number, got {value!r}")
        if self.max_cte_m <= 0:
            raise BadValue(f"reward max_cte_m must be positive, got {self.max_cte_m!r}")

    @classmethod
    def of(cls, value: object) -> RewardConfig:
        """A RewardConfig from itself or a mapping of its fields (an unknown key is a BadValue naming the known)."""
        if isinstance(value, cls):
            return value
        if not isinstance(value, dict):
            raise BadValue(f"reward must be a tools.envs.RewardConfig or a dict of its fields, got {value!r}")
        known = [f.name for f in fields(cls)]
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise BadValue(f"unknown reward option(s): {', '.join(map(str, unknown))}", f"known: {', '.join(known)}")
        return cls(**value)

    def reward(self, step: StepReport) -> float:
        """The reward of one step of the simulator."""
        reward = self.progress_per_m * step.progress_m - self.out_of_lane_per_s * step.out_of_lane_s
        if step.intervention:
            reward -= self.takeover
        if self.lane_per_m:
            reward += self.lane_per_m * (step.distance_m - step.abs_cte_distance_m2 / self.max_cte_m)
        if self.speed_per_m:
            reward += self.speed_per_m * step.distance_m
        return reward


@dataclass(frozen=True)
class DriveEnvConfig:
    """The keyword arguments of ``gymnasium.make("rbc/Drive-v0", ...)`` (defaults: lake, one camera, the paper's
    coupled control law at drive_server's 25 km/h). Angles in degrees, speeds in km/h."""

    track: str | None = None  # built-in name, track file path or world:SEED; None: lake (or world_seed's world)
    world_seed: int | None = None  # a procedural world instead of track
    purpose: str = "train"  # "train" refuses evaluation worlds (rbc collect's rule); "eval" allows every seed
    camera: str = ScenarioConfig.camera  # the camera rig (tools.sim.render.camera.RIGS)
    cameras: int = 1  # 1: centre only; 3: a Dict observation of centre, left and right
    control: str = "steer"  # "steer": throttle and brake from Eq. 14 as drive_server; "steer_throttle": both actions
    # Eq. 14 (drive_server's own ControlLaw, or a dict of its fields); its speed limit is a governor in steer_throttle
    law: ControlLaw = ControlLaw()
    jpeg: bool = True  # observe the frame after the wire's JPEG round trip (what drive_server and recordings see)
    laps: int = 1  # the episode is truncated after this many laps
    max_episode_steps: int | None = None  # truncated after this many steps (None: only the lap and its time limit)
    max_lap_time_s: float | None = None  # None: the simulator's (4x a lap at the speed limit, at least 120 s)
    vehicle: str = ScenarioConfig.vehicle  # "dynamic" (tyre slip) or "kinematic"
    control_hz: float = ScenarioConfig.control_hz  # steps per simulated second (must divide 60)
    spawn: str = "start"  # "start": the track's start line; "random": anywhere along the lap (drawn from the seed)
    spawn_noise: bool = True  # up to 0.5 m sideways and 3 degrees of yaw off the line, drawn from the seed
    action_delay: int = 0  # 1: each action applies one step late, as with Unity's two frames in flight
    light_intensity: float = ScenarioConfig.light_intensity
    cones: int = 0
    reverse: bool = False  # drive the lap the other way round
    # False: a take-over does not end the episode; the referee has put the car back on its line, the step's
    # observation is the car there and info["intervention"] names the cause (DAgger: the learner drives on)
    terminate_on_takeover: bool = True
    reward: RewardConfig = field(default_factory=RewardConfig)  # or a dict of its fields
    # an ONNX model file carrying a misbehaviour monitor (rbc monitor fit): each observation is scored as
    # drive_server --monitor warn scores a frame, and info["monitor"] holds its score, one-second mean and state
    monitor: str | None = None
    # domain randomisation: a new world, sun, light and fog per episode (tools.envs.worlds.WorldDistribution,
    # a dict of its fields, or True for its defaults); only training worlds are ever drawn
    worlds: WorldDistribution | None = None
    # "frame": the camera's 160x320 frame; "model": the network's own input (crop, resize, colour of the
    # preprocessing contract, from the JPEG decoded as drive_server decodes it), uint8
    observation: str = "frame"
    # the preprocessing contract of observation="model": None (generalist.onnx's for the unity rig: rows
    # 64-136 to 64x64 RGB; the paper's whole frame to 64x64 for classic), a PreprocessContract, a dict of its
    # fields or an .onnx model file (its contract)
    contract: PreprocessContract | None = None
    speed: bool = False  # True: a Dict observation of the camera(s) and "speed" (km/h, as the telemetry says)
    # OpenCV's threads in the env's process (cv2.setNumThreads, for the whole process), set when the env is made:
    # 1 (a 320x160 frame is too small for threads to pay, and a vector env's processes would fight over the
    # cores with them), or None to leave OpenCV's setting as it is
    threads: int | None = 1

    def __post_init__(self) -> None:
        _choice("camera", self.camera, tuple(RIGS))
        _choice("control", self.control, CONTROLS)
        _choice("purpose", self.purpose, PURPOSES)
        _choice("spawn", self.spawn, SPAWNS)
        _choice("vehicle", self.vehicle, VEHICLE_KINDS)
        if self.cameras not in (1, 3):
            raise BadValue(f"cameras must be 1 or 3, got {self.cameras!r}")
        if not isinstance(self.control_hz, int | float) or not math.isfinite(self.control_hz) or self.control_hz <= 0:
            raise BadValue(f"control_hz must be a positive number, got {self.control_hz!r}")
        ratio = ScenarioConfig.sim_fps / self.control_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise BadValue(f"control_hz must divide the simulator's {ScenarioConfig.sim_fps} Hz, got {self.control_hz}")
        for name in ("laps", "max_episode_steps", "cones", "action_delay", "world_seed"):
            value = getattr(self, name)
            low = {"laps": 1, "max_episode_steps": 1}.get(name, 0)
            if value is None and name in ("max_episode_steps", "world_seed"):
                continue
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise BadValue(f"{name} must be an integer >= {low}, got {value!r}")
        if self.action_delay > 1:
            raise BadValue(f"action_delay must be 0 or 1 (Unity keeps two frames in flight), got {self.action_delay}")
        if self.max_lap_time_s is not None and not (math.isfinite(self.max_lap_time_s) and self.max_lap_time_s > 0):
            raise BadValue(f"max_lap_time_s must be a positive number, got {self.max_lap_time_s!r}")
        if not math.isfinite(self.light_intensity) or self.light_intensity < 0:
            raise BadValue(f"light_intensity must be a number >= 0, got {self.light_intensity!r}")
        if self.track is not None and self.world_seed is not None:
            raise BadValue("give track or world_seed, not both",
                           "world_seed=S is the procedural world S; track='world:S' names the same world")
        _choice("observation", self.observation, OBSERVATIONS)
        if not isinstance(self.speed, bool):
            raise BadValue(f"speed must be True or False, got {self.speed!r}")
        if self.threads is not None and (not isinstance(self.threads, int) or isinstance(self.threads, bool)
                                         or self.threads < 1):
            raise BadValue(f"threads must be an integer >= 1 or None, got {self.threads!r}")
        if self.worlds is not None and (self.track is not None or self.world_seed is not None):
            raise BadValue("give track/world_seed or worlds, not both",
                           "worlds draws the world of every episode; tracks=('lake',) puts a built-in one in the draw")
        object.__setattr__(self, "reward", RewardConfig.of(self.reward))
        object.__setattr__(self, "law", _law_of(self.law))
        object.__setattr__(self, "worlds", WorldDistribution.of(self.worlds))
        if self.contract is not None and self.observation != "model":
            raise BadValue("contract sets the preprocessing of observation='model'; give both or neither")
        object.__setattr__(self, "contract", _contract_of(self.contract, self.camera))

    @property
    def track_name(self) -> str:
        """The track as ``rbc sim --track`` names it: a built-in name, a path or ``world:SEED``."""
        if self.world_seed is not None:
            return f"world:{self.world_seed}"
        return str(self.track) if self.track is not None else ScenarioConfig.track

    @property
    def frames_per_step(self) -> int:
        return round(ScenarioConfig.sim_fps / self.control_hz)


def _law_of(value: object) -> ControlLaw:
    """A ControlLaw from itself or a mapping of its fields (an unknown key is a BadValue naming the known)."""
    if isinstance(value, ControlLaw):
        return value
    if not isinstance(value, dict):
        raise BadValue(f"law must be a drive_server.serving.control.ControlLaw or a dict of its fields, got {value!r}")
    known = [f.name for f in fields(ControlLaw)]
    unknown = sorted(set(value) - set(known))
    if unknown:
        raise BadValue(f"unknown law option(s): {', '.join(map(str, unknown))}", f"known: {', '.join(known)}")
    return ControlLaw(**value)


def _contract_of(value: object, camera: str) -> PreprocessContract:
    """The contract of observation="model" (see :attr:`DriveEnvConfig.contract`); one line when it is bad."""
    from pathlib import Path

    if value is None:
        return MODEL_CONTRACTS.get(camera, PreprocessContract())
    if isinstance(value, PreprocessContract):
        return value
    if isinstance(value, dict):
        known = [f.name for f in fields(PreprocessContract)]
        unknown = sorted(map(str, set(value) - set(known)))
        if unknown:
            raise BadValue(f"unknown contract option(s): {', '.join(unknown)}", f"known: {', '.join(known)}")
        return PreprocessContract(**value)
    if isinstance(value, str | Path) and str(value).endswith(".onnx"):
        from drive_server.serving.model import SteeringModel

        return SteeringModel(Path(value)).contract
    raise BadValue(f"contract must be a PreprocessContract, a dict of its fields or an .onnx file, got {value!r}")


def _choice(name: str, value: object, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise BadValue(f"{name} must be one of {', '.join(allowed)}, got {value!r}")


def config_from_kwargs(kwargs: dict[str, object]) -> DriveEnvConfig:
    """The config of ``DriveEnv(**kwargs)``; an unknown keyword is a BadValue listing the known ones."""
    known = {f.name for f in fields(DriveEnvConfig)}
    unknown = sorted(set(kwargs) - known)
    if unknown:
        moved = sorted(set(unknown) & {f.name for f in fields(ControlLaw)})
        hint = (f"the control law's parameters are one argument: law={{'{moved[0]}': ...}}" if moved
                else f"known: render_mode, {', '.join(sorted(known))}")
        raise BadValue(f"unknown argument(s) of rbc/Drive-v0: {', '.join(unknown)}", hint)
    return DriveEnvConfig(**kwargs)  # type: ignore[arg-type]


def resolve_track(config: DriveEnvConfig) -> str:
    """The track file or name the simulator loads, after ``rbc collect``'s refusal of held-out worlds.

    ``purpose="train"`` with a world seed outside the training range is refused (a model must never see the
    worlds it is evaluated on); ``purpose="eval"`` allows it.
    """
    from tools.sim.collect.worlds import training_seed_problem
    from tools.sim.track.files import get_track, world_seed_of
    from tools.sim.worldgen.generate import resolve_track_name

    name = config.track_name
    seed = world_seed_of(name)  # a malformed world:SEED is a TrackError
    if seed is not None and config.purpose == "train":
        problem = training_seed_problem(seed, 1)
        if problem:
            raise BadValue(problem, "pick a world_seed in the training range, or make the environment with "
                                    "purpose='eval' to evaluate on it (never train on it)")
    path = resolve_track_name(name)
    get_track(path)  # a bad name or file fails here, at make, not at the first reset (loaded once per process)
    return path


def steer_command(steering: float, throttle: float | None, control: str, law: ControlLaw,
                  speed_kmh: float) -> SteerCommand:
    """The command of an action (each part already within -1..1): the steering as given; the throttle and brake
    from Eq. 14 on the telemetry speed (``control="steer"``, as drive_server's pipeline computes them) or the
    action's ``throttle``, cut to 0 at the speed limit (``control="steer_throttle"``)."""
    if control == "steer":
        return SteerCommand(steering=steering, throttle=law.command(law.steering_deg(steering), speed_kmh))
    assert throttle is not None  # steer_throttle's actions have two parts
    return SteerCommand(steering=steering, throttle=min(throttle, 0.0) if speed_kmh >= law.speed_limit_kmh
                        else throttle)
