"""Facts of the simulator and the paper that every package shares, defined here and nowhere else.

The real simulator's camera rig (field of view, pitch, height, side offset, bonnet row, the car's width) is
facts too; they live in :mod:`protocol.camera`, beside the pinhole maths that uses them (numpy: this module
stays standard library only).
"""

from __future__ import annotations

#: Camera frame size of the Udacity/Unity simulator (and of the headless one), pixels.
FRAME_WIDTH = 320
FRAME_HEIGHT = 160
#: Largest wheel angle, degrees: the wire's normalised steering -1..1 is multiplied by it.
MAX_STEERING_DEG = 25.0
#: Unity's ``EncodeToJPG`` default, used for telemetry frames and recorded images alike.
JPEG_QUALITY = 75
#: The cameras of a recording, in driving-log column order.
CAMERAS = ("center", "left", "right")
#: The paper's three driving behaviors (one bundled model each).
BEHAVIORS = ("simplistic", "rigorous", "collision")
#: File signatures accepted as camera frames (Unity writes JPEG; some recorders PNG).
IMAGE_MAGIC = (b"\xff\xd8", b"\x89PNG")
#: The paper's speeds: data collected at 30 km/h, models deployed at 25 km/h (the default speed limit).
COLLECT_SPEED_KMH = 30.0
DEPLOY_SPEED_KMH = 25.0
