#!/usr/bin/env bash
# Creates .venv-ci with the independent ROS 2 / DDS peers the tests use (issue 7):
#   cyclonedds — Eclipse Cyclone DDS (its wheel bundles the C library and `ddsls`), the DDS
#                subscriber that checks what omnirow publishes (tests/ros2/subscribe.py);
#   rosbags    — pure-Python ROS 2 CDR decoder and type-hash calculator, checks MCAP
#                recordings (tests/ros2/check_mcap.py).
# Versions are pinned so CI is reproducible. Idempotent: reuses an existing venv whose
# packages already match. Usage: scripts/ci-python-env.sh [VENV_DIR]  (default .venv-ci)
set -euo pipefail
cd "$(dirname "$0")/.."

VENV="${1:-.venv-ci}"
CYCLONEDDS_VERSION=11.0.1
ROSBAGS_VERSION=0.11.9

PY="${PYTHON:-python3}"
if ! "$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 10) else 1)'; then
  echo "ci-python-env: $PY is older than 3.10 (rosbags needs >= 3.10)" >&2
  exit 1
fi
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
if "$VENV/bin/python" - "$CYCLONEDDS_VERSION" "$ROSBAGS_VERSION" <<'PYEOF' 2>/dev/null; then
import sys
from importlib.metadata import version
sys.exit(0 if (version("cyclonedds"), version("rosbags")) == (sys.argv[1], sys.argv[2]) else 1)
PYEOF
  echo "ci-python-env: $VENV already has cyclonedds $CYCLONEDDS_VERSION and rosbags $ROSBAGS_VERSION"
  exit 0
fi
"$VENV/bin/python" -m pip install --disable-pip-version-check --quiet \
  "cyclonedds==$CYCLONEDDS_VERSION" "rosbags==$ROSBAGS_VERSION"
"$VENV/bin/python" -c 'import cyclonedds, rosbags; print("ci-python-env: ok")'
test -x "$VENV/bin/ddsls" || { echo "ci-python-env: $VENV/bin/ddsls missing" >&2; exit 1; }
