"""``rbc train``: balance, augment and train a model on driving logs; export it to ONNX."""

from __future__ import annotations

import argparse

from models.training.train_config import TrainConfig
from tools.arguments import add_pipeline_arguments, add_preprocess_arguments, add_yaw_arguments, parse_speed
from tools.errors import CommandError


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", action="append", default=[], metavar="DIR",
                        help="recording directory or driving log (repeat to combine several)")
    add_pipeline_arguments(parser)
    parser.add_argument("--out", required=True, metavar="RUN_DIR", help="run directory (config, history, model)")
    parser.add_argument("--epochs", type=int, help="default: the paper's 5 / 10 / 5 by behavior")
    parser.add_argument("--aug-loops", type=int, default=TrainConfig.aug_loops,
                        help="augmentation loops per epoch: each pass over the training data draws new "
                             "augmentations (chi of the paper; default %(default)s)")
    parser.add_argument("--batch-size", type=int, default=TrainConfig.batch_size, help="default %(default)s")
    parser.add_argument("--seed", type=int, default=TrainConfig.seed, help="split, balancing, augmentation and "
                        "initialisation seed (default %(default)s)")
    parser.add_argument("--split", choices=("blocks", "random", "recordings"), default=TrainConfig.split,
                        help="blocks: hold out contiguous stretches of the log (what a new road looks like); "
                             "random: hold out random frames, the paper's setting, optimistic at 9-15 Hz because "
                             "neighbouring frames are near-copies (the bundled models were trained with random); "
                             "recordings: hold out a fifth of the --data recordings whole (what a new driver's "
                             "data looks like), chosen by --seed")
    parser.add_argument("--val-data", action="append", default=[], metavar="DIR",
                        help="a recording held out whole for validation (repeat; implies --split recordings): "
                             "e.g. one fold of other drivers' recordings")
    parser.add_argument("--balance-recordings", action="store_true",
                        help="each recording gives a pass over the data at most as many samples as the median "
                             "recording, drawn afresh each pass, so one long recording does not dominate")
    parser.add_argument("--recovery-distance", type=float, default=TrainConfig.recovery_distance, metavar="M",
                        help="side-camera labels steer a car 0.95 m off back within M metres (Eq. 4/5, gamma = "
                             "0.95 / M; default: the paper's 10); shorter teaches a stronger pull to the centre line")
    add_yaw_arguments(parser)
    parser.add_argument("--label-lag", type=int, default=TrainConfig.label_lag, metavar="N",
                        help="label each frame with the steering recorded N frames later (drivers steer a few "
                             "frames after the picture that calls for it); 0: as recorded")
    parser.add_argument("--centre-gain", type=float, default=TrainConfig.centre_gain, metavar="K",
                        help="not in the paper: add K steering per metre that the road's middle lies to the side "
                             "(each --data folder needs the road file of rbc data road): drivers hold lines of their "
                             "own on a wide road, and an image can only show where the road is. 0: off")
    parser.add_argument("--edge-gain", type=float, default=TrainConfig.edge_gain, metavar="K",
                        help="not in the paper: add K steering per metre that a camera (each at its own offset) "
                             "stands beyond --edge-margin from the road's middle, towards it (from the road files of "
                             "rbc data road; a recording without one is not pulled): the drivers' own lines are left "
                             "alone, the views near an edge learn to steer away from it. 0: off")
    parser.add_argument("--edge-margin", type=float, default=TrainConfig.edge_margin, metavar="M",
                        help="metres from the road's middle within which --edge-gain pulls nothing")
    parser.add_argument("--block-frames", type=int, default=TrainConfig.block_frames,
                        help="frames per held-out block with --split blocks (shortened for logs under 5 blocks)")
    parser.add_argument("--gap-frames", type=int, default=TrainConfig.gap_frames,
                        help="training frames dropped on each side of a held-out block (at most a quarter block)")
    parser.add_argument("--export", choices=("best", "last"), default=TrainConfig.export,
                        help="which epoch becomes model.onnx: the one with the lowest validation MSE, or the last "
                             "(the bundled models: last)")
    parser.add_argument("--mirror-average", action="store_true",
                        help="not in the paper: the exported model averages its steering for the frame and minus its "
                             "steering for the mirrored frame (one batch of two): a mirrored road gets exactly the "
                             "opposite answer, and the network's left-right noise cancels. Training is unchanged; "
                             "inference costs two passes")
    parser.add_argument("--output-scale", type=float, default=TrainConfig.output_scale, metavar="S",
                        help="not in the paper: the exported model's steering times S, 0.1..2 (S < 1 shrinks the "
                             "answers towards 0 for drivers the model never saw; training is unchanged; default "
                             "%(default)s: as trained)")
    parser.add_argument("--serve-smooth", type=float, default=TrainConfig.serve_smooth, metavar="ALPHA",
                        help="written into the model: drive_server (and rbc score, drive-log, data crossval) smooth "
                             "each client's steering over time with this weight of the new output unless --smooth says "
                             "otherwise, 0 < ALPHA <= 1 (default %(default)s: off)")
    add_preprocess_arguments(parser)
    parser.add_argument("--min-speed", type=str, default=str(TrainConfig.min_speed), metavar="SPEED",
                        help="drop rows recorded slower than this, e.g. 5mph or 8kmh (a bare number is in "
                             "--speed-unit); 0 keeps every row")
    parser.add_argument("--speed-unit", choices=("mph", "kmh"), default=TrainConfig.speed_unit,
                        help="unit of the log's speed column: mph (stock Udacity simulator) or kmh (the paper's)")
    parser.add_argument("--smooth-labels", type=int, default=TrainConfig.smooth_labels, metavar="N",
                        help="fit a centred moving average of the steering over N frames (keyboard taps averaged "
                             "to what the driver meant); validation still scores the recorded steering. 0: off")
    parser.add_argument("--row-stride", type=int, default=TrainConfig.row_stride, metavar="N",
                        help="train and validate on every Nth row of the logs: neighbouring frames are near-copies, "
                             "so the roads stay and the frame cache shrinks N-fold (PilotNet on large data sets)")
    parser.add_argument("--max-steps-per-epoch", type=int, help="cap steps per epoch (quick runs)")
    parser.add_argument("--threads", type=int,
                        help="PyTorch threads (default: cores - 1 for the shallow CNN, whose batches need a core of "
                             "their own; every core for PilotNet)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in RUN_DIR from its checkpoint, with the configuration stored there")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    from models.training.metrics import format_metrics
    from models.training.train import train
    from tools.arguments import preprocess_options

    if not args.data and not args.resume:
        raise CommandError("no training data", "give at least one --data DIR (a folder rbc collect wrote)")
    min_speed, min_unit = parse_speed(args.min_speed, args.speed_unit)
    config = TrainConfig(data=args.data, out=args.out, behavior=args.behavior, arch=args.arch,
                         approach=args.approach, epochs=args.epochs, aug_loops=args.aug_loops,
                         batch_size=args.batch_size, seed=args.seed, max_steps_per_epoch=args.max_steps_per_epoch,
                         split=args.split, block_frames=args.block_frames, gap_frames=args.gap_frames,
                         export=args.export, min_speed=min_speed, min_speed_unit=min_unit, speed_unit=args.speed_unit,
                         smooth_labels=args.smooth_labels, row_stride=args.row_stride, val_data=args.val_data,
                         balance_recordings=args.balance_recordings, label_lag=args.label_lag,
                         centre_gain=args.centre_gain, edge_gain=args.edge_gain, edge_margin=args.edge_margin,
                         recovery_distance=args.recovery_distance, yaw_aug=args.yaw_aug, yaw_range=args.yaw_range,
                         yaw_gain=args.yaw_gain, mirror_average=args.mirror_average,
                         output_scale=args.output_scale,
                         serve_smooth=args.serve_smooth,
                         threads=args.threads, progress=not args.no_progress, **preprocess_options(args))
    result = train(config, resume=args.resume)
    if result.info.get("rank") and not result.interrupted:  # torchrun: rank 0 reports (and exported)
        return 0
    if "summary" in result.info:
        print(result.info["summary"])
    for row in result.history:
        print(f"epoch {row['epoch']}: train MSE {row['train_loss']:.5f}  val MSE {row['val_loss']:.5f}  "
              f"{row['seconds']:.0f} s")
    if result.interrupted:
        print(f"interrupted; checkpoint in {result.run_dir}; continue with: rbc train --out {result.run_dir} --resume")
        return 130
    info = result.info
    print(f"exported epoch {info['exported_epoch']} ({info['export']}); held-out frames ({info['split']} split): "
          f"{format_metrics(info['metrics'])}")
    by_recording = info.get("val_by_recording", [])
    if len(by_recording) > 1:
        beats = sum(m["beats_zero"] for m in by_recording)
        print(f"per held-out recording ({beats} of {len(by_recording)} beat always-0):")
        for m in by_recording:
            print(f"  {_recording_name(m['log']):<40} {format_metrics(m)}{'' if m['beats_zero'] else '  (not)'}")
    print(f"model: {result.onnx} (val MSE {result.val_loss:.5f}; ONNX Runtime matches PyTorch to "
          f"{result.export_diff:.1e}); {result.samples_per_s:.0f} training samples/s")
    return 0


def _recording_name(log: str) -> str:
    """A recording's folder name (its log is usually ``FOLDER/driving_log.csv``)."""
    from pathlib import Path

    path = Path(log)
    return path.parent.name if path.suffix == ".csv" else path.name
