"""``measure``: run a measured record's commands again and rewrite the record with their output.

Apart from the rendering because it runs the project's commands (minutes, a machine's worth of load) and writes
the record; rendering and checking only read.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from tools.results.records import REPO, RESULTS, RecordError, load

#: Paths the measured commands find in their working folder (a temporary one): the repository's models and
#: test data, and ``real/`` (where ``rbc data fetch --out real`` puts the public recordings).
LINKED = ("models", "tests")


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = f", load average {os.getloadavg()[0]:.1f} when measured" if hasattr(os, "getloadavg") else ""
    return f"{os.cpu_count()} cores ({cpu}), no GPU, {platform.system()} {platform.release().split('-')[0]}{load}"


def measure(name: str, real: Path | None = None, root: Path = RESULTS) -> dict[str, Any]:
    """Run a measured record's commands again and rewrite it with their output, the date, code and machine.

    Each command runs in a fresh temporary folder that links the repository's ``models/`` and ``tests/``
    (and ``real/`` to ``real``, where the public recordings are), so its paths read as a user types them.
    """
    from protocol.runrecords import code_version

    record = load(name, root)
    if record["provenance"] != "measured":
        raise RecordError(f"results/{name}.json is transcribed: there is no command to run here")
    where = machine()  # before the commands load it
    for run in record["runs"]:
        with tempfile.TemporaryDirectory(prefix="rbc-results-") as tmp:
            work = Path(tmp)
            for link in LINKED:
                (work / link).symlink_to(REPO / link)
            if real is not None:
                (work / "real").symlink_to(real.resolve())
            argv = shlex.split(run["command"])
            if argv[0] == "rbc":
                argv = [sys.executable, "-m", "tools.cli", *argv[1:]]
            print(f"$ {run['command']}", flush=True)
            start = time.monotonic()
            done = subprocess.run(argv, cwd=work, text=True, capture_output=True)
            if done.returncode not in run.get("exit_codes", [0]):
                raise RecordError(f"{run['command']}: exit {done.returncode}\n{done.stderr[-2000:]}")
            # paths the command wrote into its output read as the user typed them, not in the temporary folder
            text = (work / run["reads"]).read_text(encoding="utf-8").replace(f"{work}/", "")
            output = json.loads(text)
            keep = run.get("keep")
            run["output"] = {k: output[k] for k in keep if k in output} if keep else output
            print(f"  {time.monotonic() - start:.1f} s", flush=True)
    record.update(date=time.strftime("%Y-%m-%d"), code_version=code_version(), machine=where)
    (root / f"{name}.json").write_text(json.dumps(record, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return record
