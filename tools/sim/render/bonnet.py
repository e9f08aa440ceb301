"""The car's bonnet as the real simulator's cameras see it: a light grey dome across the bottom of the frame.

Measured on the real lake frames (the shared sample, 613 rows): in the centre camera the bonnet's top
edge is at row 137 in the middle and meets the bottom of the frame about 104 columns to either side
(a parabola: row 150 at +-78 columns); it is light grey, about (172, 178, 164) just below the edge and
(160, 165, 150) lower down, and it reflects the scene, so its brightness follows the light. In the side
cameras it is the same shape moved about 110 columns towards the car (0.95 m at about 1.2 m ahead).
Drawn procedurally: nothing is taken from the Unity project or the recordings.
"""

from __future__ import annotations

import numpy as np

from protocol.camera import BONNET_ROW
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

#: Top row of the bonnet's edge in the middle of the centre camera's frame.
TOP_ROW = float(BONNET_ROW)
#: Rows the edge drops per column squared away from the bonnet's middle (row 150 at +-78 columns).
CURVE = 13.0 / 78.0**2
#: Colour just below the edge and at the bottom of the frame (RGB at light intensity 1).
TOP_RGB = np.array([172.0, 178.0, 164.0])
BOTTOM_RGB = np.array([160.0, 165.0, 150.0])
#: Columns the bonnet moves in a side camera per metre of its lateral offset (110 px for 0.95 m).
SHIFT_PX_PER_M = 116.0
#: The frame rows the bonnet can cover.
ROWS = slice(int(TOP_ROW), FRAME_HEIGHT)


class BonnetLayer:
    """The bonnet of one camera: per pixel its coverage (0..1, anti-aliased edge) and colour, split for speed.

    Most pixels are either fully covered or not at all; only the edge's pixels need the blend. Drawing blends
    those alone, copies the fully covered ones from a table per light level, and leaves the rest: the same
    float32 operations pixel for pixel as blending the whole strip, so the same bytes, at a fifth of the cost.
    """

    def __init__(self, coverage: np.ndarray, colour: np.ndarray) -> None:
        self.coverage, self.colour = coverage, colour
        cov, col = coverage[ROWS], colour[ROWS]
        # where the bonnet hides the scene: one run of columns per row (the edge is a parabola)
        self.full_runs = [(r, int(cols[0]), int(cols[-1]) + 1) for r in range(cov.shape[0])
                          if len(cols := np.flatnonzero(cov[r, :, 0] == 1.0))]
        if any(b - a != int((cov[r, a:b, 0] == 1.0).sum()) for r, a, b in self.full_runs):
            raise ValueError("the bonnet's fully covered pixels must be one run of columns per row")
        self.edge = np.nonzero((cov[..., 0] > 0.0) & (cov[..., 0] < 1.0))
        self.edge_cov = cov[self.edge]
        self.edge_keep = 1 - self.edge_cov
        self.edge_colour = col[self.edge]
        self._col, self._cov = col, cov
        self._full_rgb: dict[float, np.ndarray] = {}

    def full_rgb(self, light: float) -> np.ndarray:
        """The fully covered pixels' colour at ``light`` (the blend's value where the scene's weight is 0)."""
        hit = self._full_rgb.get(light)
        if hit is None:
            hit = np.clip(self._col * light * self._cov + 0.5, 0, 255).astype(np.uint8)
            if len(self._full_rgb) > 64:
                self._full_rgb.clear()
            self._full_rgb[light] = hit
        return hit



def bonnet_layer(lateral_m: float) -> BonnetLayer:
    """Coverage (HxWx1 float32 in 0..1) and colour (HxWx3 float32) of the bonnet for a camera ``lateral_m``
    metres left of the car's centre line (+ = left camera: the bonnet moves right)."""
    v, u = np.mgrid[0:FRAME_HEIGHT, 0:FRAME_WIDTH].astype(np.float64)
    middle = (FRAME_WIDTH - 1) / 2 + lateral_m * SHIFT_PX_PER_M
    edge = TOP_ROW + CURVE * (u - middle) ** 2
    coverage = np.clip(v + 0.5 - edge, 0.0, 1.0)  # anti-aliased: the share of the pixel below the edge
    depth = np.clip((v - edge) / max(1.0, FRAME_HEIGHT - TOP_ROW), 0.0, 1.0)[..., None]
    colour = TOP_RGB * (1 - depth) + BOTTOM_RGB * depth
    return BonnetLayer(coverage[..., None].astype(np.float32), colour.astype(np.float32))


def draw_bonnet(frame: np.ndarray, layer: BonnetLayer, light: float) -> np.ndarray:
    """The bonnet over an RGB uint8 frame, its brightness scaled like the scene's (``light``).

    Per pixel: ``frame * (1 - coverage) + colour * light * coverage``, rounded (float32), as
    :func:`blend_bonnet` computes for the whole strip.
    """
    light = min(1.6, max(0.2, light))
    strip = frame[ROWS]
    full = layer.full_rgb(light)
    for r, a, b in layer.full_runs:
        strip[r, a:b] = full[r, a:b]
    part = strip[layer.edge].astype(np.float32) * layer.edge_keep + layer.edge_colour * light * layer.edge_cov
    strip[layer.edge] = np.clip(part + 0.5, 0, 255).astype(np.uint8)
    return frame


def blend_bonnet(frame: np.ndarray, layer: BonnetLayer, light: float) -> np.ndarray:
    """:func:`draw_bonnet` the plain way, over every pixel of the strip (the reference its tests compare with)."""
    cov = layer.coverage[ROWS]
    part = frame[ROWS].astype(np.float32) * (1 - cov) + layer.colour[ROWS] * min(1.6, max(0.2, light)) * cov
    frame[ROWS] = np.clip(part + 0.5, 0, 255).astype(np.uint8)
    return frame
