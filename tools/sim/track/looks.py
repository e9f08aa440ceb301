"""How a track looks beyond its geometry (track format version 2): road edges, sky and the camera image.

Every default here is what version 1 drew, so a track without these keys renders exactly as before.
They are parsed by :mod:`tools.sim.track.v2`; the renderer applies them in :mod:`tools.sim.render.texture`,
:mod:`tools.sim.render.sky` and :mod:`tools.sim.render.postfx`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from protocol.facts import JPEG_QUALITY

LINE_COLORS = ("white", "yellow")
LINE_STYLES = ("solid", "dashed", "none")
CENTER_COLORS = ("theme", "white", "yellow")  # theme: the theme palette's "dash" colour (version 1)
#: shoulder: the theme's shoulder colour (version 1); concrete: the real lake's light kerb strip
VERGES = ("shoulder", "grass", "sand", "dirt", "gravel", "concrete")


@dataclass(frozen=True)
class Edges:
    """Markings and what lies beside the road."""

    line_color: str = "white"  # edge lines
    line_style: str = "solid"
    center_color: str = "theme"  # centre line of a two-lane road
    center_style: str = "dashed"
    verge: str = "shoulder"  # colour of the shoulder band
    barriers: bool = False  # metal guard rails on the outside of sharp curves


@dataclass(frozen=True)
class SkySpec:
    """Sky panorama: cloud noise seed and amount, optional colours overriding the theme's."""

    seed: int = 3
    cloud_threshold: float = 0.15  # noise level above which clouds form (file key "clouds" = 0.65 - this)
    zenith: tuple[int, int, int] | None = None
    haze: tuple[int, int, int] | None = None  # horizon and fog colour

    @property
    def clouds(self) -> float:
        return 0.65 - self.cloud_threshold


@dataclass(frozen=True)
class FrameJitter:
    """Per-frame standard deviations, drawn from the renderer's seeded generator."""

    exposure_ev: float = 0.0
    contrast: float = 0.0
    white_balance: float = 0.0  # per-channel gain
    noise: float = 0.0  # extra sensor noise, grey levels

    @property
    def active(self) -> bool:
        return bool(self.exposure_ev or self.contrast or self.white_balance or self.noise)


@dataclass(frozen=True)
class Appearance:
    """Per-world appearance: palette overrides, ground texture and the camera's image processing."""

    seed: int = 0  # ground texture noise
    palette: tuple[tuple[str, tuple[int, int, int]], ...] = ()  # theme palette entries replaced
    grain: float = 1.0  # fine texture grain amplitude
    texture_scale: float = 1.0  # size of the large-scale ground colour blotches
    exposure_ev: float = 0.0
    contrast: float = 1.0
    white_balance: tuple[float, float, float] = (1.0, 1.0, 1.0)  # RGB gains
    haze: float = 1.0  # fog density factor
    blur: float = 0.0  # Gaussian blur sigma, pixels
    noise: float = 0.0  # sensor noise standard deviation, grey levels
    jpeg_quality: int = JPEG_QUALITY
    jitter: FrameJitter = field(default_factory=FrameJitter)

    @property
    def tone_mapped(self) -> bool:
        """Whether frames need the exposure/contrast/white-balance table (not for version-1 tracks)."""
        return bool(self.exposure_ev or self.contrast != 1.0 or self.white_balance != (1.0, 1.0, 1.0)
                    or self.jitter.exposure_ev or self.jitter.contrast or self.jitter.white_balance)

    @property
    def postprocessed(self) -> bool:
        return self.tone_mapped or self.blur > 0 or self.noise > 0 or self.jitter.noise > 0
