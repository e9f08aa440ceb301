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

from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

#: Top row of the bonnet's edge in the middle of the centre camera's frame.
TOP_ROW = 137.0
#: Rows the edge drops per column squared away from the bonnet's middle (row 150 at +-78 columns).
CURVE = 13.0 / 78.0**2
#: Colour just below the edge and at the bottom of the frame (RGB at light intensity 1).
TOP_RGB = np.array([172.0, 178.0, 164.0])
BOTTOM_RGB = np.array([160.0, 165.0, 150.0])
#: Columns the bonnet moves in a side camera per metre of its lateral offset (110 px for 0.95 m).
SHIFT_PX_PER_M = 116.0


def bonnet_layer(lateral_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(coverage HxWx1 float32 in 0..1, colour HxWx3 float32) of the bonnet for a camera ``lateral_m``
    metres left of the car's centre line (+ = left camera: the bonnet moves right)."""
    v, u = np.mgrid[0:FRAME_HEIGHT, 0:FRAME_WIDTH].astype(np.float64)
    middle = (FRAME_WIDTH - 1) / 2 + lateral_m * SHIFT_PX_PER_M
    edge = TOP_ROW + CURVE * (u - middle) ** 2
    coverage = np.clip(v + 0.5 - edge, 0.0, 1.0)  # anti-aliased: the share of the pixel below the edge
    depth = np.clip((v - edge) / max(1.0, FRAME_HEIGHT - TOP_ROW), 0.0, 1.0)[..., None]
    colour = TOP_RGB * (1 - depth) + BOTTOM_RGB * depth
    return coverage[..., None].astype(np.float32), colour.astype(np.float32)


def draw_bonnet(frame: np.ndarray, layer: tuple[np.ndarray, np.ndarray], light: float) -> np.ndarray:
    """The bonnet over an RGB uint8 frame, its brightness scaled like the scene's (``light``)."""
    coverage, colour = layer
    rows = slice(int(TOP_ROW), FRAME_HEIGHT)
    cov = coverage[rows]
    part = frame[rows].astype(np.float32) * (1 - cov) + colour[rows] * min(1.6, max(0.2, light)) * cov
    frame[rows] = np.clip(part + 0.5, 0, 255).astype(np.uint8)
    return frame
