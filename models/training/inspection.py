"""``rbc inspect RUN_DIR``: the paper's analysis pictures of a training run, in ``RUN_DIR/inspect/``.

* ``steering_histograms.png``: training labels as recorded, after one balanced pass (Table 4), and
  after balancing + augmentation (what the network is actually fitted to);
* ``loss.png``: training and validation MSE per epoch;
* ``predictions.png``: the exported model's steering against the recorded labels over about one lap
  of consecutive frames (Fig. 13), through the deployment path (ONNX Runtime, shared preprocessing);
* ``activations.png``: input and the activation maps of every convolution layer (Fig. 12), plus a
  VisualBackProp mask (Bojarski et al. 2017) showing which input pixels drive the deepest layer.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from models.networks.runfiles import EpochRow, RunPaths
from protocol.runrecords import write_bytes

LAP_FRAMES = 1200  # about one lap of the lake track at the simulator's recording rate


def plot_histograms(out: Path, data, pipeline, seed: int) -> Path:
    import matplotlib.pyplot as plt

    from models.augmentation.augment import draw_params
    from models.data.balance import balanced_pass

    rng = np.random.default_rng(seed)
    steering = data.steering[data.train]
    sides = data.has_sides[data.train]
    kept = balanced_pass(steering, pipeline.deletion_rate, rng)
    augmented = draw_params(steering[kept], sides[kept], pipeline.augment, rng).steering
    bins = np.linspace(-1, 1, 52)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.4), sharex=True)
    titles = ("recorded (training split)", f"one balanced pass ({pipeline.deletion_rate:.0%} of zero-steer dropped)",
              "balanced + augmented")
    for ax, values, title in zip(axes, (steering, steering[kept], augmented), titles, strict=True):
        ax.hist(values, bins=bins, color="tab:blue")
        zeros = int((values == 0).sum())
        ax.set_title(f"{title}\n{len(values)} samples, {zeros} exactly zero", fontsize=9)
        ax.set_xlabel("steering (-1..1 = ±25°, + = right)")
    axes[0].set_ylabel("samples")
    fig.tight_layout()
    path = out / "steering_histograms.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_loss(out: Path, history: Sequence[EpochRow], exported_epoch: int | None = None) -> Path:
    """``loss.png`` in ``out``. Drawn on a bare Figure (no pyplot): it never changes the caller's backend, so a
    notebook that trains keeps its own plots."""
    from matplotlib.figure import Figure

    epochs = [h.epoch for h in history]
    fig = Figure(figsize=(5.5, 3.5))
    ax = fig.add_subplot()
    ax.plot(epochs, [h.train_loss for h in history], "o-", label="training (augmented)")
    ax.plot(epochs, [h.val_loss for h in history], "s-", label="validation (held-out frames)")
    if exported_epoch:
        ax.axvline(exported_epoch, color="0.4", ls=":", label=f"exported (epoch {exported_epoch})")
    ax.set_yscale("log")
    ax.set_xlabel("epoch")
    ax.set_ylabel("mean squared error of the steering")
    ax.set_xticks(epochs)
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = RunPaths(out).loss_plot
    write_bytes(path, lambda tmp: fig.savefig(tmp, dpi=110, format="png"))  # a viewer never opens half a picture
    return path


def plot_predictions(out: Path, data, pipeline, model, onnx_path: Path, frames: int) -> tuple[Path, dict]:
    import matplotlib.pyplot as plt
    import torch

    from drive_server.serving.preprocess import to_input_tensor
    from models.training.metrics import steering_metrics

    first_log = data.dataset.samples[0].log
    positions = [i for i in data.usable if data.dataset.samples[i].log == first_log][:frames]
    images = data.cache.frames[0, positions]
    truth = data.steering[positions]
    if onnx_path.exists():
        import onnxruntime as ort

        session = ort.InferenceSession(str(onnx_path), providers=["CPUExecutionProvider"])
        name = session.get_inputs()[0].name
        x = to_input_tensor(images, pipeline.contract)
        pred = np.concatenate([session.run(None, {name: x[i:i + 256]})[0] for i in range(0, len(x), 256)]).ravel()
        source = f"{onnx_path.name} (ONNX Runtime)"
    else:
        from models.augmentation.fastaug import training_contract

        x = to_input_tensor(images, training_contract(pipeline.contract))
        with torch.no_grad():
            pred = model(torch.from_numpy(x)).numpy().ravel()
        source = "checkpoint (PyTorch)"
    is_val = np.isin(positions, data.val)
    window = steering_metrics(pred[is_val], truth[is_val])  # training frames say nothing about generalisation
    fig, ax = plt.subplots(figsize=(12, 3.6))
    t = np.arange(len(positions))
    ax.plot(t, truth, color="0.5", lw=1.0, label="recorded (manual)")
    ax.plot(t, pred, color="tab:red", lw=1.2, label=f"predicted, {source}")
    ax.scatter(t[is_val], truth[is_val], s=4, color="tab:blue", label="validation frames (held out)", zorder=3)
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel(f"frame (log order, {first_log.name})")
    ax.set_ylabel("steering (-1..1 = ±25°)")
    ax.set_title(f"{len(positions)} frames in log order ({data.split.kind.value} split); on its {window['n']} "
                 f"validation frames only: MSE {window['mse']:.4f}, r {window['r']:.2f} "
                 f"(always 0: MSE {window['zero_mse']:.4f})", fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = out / "predictions.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path, window


def visual_backprop(activations: list) -> np.ndarray:
    """VisualBackProp mask at the first layer's input size: channel means multiplied from deep to shallow."""
    import torch
    import torch.nn.functional as F

    mask = None
    for act in reversed(activations):
        mean = act.mean(dim=1, keepdim=True)
        mask = mean if mask is None else mean * F.interpolate(mask, size=mean.shape[-2:], mode="bilinear",
                                                               align_corners=False)
    assert mask is not None
    return torch.nan_to_num(mask)[0, 0].numpy()


def _channel_mosaic(act: np.ndarray) -> np.ndarray:
    """All channel maps (C, h, w) of one layer tiled into one image, normalised per layer."""
    c, h, w = act.shape
    cols = int(np.ceil(np.sqrt(c * w / max(h, 1) * 0.5))) if h > 1 else int(np.ceil(np.sqrt(c)))
    cols = max(1, min(c, cols))
    rows = int(np.ceil(c / cols))
    pad = 1 if h > 1 else 0
    mosaic = np.full((rows * (h + pad), cols * (w + pad)), np.nan, np.float32)
    peak = float(act.max()) or 1.0
    for k in range(c):
        r, q = divmod(k, cols)
        mosaic[r * (h + pad):r * (h + pad) + h, q * (w + pad):q * (w + pad) + w] = act[k] / peak
    return mosaic


def plot_activations(out: Path, data, pipeline, model, count: int, seed: int) -> Path:
    import cv2
    import matplotlib.pyplot as plt
    import torch

    from drive_server.serving.preprocess import to_input_tensor
    from models.augmentation.fastaug import training_contract
    from models.networks.nets import conv_activations

    rng = np.random.default_rng(seed)
    pool = data.train[data.steering[data.train] != 0] if (data.steering[data.train] != 0).any() else data.train
    picks = np.sort(rng.choice(pool, size=min(count, len(pool)), replace=False))
    images = data.cache.frames[0, picks]
    x = torch.from_numpy(to_input_tensor(images, training_contract(pipeline.contract)))
    with torch.no_grad():
        acts = conv_activations(model, x)
        predicted = model.eval()(x).reshape(-1).numpy()
    layers = len(acts)
    fig, axes = plt.subplots(len(picks), layers + 2, figsize=(2.6 * (layers + 2), 2.4 * len(picks)), squeeze=False)
    for row, img in enumerate(images):
        shown = cv2.cvtColor(img, cv2.COLOR_YUV2RGB) if pipeline.contract.color == "yuv" else img
        axes[row, 0].imshow(shown)
        axes[row, 0].set_title(f"recorded steering {data.steering[picks[row]]:+.3f}\n"
                               f"predicted {predicted[row]:+.3f}", fontsize=8)
        for k, act in enumerate(acts):
            a = act[row].numpy()
            im = axes[row, k + 1].imshow(_channel_mosaic(a), cmap="inferno", interpolation="nearest", vmin=0, vmax=1)
            axes[row, k + 1].set_title(f"conv{k + 1}: {a.shape[0]} maps of {a.shape[1]}x{a.shape[2]}", fontsize=8)
            bar = fig.colorbar(im, ax=axes[row, k + 1], fraction=0.046, pad=0.02)
            bar.ax.tick_params(labelsize=6)
            if k == len(acts) - 1:
                bar.set_label("activation / layer max", fontsize=7)
        vbp = visual_backprop([a[row:row + 1] for a in acts])
        vbp = cv2.resize(vbp, (img.shape[1], img.shape[0]), interpolation=cv2.INTER_LINEAR)
        vbp = vbp / (vbp.max() or 1.0)
        axes[row, -1].imshow(shown)
        mask = axes[row, -1].imshow(vbp, cmap="inferno", alpha=0.6, vmin=0, vmax=1)
        axes[row, -1].set_title("where the network looks\n(VisualBackProp)", fontsize=8)
        bar = fig.colorbar(mask, ax=axes[row, -1], fraction=0.046, pad=0.02)
        bar.ax.tick_params(labelsize=6)
        for ax in axes[row]:
            ax.axis("off")
    fig.tight_layout()
    path = out / "activations.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
