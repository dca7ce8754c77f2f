#!/usr/bin/env python3
"""Writes the tiny random-weight ONNX models of the CNN tests into models/test/.

Run through the project venv: `$(bash scripts/python-env.sh) scripts/make_test_models.py`.
The outputs are committed, so the tests need no Python. Deterministic (fixed seed).

- tiny_cnn.onnx: input [1,3,H,W] (H, W dynamic) -> `s2` [1,4,h/2,w/2] (3x3 conv stride 2 +
  ReLU) and `s4` [1,6,h/4,w/4] (another 3x3 conv stride 2 + ReLU).
- tiny_fixed.onnx: the same graph with the input fixed at [1,3,32,32].
- tiny_nan.onnx: `s2` = Log(-1 - |conv|): NaN for every input.
- tiny_rank3.onnx: `s2` reshaped to rank 3 [1,4,-1].
"""
import os
import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "models", "test")
OPSET = 13
IR_VERSION = 8


def conv(name, x, cin, cout, rng):
    w = numpy_helper.from_array(
        (rng.standard_normal((cout, cin, 3, 3)) * 0.3).astype(np.float32), f"{name}_w")
    b = numpy_helper.from_array((rng.standard_normal(cout) * 0.1).astype(np.float32), f"{name}_b")
    node = helper.make_node("Conv", [x, w.name, b.name], [f"{name}_y"], strides=[2, 2],
                            pads=[1, 1, 1, 1], kernel_shape=[3, 3])
    return node, [w, b], f"{name}_y"


def build(fixed=False, nan=False, rank3=False):
    rng = np.random.default_rng(7)
    h, w = (32, 32) if fixed else ("H", "W")
    nodes, inits = [], []
    n1, i1, y1 = conv("c1", "input", 3, 4, rng)
    nodes += [n1, helper.make_node("Relu", [y1], ["r1"])]
    inits += i1
    n2, i2, y2 = conv("c2", "r1", 4, 6, rng)
    nodes += [n2, helper.make_node("Relu", [y2], ["s4"])]
    inits += i2
    s2_shape = [1, 4, "h2", "w2"]
    if nan:
        inits.append(numpy_helper.from_array(np.array(-1.0, np.float32), "minus_one"))
        nodes += [helper.make_node("Abs", ["r1"], ["a1"]),
                  helper.make_node("Sub", ["minus_one", "a1"], ["neg"]),
                  helper.make_node("Log", ["neg"], ["s2"])]
    elif rank3:
        inits.append(numpy_helper.from_array(np.array([1, 4, -1], np.int64), "shape3"))
        nodes.append(helper.make_node("Reshape", ["r1", "shape3"], ["s2"]))
        s2_shape = [1, 4, "hw2"]
    else:
        nodes.append(helper.make_node("Identity", ["r1"], ["s2"]))
    graph = helper.make_graph(
        nodes, "tiny",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, [1, 3, h, w])],
        [helper.make_tensor_value_info("s2", TensorProto.FLOAT, s2_shape),
         helper.make_tensor_value_info("s4", TensorProto.FLOAT, [1, 6, "h4", "w4"])],
        inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="bevt-rs scripts/make_test_models.py")
    model.ir_version = IR_VERSION
    onnx.checker.check_model(model)
    return model


def main():
    os.makedirs(OUT, exist_ok=True)
    for name, kw in [("tiny_cnn", {}), ("tiny_fixed", {"fixed": True}),
                     ("tiny_nan", {"nan": True}), ("tiny_rank3", {"rank3": True})]:
        path = os.path.join(OUT, f"{name}.onnx")
        onnx.save(build(**kw), path)
        print(path, os.path.getsize(path), "bytes")


if __name__ == "__main__":
    main()
