"""The preprocessing contract a model carries in its ONNX metadata.

Training writes it (``models.export``), the drive server reads it: the keys are defined here
and only here. A model without the metadata gets the paper's default, inferred from its input
shape.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass, replace
from typing import Any

from protocol.facts import FRAME_HEIGHT

log = logging.getLogger(__name__)

#: ONNX ``metadata_props`` key holding the JSON-encoded contract.
METADATA_KEY = "rbc.preprocess"
#: Other metadata keys written by training (informational: behavior, arch, approach, run config).
METADATA_MODEL_INFO_KEY = "rbc.model"
CONTRACT_VERSION = 1

_COLORS = ("rgb", "yuv", "bgr")
_LAYOUTS = ("nhwc", "nchw")
_INTERPOLATIONS = ("area", "linear")


class ContractError(ValueError):
    """The model's preprocessing contract is missing, malformed or inconsistent with the model."""


@dataclass(frozen=True)
class PreprocessContract:
    """How a 320x160 RGB camera frame becomes the network's input tensor.

    Steps, in order: crop rows ``[crop_top, crop_bottom)`` of the full frame, resize to
    ``width`` x ``height`` (``interpolation``), convert to ``color``, then ``x * scale + offset``
    as float32 in ``layout``. The paper's default is 64x64 RGB with x/255 - 0.5.
    """

    width: int = 64
    height: int = 64
    crop_top: int = 0
    crop_bottom: int = FRAME_HEIGHT
    color: str = "rgb"
    scale: float = 1.0 / 255.0
    offset: float = -0.5
    layout: str = "nhwc"
    interpolation: str = "area"
    version: int = CONTRACT_VERSION

    def __post_init__(self) -> None:
        if self.color not in _COLORS:
            raise ContractError(f"color must be one of {_COLORS}, not {self.color!r}")
        if self.layout not in _LAYOUTS:
            raise ContractError(f"layout must be one of {_LAYOUTS}, not {self.layout!r}")
        if self.interpolation not in _INTERPOLATIONS:
            raise ContractError(f"interpolation must be one of {_INTERPOLATIONS}, not {self.interpolation!r}")
        if not (0 <= self.crop_top < self.crop_bottom <= FRAME_HEIGHT):
            raise ContractError(f"crop rows [{self.crop_top}, {self.crop_bottom}) outside 0..{FRAME_HEIGHT}")
        if self.width < 8 or self.height < 8:
            raise ContractError(f"input size {self.width}x{self.height} is too small")

    @property
    def input_shape(self) -> tuple[int, int, int, int]:
        """Expected ONNX input shape with batch 1."""
        if self.layout == "nhwc":
            return (1, self.height, self.width, 3)
        return (1, 3, self.height, self.width)

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> PreprocessContract:
        try:
            data: dict[str, Any] = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ContractError(f"{METADATA_KEY} is not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise ContractError(f"{METADATA_KEY} must be a JSON object")
        known = set(cls.__dataclass_fields__)
        unknown = set(data) - known
        if unknown:
            raise ContractError(f"{METADATA_KEY} has unknown keys {sorted(unknown)}")
        if data.get("version", CONTRACT_VERSION) > CONTRACT_VERSION:
            raise ContractError(f"contract version {data['version']} is newer than this drive server supports")
        try:
            return cls(**data)
        except TypeError as exc:
            raise ContractError(f"{METADATA_KEY}: {exc}") from None


#: The paper's preprocessing (section 3.1.5): 64x64, RGB, x/255 - 0.5.
PAPER_CONTRACT = PreprocessContract()
#: NVIDIA's approach for PilotNet: crop rows 60..160, YUV, 200x66, x/255.
NVIDIA_CONTRACT = PreprocessContract(width=200, height=66, crop_top=60, crop_bottom=FRAME_HEIGHT, color="yuv",
                                     scale=1.0 / 255.0, offset=0.0)


def infer_contract(input_shape: tuple[Any, ...]) -> PreprocessContract:
    """Guess the contract of a model without metadata from its input shape (paper defaults)."""
    if len(input_shape) != 4:
        raise ContractError(f"model input must have rank 4 (N,H,W,C or N,C,H,W), got shape {list(input_shape)}")
    dims = [d if isinstance(d, int) else None for d in input_shape[1:]]
    if dims[2] == 3 and dims[0] and dims[1]:
        h, w, layout = dims[0], dims[1], "nhwc"
    elif dims[0] == 3 and dims[1] and dims[2]:
        h, w, layout = dims[1], dims[2], "nchw"
    else:
        raise ContractError(f"cannot infer a 3-channel image input from shape {list(input_shape)}")
    contract = replace(PAPER_CONTRACT, width=w, height=h, layout=layout)
    log.info("model has no %s metadata: assuming the paper's preprocessing %s", METADATA_KEY, contract)
    return contract
