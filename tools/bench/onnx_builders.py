"""ONNX graphs of the paper's networks with random weights, built with ``onnx.helper`` (no torch).

Why: latency benchmarks and tests need real-shaped models on installs without torch, and the tests
must not depend on binary fixtures. The graphs are built from the one layer table of
:mod:`models.networks.architectures` (parameter counts are asserted) and carry the preprocessing contract
in their metadata like a trained export would. ``onnx`` (train extra) is imported lazily.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from drive_server.serving.contract import METADATA_KEY, METADATA_MODEL_INFO_KEY, PAPER_CONTRACT, PreprocessContract
from models.networks.architectures import ARCHITECTURES, Architecture

if TYPE_CHECKING:
    import onnx

OPSET = 17


Arch = Architecture  # short name used by the benchmarks and tests
ARCHS = ARCHITECTURES


def _onnx() -> ModuleType:
    try:
        import onnx
    except ModuleNotFoundError:
        raise ModuleNotFoundError(
            "building benchmark models needs the 'onnx' package: pip install -e \".[train]\" "
            "(or pass --model PATH)", name="onnx") from None
    return onnx


def build_model(arch: Arch, contract: PreprocessContract | None = None, seed: int = 0,
                with_metadata: bool = True, layout: str = "nhwc") -> onnx.ModelProto:
    """An ``onnx.ModelProto`` of ``arch`` with Glorot-uniform random weights and zero biases.

    ``layout`` is the input layout (NHWC like the paper's Keras models, or NCHW like a torch export);
    ``contract`` defaults to the paper's preprocessing at the architecture's input size.
    """
    onnx = _onnx()
    from onnx import TensorProto, helper, numpy_helper

    if contract is None:
        contract = PreprocessContract(width=arch.width, height=arch.height, layout=layout,
                                      **{k: getattr(PAPER_CONTRACT, k) for k in ("color", "scale", "offset")})
    if (contract.height, contract.width, contract.layout) != (arch.height, arch.width, layout):
        raise ValueError(f"contract {contract.width}x{contract.height} {contract.layout} does not match "
                         f"{arch.name} {arch.width}x{arch.height} {layout}")
    rng = np.random.default_rng(seed)
    nodes, inits = [], []
    count = 0

    def weight(name: str, shape: tuple[int, ...], fan_in: int, fan_out: int) -> str:
        nonlocal count
        limit = np.sqrt(6.0 / (fan_in + fan_out))
        inits.append(numpy_helper.from_array(rng.uniform(-limit, limit, shape).astype(np.float32), name))
        count += int(np.prod(shape))
        return name

    def bias(name: str, n: int) -> str:
        nonlocal count
        inits.append(numpy_helper.from_array(np.zeros(n, np.float32), name))
        count += n
        return name

    in_shape = [1, arch.height, arch.width, 3] if layout == "nhwc" else [1, 3, arch.height, arch.width]
    graph_in = helper.make_tensor_value_info("image", TensorProto.FLOAT, ["batch", *in_shape[1:]])
    x = "image"
    if layout == "nhwc":
        nodes.append(helper.make_node("Transpose", [x], ["nchw"], perm=[0, 3, 1, 2]))
        x = "nchw"
    channels, h, w = 3, arch.height, arch.width
    for i, c in enumerate(arch.convs):
        k = c.kernel
        wname = weight(f"conv{i}.w", (c.filters, channels, k, k), channels * k * k, c.filters * k * k)
        nodes.append(helper.make_node("Conv", [x, wname, bias(f"conv{i}.b", c.filters)], [f"conv{i}"],
                                      kernel_shape=[k, k], strides=[c.stride, c.stride]))
        nodes.append(helper.make_node("Relu", [f"conv{i}"], [f"relu{i}"]))
        x, channels = f"relu{i}", c.filters
        h, w = (h - k) // c.stride + 1, (w - k) // c.stride + 1
    nodes.append(helper.make_node("Flatten", [x], ["flat"], axis=1))
    x, features = "flat", channels * h * w
    for i, units in enumerate((*arch.dense, 1)):
        wname = weight(f"dense{i}.w", (units, features), features, units)
        out = "steering" if i == len(arch.dense) else f"dense{i}"
        nodes.append(helper.make_node("Gemm", [x, wname, bias(f"dense{i}.b", units)], [out], transB=1))
        if out != "steering":
            nodes.append(helper.make_node("Relu", [out], [f"drelu{i}"]))
            out = f"drelu{i}"
        x, features = out, units
    if count != arch.params:
        raise AssertionError(f"{arch.name}: built {count} parameters, the architecture has {arch.params}")
    graph_out = helper.make_tensor_value_info("steering", TensorProto.FLOAT, ["batch", 1])
    graph = helper.make_graph(nodes, arch.name, [graph_in], [graph_out], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="rbc.tools.bench.onnx_builders")
    model.ir_version = min(model.ir_version, 8)  # loadable by older ONNX Runtime releases too
    if with_metadata:
        helper.set_model_props(model, {METADATA_KEY: contract.to_json(),
                                       METADATA_MODEL_INFO_KEY: f'{{"arch": "{arch.name}", "weights": "random"}}'})
    onnx.checker.check_model(model)
    return model


def save_model(arch: Arch | str, path: Path, *, contract: PreprocessContract | None = None, seed: int = 0,
               with_metadata: bool = True, layout: str = "nhwc") -> Path:
    """Build ``arch`` (an ``Arch`` or its name) with :func:`build_model`'s arguments and write it to ``path``."""
    arch = ARCHS[arch] if isinstance(arch, str) else arch
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    model = build_model(arch, contract=contract, seed=seed, with_metadata=with_metadata, layout=layout)
    path.write_bytes(model.SerializeToString())
    return path


def count_parameters(model: onnx.ModelProto) -> int:
    """Number of weights in a ``ModelProto``'s initializers."""
    return sum(int(np.prod(t.dims)) for t in model.graph.initializer)
