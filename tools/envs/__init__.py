"""The headless simulator as a Gymnasium environment, ``rbc/Drive-v0`` (``pip install -e ".[gym]"``; SB3: ``[rl]``).

Importing this package registers it, so ``gymnasium.make("tools.envs:rbc/Drive-v0", track="lake")`` needs no
other import. Ten lines with the autopilot driving::

    import gymnasium as gym

    env = gym.make("tools.envs:rbc/Drive-v0", track="lake", render_mode="rgb_array")
    obs, info = env.reset(seed=0)
    total = 0.0
    for _ in range(500):
        obs, reward, terminated, truncated, info = env.step(info["expert_action"])
        total += reward
        if terminated or truncated:
            obs, info = env.reset()
    print(f"{total:.0f} m, cte {info['cte_m']:+.2f} m, {info['speed_kmh']:.1f} km/h")

Keyword arguments (:class:`DriveEnvConfig`): ``track`` (a built-in name, a track file or ``world:SEED``) or
``world_seed``; ``purpose`` ("train" refuses evaluation worlds as ``rbc collect`` does, "eval" allows them);
``camera`` (the rig: "unity", "classic"); ``cameras`` (1 or 3); ``control`` ("steer": throttle and brake from
the paper's Eq. 14 exactly as drive_server computes them, or "steer_throttle"); ``law`` (drive_server's
``ControlLaw`` or a dict of its fields; its speed limit is a governor with steer_throttle too); ``jpeg``
(default True: the wire's JPEG round trip); ``laps``; ``max_episode_steps``; ``spawn`` ("start" or "random");
``action_delay`` (1: Unity's two frames in flight); ``render_mode`` (None, "rgb_array": the centre camera as
rendered, or "human": in a window, with pygame); ``worlds`` (:class:`WorldDistribution`: a new world, sun,
light and fog per episode, training worlds only); ``observation`` ("frame", or "model": the network's own
64x64 input by a preprocessing ``contract``) and ``speed`` (a Dict observation with the speed); and more in
the config. ``reset(options=...)`` pins one episode's world, light, fog, sun or spawn.

Spaces: the observation is the centre camera's frame, uint8 (160, 320, 3) RGB, decoded from the JPEG the
simulator would send (``jpeg=True``, the pixels drive_server and recorded datasets have), or the network's
input (``observation="model"``); with ``cameras=3`` or ``speed=True`` a ``Dict`` of "center" (and "left" and
"right") images and "speed" (km/h) (SB3: ``MultiInputPolicy``). The action is a float32 ``Box``
in [-1, 1]: steering (+ = right, 1 = 25 degrees), and with ``steer_throttle`` throttle (< 0 brakes).

Reward (:class:`RewardConfig`, ``reward={...}``): by default metres along the lap (about 1,003 a lake lap),
less 2.5 per second with the car's body over its lane's edge, less 10 on a take-over; gym-donkeycar's
``(1 - |cte| / max_cte) * speed`` (``lane_per_m``, ``max_cte_m``) and a speed term (``speed_per_m``) are
off by default. ``terminated``: the referee took over (off the road, a cone, spun out, wrong
way, stuck; ``info["intervention"]`` says which); with ``terminate_on_takeover=False`` the episode goes on from
where the referee put the car back (the take-over still costs its penalty and is named in ``info``: DAgger's
learner drives on). ``truncated``: the laps are driven (``info["laps_done"]``), the lap's time limit or
``max_episode_steps``.

``info``: ``cte_m`` (from the car's line, + = left), ``heading_error_deg`` (+ = turned left of the lap),
``speed_kmh``, ``progress_m``, ``lap_progress`` (laps driven), ``t_s``, ``step``, ``expert_action`` (the
autopilot's pure-pursuit steering for this state, as an action: the DAgger label), ``intervention``,
``laps_done`` and, with ``jpeg=True``, ``jpeg`` (the centre frame's bytes as on the wire). At an SB3 VecEnv's
auto-reset the step's ``expert_action`` labels the new episode's first observation, the one returned with it,
and ``terminal_expert_action`` the terminal one (``terminal_observation``).

:class:`OnnxPolicy` drives it with a model from ``rbc train`` through drive_server's pipeline:
``policy = OnnxPolicy("models/pretrained/generalist.onnx"); action = policy(obs, info)``. :class:`ExpertPolicy`
is the autopilot as a policy bound to the env(s) it labels: SB3's ``predict``, imitation's policy callable and
(``.sb3()``) an SB3 ``BasePolicy``. :func:`pin_workers` puts each worker of a vector env (Gymnasium's
``AsyncVectorEnv``, SB3's ``SubprocVecEnv``) on a CPU of its own, which a sleeping-and-waking worker needs to keep
its caches (Linux).
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

from tools.envs.affinity import pin_workers
from tools.envs.config import DriveEnvConfig, RewardConfig
from tools.envs.drive_env import DriveEnv
from tools.envs.expert import ExpertPolicy
from tools.envs.policy import OnnxPolicy
from tools.envs.worlds import WorldDistribution

ENV_ID = "rbc/Drive-v0"

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="tools.envs.drive_env:make")  # DriveEnv; "human": in a window

__all__ = ["ENV_ID", "DriveEnv", "DriveEnvConfig", "ExpertPolicy", "OnnxPolicy", "RewardConfig", "WorldDistribution",
           "pin_workers"]
