"""EdgeTrack: a fast edge 2D tracker (depthwise-separable Siamese net, pixel-wise correlation,
classification + box heads, calibrated score, lost detection): model, data, training with
resume, ONNX export for the runtime (track3d.edgetrack), evaluation."""
from .model import EdgeTrack, EdgeTrackConfig, edgetrack_loss, make_targets

__all__ = ["EdgeTrack", "EdgeTrackConfig", "edgetrack_loss", "make_targets"]
