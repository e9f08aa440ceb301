"""``rbc/Drive-v0``: the headless simulator as a Gymnasium environment (see :mod:`tools.envs` for the API).

One step is one command of the lock-step simulator (1/15 s, four 60 Hz physics frames): the action becomes a
steer command (in ``control="steer"`` its throttle and brake come from drive_server's Eq. 14 on the speed the
telemetry reports), the simulator runs it, and the observation is the next camera frame as the wire delivers it.
"""

from __future__ import annotations

import importlib.util
from collections import deque
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from drive_server.preprocess import frame_to_network_image, jpeg_reduction
from protocol import CAMERAS, FRAME_HEIGHT, FRAME_WIDTH, SteerCommand
from protocol.errors import BadValue, UserError
from protocol.jpeg import decode_jpeg
from tools.envs.client import Episode, HeadlessSimClient
from tools.envs.config import config_from_kwargs, resolve_track
from tools.envs.worlds import WorldKey, shared_cache

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from drive_server.contract import PreprocessContract
    from drive_server.monitor import ClientMonitor
    from drive_server.pipeline import DrivePipeline

FRAME_SHAPE = (FRAME_HEIGHT, FRAME_WIDTH, 3)
#: the speed observation's upper bound (km/h): the simulated car's top speed
MAX_SPEED_KMH = 130.0
#: the distribution's stream of worlds, apart from the episode's own draws (np_random)
WORLD_STREAM = 0x3D1
#: what ``reset(options=...)`` may pin for one episode
RESET_OPTIONS = ("spawn_s", "cone_seed", "track", "world_seed", "themes", "sun_deg", "light_intensity", "fog")


def check_reset_options(options: dict[str, Any] | None, purpose: str) -> dict[str, Any]:
    """``reset``'s options, checked and normalised (``world_seed`` becomes ``track="world:SEED"``); every bad one
    is a BadValue of one line, before anything changes."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise BadValue(f"reset options must be a dict, got {options!r}")
    unknown = sorted(map(str, set(options) - set(RESET_OPTIONS)))
    if unknown:
        raise BadValue(f"unknown reset option(s): {', '.join(unknown)} (known: {', '.join(RESET_OPTIONS)})")
    pinned = dict(options)
    numbers = {"spawn_s": ("a finite number", lambda v: True),
               "sun_deg": ("an angle in [-90, 90]", lambda v: -90 <= v <= 90),
               "light_intensity": ("a number >= 0", lambda v: v >= 0), "fog": ("a number > 0", lambda v: v > 0)}
    for name, (bounds, ok) in numbers.items():
        value = pinned.get(name)
        if value is None:
            pinned.pop(name, None)
            continue
        if not isinstance(value, int | float) or isinstance(value, bool) or not np.isfinite(value) or not ok(value):
            raise BadValue(f"reset option {name} must be {bounds}, got {value!r}")
        pinned[name] = float(value)
    for name in ("cone_seed", "world_seed"):
        value = pinned.get(name)
        if value is not None and (not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 0):
            raise BadValue(f"reset option {name} must be an integer >= 0, got {value!r}")
    if "world_seed" in pinned and pinned.get("track") is not None:
        raise BadValue("reset options: give track or world_seed, not both")
    if pinned.get("world_seed") is not None:
        pinned["track"] = f"world:{int(pinned.pop('world_seed'))}"
    pinned.pop("world_seed", None)
    track = pinned.get("track")
    if track is not None:
        if not isinstance(track, str) or not track:
            raise BadValue(f"reset option track must be a track name, file or world:SEED, got {track!r}")
        from tools.sim.collect.worlds import training_seed_problem
        from tools.sim.track.files import world_seed_of

        seed = world_seed_of(track)
        problem = training_seed_problem(seed, 1) if seed is not None and purpose == "train" else None
        if problem:
            raise BadValue(f"reset option track={track}: {problem}", "make the environment with purpose='eval' "
                                                                    "to evaluate on it (never train on it)")
    else:
        pinned.pop("track", None)
    if "themes" in pinned:
        from tools.envs.worlds import _strings
        from tools.sim.track.road import THEMES

        themes = _strings("reset option themes", pinned["themes"])
        if not themes or set(themes) - set(THEMES):
            raise BadValue(f"reset option themes must be a non-empty list of {', '.join(THEMES)}, "
                           f"got {pinned['themes']!r}")
        pinned["themes"] = tuple(sorted(set(themes)))
    return pinned


class EnvClosedError(BadValue, gym.error.ClosedEnvironmentError):
    """``step()`` on an environment after ``close()`` (``reset()`` opens it again)."""


class EnvNotResetError(UserError, gym.error.ResetNeeded):
    """``step()`` before the first ``reset()``."""


def make(render_mode: str | None = None, **kwargs: Any) -> gym.Env[Any, Any]:
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

    def __init__(self, render_mode: str | None = None, **kwargs: Any) -> None:
        if render_mode not in (None, "rgb_array"):
            raise BadValue(f"render_mode must be None or 'rgb_array', got {render_mode!r}",
                           "gymnasium.make('rbc/Drive-v0', render_mode='human') shows the frames in a window")
        self.render_mode = render_mode
        self.config = config = config_from_kwargs(kwargs)
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
        self._pending: deque[SteerCommand] = deque()
        self._steps = 0
        self._frame: np.ndarray | None = None  # the centre camera as rendered, for render()
        self._closed = False
        self._last_info: dict[str, Any] | None = None  # the last step's, until reset() (see _relabel_auto_reset)
        self._monitor_pipeline, self._monitor = self._load_monitor(config.monitor)
        self.worlds = shared_cache(config.worlds.pool + 2 if config.worlds else 1)
        # the distribution's own streams (see reset): the worlds that enter the pool, and each episode's pick
        self._world_rng: np.random.Generator | None = None
        self._pick_rng: np.random.Generator | None = None
        self._next_world: tuple[str, float] | None = None  # drawn for the next episode (being prefetched)
        self._since_new = 0  # steps since the newest world of the pool entered it
        self._pool: list[tuple[str, float]] = []  # the distribution's worlds (and suns) in play, oldest first
        self._episode: Episode | None = None  # this episode's world, light and fog (None: the env's track)
        self._reduce = jpeg_reduction(self.contract)

    # --- the Gymnasium API --------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """A new episode; ``seed`` makes it and every step after it reproducible. ``options`` pin this episode's
        draws (:data:`RESET_OPTIONS`): ``spawn_s`` (metres along the track to start at), ``cone_seed`` (the
        cones' layout, with ``cones=N``), ``track`` or ``world_seed`` (the world; held-out ones only with
        ``purpose="eval"``) and ``themes``, ``sun_deg``, ``light_intensity``, ``fog``."""
        pinned = check_reset_options(options, self.config.purpose)
        super().reset(seed=seed)
        self._closed = False
        run_seed = int(self.np_random.integers(1, 2**31 - 1))  # never 0: the simulator's "no spawn noise" seed
        self._episode = episode = self._draw_episode(seed, pinned)
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
        self._prefetch()
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
        worlds = self.config.worlds
        if worlds is not None:
            self._since_new += 1
            if worlds.prefetch and self._next_world is None and 2 * self._since_new >= worlds.new_world_steps:
                self._prefetch()  # halfway to a new world: build it in the background
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

    # --- the world of an episode --------------------------------------------------------------------
    def _draw_episode(self, seed: int | None, pinned: dict[str, Any]) -> Episode | None:
        """This episode's world: pinned by the options, drawn from the distribution's pool or None (the env's own
        track, built as ``rbc sim`` builds it)."""
        dist = self.config.worlds
        if dist is not None and (seed is not None or self._world_rng is None):
            # the worlds' own streams: the same worlds for a seed, whatever the episodes did with np_random
            entropy = seed if seed is not None else int(self.np_random.integers(2**62))
            self._world_rng = np.random.default_rng([entropy, WORLD_STREAM, 0])
            self._pick_rng = np.random.default_rng([entropy, WORLD_STREAM, 1])
            self._since_new, self._next_world = 0, None
            self._pool = [dist.draw_world(self._world_rng) for _ in range(dist.pool)]
        track, sun = pinned.get("track"), pinned.get("sun_deg")
        if track is None and dist is not None:
            assert self._world_rng is not None and self._pick_rng is not None  # seeded above
            if self._since_new >= dist.new_world_steps:  # a new world, driven at once
                self._pool = [*self._pool[1:], self._next_world or dist.draw_world(self._world_rng)]
                self._next_world, self._since_new = None, 0
                track, drawn_sun = self._pool[-1]
            else:
                track, drawn_sun = self._pool[int(self._pick_rng.integers(len(self._pool)))]
            sun = drawn_sun if sun is None else sun
        elif track is None:
            if not {"sun_deg", "light_intensity", "fog"} & set(pinned):
                return None
            track = self.config.track_name
        key = self._world_key(track, sun or 0.0, pinned.get("themes"), int(pinned.get("cone_seed", 0)))
        return Episode(key, self.worlds.get(key), pinned.get("light_intensity", self.config.light_intensity),
                       pinned.get("fog", 1.0))

    def _world_key(self, track: str, sun: float, themes: tuple[str, ...] | None = None,
                   cone_seed: int = 0) -> WorldKey:
        from tools.sim.track.files import world_seed_of

        if themes is None and self.config.worlds is not None:
            themes = self.config.worlds.themes
        return WorldKey(track, themes if world_seed_of(track) is not None else None, float(sun), self.config.cones,
                        cone_seed)

    def _prefetch(self) -> None:
        """Build in the background the pool's worlds not built yet and, from halfway to ``new_world_steps``, the
        world the next new-world reset brings into the pool (drawn now: the draws stay those of resets)."""
        dist, rng = self.config.worlds, self._world_rng
        if dist is None or not dist.prefetch or rng is None:
            return
        for track, sun in self._pool:
            self.worlds.prefetch(self._world_key(track, sun))
        if 2 * self._since_new >= dist.new_world_steps:
            if self._next_world is None:
                self._next_world = dist.draw_world(rng)
            self.worlds.prefetch(self._world_key(*self._next_world))

    # --- what the agent gets ------------------------------------------------------------------------
    def command(self, action: ArrayLike) -> SteerCommand:
        """The steer command an action asks for: steering as given; throttle and brake from Eq. 14 on the
        telemetry speed (``control="steer"``, as drive_server's pipeline computes them) or the second action,
        cut to 0 at the speed limit (``control="steer_throttle"``)."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != self.action_space.shape or not np.isfinite(a).all():
            raise BadValue(f"action must be {self.action_space.shape[0]} finite number(s) in [-1, 1], got {action!r}")
        a = np.clip(a, -1.0, 1.0)
        steering = float(a[0])
        speed_kmh = self.client.wire_speed_kmh()
        if self.config.control == "steer":
            throttle = self.law.command(self.law.steering_deg(steering), speed_kmh)
        else:
            throttle = float(a[1])
            if speed_kmh >= self.law.speed_limit_kmh:
                throttle = min(throttle, 0.0)
        return SteerCommand(steering=steering, throttle=throttle)

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

    def _observation_space(self) -> spaces.Space[Any]:
        config = self.config
        shape = FRAME_SHAPE if config.observation == "frame" else (self.contract.height, self.contract.width, 3)
        image = spaces.Box(0, 255, shape, np.uint8)
        if config.cameras == 1 and not config.speed:
            return image
        parts: dict[str, spaces.Space[Any]] = {c: image for c in self.camera_names}
        if config.speed:
            parts["speed"] = spaces.Box(0.0, MAX_SPEED_KMH, (1,), np.float32)
        return spaces.Dict(parts)

    def _observe(self) -> tuple[np.ndarray | dict[str, np.ndarray], bytes]:
        frames = self.client.render()
        self._frame = frames["center"]
        seen: dict[str, np.ndarray] = {}
        jpeg = b""
        model = self.config.observation == "model"
        for name, rgb in frames.items():
            if model:
                data = self.client.encode(rgb)
                image = decode_jpeg(data, self._reduce) if data else rgb  # as drive_server decodes for the model
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
            reading = self._monitor.observe(self._monitor_input(jpeg))
            info["monitor"] = None if reading is None else {"score": reading.score, "mean": reading.mean,
                                                             "state": reading.level.label}
        return info

    @staticmethod
    def _load_monitor(path: str | None) -> tuple[DrivePipeline | None, ClientMonitor | None]:
        """(the monitor's pipeline, None until reset) for ``monitor=PATH``; one line if the file has none."""
        if path is None:
            return None, None
        from drive_server.model import SteeringModel
        from drive_server.monitor import MonitorMode, MonitorPolicy
        from drive_server.pipeline import DriveConfig, DrivePipeline

        pipeline = DrivePipeline(SteeringModel(Path(path)), DriveConfig(monitor=MonitorPolicy(MonitorMode.WARN,
                                                                                                   budget_ms=None)))
        if pipeline.monitor_spec is None:
            raise BadValue(f"monitor={path}: the model file carries no misbehaviour monitor",
                           "attach one with rbc monitor fit")
        return pipeline, None

    def _monitor_input(self, jpeg: bytes) -> np.ndarray:
        """The centre frame as drive_server would prepare it for the monitor's model (decoded from the wire's JPEG
        at the model's scale when there is one)."""
        from drive_server.preprocess import preprocess
        from protocol.jpeg import decode_jpeg

        pipeline = self._monitor_pipeline
        assert pipeline is not None  # _info scores only with a monitor
        rgb = decode_jpeg(jpeg, pipeline.reduce) if jpeg else self._frame
        assert rgb is not None  # _info scores only after a frame was rendered
        return preprocess(rgb, pipeline.contract)
