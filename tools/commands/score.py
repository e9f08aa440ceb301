"""``rbc score``: open-loop scores of models on a recorded driving log (e.g. real Unity frames).

Each model predicts the steering of every frame of the log through drive_server's pipeline; prints MSE,
Pearson r and the MSE of always predicting 0 per model (the sim-to-real figure of the README).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from protocol.facts import CAMERAS
from tools.arguments import add_smooth_argument, smooth_alpha
from tools.console import Progress
from tools.errors import CommandError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", type=Path, required=True, help="driving-log folder (driving_log.csv and IMG/)")
    p.add_argument("--model", type=Path, action="append", default=None,
                   help="ONNX model to score (repeat; default: every bundled model)")
    p.add_argument("--camera", choices=CAMERAS, default=CAMERAS[0], help="which camera's frames to score")
    p.add_argument("--smooth-labels", type=int, default=0, metavar="N",
                   help="also score against the recorded steering averaged over N frames (centred): keyboard "
                        "taps averaged to what the driver meant, e.g. 9 at 10 Hz; 0: off (default %(default)s)")
    add_smooth_argument(p)
    p.add_argument("--json", type=Path, default=None, help="also write the scores to this JSON file")


def run(args: argparse.Namespace) -> int:
    from drive_server.serving.models_dir import bundled_models
    from protocol.datalog import read_log
    from protocol.runrecords import code_version, write_json
    from tools.evaluate.offline import camera_frames, score_models

    if not 0 <= args.smooth_labels <= 1000:
        raise CommandError("--smooth-labels must be 0..1000 frames")
    alpha = smooth_alpha(args)
    models = args.model or bundled_models()
    total = len(camera_frames(read_log(args.data)[0], args.camera)) * len(models)
    progress, done = Progress("score", unit="frame"), [0]

    def tick() -> None:
        done[0] += 1
        progress(done[0], total)

    try:
        scores = score_models(models, args.data, args.camera, on_frame=tick, smooth_frames=args.smooth_labels,
                              smooth=alpha)
    finally:
        progress.close()
    smooth = args.smooth_labels > 1
    extra = f"  {'r, ' + str(args.smooth_labels) + '-frame average':>22}" if smooth else ""
    print(f"{'model':<24} {'frames':>6} {'MSE':>8} {'r':>6} {'always-0':>9}  beats always-0{extra}")
    names = [Path(s.model).name for s in scores]
    for s, name in zip(scores, names, strict=True):
        name = name if names.count(name) == 1 else s.model  # two runs' model.onnx: tell them apart
        extra = f"  {s.pearson_r_smoothed:>22.2f}" if smooth else ""
        print(f"{name:<24} {s.frames:>6} {s.mse:>8.4f} {s.pearson_r:>6.2f} {s.zero_mse:>9.4f}  "
              f"{'yes' if s.beats_zero else 'no':<14}{extra}")
    if args.json:
        write_json(args.json, {"data": str(args.data), "camera": args.camera, "smooth_labels": args.smooth_labels,
                               "smooth": alpha, "code_version": code_version(),
                               "scores": [s.as_dict() for s in scores]})
    return 0
