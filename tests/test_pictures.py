"""Pictures a person can read: real text, take-overs marked, axes in words, strips of sensible size."""

from __future__ import annotations

import numpy as np
import pytest

from protocol import SteerCommand
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH
from tools.evaluate.experiments import EXPERIMENTS
from tools.sim.driving.rules import Cause, Intervention
from tools.sim.driving.scenario import FrameEvent
from tools.sim.pictures.text import draw_text, text_size
from tools.sim.pictures.viz import TAKEOVER_MARK_S, StripCollector, annotate
from tools.sim.vehicle.kinematic import VehicleState


def _event(t: float, intervention: Intervention | None = None, seed: int = 0) -> FrameEvent:
    rgb = np.random.default_rng(seed).integers(60, 200, (FRAME_HEIGHT, FRAME_WIDTH, 3), dtype=np.uint8)
    return FrameEvent(t, 1, rgb, VehicleState(0.0, 0.0, 0.0, speed=6.0), SteerCommand(0.1, 0.2), intervention)


def test_text_is_drawn_with_a_real_font_and_grows_with_its_size():
    img = np.zeros((40, 200, 3), np.uint8)
    draw_text(img, "speed 22.6 km/h", (4, 24), px=14)
    assert img.max() > 200 and 50 < (img > 0).any(axis=2).sum() < 2000
    assert text_size("speed", 28)[0] > 1.8 * text_size("speed", 14)[0]


def test_a_take_over_is_marked_on_the_frame_then_fades():
    iv = Intervention(Cause.OFF_ROAD, 100.0, 0.0, 0.0, 10.0)
    plain = annotate(_event(10.5))
    marked = annotate(_event(10.5, iv))
    later = annotate(_event(10.0 + TAKEOVER_MARK_S + 0.5, iv))
    border = (slice(0, 3), slice(None))
    assert not np.array_equal(marked[border], plain[border])  # a coloured frame around the picture
    assert np.array_equal(later[border], plain[border])


def test_the_strip_keeps_a_frame_of_every_take_over():
    strip = StripCollector(every_s=100.0)
    iv1 = Intervention(Cause.OFF_ROAD, 100.0, 0.0, 0.0, 12.0)
    iv2 = Intervention(Cause.CONE, 180.0, 0.0, 0.0, 30.0)
    for k, t in enumerate(np.arange(0.0, 40.0, 1 / 15)):
        iv = iv2 if t >= 30.0 else iv1 if t >= 12.0 else None
        strip(_event(float(t), iv, seed=k % 3))
    assert len(strip.frames) == 3  # the first frame, then one per take-over, none else in 100 s


def test_strips_are_written_as_jpeg_of_sensible_size(tmp_path):
    strip = StripCollector(every_s=0.0)
    for k in range(24):
        strip(_event(float(k), seed=k))
    path = strip.write(tmp_path / "strip.jpg")
    data = path.read_bytes()
    assert data[:2] == b"\xff\xd8" and len(data) < 2_500_000


@pytest.mark.parametrize("exp", [e for e in EXPERIMENTS if e.measure != "eta"], ids=lambda e: e.key)
def test_every_plotted_experiment_names_its_axis_in_words_with_a_unit(exp):
    assert exp.axis and "_" not in exp.axis and "(" in exp.axis
