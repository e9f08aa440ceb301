"""``rbc train`` under torchrun: two CPU processes (gloo) take the single-process step of the global batch."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
dist = pytest.importorskip("torch.distributed")

from models.networks.nets import build_model  # noqa: E402
from models.training import distributed as ddp  # noqa: E402

SAMPLE = Path(__file__).parent / "data" / "udacity-sample"
BATCH = 8
pytestmark = pytest.mark.skipif(not dist.is_available() or not dist.is_gloo_available(), reason="no gloo backend")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _setup() -> tuple[torch.nn.Module, torch.optim.Optimizer, torch.Tensor, torch.Tensor]:
    """The same initial weights and the same global batch in every process.

    Plain SGD, not training's Adam: Adam's first step is about lr * sign(g), so a gradient within float
    rounding of zero flips a weight by lr; SGD shows the averaged gradient itself, which is what DDP adds.
    """
    torch.manual_seed(0)
    model = build_model("pilotnet", 66, 200)  # no dropout: the step is deterministic
    x = torch.from_numpy(np.random.default_rng(1).random((BATCH, 3, 66, 200), dtype=np.float32))
    y = torch.from_numpy(np.random.default_rng(2).uniform(-1, 1, (BATCH, 1)).astype(np.float32))
    return model, torch.optim.SGD(model.parameters(), lr=0.1), x, y


def _rank(rank: int, size: int, port: int, out: str) -> None:
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), RANK=str(rank), WORLD_SIZE=str(size),
                      LOCAL_RANK=str(rank))
    torch.set_num_threads(1)
    world = ddp.world_from_env()
    ddp.init_world(world)
    try:
        model, opt, x, y = _setup()
        half = slice(rank * BATCH // size, (rank + 1) * BATCH // size)
        ddp.train_step(ddp.wrap(model, world), opt, torch.nn.MSELoss(), x[half], y[half])
        if world.is_main:
            torch.save(model.state_dict(), out)
    finally:
        ddp.close_world(world)


def test_two_process_step_equals_the_single_process_step_on_the_global_batch(tmp_path):
    import torch.multiprocessing as mp

    out = tmp_path / "ddp.pt"
    mp.spawn(_rank, args=(2, _free_port(), str(out)), nprocs=2, join=True)
    model, opt, x, y = _setup()
    before = {k: v.clone() for k, v in model.state_dict().items()}
    ddp.train_step(model, opt, torch.nn.MSELoss(), x, y)
    distributed = torch.load(out)
    assert any(not torch.equal(before[k], v) for k, v in model.state_dict().items())  # the step moved the weights
    for k, v in model.state_dict().items():
        torch.testing.assert_close(distributed[k], v, rtol=1e-5, atol=1e-6)


def test_a_shard_is_every_size_th_sample_and_its_share_of_the_batch():
    from models.data.batches import TrainingSet

    data = TrainingSet(np.arange(10), np.zeros(10, np.float32), np.ones(10, bool), 0.0, 8)
    one = ddp.shard(data, ddp.World(1, 2, 1))
    assert list(one.indices) == [1, 3, 5, 7, 9] and one.batch_size == 4
    assert ddp.shard(data, ddp.SINGLE) is data
    with pytest.raises(ddp.DistributedError, match="divisible"):
        ddp.shard(data, ddp.World(0, 3, 0))
    assert ddp.rank_seed(11, ddp.SINGLE) == 11 and ddp.rank_seed(11, ddp.World(1, 2, 1)) != 11


@pytest.mark.slow
def test_torchrun_two_processes_trains_and_exports_a_model_drive_server_loads(tmp_path):
    torchrun = shutil.which("torchrun") or str(Path(sys.executable).with_name("torchrun"))
    if not Path(torchrun).exists():
        pytest.skip("torchrun is not installed")
    out = tmp_path / "run"
    env = os.environ | {"OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [torchrun, "--nproc_per_node", "2", "--master_addr", "127.0.0.1", "--master_port", str(_free_port()),
         "-m", "tools.cli", "train", "--data", str(SAMPLE), "--out", str(out), "--epochs", "1",
         "--max-steps-per-epoch", "2", "--threads", "1", "--no-progress"],
        capture_output=True, text=True, timeout=240, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    record = json.loads((out / "config.json").read_text())
    assert record["world_size"] == 2 and record["result"]["onnx_max_diff"] < 1e-4
    from drive_server.serving.model import SteeringModel

    SteeringModel(out / "model.onnx")  # loads as the drive server loads it
