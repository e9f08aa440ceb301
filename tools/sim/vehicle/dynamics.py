"""Dynamic single-track ("bicycle") model with tyre slip: the car that runs wide and slides at speed.

Why: the kinematic bicycle turns on ``L / tan(delta)`` at any speed, so a steering model never meets
the limits the paper's speed-limit experiment found in Unity. Here the tyres need slip angles to make
lateral force, the force saturates at ``mu * Fz``, and the path radius for a wheel angle grows with
speed (understeer) until the car cannot follow the road at all.

Why not CommonRoad's implementation (``commonroad-vehicle-models`` 3.0.2, measured by
``rbc sim-bench``, :mod:`tools.bench.vehicle_models`): its cost is fine (ST 1.3-2.8 us, STD
7.6-11.9 us per Euler step on this CPU; this model 4.1-5.7 us per step, 12-17 us per 60 Hz frame),
but its ST model has LINEAR tyres (``F_y = mu * C_S * F_z * alpha``): lateral acceleration never
saturates (10 g at 30 m/s and 0.3 rad in the measurement) and, with the same cornering coefficient
per unit load front and rear, the published cars steer neutrally, so neither understeer nor a grip
limit appears. Its STD model has saturating Pacejka tyres but wheel-spin states whose stiffness
needs kHz steps near standstill (explicit Euler at 180 Hz rolls it backwards at a stop). So the
same single-track equations are written here, with a saturating brush tyre.

Equations (body frame at the centre of gravity: x forward, y left, yaw rate r counter-clockwise;
Rajamani, *Vehicle Dynamics and Control*, 2nd ed., 2012, sec. 2.3; CommonRoad: Althoff & Wuersching,
*CommonRoad: Vehicle Models*, 2020, single-track model)::

    m (dvx/dt - vy r) = Fxf cos(d) - Fyf sin(d) + Fxr - F_res,x
    m (dvy/dt + vx r) = Fxf sin(d) + Fyf cos(d) + Fyr - F_res,y
    Iz dr/dt          = lf (Fxf sin(d) + Fyf cos(d)) - lr Fyr
    alpha_f = atan2(vy + lf r, vx) - d,   alpha_r = atan2(vy - lr r, vx)
    Fzf = m (g lr - a_x h) / L,   Fzr = m (g lf + a_x h) / L        (longitudinal load transfer)

Lateral tyre force: the brush (Fiala) model, Pacejka, *Tire and Vehicle Dynamics*, 3rd ed., 2012,
sec. 3.2, in the form of Hindiyeh & Gerdes, "A controller framework for autonomous drifting", 2014,
with the friction circle derating ``Fy_max = sqrt((mu Fz)^2 - Fx^2)``. The axles' friction is the
surface's times a front/rear grip balance (0.95 / 1.05) so that the car understeers at the limit
(see ``VehicleParams``). Longitudinal force: engine
(``min(F_max, P / v)``) and brakes split per axle, each axle held at ``mu * Fz`` at most (ABS, no wheel
states). Resistance: aerodynamic drag ``rho Cd A v^2 / 2`` and rolling resistance ``c_rr m g``.

Low speed: the slip angles are singular at standstill. Below ``kinematic_below_mps`` the velocity
state is the kinematic bicycle's (``vy = lr r``, ``r = vx tan(d) / L``), above ``dynamic_above_mps``
the tyre model's, blended linearly in speed in between (the kinematic/dynamic blend of Kabzan et al.,
"AMZ Driverless: The full autonomous racing system", arXiv 1905.05150, 2019). Blending the states
rather than the derivatives puts the car exactly on the kinematic path at walking speed.

Integration: explicit Euler for the velocities at ``dynamics_hz`` (180 Hz: 3 steps per 60 Hz
simulation frame, whatever the camera and telemetry rates), positions with the mid-step heading.
Pure Python floats in a fixed order: bit-for-bit reproducible.
"""

from __future__ import annotations

import math

from protocol.errors import BadValue
from tools.sim.vehicle.kinematic import GRAVITY_MPS2, VEHICLE_KINDS, Vehicle, VehicleParams, VehicleState

__all__ = ["DynamicVehicle", "brush_lateral_force", "make_vehicle"]

#: The governor fades the drive force out over this last stretch below the top speed (no on/off chatter).
GOVERNOR_BAND_MPS = 0.5


def brush_lateral_force(alpha: float, stiffness: float, f_max: float) -> float:
    """Lateral force (N) of an axle at slip angle ``alpha`` (rad): brush model, saturating at ``f_max``."""
    if f_max <= 0.0:
        return 0.0
    t = math.tan(alpha)
    if abs(t) >= 3.0 * f_max / stiffness:  # the whole contact patch slides
        return -math.copysign(f_max, alpha)
    return (-stiffness * t + stiffness * stiffness / (3.0 * f_max) * abs(t) * t
            - stiffness ** 3 / (27.0 * f_max * f_max) * t ** 3)


class DynamicVehicle:
    """Single-track car with tyre slip; the same interface as :class:`tools.sim.vehicle.kinematic.Vehicle`.

    One ``step`` advances one simulation frame (``1 / physics_hz``) by as many ``1 / dynamics_hz``
    integration steps as fall into it. ``friction`` is the tyre-road coefficient under the car; the
    simulation sets it from the surface every frame.
    """

    def __init__(self, state: VehicleState, params: VehicleParams | None = None) -> None:
        self.params = p = params or VehicleParams()
        self.friction = p.friction("asphalt")
        self._lf, self._lr, self._L = p.cg_to_front_axle_m, p.cg_to_rear_axle_m, p.wheelbase_m
        self._dt = 1.0 / p.dynamics_hz
        self._frames = 0  # frames and integration steps taken: integer bookkeeping, no drift
        self._steps = 0
        yaw = state.yaw
        self._X = state.x + self._lr * math.cos(yaw)  # centre of gravity
        self._Y = state.y + self._lr * math.sin(yaw)
        self._psi = yaw
        self._delta = -state.steer  # + = left inside this module (Unity: + = right)
        self._vx = max(0.0, state.speed)
        tan_d = math.tan(self._delta)
        self._vy = self._vx * tan_d * self._lr / self._L  # start on the kinematic path
        self._r = self._vx * tan_d / self._L
        self._ax = 0.0
        self.state = self._snapshot(state.throttle, state.brake)

    # --- the interface the simulation uses ----------------------------------------------------------
    @property
    def centre(self) -> tuple[float, float]:
        """Body centre (half a wheelbase ahead of the rear axle), as for the kinematic car."""
        s = self.state
        h = 0.5 * self._L
        return s.x + h * math.cos(s.yaw), s.y + h * math.sin(s.yaw)

    def place(self, cx: float, cy: float, yaw: float, speed: float = 0.0) -> None:
        """Put the body centre at (cx, cy) heading ``yaw``, wheels straight, rolling straight at ``speed``."""
        off = self._lr - 0.5 * self._L  # centre of gravity ahead of the body centre
        self._X, self._Y, self._psi = cx + off * math.cos(yaw), cy + off * math.sin(yaw), yaw
        self._delta, self._vx, self._vy, self._r, self._ax = 0.0, max(0.0, speed), 0.0, 0.0, 0.0
        self.state = self._snapshot(0.0, 0.0)

    @property
    def steering_deg(self) -> float:
        return math.degrees(self.state.steer)

    def with_speed(self, speed_mps: float) -> None:
        """Scale the velocity state to ``speed_mps`` (same direction of travel and path curvature)."""
        speed_mps = max(0.0, min(self.params.top_speed_mps, speed_mps))
        v = math.hypot(self._vx, self._vy)
        if v > 0.0:
            k = speed_mps / v
            self._vx, self._vy, self._r = self._vx * k, self._vy * k, self._r * k
        else:
            self._vx = speed_mps
        self.state = self._snapshot(self.state.throttle, self.state.brake)

    def step(self, steering: float, throttle: float) -> VehicleState:
        """Advance one simulation frame with a command: steering -1..1 (+ = right), throttle -1..1 (<0 brakes)."""
        p = self.params
        steering = min(1.0, max(-1.0, steering))
        throttle = min(1.0, max(-1.0, throttle))
        accel_in, brake_in = max(0.0, throttle), max(0.0, -throttle)
        self._frames += 1
        target = self._frames * p.dynamics_hz // p.physics_hz
        target_delta = -steering * math.radians(p.max_steer_deg)
        for _ in range(target - self._steps):
            self._integrate(target_delta, accel_in, brake_in)
        self._steps = target
        self.state = self._snapshot(accel_in, brake_in)
        return self.state

    # --- internals ----------------------------------------------------------------------------------
    def _snapshot(self, accel_in: float, brake_in: float) -> VehicleState:
        c, s = math.cos(self._psi), math.sin(self._psi)
        slip = math.atan2(self._vy, self._vx) if self._vx > 0.0 or self._vy else 0.0
        return VehicleState(self._X - self._lr * c, self._Y - self._lr * s, math.remainder(self._psi, math.tau),
                            math.hypot(self._vx, self._vy), -self._delta, accel_in, brake_in, self._r, slip)

    def _integrate(self, target_delta: float, accel_in: float, brake_in: float) -> None:
        """One integration step of ``1 / dynamics_hz`` (the equations of the module docstring)."""
        p, dt, lf, lr, L = self.params, self._dt, self._lf, self._lr, self._L
        m, g, mu = p.mass_kg, GRAVITY_MPS2, self.friction
        max_change = math.radians(p.steer_rate_deg_s) * dt
        d = self._delta + min(max_change, max(-max_change, target_delta - self._delta))
        vx, vy, r = self._vx, self._vy, self._r
        v = math.hypot(vx, vy)

        # axle loads (load transfer from the previous step's acceleration) and longitudinal forces
        fzf = max(0.0, m * (g * lr - self._ax * p.cg_height_m) / L)
        fzr = max(0.0, m * (g * lf + self._ax * p.cg_height_m) / L)
        governor = min(1.0, max(0.0, (p.top_speed_mps - v) / GOVERNOR_BAND_MPS))
        drive = accel_in * governor * min(p.drive_force_max_n, p.engine_power_w / max(v, 1e-3))
        brake = brake_in * p.brake_force_max_n if vx > 0.0 else 0.0  # brakes hold a stopped car, never reverse it
        cap_f, cap_r = mu * p.front_grip_factor * fzf, mu * p.rear_grip_factor * fzr
        fxf = min(cap_f, max(-cap_f, drive * p.drive_front_share - brake * p.brake_front_share))
        fxr = min(cap_r, max(-cap_r, drive * (1.0 - p.drive_front_share) - brake * (1.0 - p.brake_front_share)))
        resist = (0.5 * p.air_density_kg_m3 * p.drag_area_m2 * v * v + p.rolling_resistance * m * g) if v > 0.0 else 0.0
        cos_d, sin_d = math.cos(d), math.sin(d)

        lo, hi = p.kinematic_below_mps, p.dynamic_above_mps
        w = min(1.0, max(0.0, (v - lo) / (hi - lo)))
        ax = (fxf * cos_d + fxr - resist) / m
        vx_new = vx + ax * dt
        vy_new = r_new = 0.0
        if w < 1.0:  # kinematic bicycle: no lateral slip at either axle
            tan_d = math.tan(d)
            vy_new, r_new = vx_new * tan_d * lr / L, vx_new * tan_d / L
        if w > 0.0:  # tyre forces (v >= kinematic_below_mps > 0 here: no singularity)
            avx = abs(vx)  # a spinning car may slide backwards: the force still opposes the lateral sliding
            fyf = brush_lateral_force(math.atan2(vy + lf * r, avx) - d, p.cornering_stiffness_front_n_per_rad,
                                      math.sqrt(max(0.0, cap_f * cap_f - fxf * fxf)))
            fyr = brush_lateral_force(math.atan2(vy - lr * r, avx), p.cornering_stiffness_rear_n_per_rad,
                                      math.sqrt(max(0.0, cap_r * cap_r - fxr * fxr)))
            front_y = fxf * sin_d + fyf * cos_d
            fx = fxf * cos_d - fyf * sin_d + fxr - resist * vx / v
            fy = front_y + fyr - resist * vy / v
            ax_dyn = fx / m
            vx_dyn = vx + (ax_dyn + vy * r) * dt
            vy_dyn = vy + (fy / m - vx * r) * dt
            r_dyn = r + (lf * front_y - lr * fyr) / p.yaw_inertia_kgm2 * dt
            k = 1.0 - w
            vx_new, vy_new, r_new = w * vx_dyn + k * vx_new, w * vy_dyn + k * vy_new, w * r_dyn + k * r_new
            ax = w * ax_dyn + k * ax
        v_new = math.hypot(vx_new, vy_new)
        if vx_new < 0.0 and v_new < lo:  # come to rest: the brakes hold it (a car never reverses here)
            vx_new = vy_new = r_new = v_new = 0.0
        if v_new > p.top_speed_mps:  # the governor (Unity's CarController caps the speed the same way)
            k = p.top_speed_mps / v_new
            vx_new, vy_new = vx_new * k, vy_new * k

        psi_mid = self._psi + 0.5 * r_new * dt
        c, s = math.cos(psi_mid), math.sin(psi_mid)
        self._X += (vx_new * c - vy_new * s) * dt
        self._Y += (vx_new * s + vy_new * c) * dt
        self._psi += r_new * dt
        self._delta, self._vx, self._vy, self._r, self._ax = d, vx_new, vy_new, r_new, ax


def make_vehicle(kind: str, state: VehicleState, params: VehicleParams | None = None) -> Vehicle | DynamicVehicle:
    """The car model ``kind`` (one of :data:`tools.sim.vehicle.kinematic.VEHICLE_KINDS`) at ``state``."""
    if kind == "kinematic":
        return Vehicle(state, params)
    if kind == "dynamic":
        return DynamicVehicle(state, params)
    raise BadValue(f"unknown vehicle model {kind!r} (known: {', '.join(VEHICLE_KINDS)})")
