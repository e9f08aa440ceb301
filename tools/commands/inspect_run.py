"""``rbc inspect``: analysis pictures of a training run (library: :mod:`models.training.inspection`).

Named ``inspect_run`` rather than after the subcommand so that it never shadows the standard library."""

from __future__ import annotations

import argparse
from pathlib import Path

from models.networks.runfiles import RunRecord
from models.training.inspection import LAP_FRAMES, plot_activations, plot_histograms, plot_loss, plot_predictions


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="directory written by rbc train")
    parser.add_argument("--data", action="append", metavar="DIR",
                        help="recordings (default: those of the run; the split shown is then of these)")
    parser.add_argument("--frames", type=int, default=LAP_FRAMES, help="consecutive frames for the prediction plot")
    parser.add_argument("--samples", type=int, default=4, help="frames shown with their activation maps")


def run(args: argparse.Namespace) -> int:
    import matplotlib

    matplotlib.use("Agg")
    from models.data.trainingdata import prepare_data
    from models.networks.checkpoint import exported_weights
    from models.networks.nets import build_model
    from models.training.metrics import format_metrics
    from models.training.train import TrainConfig

    run_dir: Path = args.run_dir
    record = RunRecord.load(run_dir)
    config = TrainConfig.from_dict(record.config, str(record.config_path))
    pipeline = config.pipeline()  # with the run's crop: the frames the model was trained on
    data = prepare_data(args.data or config.data, pipeline, config.seed, config.data_options())
    out = run_dir / "inspect"
    out.mkdir(parents=True, exist_ok=True)
    written = [plot_histograms(out, data, pipeline, config.seed)]
    if record.history:
        exported = (record.result or {}).get("exported_epoch")
        written.append(plot_loss(out, record.history, exported))
    model = build_model(config.arch, pipeline.contract.height, pipeline.contract.width)
    if record.checkpoint_path.exists():
        model.load_state_dict(exported_weights(record.checkpoint_path, config.export))
    model.eval()
    path, window = plot_predictions(out, data, pipeline, model, record.model_path, args.frames)
    written.append(path)
    written.append(plot_activations(out, data, pipeline, model, args.samples, config.seed))
    for p in written:
        print(p)
    print(f"held-out frames in the plotted window: {format_metrics(window)}")
    if record.result is not None:
        print(f"all held-out frames: {format_metrics(record.result['val_metrics'])}")
    return 0
