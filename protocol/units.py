"""Speed units: the stock Udacity simulator reports mph, the paper's modified one km/h."""

from __future__ import annotations

from enum import StrEnum
from typing import TYPE_CHECKING, overload

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

KMH_PER_MPH = 1.609344


class SpeedUnit(StrEnum):
    MPH = "mph"
    KMH = "kmh"


@overload
def to_kmh(speed: float, unit: SpeedUnit | str) -> float: ...
@overload
def to_kmh(speed: NDArray[np.float64], unit: SpeedUnit | str) -> NDArray[np.float64]: ...
def to_kmh(speed: float | NDArray[np.float64], unit: SpeedUnit | str) -> float | NDArray[np.float64]:
    """Convert a telemetry speed in ``unit`` (one, or an array of them) to km/h."""
    return speed * KMH_PER_MPH if SpeedUnit(unit) is SpeedUnit.MPH else speed


def from_kmh(speed_kmh: float, unit: SpeedUnit | str) -> float:
    """Convert a speed in km/h to ``unit`` (what a simulator puts on the wire)."""
    return speed_kmh / KMH_PER_MPH if SpeedUnit(unit) is SpeedUnit.MPH else speed_kmh
