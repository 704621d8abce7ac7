#!/usr/bin/env bash
# The test command of the README: makes a virtual environment (.venv, or $TRACK3D_VENV),
# installs track3d with every extra (torch only as the pinned CPU build) and runs pytest.
# Extra arguments go to pytest, e.g. `./test.sh -k frustum`.
set -euo pipefail
cd "$(dirname "$0")"
VENV=${TRACK3D_VENV:-.venv}
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -m pip install -q torch==2.13.0
"$VENV/bin/python" -m pip install -q -e ".[dev,sim,train,cluster,openvino]"
exec "$VENV/bin/python" -m pytest -q "$@"
