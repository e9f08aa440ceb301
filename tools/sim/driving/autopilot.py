"""A scripted driver that drives like the paper's humans at a keyboard.

Why imitate the keyboard instead of steering smoothly: behavioral cloning learns from the labels'
distribution, and the paper's data (like every Udacity recording) is dominated by exactly-zero
steering with short pulses in between, because a key press ramps Unity's input axis up and a
release lets it fall back to 0. A pure-pursuit controller says what steering the driver wants; the
driver approximates it with key presses whose peaks average to that value.

The driving line is the centre line (right-lane centre on 2-lane tracks), bent around cones to the
free half of the road, with a speed profile that slows for curves and swerves. Reaction time is
drawn from a seeded generator, so different seeds drive differently and each seed reproducibly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol import SteerCommand
from protocol.facts import COLLECT_SPEED_KMH
from tools.sim.driving.rules import TrackFollower, angle_diff
from tools.sim.track.road import Track
from tools.sim.vehicle.kinematic import VehicleParams, VehicleState, kmh_to_mps


@dataclass(frozen=True)
class AutopilotParams:
    speed_kmh: float = COLLECT_SPEED_KMH  # the paper collected data at 30 km/h
    lookahead_s: float = 0.9  # pure-pursuit look-ahead, seconds of travel ...
    lookahead_min_m: float = 6.0  # ... but at least this far
    max_lat_accel: float = 2.5  # m/s^2 in curves and swerves
    max_decel: float = 2.0  # m/s^2 when slowing for a curve ahead
    key_rate: float = 3.0  # Unity axis sensitivity: units/s while a key is held
    release_rate: float = 3.0  # Unity axis gravity: units/s back to exactly 0 (math.inf = snap)
    deadband: float = 0.04  # wanted steering below this: no key
    hold_above: float = 0.6  # wanted steering above this: keep the key down
    decide_every_s: tuple[float, float] = (0.25, 0.5)  # a person re-decides this often (seeded draw)
    urgent: float = 0.3  # ... but reacts at once when the wanted steering changes more than this
    speed_band_kmh: float = 0.8  # press the accelerator below target - band
    brake_above_kmh: float = 3.0  # press the brake above target + this
    cone_clearance_m: float = 3.0  # lateral distance from a cone's centre to the car's line while passing
    cone_hold_m: float = 5.0  # stay on the swerve line this far before and after a cone
    cone_ramp_m: float = 16.0  # metres to move onto / off the swerve line


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(math.pi * u)


class DrivingLine:
    """Where the autopilot wants to be (lateral offset per track sample) and how fast.

    Offsets are in the lap frame: metres to the LEFT of the lap direction. Arrays are indexed like
    the track's samples; ``direction`` -1 drives them backwards.
    """

    def __init__(self, track: Track, direction: int, cones: np.ndarray | None, params: AutopilotParams,
                 bias_m: float = 0.0) -> None:
        self.track, self.direction, self.params = track, direction, params
        n = len(track.s)
        base = (-track.road_width / 4 if track.lanes == 2 else 0.0) + bias_m
        offset = np.full(n, base)
        if cones is not None and len(cones):
            offset = self._around_cones(offset, base, cones)
        self.offset = offset
        self.points = track.centerline + track.normals * (offset * direction)[:, None]
        self.speed = self._speed_profile()

    def _around_cones(self, offset: np.ndarray, base: float, cones: np.ndarray) -> np.ndarray:
        t, p = self.track, self.params
        half = t.road_width / 2 - 1.4  # keep the car's centre this far inside the edge
        weights, targets = [], []
        for cx, cy in cones:
            proj = t.project(float(cx), float(cy))
            lat = proj.cte * self.direction
            side = -1.0 if lat > 0 else 1.0
            target = float(np.clip(lat + side * p.cone_clearance_m, -half, half))
            # distance along the lap from the cone to every sample (+ = after the cone)
            d = (t.s - proj.s) * self.direction
            d = (d + t.length / 2) % t.length - t.length / 2
            w = np.where(d < 0, _smoothstep((d + p.cone_hold_m + p.cone_ramp_m) / p.cone_ramp_m),
                         _smoothstep((p.cone_hold_m + p.cone_ramp_m - d) / p.cone_ramp_m))
            weights.append(w)
            targets.append(target)
        w = np.array(weights)
        total = w.sum(0)
        blended = (w * np.array(targets)[:, None]).sum(0) + np.maximum(0.0, 1.0 - total) * base
        return blended / np.maximum(1.0, total)

    def _speed_profile(self) -> np.ndarray:
        t, p = self.track, self.params
        order = np.arange(len(t.s)) if self.direction > 0 else np.arange(len(t.s))[::-1]
        pts = self.points[order]
        d1 = np.roll(pts, -1, 0) - pts
        heading = np.arctan2(d1[:, 1], d1[:, 0])
        ds = np.maximum(np.linalg.norm(d1, axis=1), 1e-6)
        kappa = np.abs(np.angle(np.exp(1j * (np.roll(heading, -1) - heading)))) / ds
        kappa = np.convolve(np.concatenate([kappa[-4:], kappa, kappa[:4]]), np.ones(9) / 9, "valid")
        v = np.minimum(kmh_to_mps(p.speed_kmh), np.sqrt(p.max_lat_accel / np.maximum(kappa, 1e-6)))
        n = len(v)
        for _ in range(2):  # backward pass around the loop: brake in time for what comes
            for i in range(n - 1, -1, -1):
                j = (i + 1) % n
                v[i] = min(v[i], math.sqrt(v[j] ** 2 + 2 * p.max_decel * ds[i]))
        out = np.empty(n)
        out[order] = v
        return out

    def index(self, s: float) -> int:
        return int(round((s % self.track.length) / self.track.spacing)) % len(self.track.s)

    def point_ahead(self, s: float, distance: float) -> np.ndarray:
        return self.points[self.index(s + self.direction * distance)]


class KeyAxis:
    """Unity's keyboard input axis: ramps toward +-1 while a key is held, falls back to exactly 0 after."""

    def __init__(self, key_rate: float, release_rate: float) -> None:
        self.key_rate, self.release_rate = key_rate, release_rate
        self.key = 0  # -1, 0, +1
        self.value = 0.0

    def update(self, dt: float) -> float:
        if self.key:
            if self.value * self.key < 0:  # Unity "snap": pressing the opposite key jumps to 0 first
                self.value = 0.0
            self.value = max(-1.0, min(1.0, self.value + self.key * self.key_rate * dt))
        elif self.value:
            step = self.release_rate * dt
            # exactly 0 at the end (no float residue: a logged -1e-17 would not count as zero steering)
            self.value = 0.0 if abs(self.value) <= step + 1e-9 else self.value - math.copysign(step, self.value)
        return self.value


class Autopilot:
    """Pure pursuit on the driving line, approximated with steering and pedal key presses."""

    def __init__(self, track: Track, direction: int = 1, cones: np.ndarray | None = None,
                 params: AutopilotParams | None = None, vehicle: VehicleParams | None = None, seed: int = 0) -> None:
        self.params = p = params or AutopilotParams()
        self.vehicle = vehicle or VehicleParams()
        self.track, self.direction = track, direction
        self.rng = np.random.default_rng(seed)
        bias = float(self.rng.uniform(-0.15, 0.15))  # each "driver" keeps a slightly different line
        self.speed_bias_kmh = float(self.rng.uniform(-0.7, 0.7))
        self.line = DrivingLine(track, direction, cones, p, bias_m=bias)
        self.steer_axis = KeyAxis(p.key_rate, p.release_rate)
        self.pedal_axis = KeyAxis(p.key_rate, math.inf)
        self._s: float | None = None
        self._follower: TrackFollower | None = None
        self._clock = 0.0
        self._next_decision = 0.0
        self._decided = 0.0
        self._peak = 0.0

    def wanted_steering(self, state: VehicleState) -> float:
        """Pure-pursuit steering (normalised -1..1, + = right) from the rear axle toward the look-ahead point."""
        L = self.vehicle.wheelbase_m
        cx, cy = state.x + 0.5 * L * math.cos(state.yaw), state.y + 0.5 * L * math.sin(state.yaw)
        if self._follower is None:
            self._follower = TrackFollower(self.track, cx, cy)
        proj = self._follower.project(cx, cy)
        self._s = proj.s
        ahead = max(self.params.lookahead_min_m, state.speed * self.params.lookahead_s)
        tx, ty = self.line.point_ahead(proj.s, ahead)
        dx, dy = tx - state.x, ty - state.y
        alpha = angle_diff(math.atan2(dy, dx), state.yaw)
        dist = max(1.0, math.hypot(dx, dy))
        delta = math.atan2(2.0 * L * math.sin(alpha), dist)  # + = left in the world frame
        return max(-1.0, min(1.0, -math.degrees(delta) / self.vehicle.max_steer_deg))  # + = right (Unity)

    def target_speed_mps(self) -> float:
        s = self._s if self._s is not None else self.track.start_s
        return float(self.line.speed[self.line.index(s)]) + kmh_to_mps(self.speed_bias_kmh)

    def update(self, dt: float, state: VehicleState) -> SteerCommand:
        """One decision step of ``dt`` seconds; returns the keyboard axes (steering, throttle/brake).

        Steering: at each decision the driver taps the key for a pulse whose area (a ramp up and a
        ramp down of the axis) equals the wanted steering times the time to the next decision; above
        ``hold_above`` the key stays down. Between pulses the axis is exactly 0.
        """
        p = self.params
        self._clock += dt
        want = self.wanted_steering(state)
        axis = self.steer_axis
        if axis.key and (abs(axis.value) >= self._peak or want * axis.key < -p.deadband):
            axis.key = 0
        if self._clock >= self._next_decision or abs(want - self._decided) > p.urgent:
            period = float(self.rng.uniform(*p.decide_every_s))
            self._next_decision = self._clock + period
            self._decided = want
            if abs(want) >= p.deadband:
                axis.key = 1 if want > 0 else -1
                # a triangular pulse of peak P has area P^2 / 2 * (1 / key_rate + 1 / release_rate)
                ramps = 0.5 * (1.0 / p.key_rate + 1.0 / p.release_rate)
                self._peak = 1.0 if abs(want) >= p.hold_above else min(1.0, math.sqrt(abs(want) * period / ramps))
        steering = axis.update(dt)

        target = self.target_speed_mps()
        v = state.speed
        pedal = self.pedal_axis
        if v < target - kmh_to_mps(p.speed_band_kmh):
            pedal.key = 1
        elif v > target + kmh_to_mps(p.brake_above_kmh):
            pedal.key = -1
        elif (pedal.key > 0 and v >= target) or (pedal.key < 0 and v <= target):
            pedal.key = 0
        throttle = pedal.update(dt)
        return SteerCommand(steering=steering, throttle=throttle)
