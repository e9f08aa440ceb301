"""Start ``drive_server`` as a child process on a free port and stop it cleanly (benchmarks, demos, tests).

The server is started with ``--port 0`` and announces the port it got ("listening on http://...") in
its log, so there is no race for a port picked in advance. Its log goes to a file, never to a pipe
nobody drains.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import TracebackType

from protocol.errors import UserError

_LISTENING = re.compile(r"listening on (http://\S+)")


class ServerStartError(UserError, RuntimeError):
    """The server exited or did not start listening in time; the message holds its log tail."""


class ServerProcess:
    """``with ServerProcess(model, extra_args) as server: server.url`` — a drive_server child process."""

    def __init__(self, model: Path, args: list[str] | None = None, stats_json: Path | None = None,
                 start_timeout: float = 60.0) -> None:
        self.model = Path(model)
        self.args = list(args or [])
        self.stats_json = stats_json
        self.start_timeout = start_timeout
        self.url = ""
        self.returncode: int | None = None
        self._dir = tempfile.TemporaryDirectory(prefix="drive_server_")
        self.log_path = Path(self._dir.name) / "server.log"
        self._proc: subprocess.Popen[bytes] | None = None

    def command(self) -> list[str]:
        cmd = [sys.executable, "-m", "drive_server", "--model", str(self.model), "--port", "0", *self.args]
        if self.stats_json is not None:
            cmd += ["--stats-json", str(self.stats_json)]
        return cmd

    def start(self) -> str:
        with self.log_path.open("wb") as log:
            self._proc = subprocess.Popen(self.command(), stdout=log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + self.start_timeout
        while time.monotonic() < deadline:
            match = _LISTENING.search(self.log())
            if match:
                self.url = match.group(1)
                return self.url
            if self._proc.poll() is not None:
                raise ServerStartError(f"drive_server exited with code {self._proc.returncode}:\n{self.log()[-2000:]}")
            time.sleep(0.05)
        self.stop()
        raise ServerStartError(f"drive_server did not start listening in {self.start_timeout:.0f} s:\n"
                               f"{self.log()[-2000:]}")

    @property
    def pid(self) -> int | None:
        """The server's process id once started (benchmarks read its memory and open files)."""
        return self._proc.pid if self._proc is not None else None

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def log(self) -> str:
        try:
            return self.log_path.read_text(encoding="utf-8", errors="replace")
        except FileNotFoundError:
            return ""

    def stop(self, timeout: float = 15.0) -> int:
        """SIGTERM (the server writes its stats and exits), then SIGKILL if it hangs."""
        if self._proc is None:
            return self.returncode or 0
        if self._proc.poll() is None:
            self._proc.send_signal(signal.SIGTERM)
            try:
                self._proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self.returncode = self._proc.returncode
        self._proc = None
        return self.returncode

    def __enter__(self) -> ServerProcess:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()

    def cleanup(self) -> None:
        self.stop()
        self._dir.cleanup()
