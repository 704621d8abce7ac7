#!/usr/bin/env bash
# The main command of the README: makes a virtual environment (.venv, or $TRACK3D_VENV),
# installs track3d with the simulator extra, generates a small test set and runs Track3D
# with the shipped models on it (`track3d-sim demo`). Extra arguments go to `track3d-sim demo`.
set -euo pipefail
cd "$(dirname "$0")"
VENV=${TRACK3D_VENV:-.venv}
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -m pip install -q -e ".[sim]"
exec "$VENV/bin/track3d-sim" demo "$@"
