"""Kinematic bicycle model of the simulated car, stepped at a fixed physics rate for determinism, and
the parameters of the car shared with the dynamic single-track model (:mod:`tools.sim.vehicle.dynamics`).

The Udacity car is a Unity wheel-collider model; at the speeds of the paper (25-45 km/h) on flat
roads a kinematic bicycle with a first-order longitudinal model reproduces what matters for
behavioral cloning: the turning radius for a wheel angle, a steering rate limit, a top speed
of about 30 mph and braking. The state is kept at the rear axle (where the turning radius is
exactly ``L / tan(delta)``); ``centre`` gives the body centre used for cameras, collisions and
cross-track error.

Sign convention of the simulator and its logs (Unity's): positive steering turns RIGHT (clockwise
seen from above), while the world frame is mathematical (x east, y north, yaw counter-clockwise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from protocol import MAX_STEERING_DEG
from protocol.errors import BadValue

MPS_PER_KMH = 1.0 / 3.6
GRAVITY_MPS2 = 9.81
#: The car models ``ScenarioConfig.vehicle`` chooses from; the first is the default.
VEHICLE_KINDS = ("dynamic", "kinematic")


def kmh_to_mps(speed_kmh: float) -> float:
    return speed_kmh * MPS_PER_KMH


def mps_to_kmh(speed_mps: float) -> float:
    return speed_mps * 3.6


@dataclass(frozen=True)
class VehicleParams:
    """The car: geometry, actuators, and the dynamic model's mass, tyres, engine and drag.

    Defaults: a mid-size car like the Udacity one (paper: width 1.9 m). The kinematic model uses the
    geometry, the steering limits, the ``*_mps2`` longitudinal model and the top speed; the dynamic
    single-track model (:mod:`tools.sim.vehicle.dynamics`) uses everything but the ``*_mps2`` fields.
    """

    wheelbase_m: float = 2.7
    length_m: float = 4.6
    width_m: float = 1.9
    max_steer_deg: float = MAX_STEERING_DEG
    # Unity's keyboard axis ramps at 3 units/s (sensitivity 3): 3 x 25 deg = 75 deg/s. The wheel
    # follows any command (keyboard or network) no faster than that.
    steer_rate_deg_s: float = 3.0 * MAX_STEERING_DEG
    max_accel_mps2: float = 3.5  # kinematic: full throttle from standstill
    max_brake_mps2: float = 7.0  # kinematic: full brake (throttle -1)
    rolling_mps2: float = 0.15  # kinematic: rolling resistance when coasting
    # The stock Udacity car tops out at 30.19 mph; the paper's modified car was driven up to 100 km/h
    # (Table 10), which the speed-limit experiment needs. Set 30.19 * KMH_PER_MPH for the stock car.
    top_speed_kmh: float = 130.0
    physics_hz: int = 60  # simulation frames per second (the kinematic model steps once per frame)

    # --- dynamic single-track model (vehicle "dynamic") ----------------------------------------------
    # A 1.5 t saloon with 55 % of its weight on the front axle; yaw inertia about m * lf * lr
    mass_kg: float = 1500.0
    yaw_inertia_kgm2: float = 2700.0
    cg_to_front_axle_m: float = 1.2  # the rear axle is wheelbase_m - this behind the centre of gravity
    cg_height_m: float = 0.55  # longitudinal load transfer
    # Axle cornering stiffness (both tyres), about 10 and 15 times the static axle load per radian:
    # understeer gradient (m / L) (lr / Cf - lf / Cr) = 3.8e-3 rad per m/s^2 (2.1 deg/g), a typical saloon.
    cornering_stiffness_front_n_per_rad: float = 80_000.0
    cornering_stiffness_rear_n_per_rad: float = 100_000.0
    drive_force_max_n: float = 5_250.0  # 3.5 m/s^2 from standstill, like the kinematic car
    engine_power_w: float = 90_000.0  # above ~17 m/s the drive force is power / speed
    drive_front_share: float = 0.5  # Unity Standard Assets' CarController (the Udacity car): four-wheel drive
    # Full pedal asks for more than the tyres give (1.2 g), as on any modern car; ABS keeps each axle
    # at its friction limit mu * Fz instead of locking.
    brake_force_max_n: float = 18_000.0
    brake_front_share: float = 0.65
    drag_area_m2: float = 0.65  # Cd x frontal area = 0.30 x 2.2 m^2
    air_density_kg_m3: float = 1.2
    rolling_resistance: float = 0.012  # coefficient (force / weight), radial tyres on asphalt
    # Peak tyre-road friction per surface kind (tools.sim.track.road.SURFACE_KINDS; a kind missing here
    # gets asphalt's): Wong, Theory of Ground Vehicles, 4th ed., ch. 1, average coefficients of road
    # adhesion (dry asphalt 0.8-0.9, dry concrete 0.8-0.9, dry earth road 0.68, gravel 0.6); the
    # wooden bridge is taken as a wet-asphalt-like 0.7, loose gravel 0.55, worn (polished) asphalt 0.8.
    surface_friction: tuple[tuple[str, float], ...] = (("asphalt", 0.9), ("bridge", 0.7), ("dirt", 0.6),
                                                       ("concrete", 0.85), ("gravel", 0.55),
                                                       ("worn_asphalt", 0.8))
    # Axle friction = surface friction x these. With equal factors both axles reach their limit at once
    # (the brush model's peak is mu Fz on each) and any deceleration tips the car into a spin; production
    # cars are set up to push their front tyres first (tyre load sensitivity, front roll stiffness), which
    # a single-track model can only express as a front/rear grip balance.
    front_grip_factor: float = 0.95
    rear_grip_factor: float = 1.05
    # Below kinematic_below_mps the car follows the kinematic bicycle exactly, above dynamic_above_mps
    # the tyre model alone; linear blend in between (the slip angles are singular at standstill).
    kinematic_below_mps: float = 1.5
    dynamic_above_mps: float = 4.0
    dynamics_hz: int = 180  # integration rate of the dynamic model, independent of physics_hz frames

    def __post_init__(self) -> None:
        if self.wheelbase_m <= 0 or self.max_steer_deg <= 0 or self.steer_rate_deg_s <= 0:
            raise BadValue("wheelbase, steering limit and steering rate must be positive")
        if self.physics_hz <= 0:
            raise BadValue(f"physics rate must be positive, got {self.physics_hz}")
        if self.max_accel_mps2 <= self.rolling_mps2:
            raise BadValue("max_accel_mps2 must exceed rolling_mps2 or the car can never reach its top speed")
        if not 0 < self.cg_to_front_axle_m < self.wheelbase_m:
            raise BadValue("the centre of gravity must lie between the axles")
        if min(self.mass_kg, self.yaw_inertia_kgm2, self.cornering_stiffness_front_n_per_rad,
               self.cornering_stiffness_rear_n_per_rad, self.dynamics_hz) <= 0:
            raise BadValue("mass, yaw inertia, cornering stiffness and dynamics_hz must be positive")
        if not 0 <= self.kinematic_below_mps < self.dynamic_above_mps:
            raise BadValue("need 0 <= kinematic_below_mps < dynamic_above_mps")
        if any(mu <= 0 for _, mu in self.surface_friction):
            raise BadValue("surface friction coefficients must be positive")

    @property
    def dt(self) -> float:
        return 1.0 / self.physics_hz

    @property
    def top_speed_mps(self) -> float:
        return kmh_to_mps(self.top_speed_kmh)

    @property
    def cg_to_rear_axle_m(self) -> float:
        return self.wheelbase_m - self.cg_to_front_axle_m

    def friction(self, surface: str) -> float:
        """Peak tyre-road friction coefficient on ``surface`` (asphalt's for a kind not listed)."""
        table = dict(self.surface_friction)
        return table.get(surface, table.get("asphalt", 0.9))

    @property
    def drag_per_mps2(self) -> float:
        """Quadratic drag coefficient chosen so full throttle balances drag exactly at the top speed."""
        return (self.max_accel_mps2 - self.rolling_mps2) / self.top_speed_mps**2


@dataclass(frozen=True)
class VehicleState:
    """Rear-axle pose (metres, radians, x east / y north), speed (m/s, never negative), wheel angle
    (radians, + = right as in Unity)."""

    x: float
    y: float
    yaw: float
    speed: float = 0.0
    steer: float = 0.0
    throttle: float = 0.0  # applied accelerator input 0..1 (what Unity reports as "throttle")
    brake: float = 0.0  # applied brake input 0..1
    yaw_rate: float = 0.0  # rad/s, counter-clockwise (dynamic model; the kinematic one leaves 0)
    slip: float = 0.0  # body slip angle at the centre of gravity, rad, + = sliding left (dynamic model)


class Vehicle:
    """Integrates commands at ``params.physics_hz``; one ``step`` is one physics frame."""

    def __init__(self, state: VehicleState, params: VehicleParams | None = None) -> None:
        self.params = params or VehicleParams()
        self.state = state
        self.friction = 1.0  # the simulation sets the surface's; a kinematic car never slides, so unused

    # --- geometry -------------------------------------------------------------------------------
    @property
    def centre(self) -> tuple[float, float]:
        """Body centre (half a wheelbase ahead of the rear axle)."""
        s = self.state
        h = 0.5 * self.params.wheelbase_m
        return s.x + h * math.cos(s.yaw), s.y + h * math.sin(s.yaw)

    def place(self, cx: float, cy: float, yaw: float, speed: float = 0.0) -> None:
        """Put the body centre at (cx, cy) heading ``yaw`` with wheels straight (spawn, intervention reset)."""
        h = 0.5 * self.params.wheelbase_m
        self.state = VehicleState(cx - h * math.cos(yaw), cy - h * math.sin(yaw), yaw, max(0.0, speed))

    @property
    def steering_deg(self) -> float:
        return math.degrees(self.state.steer)

    # --- dynamics -------------------------------------------------------------------------------
    def step(self, steering: float, throttle: float) -> VehicleState:
        """Advance one physics frame with a command: steering -1..1 (x max angle), throttle -1..1 (<0 brakes)."""
        p, s, dt = self.params, self.state, self.params.dt
        steering = min(1.0, max(-1.0, steering))
        throttle = min(1.0, max(-1.0, throttle))
        max_steer = math.radians(p.max_steer_deg)
        target = steering * max_steer
        max_change = math.radians(p.steer_rate_deg_s) * dt
        steer = s.steer + min(max_change, max(-max_change, target - s.steer))

        accel_in, brake_in = max(0.0, throttle), max(0.0, -throttle)
        resist = p.drag_per_mps2 * s.speed * s.speed + (p.rolling_mps2 if s.speed > 0 else 0.0)
        accel = accel_in * p.max_accel_mps2 - brake_in * p.max_brake_mps2 - resist
        speed = min(p.top_speed_mps, max(0.0, s.speed + accel * dt))

        # exact arc for constant speed and wheel angle over the step (average speed of the step)
        v = 0.5 * (s.speed + speed)
        omega = -v * math.tan(steer) / p.wheelbase_m  # + steer = right = clockwise
        yaw = s.yaw + omega * dt
        if abs(omega) > 1e-9:
            x = s.x + v / omega * (math.sin(yaw) - math.sin(s.yaw))
            y = s.y - v / omega * (math.cos(yaw) - math.cos(s.yaw))
        else:
            x = s.x + v * dt * math.cos(s.yaw)
            y = s.y + v * dt * math.sin(s.yaw)
        yaw = math.remainder(yaw, math.tau)
        self.state = VehicleState(x, y, yaw, speed, steer, accel_in, brake_in)
        return self.state

    def with_speed(self, speed_mps: float) -> None:
        self.state = replace(self.state, speed=max(0.0, min(self.params.top_speed_mps, speed_mps)))
