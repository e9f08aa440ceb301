"""The two networks: exact parameter counts, initialisation, layouts."""

from __future__ import annotations

import math

import pytest

torch = pytest.importorskip("torch")

from models.networks.nets import ContractInput, PilotNet, ShallowCNN, build_model, conv_activations, count_parameters  # noqa: E402


def test_parameter_counts_match_the_papers() -> None:
    assert count_parameters(ShallowCNN()) == 14065
    assert count_parameters(PilotNet()) == 252219
    assert count_parameters(build_model("shallow", 64, 64)) == 14065
    assert count_parameters(build_model("pilotnet", 66, 200)) == 252219


def test_shallow_cnn_layers_and_shapes() -> None:
    net = ShallowCNN().eval()
    acts = conv_activations(net, torch.zeros(2, 3, 64, 64))
    assert [tuple(a.shape[1:]) for a in acts] == [(8, 11, 11), (16, 4, 4), (32, 1, 1)]
    assert net(torch.zeros(5, 3, 64, 64)).shape == (5, 1)
    dropouts = [m.p for m in net.modules() if isinstance(m, torch.nn.Dropout)]
    assert dropouts == [0.25, 0.25, 0.25]
    assert len(conv_activations(PilotNet(), torch.zeros(1, 3, 66, 200))) == 5


def test_glorot_uniform_weights_and_zero_biases() -> None:
    torch.manual_seed(0)
    for net in (ShallowCNN(), PilotNet()):
        for m in net.modules():
            if isinstance(m, torch.nn.Conv2d | torch.nn.Linear):
                fan_in = m.weight[0].numel()
                fan_out = m.weight.shape[0] * m.weight[0, 0].numel()
                bound = math.sqrt(6 / (fan_in + fan_out))
                assert float(m.weight.detach().abs().max()) <= bound + 1e-6
                assert float(m.weight.detach().abs().max()) > 0.5 * bound
                assert float(m.bias.detach().abs().max()) == 0.0


def test_contract_input_takes_nhwc_and_matches_nchw() -> None:
    torch.manual_seed(1)
    net = ShallowCNN().eval()
    x = torch.rand(3, 64, 64, 3) - 0.5
    with torch.no_grad():
        a = ContractInput(net, "nhwc")(x)
        b = net(x.permute(0, 3, 1, 2).contiguous())
        c = ContractInput(net, "nchw")(x.permute(0, 3, 1, 2))
    # the same numbers up to float rounding: oneDNN may pick another kernel for a channels-last input
    assert torch.allclose(a, b, atol=1e-6) and torch.allclose(b, c, atol=1e-6)


@pytest.mark.parametrize("name", ["shallow", "pilotnet", "shallow-wide"])
def test_torch_and_onnx_builders_make_the_same_layers_from_the_one_table(name):
    """The random-weight ONNX networks of the tests and benchmarks are the trained architectures."""
    pytest.importorskip("onnx")
    from models.networks.architectures import ARCHITECTURES
    from tools.bench.onnx_builders import build_model as build_onnx

    spec = ARCHITECTURES[name]
    torch_shapes = [tuple(p.shape) for p in build_model(name, spec.height, spec.width).parameters()]
    onnx_shapes = [tuple(t.dims) for t in build_onnx(spec).graph.initializer]
    assert torch_shapes == onnx_shapes
    assert sum(int(torch.tensor(s).prod()) for s in torch_shapes) == spec.params


@pytest.mark.parametrize(("arch", "size"),
                         [("shallow", (64, 64)), ("pilotnet", (200, 66)), ("shallow-wide", (128, 64))])
@pytest.mark.parametrize("approach", ["ours", "nvidia"])
def test_each_network_is_fed_at_its_own_input_size(arch, size, approach):
    """The contract a run trains and serves with is the network's size, whichever approach."""
    from models.data.behavior import pipeline_for

    contract = pipeline_for("simplistic", arch, approach).contract
    assert (contract.width, contract.height) == size
