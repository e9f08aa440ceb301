"""Per-behavior and per-approach settings: every number of the paper's Tables 4, 5 and 6 in one place.

Here, below the data, the export and the training that all read it: the data takes a behavior's pipeline
(:func:`pipeline_for`), ``rbc mirror`` asks whether a behavior keeps to a lane (:func:`keeps_lane`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import StrEnum

from drive_server.serving.contract import NVIDIA_CONTRACT, PAPER_CONTRACT, PreprocessContract
from models.augmentation.augment import AugmentSpec
from models.networks.architectures import ARCHITECTURES, Arch


class Behavior(StrEnum):
    """The paper's behaviors: protocol.facts.BEHAVIORS, in its order (tests/test_balance.py holds them equal);
    spelled out so the type checker knows the members."""

    SIMPLISTIC = "simplistic"
    RIGOROUS = "rigorous"
    COLLISION = "collision"


class Approach(StrEnum):
    OURS = "ours"  # the paper's pipeline: balancing + six augmentations
    NVIDIA = "nvidia"  # NVIDIA's: crop, YUV, no balancing, light augmentation


@dataclass(frozen=True)
class BehaviorSpec:
    deletion_rate: float  # Table 4, lambda of Eq. 3
    epochs: int  # Table 6
    augment: AugmentSpec  # Table 5


BEHAVIOR_SPECS: dict[Behavior, BehaviorSpec] = {
    Behavior.SIMPLISTIC: BehaviorSpec(0.7, 5, AugmentSpec(perspective=0.5, flip=0.5)),
    Behavior.RIGOROUS: BehaviorSpec(0.8, 10, AugmentSpec(perspective=0.5, flip=0.0)),  # flipping changes lanes
    Behavior.COLLISION: BehaviorSpec(0.8, 5, AugmentSpec(perspective=0.0, flip=0.5)),  # one camera
}


def keeps_lane(behavior: str | None) -> bool:
    """Whether ``behavior`` keeps to one lane of a two-lane road: a left-right asymmetric task, so it trains
    without flips, and averaging with the mirrored frame (``--mirror-average``, ``rbc mirror``) would undo it."""
    return behavior in set(Behavior) and BEHAVIOR_SPECS[Behavior(behavior)].augment.flip == 0.0


#: NVIDIA's approach (Table 10, left column): no side cameras, no shadows/pan/tilt; random flip, a
#: horizontal viewpoint shift of up to 25 px with 0.004 steering per pixel, and milder brightness.
NVIDIA_AUGMENT = AugmentSpec(perspective=0.0, shadow=0.0, brightness=0.4, flip=0.5, pan=0.0, tilt=0.0, shift=0.5,
                             brightness_range=50.0, shift_range_px=25.0, shift_steering_per_px=0.004)

BATCH_SIZE = 256
LEARNING_RATE = 1e-3
AUGMENTATION_LOOPS = 64


@dataclass(frozen=True)
class Pipeline:
    """What a (behavior, arch, approach) triple trains with."""

    contract: PreprocessContract
    augment: AugmentSpec
    deletion_rate: float
    epochs: int


def pipeline_for(behavior: Behavior | str, arch: Arch | str, approach: Approach | str) -> Pipeline:
    """The paper's pipeline ("ours", at the network's own input size: 200x66 for PilotNet) or NVIDIA's, for one
    behavior."""
    spec = BEHAVIOR_SPECS[Behavior(behavior)]
    net = ARCHITECTURES[Arch(arch).value]
    if Approach(approach) is Approach.NVIDIA:
        augment = NVIDIA_AUGMENT if spec.augment.flip else replace(NVIDIA_AUGMENT, flip=0.0)
        return Pipeline(replace(NVIDIA_CONTRACT, width=net.width, height=net.height), augment, 0.0, spec.epochs)
    contract = replace(PAPER_CONTRACT, width=net.width, height=net.height)
    return Pipeline(contract, spec.augment, spec.deletion_rate, spec.epochs)
