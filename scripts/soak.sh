#!/usr/bin/env bash
# The whole node for a long run with faults, measured (issue 15; docs/recording.md, Soak).
#
#   scripts/soak.sh [--duration 600] [--kills 10] [--loss 10] [--fps 10] [--out DIR]
#
# `omnirow record` streams full-size frames (2448x2048 BayerRG8) from Aravis's GigE Vision
# simulator (arv-fake-gv-camera-0.8) with --loss lost packets per thousand (10 = 1%),
# recording into a small tmpfs; the simulator is killed and restarted --kills times, the
# recording disk is filled once and freed again, /healthz and /metrics are scraped every
# second, RSS, open file descriptors and threads sampled every 10 s. Afterwards: every
# recording checks intact and the last one replays, every camera loss was followed by
# streaming again, no thread stopped, RSS and fds flat after warm-up. Prints the figures and
# writes them to DIR/soak.json; exit 0 when every check passes.
#
# As root it runs in private network and mount namespaces (unshare): its own loopback, so the
# simulator's GVCP port and discovery meet no other run, and a tmpfs that vanishes with it.
# Without root there is no tmpfs to fill: the disk fault is skipped, and said so.
set -euo pipefail
cd "$(dirname "$0")/.."

if [ "$(id -u)" = 0 ] && [ -z "${OMNIROW_SOAK_NS:-}" ] && unshare --net --mount true 2>/dev/null; then
  exec env OMNIROW_SOAK_NS=1 unshare --net --mount --propagation private "$0" "$@"
fi
if [ -n "${OMNIROW_SOAK_NS:-}" ]; then
  ip link set lo up
fi
command -v arv-fake-gv-camera-0.8 >/dev/null || {
  echo "soak: arv-fake-gv-camera-0.8 missing (apt-get install aravis-tools)" >&2
  exit 1
}
bin="${OMNIROW_BIN:-target/release/omnirow}"
if [ ! -x "$bin" ]; then
  cargo build --release --locked --all-features
fi
exec python3 scripts/soak.py --bin "$bin" "$@"
