"""The camera rig travels with the data and the model: collect records it, train stamps it, the simulator shows it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_rules import stadium  # the small test tracks live with the rules tests

from protocol.rigfile import MIXED, REAL_RIG, RIG_FILE, data_rig, read_rig, read_track, write_rig
from tools.sim.collect.dataset import CollectConfig, collect
from tools.sim.driving.model_rig import model_rig, resolve_rig
from tools.sim.render.camera import DEFAULT_RIG, LEGACY_RIG

REPO = Path(__file__).resolve().parents[1]
SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
BUNDLED = REPO / "models" / "pretrained"


def test_a_folder_without_a_rig_file_is_the_real_simulators_camera(tmp_path):
    assert read_rig(tmp_path) == REAL_RIG == "unity"
    write_rig(tmp_path, "classic")
    assert read_rig(tmp_path) == "classic" and read_rig(tmp_path / "driving_log.csv") == "classic"
    write_rig(tmp_path, "unity", append=True)  # frames of another rig appended: mixed
    assert read_rig(tmp_path) == MIXED
    (tmp_path / RIG_FILE).write_text("{not json", encoding="utf-8")
    assert read_rig(tmp_path) == REAL_RIG  # unreadable: a warning, the real camera
    real = tmp_path / "real"  # frames of the real simulator (a log, no rig file), then classic ones appended
    real.mkdir()
    (real / "driving_log.csv").write_text("", encoding="utf-8")
    write_rig(real, "classic", append=True)
    assert read_rig(real) == MIXED
    write_rig(tmp_path / "new", "classic", append=True)  # appending to nothing: just the rig
    assert read_rig(tmp_path / "new") == "classic"
    other = tmp_path / "other"
    write_rig(other, "classic")
    assert data_rig([other, other / "driving_log.csv"]) == "classic"
    assert data_rig([other, tmp_path / "nothing"]) == MIXED


@pytest.mark.parametrize("rig", ["unity", "classic"])
def test_collect_records_the_rig_its_frames_were_rendered_with(tmp_path, rig):
    track = stadium(tmp_path, straight=30.0, radius=16.0)
    out = tmp_path / "data"
    collect(CollectConfig(track=track, rate_hz=4.0, cameras=1, camera=rig), out)
    assert json.loads((out / RIG_FILE).read_text()) == {"rig": rig}


def test_laps_of_a_named_track_say_it_and_drive_log_finds_that_tracks_road(tmp_path):
    # a headless lake lap's dark asphalt is nearer the mountain's colour: drive-log named it "mountain road"
    from tools.drivelog.track import recorded_track

    out = tmp_path / "laps"
    collect(CollectConfig(track="lake", rate_hz=1.0, cameras=1), out)
    assert read_track(out) == "lake" and recorded_track(out / "driving_log.csv") == "lake"
    write_rig(out, "unity", append=True, track="mountain")  # laps of another track appended: none said
    assert read_track(out) is None and read_rig(out) == "unity"
    write_rig(tmp_path / "file", "unity", track="my_track.json")  # a track file: no profile of that name
    assert read_track(tmp_path / "file") == "my_track.json" and recorded_track(tmp_path / "file") is None
    assert read_track(SAMPLE) is None and recorded_track(SAMPLE) is None  # a real recording: told from its frames
    world = tmp_path / "world"
    collect(CollectConfig(track=stadium(tmp_path, straight=30.0, radius=16.0), rate_hz=2.0, cameras=1), world)
    assert read_track(world) is None


def test_the_default_rig_is_unity_and_models_of_before_keep_the_classic_camera():
    assert DEFAULT_RIG == "unity" and LEGACY_RIG == "classic"
    # every bundled model learnt classic frames (their record names no rig), so their tables stand
    for name in ("simplistic", "rigorous", "collision", "pilotnet_nvidia", "pilotnet_ours"):
        assert model_rig(BUNDLED / f"{name}.onnx") == "classic", name
    assert resolve_rig("unity", BUNDLED / "simplistic.onnx") == "unity"  # --camera wins
    assert resolve_rig(None, None) == DEFAULT_RIG  # the autopilot, or a server whose model is unknown


def test_a_model_of_no_record_of_ours_is_shown_the_real_camera(tmp_path):
    onnx = pytest.importorskip("onnx")
    proto = onnx.load(str(BUNDLED / "simplistic.onnx"))
    del proto.metadata_props[:]  # a model from elsewhere: no rbc.model record
    foreign = tmp_path / "foreign.onnx"
    onnx.save(proto, str(foreign))
    assert model_rig(foreign) == "unity"
    assert model_rig(tmp_path / "missing.onnx") == DEFAULT_RIG  # its own loader reports the bad file


def test_train_stamps_the_rig_of_its_data_into_the_model(tmp_path):
    pytest.importorskip("torch")
    import shutil

    from models.training.train import train
    from models.training.train_config import TrainConfig

    data = tmp_path / "sim"
    shutil.copytree(SAMPLE, data)
    write_rig(data, "classic")
    result = train(TrainConfig(data=[str(data)], out=str(tmp_path / "run"), epochs=1, aug_loops=1,
                               max_steps_per_epoch=1, threads=1, progress=False))
    assert model_rig(result.run_dir / "model.onnx") == "classic"
    real = train(TrainConfig(data=[str(SAMPLE)], out=str(tmp_path / "real"), epochs=1, aug_loops=1,
                             max_steps_per_epoch=1, threads=1, progress=False))
    assert model_rig(real.run_dir / "model.onnx") == "unity"  # recordings of the real simulator
    both = train(TrainConfig(data=[str(SAMPLE), str(data)], out=str(tmp_path / "both"), epochs=1, aug_loops=1,
                             max_steps_per_epoch=1, threads=1, progress=False))
    assert model_rig(both.run_dir / "model.onnx") == DEFAULT_RIG  # data of two rigs: the default
