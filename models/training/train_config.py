"""What determines a training run, torch-free so the command line can read its defaults without torch."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from drive_server.serving.contract import DECODE_REDUCTIONS, ContractError, PreprocessContract
from drive_server.serving.settings import GAIN_RANGE, NO_GAIN
from drive_server.serving.smoothing import OFF as SMOOTHING_OFF
from models.augmentation import geometry
from models.augmentation.augment import AugmentSpec
from models.data.behavior import (
    AUGMENTATION_LOOPS,
    BATCH_SIZE,
    LEARNING_RATE,
    Approach,
    Arch,
    Behavior,
    Pipeline,
    keeps_lane,
    pipeline_for,
)
from models.data.split import SplitKind, SplitSpec
from models.data.trainingdata import DataOptions
from models.networks.runfiles import MODEL
from models.training.knobs import Range, knob, knob_fields
from models.training.knobs import check as check_knobs
from protocol.errors import BadValue
from protocol.facts import BEHAVIORS, FRAME_HEIGHT, FRAME_WIDTH
from protocol.units import SpeedUnit

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

#: Brightness range of ``brightness_mode="scale"`` when none is given: gain 1 +- 0.5.
SCALE_BRIGHTNESS_RANGE = 0.5
#: What a stored run without these keys did (runs written before they existed): the paper's split, last epoch.
LEGACY = {"split": "random", "export": "last"}
#: Recipe keys added since model files record their recipe, with what a recipe recorded before did without them.
ADDED_TO_RECIPES = {"drop_turnround": False}
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
SPEED_UNITS = tuple(u.value for u in SpeedUnit)


def turned_edge_columns(augment: AugmentSpec, contract: PreprocessContract) -> int:
    """Network columns that a turn of up to ``yaw_range`` degrees leaves without picture, plus one: blanked on both
    sides of every input, so the network cannot read the turn from the missing edge (the closed loop's views
    have that edge too, so a model that did would score there what it could not do in Unity). The camera's
    wide angle makes the edges move most: a 6 degree turn leaves 30 of 320 columns at the edge empty."""
    ys = np.arange(contract.crop_top, contract.crop_bottom + 1, dtype=np.float64)
    xs = np.arange(0.0, FRAME_WIDTH / 2 + 1)
    worst = 0.0
    for sign in (-1.0, 1.0):
        pull = geometry.yaw_pullbacks(FRAME_WIDTH, FRAME_HEIGHT, np.radians([sign * augment.yaw_range]),
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
    """Everything that determines a run. ``None`` means the paper's (or the approach's) value.

    Each recipe key is a field made by :func:`~models.training.knobs.knob`, its one declaration: default, section,
    help, range or choices. A key named like a field of the preprocessing contract or the augmentation sets that
    field (:meth:`pipeline`) and takes its default from there; the fields after the knobs are the command line's."""

    data: list[str]
    out: str
    split: str = knob(SplitKind.BLOCKS.value, "data", "held-out frames: blocks (stretches of each log), random (the "
                      "paper's; optimistic at 9-15 Hz), recordings (whole recordings: a new driver)",
                      choices=tuple(k.value for k in SplitKind))
    val_fraction: float = knob(SplitSpec.val_fraction, "data", "share of the data held out for validation")
    block_frames: int = knob(SplitSpec.block_frames, "data", "frames per held-out block (split blocks; shortened "
                             "for logs under 5 blocks)")
    gap_frames: int = knob(SplitSpec.gap_frames, "data", "training frames dropped on each side of a held-out "
                           "block, so none is a near-copy of one")
    min_speed: float = knob(DataOptions.min_speed, "data", "drop rows recorded slower than this (laps start and end "
                            "creeping; 0 keeps every row)", range=Range(0.0))
    min_speed_unit: str = knob(SpeedUnit.MPH.value, "data", "unit of min_speed: mph or kmh", choices=SPEED_UNITS)
    speed_unit: str = knob(SpeedUnit.MPH.value, "data", "unit of the log's speed column: mph (stock Udacity "
                           "simulator) or kmh (the paper's)", choices=SPEED_UNITS)
    label_smoothing_frames: int = knob(DataOptions.label_smoothing_frames, "data", "fit a centred moving average of "
                                       "the steering over this many frames (keyboard taps averaged to what the driver "
                                       "meant; validation scores the recorded one). 0: off",
                                       range=Range(0, 1000, unit="frames"))
    row_stride: int = knob(DataOptions.row_stride, "data", "use every Nth row of the logs: neighbouring frames are "
                           "near-copies, the frame cache shrinks", range=Range(1, 1000))
    drop_turnround: bool = knob(DataOptions.drop_turnround, "data", "leave out the rows where the driver turned the "
                                "car round (reversing, then the full-lock leg forwards): the log's speed has no sign, "
                                "so those rows pair the picture with the opposite wheel")
    balance_recordings: bool = knob(False, "data", "each recording gives a pass over the data at most the median "
                                    "recording's samples")
    centre_gain: float = knob(DataOptions.centre_gain, "data", "not in the paper: add this much steering per metre "
                              "that the road's middle lies to the side (every --data folder needs its road file, rbc "
                              "data road). 0: off", range=Range(0.0, 1.0, unit="steering per metre"))
    aug_loops: int = knob(AUGMENTATION_LOOPS, "augmentation", "passes over the training data per epoch, each "
                          "drawing new augmentations (the paper's chi)")
    brightness_mode: str = knob(AugmentSpec.brightness_mode, "augmentation", "add: the paper's p + beta (grey "
                                "levels); scale: p * (1 + beta), relative to the frame", choices=BRIGHTNESS_MODES)
    brightness_range: float | None = knob(None, "augmentation", "beta ~ U(-R, R): grey levels for add, a share of "
                                          "the pixel for scale (unset: the mode's and the approach's)",
                                          range=Range(0.0))
    yaw_aug: float = knob(AugmentSpec.yaw_aug, "augmentation", "not in the paper: share of samples seen from the car "
                          "turned, labelled to turn back (the heading feedback a closed loop needs). 0: off",
                          range=Range(0.0, 1.0))
    yaw_range: float = knob(AugmentSpec.yaw_range, "augmentation", "largest turn of yaw_aug",
                            range=Range(0.0, 30.0, low_open=True, unit="degrees"))
    yaw_gain: float = knob(AugmentSpec.yaw_gain, "augmentation", "how much of a turn yaw_aug's label steers back at "
                           "once (1: aim along the road again)", range=Range(0.0, 5.0))
    offset_aug: float = knob(AugmentSpec.offset_aug, "augmentation", "not in the paper: share of centre-camera "
                             "samples seen from the car moved sideways (DAVE-2's shifts; the road re-projected through "
                             "the ground plane), labelled to aim back. 0: off", range=Range(0.0, 1.0))
    offset_range: float = knob(AugmentSpec.offset_range, "augmentation", "largest sideways move of offset_aug "
                               "(drawn uniformly in +-range)", range=Range(0.0, 4.0, low_open=True, unit="m"))
    offset_lookahead: float = knob(AugmentSpec.offset_lookahead, "augmentation", "metres ahead on the driver's line "
                                   "that offset_aug's label aims at (10: the side cameras' Eq. 4/5)",
                                   range=Range(1.0, 100.0, unit="m"))
    edge_gain: float = knob(AugmentSpec.edge_gain, "augmentation", "not in the paper: steering per metre that a "
                            "camera stands beyond edge_margin from the road's middle, towards it (from road files; a "
                            "recording without one is not pulled). 0: off",
                            range=Range(0.0, 1.0, unit="steering per metre"))
    edge_margin: float = knob(AugmentSpec.edge_margin, "augmentation", "metres from the road's middle within which "
                              "edge_gain pulls nothing", range=Range(0.0, 10.0, unit="m"))
    behavior: str = knob(Behavior.SIMPLISTIC.value, "network", "simplistic, rigorous or collision: zero-steer "
                         "balancing, augmentations and epochs (paper Tables 4-6)", choices=BEHAVIORS)
    arch: str = knob(Arch.SHALLOW.value, "network", "shallow (the paper's CNN), pilotnet (NVIDIA's), shallow-wide "
                     "(128x64, twice the filters)", choices=tuple(a.value for a in Arch))
    approach: str = knob(Approach.OURS.value, "network", "ours: the paper's balancing and augmentation; nvidia: crop, "
                         "YUV, no balancing", choices=tuple(a.value for a in Approach))
    crop_top: int | None = knob(None, "network", "first row of the 320x160 frame the network sees (in the model's "
                                "contract; unset: the approach's)")
    crop_bottom: int | None = knob(None, "network", "row after the last one the network sees (unset: the approach's)")
    decode_reduce: int = knob(0, "network", "decode frames at 1/N size in training and drive_server alike; 0: the "
                              "largest that keeps the network's resolution", choices=DECODE_REDUCTIONS)
    epochs: int | None = knob(None, "training", "passes of aug_loops x the training data (unset: the behavior's, the "
                              "paper's Table 6)")
    batch_size: int = knob(BATCH_SIZE, "training", "samples per step")
    learning_rate: float = knob(LEARNING_RATE, "training", "Adam's step size")
    seed: int = knob(0, "training", "split, balancing, augmentation and initialisation: the same seed and data give "
                     "the same weights")
    export: str = knob("best", "training", f"which epoch becomes {MODEL}: best (lowest validation MSE) or last",
                       choices=EXPORTS)
    max_steps_per_epoch: int | None = knob(None, "training", "cap on steps per epoch, for quick runs; 0: none")
    mirror_average: bool = knob(False, "export", "not in the paper: the model answers (f(x) - f(mirror x)) / 2, its "
                                "left-right noise cancelled (not for a behavior that keeps to one lane); training is "
                                "unchanged")
    gain: float = knob(NO_GAIN, "export", "not in the paper, written into the model: drive_server multiplies the "
                       "network's steering by this unless its --gain says otherwise (above 1: the closed loop steers "
                       "harder than the drivers' average); training, the network and its open-loop figures are "
                       "unchanged", range=Range(*GAIN_RANGE))
    smoothing: float = knob(SMOOTHING_OFF, "export", "written into the model: drive_server smooths each client's "
                            "steering with this weight of the new output (1: off) unless its --smooth says otherwise",
                            range=Range(0.0, SMOOTHING_OFF, low_open=True))
    # the command line's, in no recipe: where the data is, and how this machine runs it (threads, decode_workers and
    # progress change no result beyond float noise)
    val_data: list[str] = field(default_factory=list)  # recordings held out whole (implies split "recordings")
    threads: int | None = None
    decode_workers: int | None = None
    progress: bool = True

    def __post_init__(self) -> None:
        if self.val_data:
            self.split = "recordings"
        check_knobs(self)
        if self.mirror_average and keeps_lane(self.behavior):
            raise BadValue(f"mirror_average: the {self.behavior} behavior keeps to one lane of a two-lane road, a "
                           f"left-right asymmetric task (trained without flips); the average would steer it to the "
                           f"road's middle")
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
        """The behavior's pipeline with this run's knobs: each named like a field of the preprocessing contract or
        the augmentation sets it (None: the pipeline's own). Built once for each setting of the knobs."""
        key = tuple(getattr(self, f.name) for f in knob_fields(self))
        if self.__dict__.get("_pipeline_key") != key:
            self.__dict__["_pipeline"], self.__dict__["_pipeline_key"] = self._build_pipeline(), key
        built: Pipeline = self.__dict__["_pipeline"]
        return built

    def _build_pipeline(self) -> Pipeline:
        p = pipeline_for(self.behavior, self.arch, self.approach)
        contract = replace(p.contract, **self._named_like(p.contract))
        augment = replace(p.augment, **self._named_like(p.augment))
        if self.brightness_range is None and self.brightness_mode == "scale":
            augment = replace(augment, brightness_range=SCALE_BRIGHTNESS_RANGE)
        if self.yaw_aug > 0:
            contract = replace(contract, blank_columns=turned_edge_columns(augment, contract))
        return replace(p, contract=contract, augment=augment)

    def _named_like(self, target: DataclassInstance) -> dict[str, Any]:  # replace()'s keywords, each its type
        """The knobs named like a field of ``target`` that are set (not None), by name."""
        names = {f.name for f in fields(target)}
        return {f.name: getattr(self, f.name) for f in knob_fields(self)
                if f.name in names and getattr(self, f.name) is not None}
