"""SiamFC (paper §IV-A): PyTorch model, training, ONNX export for the runtime (track3d.siamfc)."""
from .model import VARIANTS, SiamFC, SiamFCConfig, balanced_bce, config_for, make_labels

__all__ = ["SiamFC", "SiamFCConfig", "VARIANTS", "config_for", "balanced_bce", "make_labels"]
