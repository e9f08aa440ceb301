"""Which track a recording was driven on, and how that track's road looks to the road finder
(:mod:`tools.drivelog.road_view`).

The three tracks of the Udacity simulators differ in what borders the road and what lies on it: the lake
road has yellow edge lines and nothing inside them; the jungle road (track 2 of the current simulator) has
white edge lines and a dashed white centre line between its two lanes, and steep rock walls throw shadows
across it; the mountain road (the first simulator's track 2) is dark, without lines, between orange leaves,
concrete barriers and rock walls. A recording's track is told from its asphalt's colour alone (the median
straight ahead over the recording): lake asphalt is a little yellow, jungle asphalt light and grey, mountain
asphalt dark. On the 39 public recordings that told every one right (200 frames each), the nearest other
track's colour at least 0.8 typical spreads further than its own (kadway, jungle; 0.8-1.1 for the four closest):
``rbc drive-log --track`` names it where a recording's colour is in doubt; laps of the headless simulator
name their track in their rig file (:func:`recorded_track`), whose asphalt no real track's colour matches.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from protocol.rigfile import read_track


@dataclass(frozen=True)
class TrackProfile:
    """How the road finder treats one track's road."""

    name: str
    # the asphalt's colour straight ahead (OpenCV's 8-bit Lab), the median over the public recordings' medians
    asphalt_lab: tuple[float, float, float]
    # gaps up to this wide (m) in a row of road pixels, with the asphalt's chroma whatever their lightness, are
    # road: the jungle's white dashed centre line lies inside the road (0: the lake, whose lines are its edges)
    line_gap_m: float = 0.0
    # the road in shadow is road too: a second asphalt colour, learnt from the recording's darker ground
    # straight ahead (the jungle's rock walls shade half the road)
    shade: bool = False
    # the ground ahead seen at its own pitch in every frame, measured on the side cameras (tools.drivelog.pitch):
    # the jungle's and the mountain's hills (the lake is flat: its figures stay as calibrated)
    ground_pitch: bool = False
    # a side seen alone is believed where the road's middle it proposes is within this of what the frames around
    # propose (m): the lake's 1 m outvotes a sunlit patch; on the jungle one lane's edge is all a frame sees in
    # two frames of three, and in a hairpin the road's middle moves metres within the 30 frames that vote
    consensus_m: float = 1.0


#: The tracks' profiles. Lake: the finder as calibrated there. Jungle: its dashes are 0.2-0.3 m wide in the
#: top-down view (blurred), so 0.6 m closes them and not a lane (3-4 m); its shade is 100 L units darker
#: than the sunlit asphalt and 10 units bluer (b*). Mountain: dark asphalt under shade of its own walls.
TRACK_PROFILES: dict[str, TrackProfile] = {
    "lake": TrackProfile("lake", (133.0, 125.0, 135.0)),
    "jungle": TrackProfile("jungle", (156.0, 128.0, 130.0), line_gap_m=0.6, shade=True, ground_pitch=True,
                           consensus_m=2.5),
    "mountain": TrackProfile("mountain", (64.0, 129.0, 129.0), shade=True, ground_pitch=True),
}
#: Typical spread (L, a, b) of a recording's asphalt colour straight ahead: the scale on which a recording's
#: asphalt is compared with the tracks' (lightness varies 20 units with sun and shade, chroma 3).
DETECT_SCALE = (20.0, 3.0, 3.0)


def profile(track: str | None, asphalt_median: np.ndarray | None) -> TrackProfile:
    """The profile of ``track``; None: of the track whose asphalt colour is nearest ``asphalt_median``."""
    if track is not None:
        if track not in TRACK_PROFILES:
            raise ValueError(f"unknown track {track!r} ({', '.join(TRACK_PROFILES)})")
        return TRACK_PROFILES[track]
    if asphalt_median is None:
        raise ValueError("no track given, and no asphalt colour to tell it from")
    return TRACK_PROFILES[detect_track(asphalt_median)]


def recorded_track(data: Path | str) -> str | None:
    """The track the recording in ``data`` says it was driven on (the headless simulator's laps of one named
    track), where a profile of that name exists; None: to be told from the frames."""
    track = read_track(data)
    return track if track in TRACK_PROFILES else None


def detect_track(asphalt_median: np.ndarray) -> str:
    """The track whose asphalt colour (Lab median straight ahead) is nearest, in typical spreads."""
    scale = np.asarray(DETECT_SCALE)
    return min(TRACK_PROFILES, key=lambda name: float(np.linalg.norm(
        (np.asarray(asphalt_median, np.float64) - TRACK_PROFILES[name].asphalt_lab) / scale)))
