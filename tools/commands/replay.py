"""``rbc replay``: send a recorded driving log to a drive server exactly as the Unity simulator would.

Closed loop over the Unity wire (``UnityWireClient``): each frame is sent after the previous reply;
prints every command received with its round trip. Useful to check a server by hand against real
recorded frames, including manual-mode (null) frames and a comma-decimal locale.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from protocol.facts import CAMERAS, MAX_STEERING_DEG
from tools.errors import CommandError
from tools.wire.frames import log_frames
from tools.wire.unity_client import ConnectionClosed, UnityWireClient

log = logging.getLogger("rbc.replay")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--server", default="http://127.0.0.1:4567", help="drive server URL (default %(default)s)")
    p.add_argument("--log", type=Path, required=True, help="driving-log folder (driving_log.csv and IMG/)")
    p.add_argument("--frames", type=int, default=None, help="frames to send (default: the whole log once)")
    p.add_argument("--null-every", type=int, default=0, metavar="K",
                   help="send a manual-mode (null) frame instead of every K-th frame")
    p.add_argument("--locale", choices=("dot", "comma"), default="dot",
                   help="decimal separator of the telemetry numbers (comma: like a European Windows)")
    p.add_argument("--camera", choices=CAMERAS, default=CAMERAS[0], help="which camera's frames of the log to send")
    p.add_argument("--quiet", action="store_true", help="print only the summary")


def run(args: argparse.Namespace) -> int:
    frames = log_frames(args.log, args.camera)
    n = len(frames) if args.frames is None else args.frames
    decimal = "," if args.locale == "comma" else "."
    rtts: list[float] = []
    manual = 0
    try:
        with UnityWireClient(args.server, decimal=decimal) as client:
            for i in range(n):
                frame = frames[i % len(frames)]
                is_null = args.null_every > 0 and (i + 1) % args.null_every == 0
                command, rtt = client.exchange(None if is_null else frame.payload())
                rtts.append(rtt)
                if command is None:
                    manual += 1
                    reply = "manual"
                else:
                    reply = f"steer {command.steering:+.4f} ({command.steering * MAX_STEERING_DEG:+6.2f} deg) " \
                            f"throttle {command.throttle:+.4f}"
                if not args.quiet:
                    sent = "null (manual)" if is_null else \
                        f"speed {frame.speed:6.2f} recorded steer {frame.steering_deg:+6.2f} deg"
                    print(f"{i:5d}  {sent:45s} -> {reply:52s} {rtt * 1e3:7.3f} ms")
    except (ConnectionError, ConnectionClosed, TimeoutError, OSError) as exc:
        raise CommandError(f"replay to {args.server} failed after {len(rtts)} frames: {exc}",
                           "is drive_server running at that address?") from exc
    r = np.asarray(rtts) * 1e3
    print(f"{len(rtts)} frames ({manual} manual) to {args.server}: round trip p50 {np.percentile(r, 50):.3f} "
          f"p99 {np.percentile(r, 99):.3f} max {r.max():.3f} ms")
    return 0
