"""``rbc import-peer``: a peer's Keras 1 PilotNet (naokishibuya/car-behavioral-cloning's model.h5) as ONNX.

The result carries its preprocessing contract (RGB in; the YUV conversion is inside the graph), so
``drive_server --model`` and ``rbc score --model`` serve it like a model of ours (library:
:mod:`models.onnxfiles.peer_keras`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.errors import CommandError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--h5", type=Path, required=True, help="the peer's Keras 1 model file (model.h5)")
    p.add_argument("--out", type=Path, required=True, help="ONNX model to write")
    p.add_argument("--yuv", choices=("opencv31", "correct"), default="opencv31",
                   help="colour conversion inside the graph: opencv31 = OpenCV 3.1's RGB2YUV, which the model was "
                        "trained and driven with (today's BGR2YUV on RGB); correct = today's RGB2YUV "
                        "(default %(default)s)")
    p.add_argument("--verify-data", type=Path, default=None, metavar="DIR",
                   help="driving-log folder whose first centre frames check ONNX Runtime against PyTorch "
                        "(default: synthetic frames)")


def run(args: argparse.Namespace) -> int:
    from models.onnxfiles.peer_keras import PeerImportError, import_peer

    if args.out.suffix != ".onnx":
        raise CommandError(f"--out {args.out}: give a path ending in .onnx")
    try:
        info, diff = import_peer(args.h5, args.out, args.yuv, args.verify_data)
    except PeerImportError as exc:
        raise CommandError(str(exc), "give the model.h5 of naokishibuya/car-behavioral-cloning, "
                                     "a Keras 1 HDF5 file") from None
    print(f"wrote {args.out}: {info['repository']}@{info['commit']} {info['file']} (Keras {info['keras_version']}, "
          f"{info['parameters']:,} parameters), yuv {info['yuv']}, contract rgb 200x66 crop 60..135 bilinear; "
          f"max |onnxruntime - torch| {diff:.1e}")
    return 0
