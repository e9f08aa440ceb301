"""What a newcomer meets when something is wrong: one line, a hint, exit 2, no traceback, no output left."""

from __future__ import annotations

import importlib.util
import json
import math
import os
import sys
from pathlib import Path

import pytest

from tools.cli import main as rbc

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"


def _fails_cleanly(argv: list[str], capsys, expect: str, leaves: list[Path] = ()) -> str:
    code = rbc(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and "WARNING" not in ln]
    assert code == 2, err
    assert "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith(f"rbc {argv[0]}: error: "), err
    assert expect in lines[0]
    for path in leaves:
        assert not path.exists(), f"{path} was left behind"
    return lines[0]


def _track(tmp_path: Path, **data) -> str:
    path = tmp_path / "t.json"
    path.write_text(json.dumps({"name": "t", "version": 1, "road_width": 8.0, **data}))
    return str(path)


def test_train_without_data_folder(tmp_path, capsys):
    _fails_cleanly(["train", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "run")], capsys,
                   "no such file or directory", [tmp_path / "run"])


def test_train_on_an_empty_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    _fails_cleanly(["train", "--data", str(tmp_path / "empty"), "--out", str(tmp_path / "run")], capsys,
                   "no driving_log.csv", [tmp_path / "run"])


def test_train_on_an_all_garbage_log(tmp_path, capsys):
    (tmp_path / "g").mkdir()
    (tmp_path / "g" / "driving_log.csv").write_text("a,b,c\nx,y,z\n")
    _fails_cleanly(["train", "--data", str(tmp_path / "g"), "--out", str(tmp_path / "run")], capsys,
                   "no usable samples", [tmp_path / "run"])


def test_train_into_a_path_that_cannot_be_a_folder(tmp_path, capsys):
    pytest.importorskip("torch")
    (tmp_path / "file").write_text("x")
    _fails_cleanly(["train", "--data", str(SAMPLE), "--out", str(tmp_path / "file" / "run"), "--epochs", "1",
                    "--max-steps-per-epoch", "1", "--no-progress"], capsys, "not a directory")


def test_train_resume_with_a_corrupt_checkpoint(tmp_path, capsys):
    pytest.importorskip("torch")
    run = tmp_path / "run"
    assert rbc(["train", "--data", str(SAMPLE), "--out", str(run), "--epochs", "1", "--max-steps-per-epoch", "1",
                "--no-progress", "--threads", "1"]) == 0
    capsys.readouterr()
    (run / "model.onnx").unlink()
    (run / "checkpoint.pt").write_bytes(b"garbage")
    _fails_cleanly(["train", "--out", str(run), "--resume", "--no-progress"], capsys, "not a readable checkpoint")


@pytest.mark.parametrize("command", [["sim", "--autopilot"], ["collect", "--out", "{out}"], ["eval", "--out", "{out}"]])
def test_unknown_track_name(command, tmp_path, capsys):
    out = tmp_path / "out"
    argv = [a.format(out=out) for a in command] + ["--track", "nope"]
    _fails_cleanly(argv, capsys, "no such track file (built-in tracks: lake, mountain; a generated world: world:SEED)",
                   [out])


@pytest.mark.parametrize(("data", "expect"), [
    ({"centerline": [[1e300, 0], [0, 1e300], [-1e300, 0], [0, -1e300]]}, "m from the origin"),
    ({"centerline": [[500 * math.cos(k / 1e4), 500 * math.sin(k / 1e4)] for k in range(100_000)]},
     "at most 2000 control points"),
    ({"centerline": [[9000, 9000], [-9000, 9000], [-9000, -9000], [9000, -9000]]}, "at most 20 km"),
    ({"centerline": [[0, 0], [10, 0]]}, "at least 4 points"),
])
def test_invalid_track_files_are_refused_before_anything_is_allocated(data, expect, tmp_path, capsys):
    out = tmp_path / "out"
    _fails_cleanly(["collect", "--out", str(out), "--track", _track(tmp_path, **data)], capsys, expect, [out])


def test_track_file_that_is_not_json(tmp_path, capsys):
    path = tmp_path / "bad.json"
    path.write_text("{not json")
    _fails_cleanly(["sim", "--autopilot", "--track", str(path)], capsys, "not valid JSON")


def test_eval_with_a_file_that_is_not_a_model(tmp_path, capsys):
    _fails_cleanly(["eval", "--model", str(SAMPLE / "driving_log.csv"), "--out", str(tmp_path / "ev")], capsys,
                   "as an ONNX model", [tmp_path / "ev"])


def test_inspect_a_folder_that_is_not_a_run(tmp_path, capsys):
    pytest.importorskip("torch")
    _fails_cleanly(["inspect", str(tmp_path / "nope")], capsys, "not a training run folder")


def test_augment_preview_without_data(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    _fails_cleanly(["augment-preview", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "g.png")], capsys,
                   "no such file or directory", [tmp_path / "g.png"])


def test_verbose_shows_the_traceback(tmp_path):
    with pytest.raises(Exception, match="no such track file"):
        rbc(["-v", "sim", "--autopilot", "--track", "nope"])


@pytest.mark.parametrize(("command", "extra", "hidden"), [
    (["train", "--data", "x", "--out", "y"], "train", "torch"),
    (["inspect", "run"], "train", "torch"),
    (["augment-preview", "--data", "x", "--out", "g.png"], "plots", "matplotlib"),
    (["mirror", "m.onnx", "--out", "x.onnx"], "onnx", "onnx"),  # an ONNX graph edit: onnx alone, not train's torch
])
def test_a_missing_extra_is_named_with_its_install_line(command, extra, hidden, monkeypatch, capsys):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == hidden else real(name, *a))
    monkeypatch.setitem(sys.modules, hidden, None)  # and an import of it fails, as when it is not installed
    assert rbc(command) == 2
    err = capsys.readouterr().err.strip()
    assert err == f'rbc {command[0]}: error: needs the package(s) {hidden} (hint: pip install -e ".[{extra}]")'


def test_version(capsys):
    assert rbc(["--version"]) == 0
    assert capsys.readouterr().out.startswith("rbc ")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_train_into_a_read_only_folder(tmp_path, capsys):
    pytest.importorskip("torch")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        _fails_cleanly(["train", "--data", str(SAMPLE), "--out", str(ro / "run"), "--no-progress"], capsys,
                       "permission denied")
    finally:
        ro.chmod(0o700)


def _interrupted(argv: list[str], ready, tmp_path: Path) -> tuple[int, str]:
    """Run ``rbc argv`` as a process; Ctrl-C it 0.5 s after ``ready(tmp_path, output_so_far)``; (exit code, output)."""
    import signal
    import subprocess
    import threading
    import time

    env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    proc = subprocess.Popen([sys.executable, "-m", "tools.cli", *argv], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout), daemon=True)
    reader.start()
    deadline = time.monotonic() + 60
    while not ready(tmp_path, "".join(lines)) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(0.5)  # let it do some work
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    reader.join(timeout=10)
    return proc.returncode, "".join(lines)


@pytest.mark.slow
def test_an_interrupted_collect_reports_the_rows_and_time_it_kept(tmp_path):
    def rows_written(d: Path, _: str) -> bool:
        log = d / "c" / "driving_log.csv"
        return log.is_file() and log.stat().st_size > 0

    code, out = _interrupted(["collect", "--out", "c", "--cameras", "1", "--laps", "3"], rows_written, tmp_path)
    assert code == 130
    rows = int(next(ln for ln in out.splitlines() if ln.startswith("rows")).split()[1])
    simulated = float(next(ln for ln in out.splitlines() if ln.startswith("time")).split()[1])
    assert rows == len((tmp_path / "c" / "driving_log.csv").read_text().splitlines()) > 0
    assert simulated == pytest.approx(rows / 15.0, abs=1.0)  # rows at 15 Hz of simulated time


@pytest.mark.slow
def test_an_interrupted_demo_says_no_lap_was_finished(tmp_path):
    code, out = _interrupted(["demo", "--out", "d", "--laps", "3"], lambda d, text: "listening on" in text, tmp_path)
    assert code == 130, out
    line = next(ln for ln in out.splitlines() if ln.startswith("degree of autonomy:"))
    assert "interrupted before the first lap was finished" in line or "laps finished: interrupted" in line, line


def test_output_piped_into_a_reader_that_leaves_is_not_an_error(tmp_path):
    # `rbc data fold A --root real | head -c 50` printed "rbc data: error: [Errno 32] Broken pipe (hint: is
    # drive_server running at that address?)": a reader that has what it wants is no error, as for any Unix tool
    import subprocess

    read, write = os.pipe()
    os.close(read)  # the reader has gone before a byte is written
    proc = subprocess.run([sys.executable, "-m", "tools.cli", "data", "fold", "A", "--root", str(tmp_path)],
                          stdout=write, stderr=subprocess.PIPE, text=True, timeout=60,
                          cwd=Path(__file__).parent.parent)
    os.close(write)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""


# --------------------------------------------------------------------------- what is the user's, what is a bug


def _with_run(monkeypatch, command: str, error: BaseException) -> None:
    """Make ``rbc command``'s run raise ``error`` (its arguments still parse as usual)."""
    from tools.cli import BY_NAME, load

    def run(args):
        raise error

    monkeypatch.setattr(load(BY_NAME[command]), "run", run)


def test_a_bare_value_error_inside_a_command_is_a_bug_with_its_traceback(monkeypatch, capsys):
    """Was: every ValueError counted as bad input, so a numpy bug printed one line and no traceback."""
    _with_run(monkeypatch, "fuzz", ValueError("operands could not be broadcast together with shapes (3,) (4,)"))
    with pytest.raises(ValueError, match="broadcast"):
        rbc(["fuzz"])
    assert "error:" not in capsys.readouterr().err


def test_a_bad_value_inside_a_command_is_one_line_with_its_hint(monkeypatch, capsys):
    from protocol.errors import BadValue

    _with_run(monkeypatch, "fuzz", BadValue("--rounds must be >= 1, got 0", hint="give a positive count"))
    assert rbc(["fuzz"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "rbc fuzz: error: --rounds must be >= 1, got 0 (hint: give a positive count)"


def _our_error_classes() -> list[tuple[type, tuple[type, ...], str]]:
    """Each error class of ours, the base(s) code catches it by, and the hint the boundary once chose by its name."""
    from drive_server.serving.contract import ContractError
    from drive_server.serving.model import ModelError
    from drive_server.serving.pipeline import InferenceError
    from drive_server.wire.listen import ListenError
    from models.data.framecache import FrameError
    from models.onnxfiles.ensemble_onnx import EnsembleError
    from models.onnxfiles.mirror_onnx import MirrorError
    from protocol.datalog import DataLogError
    from protocol.errors import ProtocolError
    from tools.errors import CommandError
    from tools.evaluate.cluster import RunLostError
    from tools.sim.collect.dataset import OutputDirError
    from tools.sim.track.road import TrackError
    from tools.wire.server_process import ServerStartError
    from tools.wire.websocket import ConnectionClosed

    model = "pass an .onnx model exported by rbc train, or a bundled one from models/pretrained/"
    out = [(DataLogError, (ValueError,), "give a recording folder with driving_log.csv and IMG/, as rbc collect or "
                                         "the simulator writes"),
           (TrackError, (ValueError,), "the track file format is in docs/formats.md (File formats: Track file)"),
           (ModelError, (), model), (ContractError, (ValueError,), model),
           (OutputDirError, (ValueError,), ""), (ProtocolError, (ValueError,), ""), (FrameError, (ValueError,), ""),
           (MirrorError, (ValueError,), ""), (EnsembleError, (ValueError,), ""), (CommandError, (), ""),
           (ListenError, (OSError,), ""), (InferenceError, (RuntimeError,), ""),
           (ServerStartError, (RuntimeError,), ""), (RunLostError, (), "rbc eval --resume continues from the journal"),
           (ConnectionClosed, (ConnectionError,), "is drive_server running at that address?")]
    if importlib.util.find_spec("torch") is not None:
        from models.networks.checkpoint import RunDirError
        from models.onnxfiles.export import ExportError
        from models.onnxfiles.peer_keras import PeerImportError
        from models.training.distributed import DistributedError

        out += [(ExportError, (RuntimeError,), model), (RunDirError, (RuntimeError,), ""),
                (PeerImportError, (ValueError,), ""), (DistributedError, (), "")]
    return out


def test_every_error_of_ours_is_a_user_error_that_carries_its_hint():
    """Was: the boundary chose hints by the exception's class name as a string (``_hint_for``); now each class
    carries its hint, and keeps the base (ValueError, OSError, RuntimeError) code catches it by."""
    from protocol.errors import UserError
    from tools.errors import is_user_error, one_line

    for cls, bases, hint in _our_error_classes():
        exc = cls("something was wrong")
        assert isinstance(exc, UserError) and all(isinstance(exc, b) for b in bases), cls
        assert is_user_error(exc) and exc.hint == hint, cls
        assert one_line("x", exc) == "rbc x: error: something was wrong" + (f" (hint: {hint})" if hint else ""), cls


def test_only_the_class_not_its_name_chooses_the_hint():
    from tools.errors import is_user_error, one_line

    impostor = type("DataLogError", (ValueError,), {})("no driving_log.csv")  # a foreign class of the same name
    assert not is_user_error(impostor) and one_line("x", impostor) == "rbc x: error: no driving_log.csv"
    assert is_user_error(TimeoutError()) and is_user_error(ConnectionRefusedError()) and is_user_error(OSError(2, "x"))
    assert not is_user_error(ValueError("a numpy bug")) and not is_user_error(KeyError("a bug"))


def test_drive_servers_boundary_keeps_a_bugs_traceback_and_gives_a_bad_values_hint(monkeypatch, capsys):
    """drive_server's own boundary caught every ValueError of its settings as bad input too."""
    import drive_server.cli as server_cli
    from drive_server.serving.control import ControlLaw
    from protocol.errors import BadValue

    def broken(self):
        raise ValueError("a bug in the control law's code")

    monkeypatch.setattr(ControlLaw, "__post_init__", broken)
    with pytest.raises(ValueError, match="a bug"):
        server_cli.main(["--port", "0"])

    def refused(self):
        raise BadValue("tau must be in [0, 1], got 2", hint="give --tau between 0 and 1")

    monkeypatch.setattr(ControlLaw, "__post_init__", refused)
    assert server_cli.main(["--port", "0"]) == 2
    assert capsys.readouterr().err.strip() == "drive_server: error: tau must be in [0, 1], got 2 (hint: give --tau " \
                                              "between 0 and 1)"
