"""``rbc/Drive-v0``: the headless simulator as a Gymnasium environment (see :mod:`tools.envs` for the API).

One step is one command of the lock-step simulator (1/15 s, four 60 Hz physics frames): the action becomes a
steer command (in ``control="steer"`` its throttle and brake come from drive_server's Eq. 14 on the speed the
telemetry reports), the simulator runs it, and the observation is the next camera frame as the wire delivers it.
"""

from __future__ import annotations

import importlib.util
import math
from collections import deque
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

from drive_server.serving.preprocess import frame_to_network_image, jpeg_reduction
from protocol import CAMERAS, FRAME_HEIGHT, FRAME_WIDTH, SteerCommand
from protocol.errors import BadValue, UserError
from tools.envs.client import Episode, HeadlessSimClient
from tools.envs.config import config_from_kwargs, resolve_track, steer_command
from tools.envs.reset_options import check_reset_options
from tools.envs.rotation import WorldRotation
from tools.envs.wire_jpeg import wire_decoder
from tools.envs.worldcache import shared_cache

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from drive_server.serving.client_monitor import ClientMonitor
    from drive_server.serving.contract import PreprocessContract
    from drive_server.serving.pipeline import DrivePipeline
    from tools.envs.policy import Observation

FRAME_SHAPE = (FRAME_HEIGHT, FRAME_WIDTH, 3)
#: the speed observation's upper bound (km/h): the simulated car's top speed
MAX_SPEED_KMH = 130.0


class EnvClosedError(BadValue, gym.error.ClosedEnvironmentError):
    """``step()`` on an environment after ``close()`` (``reset()`` opens it again)."""


class EnvNotResetError(UserError, gym.error.ResetNeeded):
    """``step()`` before the first ``reset()``."""


def make(render_mode: str | None = None, **kwargs: object) -> gym.Env[Observation, np.ndarray]:
    """``gymnasium.make``'s entry point: a :class:`DriveEnv`; with ``render_mode="human"`` inside Gymnasium's
    ``HumanRendering`` window, which needs pygame: without it the make fails here, in one line."""
    if render_mode != "human":
        return DriveEnv(render_mode=render_mode, **kwargs)
    if importlib.util.find_spec("pygame") is None:
        raise BadValue("render_mode='human' shows the frames in a pygame window, and pygame is not installed",
                       "pip install pygame, or use render_mode='rgb_array' and env.render()")
    from gymnasium.wrappers import HumanRendering

    return HumanRendering(DriveEnv(render_mode="rgb_array", **kwargs))


class DriveEnv(gym.Env):
    """The headless simulator on one track or procedural world; keyword arguments are
    :class:`tools.envs.config.DriveEnvConfig`'s fields plus ``render_mode`` (None or "rgb_array")."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    def __init__(self, render_mode: str | None = None, **kwargs: object) -> None:
        if render_mode not in (None, "rgb_array"):
            raise BadValue(f"render_mode must be None or 'rgb_array', got {render_mode!r}",
                           "gymnasium.make('rbc/Drive-v0', render_mode='human') shows the frames in a window")
        self.render_mode = render_mode
        self.config = config = config_from_kwargs(kwargs)
        if config.threads is not None:
            cv2.setNumThreads(config.threads)
        self.metadata = {**self.metadata, "render_fps": config.control_hz}
        self.law = config.law
        assert config.contract is not None  # DriveEnvConfig always sets one
        self.contract: PreprocessContract = config.contract
        self.camera_names = CAMERAS if config.cameras == 3 else ("center",)
        self.observation_space = self._observation_space()
        size = 1 if config.control == "steer" else 2
        self.action_space: spaces.Box = spaces.Box(-1.0, 1.0, (size,), np.float32)
        self.client = HeadlessSimClient(
            resolve_track(config), config.camera, self.camera_names, config.jpeg, laps=config.laps,
            vehicle=config.vehicle, speed_limit_kmh=config.law.speed_limit_kmh, control_hz=config.control_hz,
            max_lap_time_s=config.max_lap_time_s, light_intensity=config.light_intensity, cones=config.cones,
            reverse=config.reverse)
        if config.worlds is None:  # built now, not at the first reset: the workers a fork-started vector env
            self.client.prepare()  # starts after making its first env in the parent share it (read-only pages)
        self._pending: deque[SteerCommand] = deque()
        self._steps = 0
        self._frame: np.ndarray | None = None  # the centre camera as rendered, for render()
        self._closed = False
        self._last_info: dict[str, Any] | None = None  # the last step's, until reset() (see _relabel_auto_reset)
        self._monitor_pipeline, self._monitor = self._load_monitor(config.monitor)
        self.worlds = shared_cache(config.worlds.pool + 2 if config.worlds else 1)
        self.rotation = WorldRotation(config, self.worlds)  # which world each episode drives
        self._episode: Episode | None = None  # this episode's world, light and fog (None: the env's track)
        self._reduce = jpeg_reduction(self.contract)
        # observation="model" without the JPEG and nothing else looking at the frame: only the rows the model crops
        whole = config.observation != "model" or config.jpeg or render_mode is not None or config.monitor is not None
        self._rows = None if whole else (self.contract.crop_top, self.contract.crop_bottom)

    # --- the Gymnasium API --------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """A new episode; ``seed`` makes it and every step after it reproducible. ``options`` pin this episode's
        draws (:data:`tools.envs.reset_options.RESET_OPTIONS`): ``spawn_s`` (metres along the track to start at),
        ``cone_seed`` (the cones' layout, with ``cones=N``), ``track`` or ``world_seed`` (the world; held-out ones
        only with ``purpose="eval"``) and ``themes``, ``sun_deg``, ``light_intensity``, ``fog``."""
        pinned = check_reset_options(options, self.config.purpose)
        super().reset(seed=seed)
        self._closed = False
        run_seed = int(self.np_random.integers(1, 2**31 - 1))  # never 0: the simulator's "no spawn noise" seed
        self._episode = episode = self.rotation.draw(seed, pinned, self.np_random)
        spawn_s = pinned.get("spawn_s")
        if spawn_s is None and self.config.spawn == "random":
            spawn_s = self.client.random_spawn_s(self.np_random, episode.built.path if episode else None)
        if episode is not None and self.config.worlds is not None:  # after the spawn: as without a distribution
            episode = self._episode = replace(
                episode, light_intensity=pinned.get("light_intensity",
                                                    self.config.worlds.draw_light(self.np_random,
                                                                                  self.config.light_intensity)),
                fog=pinned.get("fog", self.config.worlds.draw_fog(self.np_random)))
        self.client.start(run_seed, spawn_s=None if spawn_s is None else float(spawn_s),
                          spawn_noise=self.config.spawn_noise, cone_seed=int(pinned.get("cone_seed", 0)),
                          world=episode)
        self.rotation.prefetch()
        self._pending = deque([SteerCommand(0.0, 0.0)] * self.config.action_delay)
        self._steps = 0
        if self._monitor_pipeline is not None:
            self._monitor = self._monitor_pipeline.client_monitor("env")  # each episode is a new client
        obs, jpeg = self._observe()
        info = self._info("", False, jpeg)
        self._relabel_auto_reset(info)
        return obs, info

    def step(self, action: ArrayLike):
        if self.client.sim is None:
            if self._closed:
                raise EnvClosedError("step() after close(): this rbc/Drive-v0 environment is closed",
                                     "reset() it to drive again, or make a new one")
            raise EnvNotResetError("step() before reset(): call env.reset(seed=...) first")
        command = self.command(action)
        if self._pending:
            self._pending.append(command)
            command = self._pending.popleft()
        report = self.client.step(command, self.config.frames_per_step)
        self._steps += 1
        self.rotation.stepped()  # halfway to a new world: built in the background
        terminated = bool(report.intervention) and self.config.terminate_on_takeover
        if report.intervention and not terminated:
            self.client.follow()  # observe the car where the referee put it: the next action drives from there
        reward = self.config.reward.reward(report)
        limit = self.config.max_episode_steps
        truncated = not terminated and (report.laps_done or report.time_out
                                        or (limit is not None and self._steps >= limit))
        obs, jpeg = self._observe()
        info = self._info(report.intervention, report.laps_done, jpeg)
        self._last_info = info
        return obs, float(reward), terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """The centre camera as rendered (before the wire's JPEG), with ``render_mode="rgb_array"``."""
        if self.render_mode != "rgb_array":
            return None
        return None if self._frame is None else self._frame.copy()

    def close(self) -> None:
        self._closed = True
        self.client.sim = None
        self.client.expert = None
        self._episode = None  # its world stays in the process's cache for the next environment

    # --- what the agent gets ------------------------------------------------------------------------
    def command(self, action: ArrayLike) -> SteerCommand:
        """The steer command an action asks for: steering as given; throttle and brake from Eq. 14 on the
        telemetry speed (``control="steer"``, as drive_server's pipeline computes them) or the second action,
        cut to 0 at the speed limit (``control="steer_throttle"``)."""
        parts = np.asarray(action, dtype=np.float64).reshape(-1).tolist()  # floats: per-step numbers in plain Python
        if len(parts) != self.action_space.shape[0] or not all(map(math.isfinite, parts)):
            raise BadValue(f"action must be {self.action_space.shape[0]} finite number(s) in [-1, 1], got {action!r}")
        steering, *throttle = (min(1.0, max(-1.0, v)) for v in parts)
        return steer_command(steering, throttle[0] if throttle else None, self.config.control, self.law,
                             self.client.wire_speed_kmh())

    def expert_action(self) -> np.ndarray:
        """The autopilot's action for the current state: its pure-pursuit steering, and (``steer_throttle``)
        Eq. 14's throttle for that steering, the throttle ``control="steer"`` would apply."""
        steering = self.client.expert_steering()
        if self.config.control == "steer":
            return np.array([steering], np.float32)
        throttle = self.law.command(self.law.steering_deg(steering), self.client.wire_speed_kmh())
        return np.array([steering, throttle], np.float32)

    def _relabel_auto_reset(self, info: dict[str, Any]) -> None:
        """At Stable-Baselines3's auto-reset, make the terminal step's label the new observation's.

        An SB3 VecEnv marks the terminal step's info with ``terminal_observation``, resets at once and returns
        that info with the NEW episode's first observation; so its ``expert_action`` becomes the label of that
        observation (the one just computed for the reset) and the terminal state's label moves to
        ``terminal_expert_action``, as the frame moved to ``terminal_observation``. Any other reset (a loop of
        one's own, Gymnasium's vector envs, which return the reset's own info) leaves the step's info as it was.
        """
        last, self._last_info = self._last_info, None
        if last is not None and "terminal_observation" in last:  # also where a wrapper's TimeLimit truncated
            last["terminal_expert_action"] = last["expert_action"]
            last["expert_action"] = info["expert_action"].copy()

    def _observation_space(self) -> spaces.Box | spaces.Dict[np.ndarray]:
        config = self.config
        shape = FRAME_SHAPE if config.observation == "frame" else (self.contract.height, self.contract.width, 3)
        image = spaces.Box(0, 255, shape, np.uint8)
        if config.cameras == 1 and not config.speed:
            return image
        parts: dict[str, spaces.Space[np.ndarray]] = {c: image for c in self.camera_names}
        if config.speed:
            parts["speed"] = spaces.Box(0.0, MAX_SPEED_KMH, (1,), np.float32)
        return spaces.Dict(parts)

    def _observe(self) -> tuple[np.ndarray | dict[str, np.ndarray], bytes]:
        frames = self.client.render(self._rows)
        self._frame = frames["center"]
        seen: dict[str, np.ndarray] = {}
        jpeg = b""
        model = self.config.observation == "model"
        for name, rgb in frames.items():
            if model:
                data = self.client.encode(rgb)
                image = wire_decoder()(data, self._reduce) if data else rgb  # drive_server's pixels for the model
                seen[name] = frame_to_network_image(image, self.contract)
            else:
                seen[name], data = self.client.wire(rgb)
            if name == "center":
                jpeg = data
        if self.config.speed:
            speed = min(max(self.client.wire_speed_kmh(), 0.0), MAX_SPEED_KMH)
            return {**seen, "speed": np.array([speed], np.float32)}, jpeg
        return (seen if self.config.cameras == 3 else seen["center"]), jpeg

    def _info(self, intervention: str, laps_done: bool, jpeg: bytes) -> dict[str, Any]:
        info: dict[str, Any] = self.client.truth()
        info["expert_action"] = self.expert_action()
        info["intervention"] = intervention
        info["laps_done"] = laps_done
        info["step"] = self._steps
        episode = self._episode
        info["world"] = episode.key.track if episode else self.config.track_name
        if episode is not None and self.config.worlds is not None or self._steps == 0:
            info["light_intensity"] = episode.light_intensity if episode else self.config.light_intensity
            info["fog"] = episode.fog if episode else 1.0
            info["sun_deg"] = episode.key.sun_deg if episode else 0.0
        if jpeg:
            info["jpeg"] = jpeg  # the centre frame's JPEG as sent on the wire (OnnxPolicy decodes it as drive_server)
        if self._monitor is not None and self._monitor_pipeline is not None and self._frame is not None:
            reading = self._monitor_pipeline.observe(self._monitor, self._monitor_input(jpeg))
            info["monitor"] = None if reading is None else {"score": reading.score, "mean": reading.mean,
                                                             "state": reading.level.label}
        return info

    @staticmethod
    def _load_monitor(path: str | None) -> tuple[DrivePipeline | None, ClientMonitor | None]:
        """(the monitor's pipeline, None until reset) for ``monitor=PATH``; one line if the file has none."""
        if path is None:
            return None, None
        from drive_server.serving.client_monitor import MonitorMode, MonitorPolicy
        from drive_server.serving.model import SteeringModel
        from drive_server.serving.pipeline import DriveConfig, DrivePipeline

        pipeline = DrivePipeline(SteeringModel(Path(path)), DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN,
                                                                                                   budget_ms=None)))
        if pipeline.monitor_spec is None:
            raise BadValue(f"monitor={path}: the model file carries no misbehaviour monitor",
                           "attach one with rbc monitor fit")
        return pipeline, None

    def _monitor_input(self, jpeg: bytes) -> np.ndarray:
        """The centre frame as drive_server would prepare it for the monitor's model (decoded from the wire's JPEG
        at the model's scale when there is one)."""
        from drive_server.serving.preprocess import preprocess
        from protocol.jpeg import decode_jpeg

        pipeline = self._monitor_pipeline
        assert pipeline is not None  # _info scores only with a monitor
        rgb = decode_jpeg(jpeg, pipeline.reduce) if jpeg else self._frame
        assert rgb is not None  # _info scores only after a frame was rendered
        return preprocess(rgb, pipeline.contract)
