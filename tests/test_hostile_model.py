"""A bad model file or bad preprocessing metadata is refused at startup: exit code 2 and one line, never a
traceback, never a server that answers every frame with the stop command."""

from __future__ import annotations

import json

import pytest
from helpers_server import build_graph, build_shallow

pytest.importorskip("onnx", reason="the tests build their ONNX models with the onnx package")
import onnx  # noqa: E402
from onnx import TensorProto, helper  # noqa: E402

from drive_server import cli  # noqa: E402
from drive_server.serving.contract import METADATA_KEY, PAPER_CONTRACT, ContractError, PreprocessContract  # noqa: E402


def with_contract(src, dst, **changes):
    """A copy of the model ``src`` whose contract metadata has ``changes`` written verbatim into its JSON."""
    model = onnx.load(str(src))
    data = json.loads(PAPER_CONTRACT.to_json()) | changes
    for prop in model.metadata_props:
        if prop.key == METADATA_KEY:
            prop.value = json.dumps(data)
    onnx.save(model, str(dst))
    return dst


def dynamic_mean_graph(path, contract_json: str | None = None, nan: bool = False, sqrt_offset: float | None = None):
    """One value out of a dynamic-size NHWC input: the mean, or NaN, or sqrt(mean + offset)."""
    nodes = [helper.make_node("ReduceMean", ["x"], ["m"], keepdims=1)]
    last = "m"
    if nan:
        nodes.append(helper.make_node("Constant", [], ["c"], value=helper.make_tensor("c", TensorProto.FLOAT, [],
                                                                                      [float("nan")])))
        nodes.append(helper.make_node("Mul", ["m", "c"], ["y"]))
        last = "y"
    elif sqrt_offset is not None:
        nodes.append(helper.make_node("Constant", [], ["c"], value=helper.make_tensor("c", TensorProto.FLOAT, [],
                                                                                      [sqrt_offset])))
        nodes.append(helper.make_node("Add", ["m", "c"], ["s"]))
        nodes.append(helper.make_node("Sqrt", ["s"], ["y"]))
        last = "y"
    if last == "m":
        nodes.append(helper.make_node("Identity", ["m"], ["y"]))
    build_graph(path, [("x", [1, "h", "w", 3])], [("y", [1, 1, 1, 1])], nodes)
    if contract_json is not None:
        model = onnx.load(str(path))
        helper.set_model_props(model, {METADATA_KEY: contract_json})
        onnx.save(model, str(path))
    return path


@pytest.fixture(scope="module")
def base_model(tmp_path_factory):
    return build_shallow(tmp_path_factory.mktemp("hostile_model") / "m.onnx")


@pytest.fixture
def never_serve(monkeypatch):
    """Fail instead of serving forever if a bad model gets through the startup checks."""
    from drive_server.wire import server

    def refuse(self, *_, **__):
        raise AssertionError("the server started with a model that should have been refused")

    monkeypatch.setattr(server.DriveServer, "serve", refuse)
    monkeypatch.setattr(server.DriveServer, "bind", lambda self: ("127.0.0.1", 0))


def assert_refused(capsys, argv, *words):
    code = cli.main(argv)
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(err) == 1 and err[0].startswith("drive_server: error:"), err
    for word in words:
        assert word in err[0], err[0]


@pytest.mark.parametrize(("changes", "words"), [
    ({"version": "1"}, "version"),
    ({"version": 1.0}, "version"),
    ({"version": True}, "version"),
    ({"version": 0}, "version"),
    ({"width": 64.0}, "width"),
    ({"height": "64"}, "height"),
    ({"crop_top": None}, "crop_top"),
    ({"scale": "1/255"}, "scale"),
    ({"scale": None}, "scale"),
    ({"scale": 1e39}, "scale"),
    ({"offset": float("inf")}, "offset"),
    ({"scale": 0}, "scale"),
    ({"color": ["rgb"]}, "color"),
])
def test_bad_contract_metadata_exits_2_with_one_line(tmp_path, capsys, never_serve, base_model, changes, words):
    """Issue #10 item 9: "1", 64.0 gave a traceback and exit 1; NaN, "1/255", null, 1e39 started the server."""
    bad = with_contract(base_model, tmp_path / "bad.onnx", **changes)
    assert_refused(capsys, ["--model", str(bad), "--port", "0"], words, "bad.onnx")


def test_nan_scale_is_refused(tmp_path, capsys, never_serve, base_model):
    model = onnx.load(str(base_model))
    for prop in model.metadata_props:
        if prop.key == METADATA_KEY:
            prop.value = prop.value.replace('"scale": 0.00392156862745098', '"scale": NaN')
            assert "NaN" in prop.value
    onnx.save(model, str(tmp_path / "nan_scale.onnx"))
    assert_refused(capsys, ["--model", str(tmp_path / "nan_scale.onnx"), "--port", "0"], "scale")


@pytest.mark.parametrize("width", [1_000_000, 64.0, 100_000])
def test_huge_or_float_width_on_a_dynamic_input_is_refused(tmp_path, capsys, never_serve, width):
    """Issue #10 item 9: width 1e6 on a dynamic input tried to allocate 10.9 TiB."""
    contract = json.loads(PAPER_CONTRACT.to_json()) | {"width": width}
    path = dynamic_mean_graph(tmp_path / "dyn.onnx", json.dumps(contract))
    assert_refused(capsys, ["--model", str(path), "--port", "0"], "width" if isinstance(width, float) else "larger")


def test_a_model_whose_output_is_nan_is_refused(tmp_path, capsys, never_serve):
    """Issue #10 item 9: a model answering NaN started, and every frame was counted as malformed input."""
    path = dynamic_mean_graph(tmp_path / "nan.onnx", PAPER_CONTRACT.to_json(), nan=True)
    assert_refused(capsys, ["--model", str(path), "--port", "0"], "not finite", "nan.onnx")


def test_contract_type_checks_in_python():
    with pytest.raises(ContractError, match="width"):
        PreprocessContract(width=64.0)  # type: ignore[arg-type]
    with pytest.raises(ContractError, match="larger"):
        PreprocessContract(width=5000)
    assert PreprocessContract(scale=1, offset=0).scale == 1  # integers are numbers too
