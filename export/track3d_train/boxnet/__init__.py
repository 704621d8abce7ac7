"""A3BoxNet training side: model, data, losses, training loop, ONNX export (`track3d-train boxnet`)."""
