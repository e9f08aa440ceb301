"""rbc realism: the band statistics see what they claim to, and the gap is 0 for the same frames."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tools.cli import main
from tools.realism.frames import nearest
from tools.realism.stats import BANDS, frame_stats, gaps, keys

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"


def _frame(bonnet: int = 90, road_noise: float = 0.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.full((160, 320, 3), 120, np.uint8)
    img[:50] = (150, 190, 230)  # sky
    road = 110 + rng.normal(0, road_noise, (37, 320, 1)) if road_noise else np.full((37, 320, 1), 110.0)
    img[100:137] = np.clip(road, 0, 255).astype(np.uint8)
    img[137:] = bonnet
    return img


def test_each_band_measures_its_own_rows():
    s = frame_stats(_frame(bonnet=200))
    assert s["bonnet.brightness"] == 200 and s["sky.blue"] == 230 and s["sky.red"] == 150
    assert len(s) == len(keys()) == len(BANDS) * 8


def test_a_coarse_road_has_more_edges_and_is_sharper_than_a_smooth_one():
    smooth, coarse = frame_stats(_frame()), frame_stats(_frame(road_noise=40))
    assert coarse["near_road.edges"] > smooth["near_road.edges"] + 0.1
    assert coarse["near_road.sharpness"] > smooth["near_road.sharpness"] + 1
    assert coarse["bonnet.brightness"] == smooth["bonnet.brightness"]  # other bands untouched


def test_gaps_are_in_the_real_frames_spread_and_signed():
    real = [frame_stats(_frame(bonnet=b)) for b in (130, 140, 150)]
    sim = [frame_stats(_frame(bonnet=b)) for b in (90, 95)]
    gap = {g.key: g for g in gaps(real, sim)}["bonnet.brightness"]
    assert gap.real_mean == 140 and gap.sim_mean == 92.5
    assert gap.standardized < -5  # far below, in units of the real frames' spread (8.2)


def test_the_nearest_frame_of_a_frame_is_itself():
    frames = [_frame(bonnet=b, seed=b) for b in (60, 120, 200)]
    assert [k for k, _ in nearest(frames[::-1], frames)] == [2, 1, 0]


def test_rbc_realism_on_the_same_recording_finds_no_gap(tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["realism", "--real", str(SAMPLE), "--sim", str(SAMPLE), "--frames", "12", "--json", str(out),
                 "--out", str(tmp_path / "r.png")]) == 0
    doc = json.loads(out.read_text())
    assert doc["overall_gap"] == 0 and all(g["standardized"] == 0 for g in doc["gaps"])
    assert (tmp_path / "r.png").stat().st_size > 10_000
    assert "overall gap" in capsys.readouterr().out


def test_a_folder_without_frames_is_one_line(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["realism", "--real", str(tmp_path / "empty"), "--sim", str(SAMPLE)]) == 2
    assert "error:" in capsys.readouterr().err
