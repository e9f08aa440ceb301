"""What determines a training run, torch-free so the command line can read its defaults without torch."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from drive_server.contract import ContractError, PreprocessContract
from models.augmentation import geometry
from models.augmentation.augment import AugmentSpec
from models.data.split import SplitSpec
from models.data.trainingdata import DataOptions
from models.training.behavior import (
    AUGMENTATION_LOOPS,
    BATCH_SIZE,
    LEARNING_RATE,
    Pipeline,
    check_output_scale,
    keeps_lane,
    pipeline_for,
)
from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH

#: Lateral offset of the side cameras from the centre one, metres (the design card; Eq. 4/5's numerator).
SIDE_CAMERA_OFFSET_M = 0.95
#: Brightness range of ``brightness_mode="scale"`` when none is given: gain 1 +- 0.5.
SCALE_BRIGHTNESS_RANGE = 0.5
#: What a stored run without these keys did (runs written before they existed): the paper's split, last epoch.
LEGACY = {"split": "random", "export": "last"}


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
    split: str = SplitSpec.kind.value  # "blocks": contiguous stretches held out; "random": the paper's
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
    smooth_labels: int = 0  # train on a centred moving average of the steering over N frames (0: as recorded)
    row_stride: int = 1  # train and validate on every Nth row of the logs (1: every row)
    val_data: list[str] = field(default_factory=list)  # recordings held out whole (implies split "recordings")
    balance_recordings: bool = False  # each recording gives a pass at most the median recording's samples
    label_lag: int = 0  # train on the steering recorded this many frames after the frame
    # not in the paper: labels plus this much steering per metre towards the road's middle (rbc data road)
    centre_gain: float = 0.0
    # not in the paper: edge_gain steering per metre that a camera (each at its own offset) stands beyond
    # edge_margin metres from the road's middle, towards it (rbc data road; 0: off)
    edge_gain: float = 0.0
    edge_margin: float = 1.5
    # side-camera label correction: the distance (m) in which a car 0.95 m off would be back (Eq. 4/5: gamma =
    # 0.95 / this); None: the paper's 10 m. Shorter teaches a stronger pull back to the centre line
    recovery_distance: float | None = None
    # not in the paper: the share of samples seen from the car turned by up to yaw_range degrees, labelled to
    # turn back (theta - yaw_gain * psi): the heading feedback a closed loop needs (0: off, the paper's)
    yaw_aug: float = 0.0
    yaw_range: float = 6.0
    yaw_gain: float = 1.0
    # not in the paper: export (f(x) - f(mirror x)) / 2 (models.networks.nets.MirrorAveraged); training is unchanged
    mirror_average: bool = False
    # not in the paper: the exported model's steering times this (models.networks.nets.OutputScaled; 1: as trained);
    # training is unchanged
    output_scale: float = 1.0
    # how drive_server smooths each client's steering unless told otherwise (drive_server.smoothing; 1: off),
    # written into the model's metadata
    serve_smooth: float = 1.0
    # execution only (do not change results beyond float noise)
    threads: int | None = None
    decode_workers: int | None = None
    progress: bool = True

    def __post_init__(self) -> None:
        if self.export not in ("best", "last"):
            raise ValueError(f"export must be best or last, not {self.export!r}")
        if self.brightness_mode not in ("add", "scale"):
            raise ValueError(f"brightness mode must be add or scale, not {self.brightness_mode!r}")
        if self.val_data:
            self.split = "recordings"
        if self.recovery_distance is not None and not 1.0 <= self.recovery_distance <= 100.0:
            raise ValueError(f"recovery distance must be 1..100 m, got {self.recovery_distance}")
        if not 0.0 <= self.yaw_aug <= 1.0:
            raise ValueError(f"yaw augmentation share must be 0..1, got {self.yaw_aug}")
        if not 0.0 < self.yaw_range <= 30.0:
            raise ValueError(f"yaw range must be above 0 and at most 30 degrees, got {self.yaw_range}")
        if not 0.0 <= self.yaw_gain <= 5.0:
            raise ValueError(f"yaw gain must be 0..5, got {self.yaw_gain}")
        if self.mirror_average and keeps_lane(self.behavior):
            raise ValueError(f"--mirror-average: the {self.behavior} behavior keeps to one lane of a two-lane road, a "
                             f"left-right asymmetric task (trained without flips); the average would steer it to the "
                             f"road's middle")
        check_output_scale(self.output_scale)
        if not 0.0 < self.serve_smooth <= 1.0:
            raise ValueError(f"serve smoothing must be above 0 and at most 1 (1: off), got {self.serve_smooth}")
        if not 0.0 <= self.centre_gain <= 1.0:
            raise ValueError(f"centre gain must be 0..1 steering per metre, got {self.centre_gain}")
        if not 0.0 <= self.edge_gain <= 1.0:
            raise ValueError(f"edge gain must be 0..1 steering per metre, got {self.edge_gain}")
        if not 0.0 <= self.edge_margin <= 10.0:
            raise ValueError(f"edge margin must be 0..10 m, got {self.edge_margin}")
        if not 0 <= self.label_lag <= 100:
            raise ValueError(f"label lag must be 0..100 frames, got {self.label_lag}")
        if not 1 <= self.row_stride <= 1000:
            raise ValueError(f"row stride must be 1..1000, got {self.row_stride}")
        if self.min_speed < 0:
            raise ValueError(f"min speed must be >= 0, got {self.min_speed}")
        if self.brightness_range is not None and self.brightness_range < 0:
            raise ValueError(f"brightness range must be >= 0, got {self.brightness_range}")
        self.split_spec()  # validates the split settings
        try:
            self.pipeline()
        except ContractError as exc:  # said in the flags' words, not as a broken model file
            raise ValueError(f"--crop-top/--crop-bottom (with the {self.approach} approach's defaults for what is "
                             f"not given): {exc}") from None

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        known = set(cls.__dataclass_fields__)
        values = {**LEGACY, **{k: v for k, v in data.items() if k in known}}
        return cls(**values)

    def split_spec(self) -> SplitSpec:
        return SplitSpec(self.split, self.val_fraction, self.block_frames, self.gap_frames)

    def data_options(self) -> DataOptions:
        return DataOptions(self.split_spec(), self.min_speed, self.min_speed_unit, self.speed_unit, self.smooth_labels,
                           self.row_stride, tuple(self.val_data), self.balance_recordings, self.label_lag,
                           self.centre_gain, self.edge_gain > 0)

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
        if self.recovery_distance is not None:
            augment = replace(augment, gamma=SIDE_CAMERA_OFFSET_M / self.recovery_distance)
        if self.yaw_aug > 0:
            augment = replace(augment, yaw=self.yaw_aug, yaw_range_deg=self.yaw_range, yaw_gain=self.yaw_gain)
            contract = replace(contract, blank_columns=turned_edge_columns(augment, contract))
        if self.edge_gain > 0:
            augment = replace(augment, edge_gain=self.edge_gain, edge_margin_m=self.edge_margin,
                              side_camera_m=SIDE_CAMERA_OFFSET_M)
        return replace(p, contract=contract, augment=augment)
