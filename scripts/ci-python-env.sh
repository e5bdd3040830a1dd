#!/usr/bin/env bash
# Creates .venv-ci with the independent ROS 2 / DDS peers the tests use (issue 7):
#   cyclonedds — Eclipse Cyclone DDS (its wheel bundles the C library and `ddsls`), the DDS
#                subscriber that checks what omnirow publishes (tests/ros2/subscribe.py);
#   rosbags    — pure-Python ROS 2 CDR decoder and type-hash calculator, checks MCAP
#                recordings (tests/ros2/check_mcap.py);
#   prometheus_client — the Prometheus project's Python client, whose text-format parser
#                checks /metrics (tests/http_service.rs, tests/http/check_metrics.py);
#   opencv-python-headless — OpenCV, the detector's speed yardstick
#                (scripts/opencv-yardstick.sh).
# Versions are pinned so CI is reproducible. Idempotent: reuses an existing venv whose
# packages already match. Usage: scripts/ci-python-env.sh [VENV_DIR]  (default .venv-ci)
set -euo pipefail
cd "$(dirname "$0")/.."

VENV="${1:-.venv-ci}"
CYCLONEDDS_VERSION=11.0.1
ROSBAGS_VERSION=0.11.9
PROMETHEUS_CLIENT_VERSION=0.26.0
OPENCV_VERSION=4.11.0.86

PY="${PYTHON:-python3}"
if ! "$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 10) else 1)'; then
  echo "ci-python-env: $PY is older than 3.10 (rosbags needs >= 3.10)" >&2
  exit 1
fi
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
if "$VENV/bin/python" - "$CYCLONEDDS_VERSION" "$ROSBAGS_VERSION" "$PROMETHEUS_CLIENT_VERSION" "$OPENCV_VERSION" <<'PYEOF' 2>/dev/null; then
import sys
from importlib.metadata import version
have = (version("cyclonedds"), version("rosbags"), version("prometheus_client"),
        version("opencv-python-headless"))
sys.exit(0 if have == tuple(sys.argv[1:5]) else 1)
PYEOF
  echo "ci-python-env: $VENV already has cyclonedds $CYCLONEDDS_VERSION, rosbags $ROSBAGS_VERSION, prometheus_client $PROMETHEUS_CLIENT_VERSION and opencv-python-headless $OPENCV_VERSION"
  exit 0
fi
"$VENV/bin/python" -m pip install --disable-pip-version-check --quiet \
  "cyclonedds==$CYCLONEDDS_VERSION" "rosbags==$ROSBAGS_VERSION" \
  "prometheus_client==$PROMETHEUS_CLIENT_VERSION" "opencv-python-headless==$OPENCV_VERSION"
"$VENV/bin/python" -c 'import cyclonedds, rosbags, prometheus_client, cv2; print("ci-python-env: ok")'
test -x "$VENV/bin/ddsls" || { echo "ci-python-env: $VENV/bin/ddsls missing" >&2; exit 1; }
