"""``rbc augment-preview``: a grid of augmented frames with their labels, to see what training sees.

Each sample is shown twice: the literal full-resolution augmentation (``augment_reference``, as in
the paper's Figures 3-9) and the network input the fast training path makes from the same draws.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from tools.arguments import add_moved_to_recipe_flags

if TYPE_CHECKING:
    from models.training.train_config import TrainConfig


#: Samples side by side (each as its reference and its network input): the picture stays readable at a page's width.
PREVIEW_COLUMNS = 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", action="append", required=True, metavar="DIR", help="recording directory or log")
    parser.add_argument("--recipe", metavar="FILE_OR_NAME",
                        help="the training recipe whose crop, decode and augmentations to show: a file or a bundled "
                             "name, as rbc train --recipe (default: rbc train's defaults)")
    parser.add_argument("--out", required=True, type=Path, help="PNG file to write")
    parser.add_argument("--n", type=int, default=16, help="number of samples")
    parser.add_argument("--seed", type=int, default=0, help="which samples and augmentations are drawn")
    add_moved_to_recipe_flags(parser)


def run(args: argparse.Namespace) -> int:
    from models.training.recipe import load_recipe

    return _write_preview(args, load_recipe(args.recipe))


def _describe(params, i: int) -> str:
    """Short text of what was applied to sample ``i``."""
    from protocol.facts import CAMERAS

    parts = []
    if params.camera[i]:
        parts.append(CAMERAS[int(params.camera[i])])
    if params.shadow[i]:
        parts.append("shadow")
    if params.brightness[i]:
        parts.append(f"bright{params.beta[i]:+.2g}")
    if params.moved[i]:
        parts.append(f"moved{params.offset_m[i]:+.2f}m")
    if params.turned[i]:
        parts.append(f"turn{params.yaw_deg[i]:+.1f}°")
    if params.flip[i]:
        parts.append("flip")
    if params.pan[i]:
        parts.append(f"pan({params.pan_xy[i, 0]:+.0f},{params.pan_xy[i, 1]:+.0f})")
    if params.shift[i]:
        parts.append(f"shift{params.shift_px[i]:+.0f}")
    if params.tilt[i]:
        parts.append(f"tilt{params.tilt_deg[i]:+.2f}°")
    return " ".join(parts) or "none"


def _write_preview(args: argparse.Namespace, config: TrainConfig) -> int:
    """The preview of ``config``'s pipeline (crop, decode, brightness, turns) on ``args.data``."""
    import cv2
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from drive_server.serving.preprocess import blank_edges
    from models.augmentation.augment import draw_params
    from models.augmentation.fastaug import FastAugmenter
    from models.augmentation.reference import augment_reference
    from models.data.framecache import build_cache, load_frame
    from protocol.datalog import read_logs
    from protocol.facts import CAMERAS

    pipeline = config.pipeline()
    dataset = read_logs(args.data)
    rng = np.random.default_rng(args.seed)
    # prefer turning frames so the label corrections are visible, as the paper's figures do
    samples = dataset.samples
    steering = np.array([s.steering for s in samples], np.float32)
    weights = np.where(steering != 0, 3.0, 1.0)
    pick = np.sort(rng.choice(len(samples), size=min(args.n, len(samples)), replace=False, p=weights / weights.sum()))
    chosen = [samples[i] for i in pick]
    cams = CAMERAS if pipeline.augment.uses_side_cameras else ("center",)
    cache = build_cache(chosen, pipeline.contract, cams)
    sides = np.array([s.has_sides for s in chosen]) & pipeline.augment.uses_side_cameras
    params = draw_params(steering[pick], sides, pipeline.augment, rng)
    fast = FastAugmenter(cache, pipeline.augment).images(np.arange(len(chosen)), params)

    cols = PREVIEW_COLUMNS
    rows = int(np.ceil(len(chosen) / cols))
    fig, axes = plt.subplots(rows, cols * 2, figsize=(cols * 2 * 2.6, rows * 1.9 + 0.5), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for k, s in enumerate(chosen):
        frames = {c: load_frame(getattr(s, c)) for c in cams if getattr(s, c) is not None}
        full, label = augment_reference(frames, params, k, pipeline.augment)
        net = blank_edges(fast[k][None].copy(), pipeline.contract.blank_columns)[0]  # as the network sees it
        if pipeline.contract.color == "yuv":
            net = cv2.cvtColor(net, cv2.COLOR_YUV2RGB)
        r, c = divmod(k, cols)
        a_full, a_net = axes[r, 2 * c], axes[r, 2 * c + 1]
        a_full.imshow(full)
        a_full.set_title(f"{s.steering:+.3f} -> {label:+.3f}\n{_describe(params, k)}", fontsize=8)
        a_net.imshow(net, interpolation="nearest")
        a_net.set_title(f"network input {net.shape[1]}x{net.shape[0]}", fontsize=8)
    a, contract = pipeline.augment, pipeline.contract
    bright = f"p + U(-{a.brightness_range:g}, {a.brightness_range:g})" if a.brightness_mode == "add" else \
        f"p x (1 + U(-{a.brightness_range:g}, {a.brightness_range:g}))"
    fig.suptitle(f"{config.behavior} / {config.approach}: recorded label -> training label; brightness {bright}\n"
                 f"left: full-resolution reference, right: training input (rows {contract.crop_top}-"
                 f"{contract.crop_bottom})", fontsize=9)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    plt.close(fig)
    print(f"wrote {args.out} ({len(chosen)} samples from {', '.join(str(p) for p in dataset.logs)})")
    return 0
