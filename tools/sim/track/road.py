"""Tracks as data: a closed road, its surfaces and scenery, and the queries the simulator makes of it.

A track file (:mod:`tools.sim.track.files`) gives a handful of centre-line control points; they are
smoothed and resampled every ~0.5 m (:mod:`tools.sim.track.spline`). Everything else in the simulator
(rendering, rules, autopilot) works on the resampled line, so every query here is an array lookup.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from protocol.errors import BadValue
from tools.sim.track.looks import Appearance, Edges, SkySpec
from tools.sim.track.themes import THEMES as THEMES  # re-exported: the track file names themes
from tools.sim.track.themes import V1_THEMES as V1_THEMES

log = logging.getLogger(__name__)

#: Road surface kinds; the order is fixed (indices are stored per sample), new kinds are appended.
SURFACE_KINDS = ("asphalt", "bridge", "dirt", "concrete", "gravel", "worn_asphalt")
V1_SURFACE_KINDS = SURFACE_KINDS[:3]  # what a version-1 track file may use
MIN_TURN_RADIUS = 6.0  # metres: a 2.7 m wheelbase at 25 degrees turns on ~5.8 m


class TrackError(BadValue):
    """A track file (or dict) is missing something or describes a road that cannot be driven."""

    hint = "the track file format is in docs/formats.md (File formats: Track file)"


@dataclass(frozen=True)
class Surface:
    """A stretch of road from ``from_s`` to ``to_s`` (metres, may wrap past the start) of one kind."""

    from_s: float
    to_s: float
    kind: str

    def contains(self, s: float, length: float) -> bool:
        a, b, s = self.from_s % length, self.to_s % length, s % length
        return a <= s < b if a <= b else (s >= a or s < b)


@dataclass(frozen=True)
class TreeSpec:
    count: int = 0
    seed: int = 0
    min_offset: float = 7.0  # metres from the centre line
    max_offset: float = 40.0
    min_height: float = 4.0  # total height, metres
    max_height: float = 9.0


@dataclass(frozen=True)
class PoleSpec:
    spacing: float = 35.0  # metres along the line; 0 disables
    offset: float = -5.5  # metres from the centre line, signed like cte (+ = left); -: outside of a CCW loop
    height: float = 6.0


@dataclass(frozen=True)
class WaterSpec:
    """An elliptic pond; the road crossing it should be a bridge surface."""

    center: tuple[float, float]
    radius: tuple[float, float]
    angle_deg: float = 0.0


@dataclass(frozen=True)
class Scenery:
    theme: str = "meadow"
    trees: TreeSpec = field(default_factory=TreeSpec)
    poles: PoleSpec = field(default_factory=lambda: PoleSpec(spacing=0.0))
    water: tuple[WaterSpec, ...] = ()
    kerbs: bool = False  # red/white kerbs on the inside of sharp curves


@dataclass(frozen=True)
class CameraJitter:
    """Standard deviation of per-frame camera pitch/roll noise, imitating a bumpy road on flat ground."""

    pitch_deg: float = 0.0
    roll_deg: float = 0.0


@dataclass(frozen=True)
class Projection:
    s: float  # arc length of the closest centre-line point, [0, length)
    cte: float  # signed cross-track error, metres, + = left of the centre line
    heading_rad: float  # centre-line heading at s (world frame, x east, y north, counter-clockwise)


@dataclass(frozen=True, eq=False)
class Track:
    """A validated, resampled closed track; immutable, so Worlds can be cached by :attr:`digest`."""

    name: str
    road_width: float
    lanes: int
    shoulder_width: float
    surfaces: tuple[Surface, ...]
    scenery: Scenery
    sun_azimuth_deg: float
    sun_elevation_deg: float
    start_s: float
    camera_jitter: CameraJitter
    centerline: np.ndarray  # (N, 2) float64, closed, first point not repeated
    tangents: np.ndarray  # (N, 2) unit
    normals: np.ndarray  # (N, 2) unit, pointing left of the driving direction
    curvature: np.ndarray  # (N,) signed 1/m, + = turning left
    s: np.ndarray  # (N,) arc length at each point
    length: float
    source: str
    description: str = ""
    digest: str = ""  # hash of the parsed definition: equal digests draw identical worlds
    version: int = 1
    edges: Edges = field(default_factory=Edges)
    sky: SkySpec = field(default_factory=SkySpec)
    appearance: Appearance = field(default_factory=Appearance)

    def __post_init__(self) -> None:
        for arr in (self.centerline, self.tangents, self.normals, self.curvature, self.s):
            arr.flags.writeable = False

    @property
    def spacing(self) -> float:
        return self.length / len(self.s)

    @property
    def min_radius(self) -> float:
        return float(1.0 / max(np.abs(self.curvature).max(), 1e-9))

    def point_at(self, s: float) -> tuple[float, float, float]:
        """Centre-line point and heading at arc length ``s`` (wraps modulo the length)."""
        s = float(s) % self.length
        u = s / self.spacing
        i = int(u) % len(self.s)
        j = (i + 1) % len(self.s)
        f = u - int(u)
        p = self.centerline[i] * (1 - f) + self.centerline[j] * f
        t = self.tangents[i] * (1 - f) + self.tangents[j] * f
        return float(p[0]), float(p[1]), math.atan2(t[1], t[0])

    def project(self, x: float, y: float, hint_s: float | None = None) -> Projection:
        """Closest centre-line point to (x, y): arc length, signed cross-track error and heading.

        ``hint_s`` (the previous answer) restricts the search to +-25 m around it, which is what a
        vehicle stepping along the road needs and avoids snapping to a nearby parallel stretch.
        """
        n = len(self.s)
        p = np.array([x, y], dtype=np.float64)
        if hint_s is not None:
            w = int(25.0 / self.spacing)
            idx = (int(round((hint_s % self.length) / self.spacing)) + np.arange(-w, w + 1)) % n
            d2 = ((self.centerline[idx] - p) ** 2).sum(1)
            k = int(np.argmin(d2))
            if d2[k] > (2.0 * self.road_width) ** 2 or k in (0, len(idx) - 1):  # lost: search everywhere
                hint_s = None
            else:
                i = int(idx[k])
        if hint_s is None:
            i = int(np.argmin(((self.centerline - p) ** 2).sum(1)))
        # refine on the segment before or after the closest sample
        best: tuple[float, int, int, float, np.ndarray] | None = None
        for a in ((i - 1) % n, i):
            b = (a + 1) % n
            seg = self.centerline[b] - self.centerline[a]
            f = float(np.clip(np.dot(p - self.centerline[a], seg) / np.dot(seg, seg), 0.0, 1.0))
            q = self.centerline[a] + f * seg
            d2 = float(((p - q) ** 2).sum())
            if best is None or d2 < best[0]:
                best = (d2, a, b, f, q)
        assert best is not None  # the loop above runs twice
        _, a, b, f, q = best
        t = self.tangents[a] * (1 - f) + self.tangents[b] * f
        t /= np.linalg.norm(t)
        nrm = np.array([-t[1], t[0]])
        s = (self.s[a] + f * self.spacing) % self.length
        return Projection(float(s), float(np.dot(p - q, nrm)), math.atan2(t[1], t[0]))

    def surface_at(self, s: float) -> str:
        """Surface kind under arc length ``s``; later entries in the file win over earlier ones."""
        for surf in reversed(self.surfaces):
            if surf.contains(s, self.length):
                return surf.kind
        return "asphalt"

    def surface_kinds(self) -> np.ndarray:
        """Surface kind index (into :data:`SURFACE_KINDS`) of every resampled point."""
        out = np.zeros(len(self.s), np.int8)
        for surf in self.surfaces:
            a, b = surf.from_s % self.length, surf.to_s % self.length
            m = (self.s >= a) & (self.s < b) if a <= b else (self.s >= a) | (self.s < b)
            out[m] = SURFACE_KINDS.index(surf.kind)
        return out




