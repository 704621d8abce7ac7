"""track3d_sim: the 3D asteroid tracking dataset simulator (paper section III).

Headless, CPU-only ray casting (Embree through `embreex`) of procedural asteroids in
procedural space scenes, seen by two identical pinhole cameras 0.4 m apart. Writes
the dataset layout of docs/dataset.md, read back by `track3d.dataset`.

Command line: ``track3d-sim generate | stats | preview`` (see ``track3d-sim --help``).
"""
from .errors import SimError

__version__ = "0.2.0"
__all__ = ["SimError", "__version__"]
