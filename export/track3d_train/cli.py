"""`track3d-train`: train and export the networks (needs the `train` extra: torch, onnx).

    track3d-train boxnet  ...   A3BoxNet (see `track3d-train boxnet --help`)
    track3d-train siamfc  ...   SiamFC, faithful and edge variants
    track3d-train --version
    track3d-train quantize ...  int8 twins of the shipped models (see `track3d-train quantize --help`)
    track3d-train edgetrack ... EdgeTrack, the fast edge 2D tracker
    track3d-train recipe ...    the shipped models' training recipes, end to end (see `track3d-train recipe list`)
"""
from __future__ import annotations

import importlib
import sys

COMMANDS = {
    "boxnet": ("track3d_train.boxnet.cli", "train, export and check A3BoxNet"),
    "siamfc": ("track3d_train.siamfc.cli", "train, export and check SiamFC"),
    "quantize": ("track3d_train.quantize", "int8 (static QDQ) twins of the models, calibrated on a train split"),
    "edgetrack": ("track3d_train.edgetrack.cli", "train, export and check EdgeTrack (fast edge 2D tracker)"),
    "recipe": ("track3d_train.recipes", "the shipped models' training recipes, data to ONNX (resumable; --tiny)"),
}


# What training imports beyond the runtime (top-level module -> the extra installing it): the
# base install also has the track3d-train command, which must say so, not end in a traceback.
EXTRA_MODULES = {"torch": "train", "onnx": "train", "tqdm": "train", "matplotlib": "train", "openvino": "openvino"}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "--version":
        from track3d.argparsing import package_version

        print(f"track3d-train {package_version()}")
        return 0
    if argv and argv[0] not in COMMANDS and argv[0] not in ("-h", "--help"):  # one line, as argparse's
        print(f"track3d-train: error: unknown command {argv[0]!r}, choose from {', '.join(COMMANDS)} "
              f"(see track3d-train --help)", file=sys.stderr)
        return 2
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        for name, (_, text) in COMMANDS.items():
            print(f"  {name:8s} {text}")
        return 0 if argv else 2
    from track3d.argparsing import exit_for_missing_extra
    from track3d.dataset import DatasetError
    from track3d.onnxmodel import ModelError
    from track3d.trackers2d import TrackerUnavailable

    try:
        module = importlib.import_module(COMMANDS[argv[0]][0])
        return int(module.main(argv[1:]) or 0)
    except (DatasetError, ModelError, TrackerUnavailable, FileNotFoundError, ValueError) as e:  # a user's mistake: one line
        print(f"track3d-train {argv[0]}: error: {e}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as e:
        return exit_for_missing_extra(e, EXTRA_MODULES, f"track3d-train {argv[0]}")


if __name__ == "__main__":
    sys.exit(main())
