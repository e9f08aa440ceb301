"""The paper's coupled longitudinal control law (Eq. 14) with explicit units.

xi = tau * ((v_l - v_a) / v_l - |theta| / delta), clamped to [-1, 1]; xi > 0 is throttle,
xi < 0 brakes. theta and delta are both in DEGREES here: the authors' code divided a normalised
theta by delta = 25, which made the steering term ~25x too small; we do not copy that.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from protocol.errors import BadValue
from protocol.facts import DEPLOY_SPEED_KMH, MAX_STEERING_DEG


@dataclass(frozen=True)
class ControlLaw:
    """Parameters of Eq. 14. Speeds in km/h, angles in degrees."""

    speed_limit_kmh: float = DEPLOY_SPEED_KMH
    steer_limit_deg: float = MAX_STEERING_DEG
    tau: float = 1.0

    def __post_init__(self) -> None:
        for name, value in (("speed_limit_kmh", self.speed_limit_kmh), ("steer_limit_deg", self.steer_limit_deg),
                            ("tau", self.tau)):
            if not isinstance(value, numbers.Real) or isinstance(value, bool):
                raise BadValue(f"{name} must be a number, got {value!r}")
        if not (math.isfinite(self.speed_limit_kmh) and self.speed_limit_kmh > 0):
            raise BadValue(f"speed limit must be a positive number, got {self.speed_limit_kmh} km/h")
        if not (math.isfinite(self.steer_limit_deg) and self.steer_limit_deg > 0):
            raise BadValue(f"steering limit must be a positive number, got {self.steer_limit_deg} deg")
        if not 0.0 <= self.tau <= 1.0:
            raise BadValue(f"tau must be in [0, 1], got {self.tau}")

    def steering_deg(self, normalised: float) -> float:
        """The wheel angle in degrees of a normalised steering command (-1..1: full lock is ``steer_limit_deg``)."""
        return normalised * self.steer_limit_deg

    def command(self, steering_deg: float, speed_kmh: float) -> float:
        """Throttle/brake command xi for a predicted steering angle (deg) and actual speed (km/h)."""
        xi = self.tau * ((self.speed_limit_kmh - speed_kmh) / self.speed_limit_kmh
                         - abs(steering_deg) / self.steer_limit_deg)
        return max(-1.0, min(1.0, xi))
