"""Tiny ONNX image models built by the tests (no weights are downloaded)."""

import json
from pathlib import Path

import onnx
from onnx import TensorProto, helper


def channel_model(path: Path, channels: list[int], meta: dict | None = None, uint8: bool = False,
                  noise: bool = False) -> Path:
    """A model whose output ``[1, len(channels), H, W]`` is the chosen input channels (or, with
    ``noise``, sin(1000 x channel): deterministic, but unrelated to anything in the scene)."""
    if uint8:
        inp = helper.make_tensor_value_info("frame", TensorProto.UINT8, ["N", "H", "W", 3])
        nodes = [helper.make_node("Cast", ["frame"], ["f"], to=TensorProto.FLOAT),
                 helper.make_node("Transpose", ["f"], ["x"], perm=[0, 3, 1, 2])]
    else:
        inp = helper.make_tensor_value_info("image", TensorProto.FLOAT, ["N", 3, "H", "W"])
        nodes = [helper.make_node("Identity", ["image"], ["x"])]
    idx = helper.make_tensor("idx", TensorProto.INT64, [len(channels)], channels)
    inits = [idx]
    if noise:
        nodes.append(helper.make_node("Gather", ["x", "idx"], ["g"], axis=1))
        inits.append(helper.make_tensor("k", TensorProto.FLOAT, [], [1000.0]))
        nodes += [helper.make_node("Mul", ["g", "k"], ["gk"]), helper.make_node("Sin", ["gk"], ["out"])]
    else:
        nodes.append(helper.make_node("Gather", ["x", "idx"], ["out"], axis=1))
    out = helper.make_tensor_value_info("out", TensorProto.FLOAT, ["N", len(channels), "H", "W"])
    graph = helper.make_graph(nodes, "channels", [inp], [out], initializer=inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    for k, v in (meta or {}).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, v if isinstance(v, str) else json.dumps(v)
    onnx.checker.check_model(model)
    onnx.save(model, path)
    return path
