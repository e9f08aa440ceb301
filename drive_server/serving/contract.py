"""The preprocessing contract a model carries in its ONNX metadata.

Training writes it (``models.onnxfiles.export``), the drive server reads it: the keys are defined here
and only here. A model without the metadata gets the paper's default, inferred from its input
shape.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import asdict, dataclass, replace

from protocol.errors import BadValue
from protocol.facts import FRAME_HEIGHT

log = logging.getLogger(__name__)

#: ONNX ``metadata_props`` key holding the JSON-encoded contract.
METADATA_KEY = "rbc.preprocess"
#: Other metadata keys written by training (informational: behavior, arch, approach, run config).
METADATA_MODEL_INFO_KEY = "rbc.model"
CONTRACT_VERSION = 1
#: Largest network input side: the camera frame is 320x160, so anything far above is a broken contract
#: (1e6 on a dynamic input once meant a 10.9 TiB allocation).
MAX_INPUT_SIDE = 1024
#: Largest |scale| and |offset|: x * scale + offset must stay finite in float32 for any pixel.
MAX_SCALE = 1e6

_COLORS = ("rgb", "yuv", "bgr")
_LAYOUTS = ("nhwc", "nchw")
_INTERPOLATIONS = ("area", "linear")
#: ``decode_reduce`` values: 0 (the serving rule chooses) or one of libjpeg's reduced-size decodes.
DECODE_REDUCTIONS = (0, 1, 2, 4, 8)


class ContractError(BadValue):
    """The model's preprocessing contract is missing, malformed or inconsistent with the model."""

    hint = "pass an .onnx model exported by rbc train, or a bundled one from models/pretrained/"


@dataclass(frozen=True)
class PreprocessContract:
    """How a 320x160 RGB camera frame becomes the network's input tensor.

    Steps, in order: crop rows ``[crop_top, crop_bottom)`` of the full frame, resize to
    ``width`` x ``height`` (``interpolation``), convert to ``color``, then ``x * scale + offset``
    as float32 in ``layout``. The paper's default is 64x64 RGB with x/255 - 0.5.
    ``decode_reduce``: decode the JPEG at 1/n size (libjpeg's DCT scaling) even where the crop then has
    fewer rows than the network (half the decode and resize cost); 0: the serving rule chooses
    (``drive_server.serving.preprocess.jpeg_reduction``: never below the network's resolution).
    ``blank_columns``: the outer n columns on each side of the network image repeat the next column
    inward. A model trained on turned views needs it: their missing edge would otherwise tell the
    network the turn, a cue a real camera never shows (0: off).
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
    decode_reduce: int = 0
    blank_columns: int = 0

    def __post_init__(self) -> None:
        # types first: JSON metadata can hold "1", 64.0, null or 1e39 where a number belongs, and each of
        # those used to start the server (or allocate terabytes) instead of being refused here
        if type(self.version) is not int or self.version != CONTRACT_VERSION:
            raise ContractError(f"version must be the integer {CONTRACT_VERSION}, not {self.version!r}")
        for name in ("width", "height", "crop_top", "crop_bottom", "decode_reduce", "blank_columns"):
            if type(getattr(self, name)) is not int:
                raise ContractError(f"{name} must be an integer, not {getattr(self, name)!r}")
        for name in ("scale", "offset"):
            value = getattr(self, name)
            if type(value) not in (int, float) or not math.isfinite(value) or abs(value) > MAX_SCALE:
                raise ContractError(f"{name} must be a finite number within +-{MAX_SCALE:g}, not {value!r}")
        if self.scale == 0:
            raise ContractError("scale must not be 0 (every frame would look the same to the network)")
        for name in ("color", "layout", "interpolation"):
            if not isinstance(getattr(self, name), str):
                raise ContractError(f"{name} must be a string, not {getattr(self, name)!r}")
        if self.color not in _COLORS:
            raise ContractError(f"color must be one of {_COLORS}, not {self.color!r}")
        if self.layout not in _LAYOUTS:
            raise ContractError(f"layout must be one of {_LAYOUTS}, not {self.layout!r}")
        if self.interpolation not in _INTERPOLATIONS:
            raise ContractError(f"interpolation must be one of {_INTERPOLATIONS}, not {self.interpolation!r}")
        if not (0 <= self.crop_top < self.crop_bottom <= FRAME_HEIGHT):
            raise ContractError(f"crop rows [{self.crop_top}, {self.crop_bottom}) outside 0..{FRAME_HEIGHT}")
        if self.decode_reduce not in DECODE_REDUCTIONS:
            raise ContractError(f"decode_reduce must be one of {DECODE_REDUCTIONS}, not {self.decode_reduce!r}")
        if self.decode_reduce and (self.crop_top % self.decode_reduce or self.crop_bottom % self.decode_reduce):
            raise ContractError(f"crop rows [{self.crop_top}, {self.crop_bottom}) are not on the "
                                f"1/{self.decode_reduce} decode's grid (both must be multiples of decode_reduce)")
        if not 0 <= self.blank_columns <= self.width // 4:
            raise ContractError(f"blank_columns must be 0..{self.width // 4} (a quarter of the width), "
                                f"not {self.blank_columns}")
        if self.width < 8 or self.height < 8:
            raise ContractError(f"input size {self.width}x{self.height} is too small")
        if self.width > MAX_INPUT_SIDE or self.height > MAX_INPUT_SIDE:
            raise ContractError(f"input size {self.width}x{self.height} is larger than {MAX_INPUT_SIDE} pixels a side "
                                "(the camera frame is 320x160)")

    @property
    def input_shape(self) -> tuple[int, int, int, int]:
        """Expected ONNX input shape with batch 1."""
        if self.layout == "nhwc":
            return (1, self.height, self.width, 3)
        return (1, 3, self.height, self.width)

    def to_json(self) -> str:
        data = asdict(self)
        for key in ("decode_reduce", "blank_columns"):  # off: left out, as in contracts written before the keys
            if not data[key]:
                del data[key]
        return json.dumps(data, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> PreprocessContract:
        try:
            data: object = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ContractError(f"{METADATA_KEY} is not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise ContractError(f"{METADATA_KEY} must be a JSON object")
        known = set(cls.__dataclass_fields__)
        unknown = set(data) - known
        if unknown:
            raise ContractError(f"{METADATA_KEY} has unknown keys {sorted(unknown)}")
        version = data.get("version", CONTRACT_VERSION)
        if type(version) is int and version > CONTRACT_VERSION:
            raise ContractError(f"contract version {version} is newer than this drive server supports")
        try:
            return cls(**data)
        except TypeError as exc:
            raise ContractError(f"{METADATA_KEY}: {exc}") from None


#: The paper's preprocessing (section 3.1.5): 64x64, RGB, x/255 - 0.5.
PAPER_CONTRACT = PreprocessContract()
#: NVIDIA's approach for PilotNet: crop rows 60..160, YUV, 200x66, x/255.
NVIDIA_CONTRACT = PreprocessContract(width=200, height=66, crop_top=60, crop_bottom=FRAME_HEIGHT, color="yuv",
                                     scale=1.0 / 255.0, offset=0.0)


def infer_contract(input_shape: tuple[int | str | None, ...]) -> PreprocessContract:
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
