"""`track3d-train`: train and export the networks (needs the `train` extra: torch, onnx).

usage: track3d-train COMMAND ...     (see track3d-train COMMAND --help)
       track3d-train --version
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


def help_text() -> str:
    """The docstring's usage, then each command once, from COMMANDS (the one list of them)."""
    rows = [f"  {name:10s}{text}" for name, (_, text) in COMMANDS.items()]
    return "\n".join([__doc__.strip(), "", "commands:", *rows])


def main(argv: list[str] | None = None) -> int:
    """The `track3d-train` console script; its warnings print as one line (argparsing.one_line_warnings)."""
    from track3d.argparsing import one_line_warnings

    with one_line_warnings("track3d-train"):
        return _main(argv)


def _main(argv: list[str] | None = None) -> int:
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
        print(help_text())
        return 0 if argv else 2
    from track3d.argparsing import USER_ERRORS, exit_for_missing_extra

    try:
        module = importlib.import_module(COMMANDS[argv[0]][0])
        return int(module.main(argv[1:]) or 0)
    except USER_ERRORS as e:  # a user's mistake (a bad path, cache, dataset or model): one line
        print(f"track3d-train {argv[0]}: error: {e}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as e:
        return exit_for_missing_extra(e, EXTRA_MODULES, f"track3d-train {argv[0]}")
    except KeyboardInterrupt as e:  # Ctrl-C, or a training stopped by a signal after its checkpoint: one line
        from .interrupt import interrupted_message

        line, code = interrupted_message(e, argv)
        print(f"track3d-train {argv[0]}: {line}", file=sys.stderr)
        return code


if __name__ == "__main__":
    sys.exit(main())
