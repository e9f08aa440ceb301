"""What determines a training run, torch-free so the command line can read its defaults without torch."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from drive_server.contract import ContractError, PreprocessContract
from drive_server.serving import check_gain
from models.augmentation import geometry
from models.augmentation.augment import LOOKAHEAD_M, AugmentSpec
from models.data.behavior import (
    AUGMENTATION_LOOPS,
    BATCH_SIZE,
    LEARNING_RATE,
    Pipeline,
    keeps_lane,
    pipeline_for,
)
from models.data.split import SplitKind, SplitSpec
from models.data.trainingdata import DataOptions
from protocol.camera import SIDE_OFFSET_M as SIDE_CAMERA_OFFSET_M  # Eq. 4/5's numerator
from protocol.errors import BadValue
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

#: Brightness range of ``brightness_mode="scale"`` when none is given: gain 1 +- 0.5.
SCALE_BRIGHTNESS_RANGE = 0.5
#: What a stored run without these keys did (runs written before they existed): the paper's split, last epoch.
LEGACY = {"split": "random", "export": "last"}
#: Keys of stored runs renamed since (old -> new), so run configs written before still load.
RENAMED = {"smooth_labels": "label_smoothing_frames", "serve_smooth": "smoothing", "serve_smoothing": "smoothing",
           "output_scale": "gain"}
#: Recipe keys renamed since recipes exist (old -> new, same section), so a recipe file written before still loads.
RENAMED_IN_RECIPES = {"serve_smoothing": "smoothing", "output_scale": "gain"}
#: Knobs removed because they were measured useless (docs/experiments.md), with the value that did nothing: a stored
#: run holding that value still loads, one holding another cannot be reproduced any more.
REMOVED = {"label_lag": 0, "recovery_distance": None}
EXPORTS = ("best", "last")
BRIGHTNESS_MODES = ("add", "scale")


def turned_edge_columns(augment: AugmentSpec, contract: PreprocessContract) -> int:
    """Network columns that a turn of up to ``yaw_range_deg`` leaves without picture, plus one: blanked on both
    sides of every input, so the network cannot read the turn from the missing edge (the closed loop's views
    have that edge too, so a model that did would score there what it could not do in Unity). The camera's
    wide angle makes the edges move most: a 6 degree turn leaves 30 of 320 columns at the edge empty."""
    ys = np.arange(contract.crop_top, contract.crop_bottom + 1, dtype=np.float64)
    xs = np.arange(0.0, FRAME_WIDTH / 2 + 1)
    worst = 0.0
    for sign in (-1.0, 1.0):
        pull = geometry.yaw_pullbacks(FRAME_WIDTH, FRAME_HEIGHT, np.radians([sign * augment.yaw_range_deg]),
                                      augment.camera_vfov_deg, augment.camera_pitch_deg)[0]
        for x in (xs, FRAME_WIDTH - xs):  # inward from the left edge, and from the right one
            gx, gy = np.meshgrid(x, ys)
            src = pull @ np.stack([gx.ravel(), gy.ravel(), np.ones(gx.size)])
            src_x = src[0] / src[2]
            outside = (src_x < 0) | (src_x > FRAME_WIDTH)
            if outside.any():
                worst = max(worst, float(np.abs(gx.ravel()[outside] - (x[0])).max()))
    return min(contract.width // 4, math.ceil(worst * contract.width / FRAME_WIDTH) + 1)


@dataclass
class TrainConfig:
    """Everything that determines a run. ``None`` means the paper's (or the approach's) value."""

    data: list[str]
    out: str
    behavior: str = "simplistic"
    arch: str = "shallow"
    approach: str = "ours"
    epochs: int | None = None
    aug_loops: int = AUGMENTATION_LOOPS
    batch_size: int = BATCH_SIZE
    learning_rate: float = LEARNING_RATE
    seed: int = 0
    max_steps_per_epoch: int | None = None
    val_fraction: float = SplitSpec.val_fraction
    split: str = SplitKind.BLOCKS.value  # "blocks": contiguous stretches held out; "random": the paper's
    block_frames: int = SplitSpec.block_frames
    gap_frames: int = SplitSpec.gap_frames
    export: str = "best"  # "best": the epoch with the lowest validation MSE; "last": the final epoch
    crop_top: int | None = None  # rows of the 320x160 frame; None: the approach's (0 ours, 60 nvidia)
    crop_bottom: int | None = None
    decode_reduce: int = 0  # decode frames at 1/n size (0: the serving rule's choice; in the model's contract)
    brightness_mode: str = "add"  # "add": the paper's p + beta; "scale": p * (1 + beta), relative to the frame
    brightness_range: float | None = None  # None: 100 (add, the paper's), 50 (nvidia), 0.5 (scale)
    min_speed: float = 0.0  # rows recorded slower than this are dropped (0: keep all)
    min_speed_unit: str = "mph"
    speed_unit: str = "mph"  # unit of the log's speed column: mph (Udacity) or kmh (the paper's simulator)
    label_smoothing_frames: int = 0  # train on a centred moving average of the steering over N frames (0: off)
    row_stride: int = 1  # train and validate on every Nth row of the logs (1: every row)
    val_data: list[str] = field(default_factory=list)  # recordings held out whole (implies split "recordings")
    balance_recordings: bool = False  # each recording gives a pass at most the median recording's samples
    # not in the paper: labels plus this much steering per metre towards the road's middle (rbc data road)
    centre_gain: float = 0.0
    # not in the paper: edge_gain steering per metre that a camera (each at its own offset) stands beyond
    # edge_margin metres from the road's middle, towards it (rbc data road; 0: off)
    edge_gain: float = 0.0
    edge_margin: float = 1.5
    # not in the paper: the share of samples seen from the car turned by up to yaw_range degrees, labelled to
    # turn back (theta - yaw_gain * psi): the heading feedback a closed loop needs (0: off, the paper's)
    yaw_aug: float = 0.0
    yaw_range: float = 6.0
    yaw_gain: float = 1.0
    # not in the paper: the share of (centre-camera) samples seen from the car moved up to offset_range metres to the
    # side (DAVE-2's shifts), labelled to aim back at the driver's line offset_lookahead metres ahead (0: off)
    offset_aug: float = 0.0
    offset_range: float = 2.0
    offset_lookahead: float = LOOKAHEAD_M
    # not in the paper: export (f(x) - f(mirror x)) / 2 (models.networks.nets.MirrorAveraged); training is unchanged
    mirror_average: bool = False
    # not in the paper: drive_server multiplies the network's steering by this unless told otherwise
    # (drive_server.serving; 1: as trained), written into the model's metadata; training and the network unchanged
    gain: float = 1.0
    # how drive_server smooths each client's steering unless told otherwise: the weight of the new output
    # (drive_server.smoothing; 1: off), written into the model's metadata
    smoothing: float = 1.0
    # execution only (do not change results beyond float noise)
    threads: int | None = None
    decode_workers: int | None = None
    progress: bool = True

    def __post_init__(self) -> None:
        if self.export not in EXPORTS:
            raise BadValue(f"export must be best or last, not {self.export!r}")
        if self.brightness_mode not in BRIGHTNESS_MODES:
            raise BadValue(f"brightness mode must be add or scale, not {self.brightness_mode!r}")
        if self.val_data:
            self.split = "recordings"
        if not 0.0 <= self.yaw_aug <= 1.0:
            raise BadValue(f"yaw augmentation share must be 0..1, got {self.yaw_aug}")
        if not 0.0 < self.yaw_range <= 30.0:
            raise BadValue(f"yaw range must be above 0 and at most 30 degrees, got {self.yaw_range}")
        if not 0.0 <= self.yaw_gain <= 5.0:
            raise BadValue(f"yaw gain must be 0..5, got {self.yaw_gain}")
        if not 0.0 <= self.offset_aug <= 1.0:
            raise BadValue(f"offset augmentation share must be 0..1, got {self.offset_aug}")
        if not 0.0 < self.offset_range <= 4.0:
            raise BadValue(f"offset range must be above 0 and at most 4 m, got {self.offset_range}")
        if not 1.0 <= self.offset_lookahead <= 100.0:
            raise BadValue(f"offset lookahead must be 1..100 m, got {self.offset_lookahead}")
        if self.mirror_average and keeps_lane(self.behavior):
            raise BadValue(f"mirror_average: the {self.behavior} behavior keeps to one lane of a two-lane road, a "
                           f"left-right asymmetric task (trained without flips); the average would steer it to the "
                           f"road's middle")
        check_gain(self.gain)
        if not 0.0 < self.smoothing <= 1.0:
            raise BadValue(f"smoothing must be above 0 and at most 1 (1: off), got {self.smoothing}")
        if not 0.0 <= self.centre_gain <= 1.0:
            raise BadValue(f"centre gain must be 0..1 steering per metre, got {self.centre_gain}")
        if not 0.0 <= self.edge_gain <= 1.0:
            raise BadValue(f"edge gain must be 0..1 steering per metre, got {self.edge_gain}")
        if not 0.0 <= self.edge_margin <= 10.0:
            raise BadValue(f"edge margin must be 0..10 m, got {self.edge_margin}")
        if not 0 <= self.label_smoothing_frames <= 1000:
            raise BadValue(f"label smoothing must be 0..1000 frames, got {self.label_smoothing_frames}")
        if not 1 <= self.row_stride <= 1000:
            raise BadValue(f"row stride must be 1..1000, got {self.row_stride}")
        if self.min_speed < 0:
            raise BadValue(f"min speed must be >= 0, got {self.min_speed}")
        if self.brightness_range is not None and self.brightness_range < 0:
            raise BadValue(f"brightness range must be >= 0, got {self.brightness_range}")
        self.split_spec()  # validates the split settings
        try:
            self.pipeline()
        except ContractError as exc:  # said in the recipe's words, not as a broken model file
            raise BadValue(f"crop_top/crop_bottom (with the {self.approach} approach's defaults for what is "
                           f"not given): {exc}") from None

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "stored config") -> TrainConfig:
        """A stored run's config (``config.json``; ``source`` names it in errors): a key this version does not know
        is refused, not dropped, since the run it describes would not be the one rebuilt; old names and removed
        knobs at the value that did nothing still load."""
        known = [f.name for f in fields(cls)]
        values: dict[str, Any] = dict(LEGACY)
        for key, value in data.items():
            key = RENAMED.get(key, key)
            if key in REMOVED:
                if value != REMOVED[key]:
                    raise BadValue(f"{source}: {key} = {value!r}: that knob was removed (measured useless, "
                                   f"docs/experiments.md), so this version cannot rebuild the run")
            elif key not in known:
                raise BadValue(f"{source}: unknown key {key!r} (known: {', '.join(known)})")
            else:
                values[key] = value
        return cls(**values)

    def split_spec(self) -> SplitSpec:
        return SplitSpec(self.split, self.val_fraction, self.block_frames, self.gap_frames)

    def data_options(self) -> DataOptions:
        """The data settings; fields named alike in both classes are copied by name, so none is forgotten."""
        same = {f.name for f in fields(DataOptions)} & {f.name for f in fields(self)} - {"split", "val_data"}
        return DataOptions(split=self.split_spec(), val_data=tuple(self.val_data), road_middles=self.edge_gain > 0,
                           **{name: getattr(self, name) for name in same})

    def pipeline(self) -> Pipeline:
        """The behavior's pipeline with this run's crop and brightness settings applied."""
        p = pipeline_for(self.behavior, self.arch, self.approach)
        contract = replace(p.contract, crop_top=p.contract.crop_top if self.crop_top is None else self.crop_top,
                           crop_bottom=p.contract.crop_bottom if self.crop_bottom is None else self.crop_bottom,
                           decode_reduce=self.decode_reduce)
        brightness_range = self.brightness_range
        if brightness_range is None:
            brightness_range = SCALE_BRIGHTNESS_RANGE if self.brightness_mode == "scale" else p.augment.brightness_range
        augment = replace(p.augment, brightness_mode=self.brightness_mode, brightness_range=brightness_range)
        if self.yaw_aug > 0:
            augment = replace(augment, yaw=self.yaw_aug, yaw_range_deg=self.yaw_range, yaw_gain=self.yaw_gain)
            contract = replace(contract, blank_columns=turned_edge_columns(augment, contract))
        if self.offset_aug > 0:
            augment = replace(augment, offset=self.offset_aug, offset_range_m=self.offset_range,
                              offset_lookahead_m=self.offset_lookahead)
        if self.edge_gain > 0:
            augment = replace(augment, edge_gain=self.edge_gain, edge_margin_m=self.edge_margin,
                              side_camera_m=SIDE_CAMERA_OFFSET_M)
        return replace(p, contract=contract, augment=augment)
