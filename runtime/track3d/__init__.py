"""track3d: 3D asteroid tracking runtime (numpy + onnxruntime + OpenCV + a small C++ extension).

The runtime never imports torch, the simulator or the training code.
"""
from .camera import Camera

__version__ = "0.1.0"
__all__ = ["Camera", "__version__"]
