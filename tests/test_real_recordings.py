"""Training on real Unity recordings (issue 13): block split, best-epoch export, crop through the contract,
the speed filter and its unit, the brightness mode, and inspection figures on validation frames only."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from models.data.split import SplitSpec, block_split, make_split
from models.training.train_config import TrainConfig
from protocol.datalog import read_log
from protocol.datalog_writer import LogWriter
from tools.arguments import parse_speed

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"


# ---- the split -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [36, 613, 2400, 12101])
def test_block_split_holds_out_whole_stretches_with_a_gap(n: int) -> None:
    spec = SplitSpec("blocks", block_frames=100, gap_frames=10)
    train, val = block_split(n, seed=3, spec=spec)
    assert len(np.intersect1d(train, val)) == 0 and len(train) and len(val)
    block = max(1, min(100, n // 5))
    gap = min(10, block // 4)
    block_of = np.minimum(np.arange(n) // block, n // block - 1)  # a short remainder joins the last block
    held = set(block_of[val])
    # every frame of a held-out block is held out; no training frame is within the gap of one
    assert set(val) == {i for i in range(n) if block_of[i] in held}
    distance = np.min(np.abs(train[:, None] - val[None, :]), axis=1)
    assert distance.min() > gap
    assert 0.1 <= len(val) / n <= 0.3


def test_block_split_is_reproducible_by_seed() -> None:
    a = block_split(2400, 5)
    assert all(np.array_equal(x, y) for x, y in zip(a, block_split(2400, 5), strict=True))
    assert not np.array_equal(a[1], block_split(2400, 6)[1])


def test_random_split_is_still_the_papers() -> None:
    train, val = make_split(12101, 3, SplitSpec("random"))
    assert (len(train), len(val)) == (9680, 2421)


def test_runs_recorded_before_the_split_option_read_as_what_they_did() -> None:
    old = TrainConfig.from_dict({"data": ["x"], "out": "y", "behavior": "simplistic"})
    assert (old.split, old.export) == ("random", "last")
    new = TrainConfig(data=["x"], out="y")
    assert (new.split, new.export) == ("blocks", "best")


# ---- speed filter ---------------------------------------------------------------------------------------------

def _log_with_speeds(folder: Path, speeds: list[float]) -> Path:
    samples, _ = read_log(SAMPLE)
    (folder / "IMG").mkdir(parents=True)
    with LogWriter(folder / "driving_log.csv") as w:
        for s, v in zip(samples, speeds, strict=False):
            names = []
            for cam in (s.center, s.left, s.right):
                shutil.copy(cam, folder / "IMG" / cam.name)
                names.append(str(folder / "IMG" / cam.name))
            w.write(names, s.steering, 0.2, 0.0, v)
    return folder


@pytest.mark.parametrize(("log_unit", "threshold", "unit", "dropped"), [
    ("mph", 5.0, "mph", 3),  # 0, 3, 4.9 mph
    ("mph", 7.0, "kmh", 2),  # 7 km/h = 4.35 mph: 0 and 3 mph
    ("kmh", 5.0, "mph", 4),  # 5 mph = 8.05 km/h: 0, 3, 4.9, 5 km/h
])
def test_min_speed_drops_slow_rows_in_its_own_unit(tmp_path: Path, log_unit: str, threshold: float, unit: str,
                                                   dropped: int) -> None:
    from models.data.behavior import pipeline_for
    from models.data.trainingdata import DataOptions, prepare_data

    data = _log_with_speeds(tmp_path / "rec", [0.0, 3.0, 4.9, 5.0, 10.0, 30.0] * 3)
    options = DataOptions(SplitSpec("random"), threshold, unit, log_unit)
    prepared = prepare_data([data], pipeline_for("simplistic", "shallow", "ours"), 0, options, workers=1)
    assert prepared.counts["slow"] == dropped * 3 and prepared.counts["kept"] == 18 - dropped * 3
    speeds = np.array([s.speed for s in prepared.dataset.samples])
    kept = np.concatenate([prepared.train, prepared.val])
    assert speeds[kept].min() >= (4.9 if (log_unit, unit) == ("mph", "kmh") else 5.0)
    line = prepared.summary(options)
    assert "18 read, 0 skipped" in line and f"{dropped * 3} dropped below {threshold:g} {unit}" in line


def test_min_speed_parsing() -> None:
    assert parse_speed("5mph", "kmh") == (5.0, "mph")
    assert parse_speed("8 km/h", "mph") == (8.0, "kmh")
    assert parse_speed("3", "kmh") == (3.0, "kmh")
    with pytest.raises(ValueError, match="min-speed"):
        parse_speed("fast", "mph")


def test_train_prints_the_row_summary(tmp_path: Path, capsys) -> None:
    pytest.importorskip("torch")
    from tools.cli import main

    recipe = tmp_path / "slow.toml"
    recipe.write_text('[data]\nmin_speed = 30.19\nmin_speed_unit = "mph"\n')
    rc = main(["train", "--recipe", str(recipe), "--data", str(SAMPLE), "--out", str(tmp_path / "r"), "--epochs", "1",
               "--max-steps-per-epoch", "1", "--threads", "1", "--no-progress"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "read: 36 rows of 1 recording; 0 bad rows or missing images, 0 unreadable frames\n" in out
    assert "below 30.19 mph" in out and "held out in blocks of 50" in out
    assert "Pearson r" in out and "always-0 MSE" in out


# ---- brightness -----------------------------------------------------------------------------------------------

def test_scale_brightness_keeps_a_dark_frame_visible() -> None:
    from models.augmentation.reference import brightness

    dark = np.full((4, 4, 3), 40, np.uint8)
    assert brightness(dark, -80.0).max() == 0  # the paper's additive beta blacks it out
    assert brightness(dark, -0.5, "scale").min() == 20 and brightness(dark, 0.5, "scale").max() == 60


def test_fast_path_applies_the_scale_mode_like_the_reference() -> None:
    from dataclasses import replace

    from models.augmentation.augment import no_augmentation
    from models.augmentation.fastaug import FastAugmenter
    from models.augmentation.reference import brightness
    from models.data.behavior import pipeline_for
    from models.data.framecache import build_cache

    samples, _ = read_log(SAMPLE)
    p = pipeline_for("simplistic", "shallow", "ours")
    spec = replace(p.augment, brightness_mode="scale", brightness_range=0.5)
    cache = build_cache(samples[:4], p.contract, ("center",), workers=1)
    params = replace(no_augmentation(4, np.zeros(4)), brightness=np.ones(4, bool),
                     beta=np.array([-0.5, -0.2, 0.3, 0.5], np.float32))
    got = FastAugmenter(cache, spec).images(np.arange(4), params)
    for i in range(4):
        want = brightness(cache.frames[0, i], float(params.beta[i]), "scale")
        assert np.abs(got[i].astype(int) - want).max() <= 1


def test_config_pipeline_carries_crop_and_brightness() -> None:
    p = TrainConfig(data=[], out="", crop_top=64, crop_bottom=136, brightness_mode="scale").pipeline()
    assert (p.contract.crop_top, p.contract.crop_bottom) == (64, 136)
    assert (p.augment.brightness_mode, p.augment.brightness_range) == ("scale", 0.5)
    paper = TrainConfig(data=[], out="").pipeline()
    assert (paper.contract.crop_top, paper.augment.brightness_range, paper.augment.brightness_mode) == (0, 100, "add")
    with pytest.raises(ValueError, match="crop"):
        TrainConfig(data=[], out="", crop_top=100, crop_bottom=90).pipeline()


def test_smoothed_labels_train_but_never_score_and_never_leak() -> None:
    from models.data.behavior import pipeline_for
    from models.data.trainingdata import DataOptions, prepare_data

    options = DataOptions(SplitSpec("blocks", block_frames=7, gap_frames=0), label_smoothing_frames=5)
    data = prepare_data([SAMPLE], pipeline_for("simplistic", "shallow", "ours"), 2, options, workers=1)
    raw = data.steering.astype(np.float64)
    assert not np.array_equal(data.targets, data.steering)  # the sample has taps to average
    train = set(data.train.tolist())
    for i in data.train:  # a training target averages training labels only, within +-2 frames
        window = [j for j in range(i - 2, i + 3) if j in train]
        assert data.targets[i] == pytest.approx(raw[window].mean(), abs=1e-6)
    # the held-out labels themselves are untouched: validation scores what was recorded
    assert np.array_equal(data.steering[data.val], np.array([s.steering for s in data.dataset.samples],
                                                            np.float32)[data.val])
