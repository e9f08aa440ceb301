"""Every command on the Quick start and in the guides runs, and shows what the page says it shows.

Each page's shell blocks are read as a user would copy them; every ``rbc`` and ``drive_server`` line runs, in
order, in one working folder that links the repository's ``models/`` and ``tests/`` (as a clone has them), on
small data where the real thing is large: the 36-row test recording stands in for the public recordings (a local
git repository serves ``rbc data fetch``), a short stadium track for the built-in ones, one short generated
world for two hundred, five rows a simulated second instead of fifteen, one epoch of one step for a training
run, one experiment and one seed for the paper's suite, and ``drive_server`` listens on a free port and is
driven by ``rbc replay``. What is short already runs as written (:data:`AS_WRITTEN`): ``rbc demo`` drives its
whole lap, which must be the one the Quick start shows, and "Record and train on your laps" records and trains
on its own lap, whose output must be the page's. A command a page gains without a way to run here fails
:func:`test_every_guide_command_is_run_here`.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.conftest import UDACITY_SAMPLE, write_stadium

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
#: The Quick start and the guides, in the order a newcomer reads them.
GUIDES = ("quickstart.md", "unity.md", "recordings.md", "unity-model.md", "headless.md", "paper.md", "evaluate.md",
          "scaling.md", "python.md")
#: Commands that cannot run on one machine without a network, and what tests them instead.
NOT_RUN = {
    "rbc eval --behavior simplistic --backend ray --address HEAD_IP:6379 --out eval/simplistic":
        "needs a Ray cluster; tests/test_evaluate_ray.py runs the Ray backend on a private instance",
}
#: Commands short enough to run as the page has them: what they print is compared with the page.
AS_WRITTEN = {
    "rbc collect --track lake --laps 1 --rate-hz 5 --out my_laps",
    "rbc train --recipe laps --data my_laps --out runs/mine",
}
FENCE = re.compile(r"^```(\w*)\s*$")
NUMBER = re.compile(r"\d+(?:[.,]\d+)*(?:e[-+]?\d+)?")
#: The stand-ins for the public recordings: one per fold, lake where the closed loop is driven.
PUBLIC = (("0xR4Y", "lake", "A"), ("AhmedonGit", "jungle", "B"), ("AVMktl-2", "mountain", "C"),
          ("WyckliffeAluga", "lake", "D"))
WORLD_CONFIG = '{"min_length_m": 300.0, "max_length_m": 400.0, "drive_check": false}'  # a short world, fast

pytestmark = pytest.mark.slow


def page_commands(name: str) -> list[str]:
    """The ``rbc`` / ``drive_server`` lines of a page's shell blocks, continuation lines joined, comments cut."""
    found, in_block, lang, pending = [], False, "", ""
    for line in (DOCS / name).read_text(encoding="utf-8").splitlines():
        fence = FENCE.match(line.strip())
        if fence:
            in_block, lang = not in_block, fence.group(1)
            continue
        if not in_block or lang not in ("bash", "sh", "shell", "console"):
            continue
        text = (pending + " " + line.strip()).strip() if pending else line.strip()
        if text.endswith("\\"):
            pending = text[:-1].strip()
            continue
        pending = ""
        text = re.split(r"\s+#\s", text)[0].strip()
        if text.startswith(("rbc ", "drive_server")):
            found.append(text)
    return found


def shape(line: str) -> str:
    """A printed line with its numbers masked: what differs from machine to machine (times, ports, the last
    digits of a training's losses) and what the line says."""
    return NUMBER.sub("#", line)


def output_block(name: str, first_line: str) -> list[str]:
    """The lines of the page's ``text`` block that starts with ``first_line``."""
    blocks = re.findall(r"```text\n(.*?)```", (DOCS / name).read_text(encoding="utf-8"), re.S)
    return next(b.splitlines() for b in blocks if b.startswith(first_line))


# ------------------------------------------------------------------------------------------------ the folder

def _git(*args: str, cwd: Path) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, capture_output=True, text=True).stdout.strip()


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """A user's folder: ``models/`` and ``tests/`` of the checkout, a short track, a Keras 1 PilotNet as the
    peer's ``model.h5``, and the list of public recordings pointing at a local repository of four copies of the
    sample. Laps of their own the pages record themselves."""
    if shutil.which("git") is None:
        pytest.skip("git is not installed (rbc data fetch)")
    pytest.importorskip("torch")
    pytest.importorskip("matplotlib")
    from tools.realdata import recordings

    ws = tmp_path_factory.mktemp("user")
    for link in ("models", "tests"):
        (ws / link).symlink_to(REPO / link)
    track = write_stadium(ws, straight=40.0, radius=25.0)
    cones_track = write_stadium(ws, straight=200.0, radius=50.0)  # 710 m: room for the collision behavior's 20 cones
    pytest.importorskip("h5py")
    from tests.test_import_peer import write_keras1_h5

    write_keras1_h5(ws / "model.h5")  # the peer's Keras file, as its repository has it
    repo = tmp_path_factory.mktemp("github") / "drivers" / "laps"
    shutil.copytree(UDACITY_SAMPLE, repo / "data", ignore=shutil.ignore_patterns("README.md"))
    _git("init", "-q", cwd=repo)
    _git("add", "-A", cwd=repo)
    _git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "laps", cwd=repo)
    commit = _git("rev-parse", "HEAD", cwd=repo)
    entries = [recordings.PublicRecording(name, track_name, "drivers/laps", commit, "data/", None, "keyboard", fold)
               for name, track_name, fold in PUBLIC]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(recordings, "public_recordings", lambda: entries)
        mp.chdir(ws)
        yield {"dir": ws, "track": track, "cones_track": cones_track, "base_url": f"file://{repo.parents[1]}"}


def _flag(argv: list[str], flag: str, value: str) -> list[str]:
    """``argv`` with ``flag`` set to ``value`` (replaced where present, else added)."""
    if flag in argv:
        i = argv.index(flag)
        return [*argv[:i + 1], value, *argv[i + 2:]]
    return [*argv, flag, value]


def small(argv: list[str], ws: dict) -> list[str]:
    """The same command on small data (see the module's docstring)."""
    cmd = argv[0]
    if cmd == "train" and "--print" not in argv:
        argv = [*argv, "--epochs", "1", "--max-steps-per-epoch", "1", "--no-progress"]
    elif cmd == "collect":
        argv = [a for a in argv if a != "--both-directions"]
        argv = _flag(_flag(argv, "--laps", "1"), "--rate-hz", "5")
        if "--worlds" in argv:
            argv = _flag(_flag(argv, "--worlds", "1"), "--world-config", WORLD_CONFIG)
        else:
            argv = _flag(argv, "--track", ws["track"])
    elif cmd == "eval":
        argv = _flag(argv, "--workers", "1")
        if "unseen_worlds" in argv:
            argv = _flag(_flag(argv, "--worlds", "1"), "--world-config", WORLD_CONFIG)
        else:
            track = ws["cones_track"] if "collision" in argv else ws["track"]
            argv = _flag(_flag(_flag(argv, "--experiments", "no_variation"), "--seeds", "1"), "--track", track)
    elif cmd == "sim":
        argv = _flag(argv, "--max-lap-time", "10")
    elif cmd == "bench":
        argv = _flag(_flag(argv, "--frames", "30"), "--warmup", "5")
    elif cmd == "compare":
        argv = _flag(argv, "--frames", "30")
    elif cmd == "dagger" and "--compare" not in argv:  # tiny rounds, one short unseen world, no tracks
        rounds = len(argv[argv.index("--budgets") + 1].split(",")) if "--budgets" in argv else 4
        argv = _flag(argv, "--budgets", ",".join(str(60 * (r + 1)) for r in range(rounds)))  # the page's rounds
        for flag, value in (("--episode-steps", "60"), ("--epochs", "1"),
                            ("--max-steps-per-epoch", "2"), ("--eval-worlds", "1"),
                            ("--eval-world-config", WORLD_CONFIG)):
            argv = _flag(argv, flag, value)
        argv = [*argv, "--tracks", "--no-progress"]
    elif argv[:2] == ["data", "fetch"]:
        argv = _flag(argv, "--base-url", ws["base_url"])
    return argv


# ------------------------------------------------------------------------------------------------ running

def rbc(argv: list[str], capsys) -> tuple[int, str]:
    from tools.cli import main

    capsys.readouterr()
    code = main(argv)
    return code, capsys.readouterr().out


def expand(command: str, ws: dict, capsys) -> list[str]:
    """The argv of a command line as the shell would make it: its ``$(...)`` substituted."""
    def loop(match: re.Match[str]) -> str:
        return " ".join(f"--data real/{d.name}/" for d in sorted((ws["dir"] / "real").iterdir()) if d.is_dir())

    command = re.sub(r"\$\(for d in real/\*/; do printf -- '--data %s ' \"\$d\"; done\)", loop, command)

    def sub(match: re.Match[str]) -> str:
        code, out = rbc(shlex.split(match.group(1))[1:], capsys)
        assert code == 0, match.group(1)
        return out.strip()

    command = re.sub(r"\$\((rbc [^()]*)\)", sub, command)
    assert "$(" not in command, command
    argv = []
    for arg in shlex.split(command):  # the shell's globbing, as in rbc data stats real/*
        matches = sorted(str(p.relative_to(ws["dir"])) for p in ws["dir"].glob(arg)) if "*" in arg else []
        argv += matches or [arg]
    return argv


def serve(argv: list[str], ws: dict, capsys) -> str:
    """``drive_server ARGS`` on a free port, driven by ``rbc replay`` of the test recording: its log."""
    log_path = ws["dir"] / f"drive_server_{time.monotonic_ns()}.log"
    with open(log_path, "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "drive_server.cli", *argv[1:], "--port", "0"],
                                cwd=ws["dir"], stdout=log, stderr=subprocess.STDOUT)
    try:
        url = None
        deadline = time.monotonic() + 60
        while url is None and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            found = re.search(r"listening on (http://\S+)", log_path.read_text())
            url = found and found.group(1)
        assert url, log_path.read_text()
        code, _ = rbc(["replay", "--log", "tests/data/udacity-sample", "--server", url, "--quiet"], capsys)
        assert code == 0
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
    return log_path.read_text()


def demo(argv: list[str], ws: dict) -> str:
    """``rbc demo ARGS`` as a user runs it, its whole lap: what it printed."""
    done = subprocess.run([sys.executable, "-m", "tools.cli", *argv], cwd=ws["dir"],
                          capture_output=True, text=True, timeout=300, env={**os.environ, "COLUMNS": "120"})
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def short_demo(argv: list[str], capsys) -> tuple[int, str]:
    """``rbc demo ARGS`` in-process, its lap given up after 10 simulated seconds (small data)."""
    from dataclasses import dataclass

    from tools.commands import demo as demo_command
    from tools.sim.driving.scenario import ScenarioConfig

    @dataclass(frozen=True)
    class Short(ScenarioConfig):
        max_lap_time_s: float | None = 10.0

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(demo_command, "ScenarioConfig", Short)
        return rbc(argv, capsys)


def watch(argv: list[str], ws: dict) -> None:
    """``rbc demo --watch`` prints where to watch, then drives at the wall clock's pace: stopped after that."""
    proc = subprocess.Popen([sys.executable, "-m", "tools.cli", *argv, "--out", "watch_out"], cwd=ws["dir"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if line.startswith("watch it live at http://"):
                break
        assert any(line.startswith("watch it live at http://") for line in lines), "".join(lines)
        time.sleep(1)
    finally:
        proc.send_signal(signal.SIGINT)
        rest = proc.communicate(timeout=60)[0]
    assert proc.returncode == 130 and "degree of autonomy" in rest, rest


def run_page(name: str, ws: dict, capsys) -> dict[str, str]:
    """Every command of the page, in order; what each printed (drive_server: its log)."""
    printed: dict[str, str] = {}
    for command in page_commands(name):
        if command in NOT_RUN:
            continue
        started = time.monotonic()

        redirect = None
        if " > " in command:
            command, redirect = (part.strip() for part in command.split(" > "))
        argv = expand(command, ws, capsys)
        if argv[0] == "drive_server":
            printed[command] = serve(argv, ws, capsys)
            continue
        argv = argv[1:]
        if argv[0] == "demo":
            if "--watch" in argv:
                watch(argv, ws)
            elif len(argv) == 1:
                printed[command] = demo(argv, ws)
            else:  # another model on another track: the same command, its lap cut short
                code, out = short_demo(argv, capsys)
                assert code == 0 and "degree of autonomy" in out, out
                printed[command] = out
            continue
        code, out = rbc(argv if command in AS_WRITTEN else small(argv, ws), capsys)
        assert code == 0, f"{name}: {command} exited {code}\n{out[-2000:]}"
        if redirect:
            (ws["dir"] / redirect).write_text(out, encoding="utf-8")
        printed[command] = out
        if os.environ.get("RBC_DOCS_TIMES"):  # a file: where each second goes
            with open(os.environ["RBC_DOCS_TIMES"], "a") as fh:
                fh.write(f"{time.monotonic() - started:6.1f} s  {name}: {command}\n")
    return printed


# ------------------------------------------------------------------------------------------------ the pages

def test_every_guide_command_is_run_here():
    commands = {c for page in GUIDES for c in page_commands(page)}
    assert len(commands) > 40
    assert set(NOT_RUN) <= commands, "a command excused here is no longer on a page"
    assert commands >= AS_WRITTEN, "a command run as written is no longer on a page"
    for command in commands - set(NOT_RUN):
        argv = shlex.split(re.sub(r"\$\([^)]*\)\)?", "", command.split(" > ")[0]))
        assert argv[0] in ("rbc", "drive_server"), command


def test_quick_start(workspace, capsys):
    printed = run_page("quickstart.md", workspace, capsys)
    ws = workspace["dir"]
    shown = output_block("quickstart.md", "drive_server generalist_pilotnet.onnx listening on")
    got = printed["rbc demo"].splitlines()
    lap = next(line for line in shown if line.lstrip().startswith("1 "))
    assert lap in got  # the lap is deterministic: the page's row is the row a fresh run prints
    assert [shape(line) for line in got] == [shape(line) for line in shown]  # and every other line, but figures
    assert got[-1] == shown[-1] == "degree of autonomy: 100.0 %"
    assert {"map.png", "strip.jpg", "result.json"} <= {p.name for p in (ws / "demo_out").iterdir()}
    # Try a few things: each demo variant writes a folder of its own, and the demo's own stays as it was
    first = (ws / "demo_out" / "result.json").read_bytes()
    for behavior in ("simplistic", "rigorous"):
        out = printed[f"rbc demo --behavior {behavior}"]
        assert f"json  demo_out_{behavior}/result.json" in out.splitlines() and "replaced" not in out
    assert (ws / "demo_out" / "result.json").read_bytes() == first
    again = short_demo(["demo", "--behavior", "rigorous"], capsys)[1]  # a rerun says what it replaced
    assert "(replaced an earlier run's files in demo_out_rigorous/; --out DIR keeps them apart)" in again


def test_quick_start_shows_what_each_variant_ends_with():
    """The variants' laps, as the page's table gives them, are the laps of the results' records (the test above
    cuts them short; the laps are deterministic: the default demo's is checked whole)."""
    rows = {cells[0]: cells for line in (DOCS / "quickstart.md").read_text(encoding="utf-8").splitlines()
            if line.startswith("| `rbc ") for cells in [[c.strip() for c in line.strip("|").split("|")]]}
    laps = {(run["model"], run["track"]): run["output"]["laps"][0]
            for run in json.loads((REPO / "results" / "headless-laps.json").read_text())["runs"]}
    for behavior, track in (("simplistic", "lake"), ("rigorous", "mountain")):
        command, lap, eta, pictures = rows[f"`rbc demo --behavior {behavior}`"]
        record = laps[(f"{behavior}.onnx", track)]
        figures = [float(x) for x in re.findall(r"(\d+\.\d+) (?:s|km/h|m)\b", lap)]
        assert lap.startswith(track) and figures == pytest.approx(
            [record["lap_time_s"], record["mean_speed_kmh"], record["cte_rms_m"]], abs=0.051), lap
        assert eta == f"{record['eta']:.1f} %" and pictures == f"`demo_out_{behavior}/`"
    worlds = {run["model"]: run["output"] for run in
              json.loads((REPO / "results" / "unseen-worlds.json").read_text())["runs"]}
    lap, eta = rows["`rbc sim --model ... world:1000009`"][1:3]
    assert worlds["generalist.onnx"]["worst"] == f"{eta} (world 1000009)" and "one take-over" in lap
    assert rows["`rbc demo --watch`"][2] == "100.0 %"


def test_record_and_train_on_your_laps(workspace, capsys):
    """The page records its own lap, trains on it as written and shows what that printed and wrote."""
    printed = run_page("recordings.md", workspace, capsys)
    ws = workspace["dir"]
    shown = output_block("recordings.md", "recording  rows")
    assert printed["rbc data stats my_laps"].splitlines() == shown  # the autopilot's lap is deterministic
    trained = printed["rbc train --recipe laps --data my_laps --out runs/mine"].splitlines()
    shown = output_block("recordings.md", "read: ")
    assert trained[:4] == shown[:4]  # what it read, used and held out, and the network: the same everywhere
    assert [shape(line) for line in trained] == [shape(line) for line in shown]  # the losses' last digits vary
    assert sorted(p.name for p in (ws / "runs" / "mine").iterdir()) == [
        "checkpoint.pt", "config.json", "drive1", "history.csv", "inspect", "loss.png", "model.onnx"]
    inspected = printed["rbc inspect runs/mine"].splitlines()
    shown = output_block("recordings.md", "runs/mine/inspect/")
    assert inspected[:4] == shown[:4] and [shape(line) for line in inspected] == [shape(line) for line in shown]
    assert all((ws / path).is_file() for path in shown[:4])
    scored = printed["rbc score --data tests/data/udacity-sample --model runs/mine/model.onnx"]
    assert "0.0112" in scored  # always-0 on the sample, as the page says
    driven = printed["rbc drive-log --data my_laps --model runs/mine/model.onnx --held-out-of runs/mine"]
    assert "degree of autonomy 100.0 %  take-overs 0\n" in driven  # no rate of driving per take-over for none
    simulated = printed["rbc sim --model runs/mine/model.onnx --track lake"].splitlines()
    assert simulated[0] == "track lake (1003 m), driver onnx:model.onnx, speed limit 25 km/h"
    assert "[data]" in (ws / "my_recipe.toml").read_text()
    assert (ws / "runs" / "mine2" / "model.onnx").is_file()


def test_drive_the_udacity_simulator(workspace, capsys):
    printed = run_page("unity.md", workspace, capsys)
    log = printed["drive_server"]
    shown = output_block("unity.md", "02:36:54 INFO drive_server: model unity.onnx")
    for line in shown:
        expected = re.sub(r"^\S+ ", "", line).split("http://")[0]
        for part in expected.split("..."):  # a line trimmed at "..."
            assert part.strip() in log, part
    shown = output_block("unity.md", "02:36:56 INFO drive_server.wire.unity_compat")
    assert "sent an event without a CONNECT packet (the Unity simulator does that): joined it to '/'" in log
    assert "(websocket-sharp/1.0); 1 connected" in log and len(shown) == 2
    rows = (workspace["dir"] / "runs" / "drive1" / "driving_log.csv").read_text().splitlines()
    assert len(rows) == 36  # every answered frame recorded
    assert (workspace["dir"] / "drive1.mp4").stat().st_size > 0


def test_reproduce_the_bundled_unity_model(workspace, capsys):
    printed = run_page("unity-model.md", workspace, capsys)
    ws = workspace["dir"]
    assert sorted(p.name for p in (ws / "real").iterdir()) == sorted(name for name, *_ in PUBLIC)
    assert (ws / "real" / "0xR4Y" / "road_edges.csv").is_file()
    assert all((ws / "runs" / f"cv-{fold}" / "model.onnx").is_file() for fold in "ABCD")
    assert all((ws / "runs" / "cv" / f"fold-{fold}" / "model.onnx").is_file() for fold in "ABCD")  # the one command
    record = json.loads((ws / "crossval.json").read_text())
    assert {r["name"] for r in record["folds"]["recordings"]} == {name for name, *_ in PUBLIC}
    assert {r["name"] for r in record["peer"]["recordings"]} == {name for name, *_ in PUBLIC}
    assert "lake" in printed["rbc data crossval --root real --models 'runs/cv-{fold}/model.onnx' --json crossval.json"]


def test_train_without_unity(workspace, capsys):
    run_page("headless.md", workspace, capsys)
    ws = workspace["dir"]
    assert (ws / "data" / "worlds" / "worlds.csv").is_file()
    assert json.loads((ws / "eval" / "unseen" / "results.json").read_text())["runs"]
    assert (ws / "world.json").is_file() and (ws / "map.png").is_file()


def test_reproduce_the_papers_tables(workspace, capsys):
    run_page("paper.md", workspace, capsys)
    ws = workspace["dir"]
    assert "No variation" in (ws / "table9.md").read_text()
    table10 = (ws / "table10.md").read_text()
    assert "PilotNet, NVIDIA's approach" in table10 and "Training time" in table10


def test_evaluate_a_model(workspace, capsys):
    printed = run_page("evaluate.md", workspace, capsys)
    ws = workspace["dir"]
    assert json.loads((ws / "lap.json").read_text())["laps"]
    assert json.loads((ws / "drive.json").read_text())["frames"] == 36
    assert "round trip" in printed["rbc bench --model models/pretrained/unity.onnx --frames 2000"]
    assert (ws / "compare.md").is_file()


def test_scale_out_and_python(workspace, capsys):
    run_page("scaling.md", workspace, capsys)
    run_page("python.md", workspace, capsys)
