"""Scenario runs: the autopilot on the built-in tracks, determinism, the pipeline and timing modes,
and end-to-end laps against the real drive server process (same lap over the socket and in-process)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from drive_server.serving.control import ControlLaw
from protocol import SteerCommand
from protocol.facts import COLLECT_SPEED_KMH
from tools.sim.driving.drivers import AutopilotDriver, Frame, LocalDriver, OnnxDriver, Reply, Scene, SocketDriver
from tools.sim.driving.scenario import RunResult, ScenarioConfig
from tools.sim.driving.session import PIPELINE_DEPTH, run_scenario


@pytest.mark.parametrize("vehicle", ["kinematic", "dynamic"])
@pytest.mark.parametrize("overrides", [
    {"track": "lake"},
    {"track": "lake", "reverse": True},
    {"track": "lake", "cones": 20, "cone_seed": 5},
    {"track": "mountain"},
    {"track": "mountain", "reverse": True},
])
def test_autopilot_drives_the_builtin_tracks_without_intervention(overrides, vehicle):
    """What ``rbc collect`` needs: eta 100 % at the paper's 30 km/h, with either car."""
    result = run_scenario(ScenarioConfig(vehicle=vehicle, speed_limit_kmh=COLLECT_SPEED_KMH, **overrides),
                          AutopilotDriver(), render=False)
    lap = result.laps[0]
    assert lap.completed and lap.interventions == [] and lap.eta == 100.0
    assert 20.0 < lap.mean_speed_kmh < 31.0
    assert lap.lane_departures == 0


@pytest.mark.parametrize("vehicle", ["kinematic", "dynamic"])
def test_same_seed_same_run_other_seed_other_run(vehicle):
    def run(seed: int):
        return run_scenario(ScenarioConfig(track="lake", seed=seed, max_lap_time_s=40.0, vehicle=vehicle),
                            AutopilotDriver(), render=False)

    a, b, c = run(1), run(1), run(2)
    assert a.to_dict()["laps"] == b.to_dict()["laps"]
    assert np.array_equal(a.trace.x, b.trace.x) and np.array_equal(a.trace.y, b.trace.y)
    assert not np.array_equal(a.trace.x, c.trace.x)


class Recorder(LocalDriver):
    """Logs the call order and answers with a fixed command."""

    def __init__(self, sleep_s: float = 0.0) -> None:
        super().__init__()
        self.calls: list[str] = []
        self.frames: list[Frame] = []
        self.sleep_s = sleep_s

    def send(self, frame: Frame) -> None:
        self.calls.append("send")
        self.frames.append(frame)
        super().send(frame)

    def receive(self) -> Reply:
        self.calls.append("receive")
        return super().receive()

    def steer(self, frame: Frame) -> SteerCommand:
        if self.sleep_s:
            time.sleep(self.sleep_s)
        return SteerCommand(0.5, 0.4)


def test_two_frames_are_in_flight_like_unity():
    rec = Recorder()
    result = run_scenario(ScenarioConfig(max_lap_time_s=1.0), rec, render=False)
    assert PIPELINE_DEPTH == 2
    assert rec.calls[:6] == ["send", "send", "receive", "send", "receive", "send"]
    assert result.frames == rec.calls.count("send")
    # the first reply takes effect only after the second frame was sent: frames 0 and 1 show the car at rest
    wheel = [float(f.payload["steering_angle"]) for f in rec.frames]
    assert wheel[0] == wheel[1] == 0.0 and wheel[2] > 0.0
    period = 1 / 15
    assert [f.t for f in rec.frames[:4]] == pytest.approx([0.0, 0.0, period, 2 * period])


def test_realtime_mode_spends_the_measured_latency_in_simulated_time():
    rec = Recorder(sleep_s=0.03)
    result = run_scenario(ScenarioConfig(realtime=True, max_lap_time_s=1.0), rec, render=False)
    steps = np.diff([f.t for f in rec.frames[1:]])
    assert np.all(steps >= 1 / 60 - 1e-9)  # at least one frame per reply
    assert np.median(steps) == pytest.approx(2 / 60, abs=1.01 / 60)  # 30 ms at 60 fps: about 2 frames
    assert result.latency_ms_p50 >= 30.0


def test_result_serialises_to_json():
    result = run_scenario(ScenarioConfig(max_lap_time_s=2.0), Recorder(), render=False)
    doc = json.loads(json.dumps(result.to_dict()))
    assert doc["config"]["track"] == "lake" and doc["rules"]["seconds_per_intervention"] == 6.0
    assert doc["laps"][0]["completed"] is False and "eta" in doc["laps"][0]
    assert doc["frames"] == result.frames > 0


def test_scenario_config_validates():
    with pytest.raises(ValueError, match="divide"):
        ScenarioConfig(control_hz=7)
    with pytest.raises(ValueError):
        ScenarioConfig(speed_unit="furlongs")
    ScenarioConfig(control_hz=7, realtime=True)  # the control rate does not apply in real time
    with pytest.raises(ValueError, match="vehicle"):
        ScenarioConfig(vehicle="hovercraft")


@pytest.mark.parametrize("command", ["sim", "collect", "eval", "demo"])
def test_vehicle_flag_shows_its_default(command, capsys):
    from tools.cli import main

    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--vehicle {dynamic,kinematic}" in text and f"(default {ScenarioConfig.vehicle})" in text


# -------------------------------------------------------------------------- end to end, real drive server


@pytest.fixture(scope="module")
def random_model(tmp_path_factory) -> Path:
    pytest.importorskip("onnx", reason="building a random-weight ONNX model needs the onnx package")
    from tools.bench.onnx_builders import save_model

    return save_model("shallow", tmp_path_factory.mktemp("model") / "shallow_random.onnx", seed=3)


@pytest.fixture(scope="module")
def drive_server(random_model):
    exe = shutil.which("drive_server") or str(Path(sys.executable).with_name("drive_server"))
    cmd = [exe] if Path(exe).is_file() else [sys.executable, "-m", "drive_server"]
    proc = subprocess.Popen([*cmd, "--model", str(random_model), "--port", "0", "--log-every", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    url = None
    deadline = time.monotonic() + 60
    lines = []
    while url is None and time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        m = re.search(r"listening on (http://[\d.]+:\d+)", line)
        if m:
            url = m.group(1)
    if url is None:
        proc.kill()
        pytest.fail("drive_server did not start:\n" + "".join(lines))
    yield url
    proc.terminate()
    proc.wait(timeout=10)


E2E = ScenarioConfig(track="lake", max_lap_time_s=12.0)


def test_socket_lap_against_the_real_drive_server(drive_server):
    result = run_scenario(E2E, SocketDriver(drive_server))
    lap = result.laps[0]
    # 180 control periods answered; the frame sent with the last but one reply is still in flight at the end
    assert result.frames == round(12.0 * 15) + PIPELINE_DEPTH - 1
    assert not lap.completed and lap.lap_time_s == pytest.approx(12.0, abs=0.02)
    assert lap.n_interventions == len(lap.interventions) and lap.distance_m > 0
    assert result.latency_ms_p50 > 0


def test_same_model_same_lap_over_the_socket_and_in_process(drive_server, random_model):
    over_socket = run_scenario(E2E, SocketDriver(drive_server))
    in_process = run_scenario(E2E, OnnxDriver(random_model, ControlLaw(E2E.speed_limit_kmh)))
    assert over_socket.to_dict()["laps"] == in_process.to_dict()["laps"]
    assert np.array_equal(over_socket.trace.x, in_process.trace.x)


def test_rbc_sim_cli_over_the_socket_writes_json_and_pictures(drive_server, tmp_path, capsys):
    from tools.cli import main

    out = tmp_path / "run.json"
    code = main(["sim", "--server", drive_server, "--max-lap-time", "6", "--json", str(out),
                 "--map", str(tmp_path / "map.png"), "--strip", str(tmp_path / "strip.png"), "--strip-every", "2"])
    assert code == 0
    text = capsys.readouterr().out
    assert "eta %" in text and "latency p50" in text and "drive server's own" in text
    doc = json.loads(out.read_text())
    assert doc["laps"][0]["lap_time_s"] == pytest.approx(6.0, abs=0.02)
    assert (tmp_path / "map.png").stat().st_size > 10_000 and (tmp_path / "strip.png").stat().st_size > 10_000


def test_driver_scene_reaches_privileged_drivers():
    seen: list[Scene] = []

    class Peek(Recorder):
        def start(self, scene: Scene) -> None:
            seen.append(scene)
            super().start(scene)

    run_scenario(ScenarioConfig(cones=3, reverse=True, max_lap_time_s=0.5), Peek(), render=False)
    assert seen[0].direction == -1 and seen[0].cones.shape == (3, 2)
    assert seen[0].control_period_s == pytest.approx(1 / 15)


def test_an_in_process_driver_reused_for_another_run_starts_it_afresh():
    """rbc eval reuses one driver per worker: a model that asks for smoothing must not carry the last run's
    steering into the next, or a run's result would depend on the runs its worker drove before it."""
    model = Path(__file__).resolve().parents[1] / "models" / "pretrained" / "generalist.onnx"  # smoothing 0.5
    short = ScenarioConfig(track="lake", max_lap_time_s=6.0, camera="unity")
    fresh = run_scenario(short, OnnxDriver(model, ControlLaw(short.speed_limit_kmh)))
    reused = OnnxDriver(model, ControlLaw(short.speed_limit_kmh))
    run_scenario(ScenarioConfig(track="lake", max_lap_time_s=6.0, camera="unity", yaw_offset_deg=30.0), reused)
    again = run_scenario(short, reused)

    def drive(result: RunResult) -> str:  # what the car did, not how long the machine took
        return json.dumps({k: v for k, v in result.to_dict().items() if "latency" not in k and "wall" not in k},
                          sort_keys=True)

    assert drive(again) == drive(fresh)
