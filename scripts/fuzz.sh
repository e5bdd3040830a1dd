#!/usr/bin/env bash
# Runs every fuzz target in fuzz/ (coverage-guided, libFuzzer through cargo-fuzz) for a bounded
# time each, seeded from real files: the configurations and calibrations in config/, MCAP
# recordings made here with `omnirow record`, small images made with `omnirow synth`. Fails when a target crashes, with the crashing input saved under
# fuzz/artifacts/TARGET/ and printed in base64 (a CI log keeps it).
#
#   scripts/fuzz.sh [SECONDS_EACH] [TARGET...]     (default: 45 s each, every target)
#
# This machine has only the stable toolchain: cargo-fuzz's instrumentation flags (-Z...) are
# let through with RUSTC_BOOTSTRAP=1, and the targets are built without a sanitizer (`-s none`;
# the parsers are safe Rust, and libFuzzer still catches panics, overflows — debug assertions
# are on — timeouts and runaway memory). OMNIROW_FUZZ_SANITIZER=address builds them with
# AddressSanitizer instead (slower to build). A corpus grows in fuzz/corpus/TARGET between runs.
set -euo pipefail
cd "$(dirname "$0")/.."

SECS="${1:-45}"
shift || true
SANITIZER="${OMNIROW_FUZZ_SANITIZER:-none}"
CARGO_FUZZ_VERSION=0.13.1
export RUSTC_BOOTSTRAP=1
export CARGO_TERM_COLOR=never

if [ $# -gt 0 ]; then
  targets=("$@")
else
  mapfile -t targets < <(sed -n 's/^name = "\(.*\)"$/\1/p' fuzz/Cargo.toml | grep -v '^omnirow-fuzz$')
fi

if ! cargo fuzz --version 2>/dev/null | grep -q "$CARGO_FUZZ_VERSION"; then
  # A debug build of the tool (it only drives cargo): half the build time.
  cargo install --locked --quiet --debug cargo-fuzz --version "$CARGO_FUZZ_VERSION"
fi

# Seeds, made fresh each run from the repository's own files and the binary.
seeds=$(mktemp -d)
trap 'rm -rf "$seeds"' EXIT
omnirow=target/release/omnirow
if [ ! -x "$omnirow" ]; then
  cargo build --release --locked --all-features
fi
for t in "${targets[@]}"; do mkdir -p "$seeds/$t" "fuzz/corpus/$t"; done
seed_dir() { [ -d "$seeds/$1" ] && echo "$seeds/$1"; }
if d=$(seed_dir calibration_toml); then cp config/calib/*.toml config/calibration.example.toml "$d"/; fi
if d=$(seed_dir ocamcalib_parse); then cp config/calib/ocamcalib/*.txt "$d"/; fi
if d=$(seed_dir node_config); then cp config/omnirow.toml "$d"/; fi
# Seeds kept in fuzz/seeds/: ROS camera_info files (both forms), HTTP requests, recordings
# with zstd and lz4 chunks (written by mcap's own writer).
for t in camera_info http_request mcap_replay; do
  if d=$(seed_dir $t); then cp fuzz/seeds/$t/* "$d"/; fi
done
if d=$(seed_dir mcap_replay); then
  cfg="$seeds/node.toml"
  printf '[source.synthetic]\nwidth = 48\nheight = 40\nfps = 30.0\nseed = 3\n\n[http]\nenabled = false\n' >"$cfg"
  "$omnirow" record --out "$seeds/rec" --frames 3 --no-print --config "$cfg" 2>/dev/null
  printf '\n[record]\njson_channels = "ros2_string"\n' >>"$cfg"
  "$omnirow" record --out "$seeds/rec2" --frames 2 --no-print --config "$cfg" 2>/dev/null
  cp tests/data/fuzz/*.mcap "$d"/  # what the fuzzer found before (regression tests too)
  i=0
  for f in "$seeds"/rec/*.mcap "$seeds"/rec2/*.mcap; do
    cp "$f" "$d/rec$i.mcap"
    # The same without its summary (what a power cut leaves).
    head -c $(($(stat -c %s "$f") * 3 / 4)) "$f" >"$d/cut$i.mcap"
    i=$((i + 1))
  done
fi
if d=$(seed_dir detect_image); then
  for ext in png jpg pgm; do
    "$omnirow" synth --lens fisheye185 --image-height 72 --image-width 96 --seed 2 \
      --out "$d/synth.$ext" >/dev/null 2>&1 || rm -f "$d/synth.$ext"
  done
  cp tests/data/fuzz/detect_image-*.png "$d"/  # what the fuzzer found before
fi

(cd fuzz && cargo fuzz build -s "$SANITIZER") || {
  echo "fuzz: building the targets failed" >&2
  exit 1
}

failed=()
for t in "${targets[@]}"; do
  rm -rf "fuzz/artifacts/$t"
  mkdir -p "fuzz/artifacts/$t"
  echo "fuzz: $t for ${SECS}s"
  log="$seeds/$t.log"
  if (cd fuzz && cargo fuzz run -s "$SANITIZER" "$t" "corpus/$t" "$seeds/$t" -- \
    -max_total_time="$SECS" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="artifacts/$t/") >"$log" 2>&1; then
    grep -E '^stat::number_of_executed_units|^Done [0-9]+ runs' "$log" | tail -n 2 | sed "s/^/fuzz: $t: /"
  else
    failed+=("$t")
    tail -n 40 "$log" >&2
    for a in fuzz/artifacts/"$t"/*; do
      [ -f "$a" ] || continue
      echo "fuzz: $t: crashing input $a (base64):" >&2
      base64 -w0 "$a" >&2
      echo >&2
    done
  fi
done

if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz: FAILED: ${failed[*]}" >&2
  exit 1
fi
echo "fuzz: ${#targets[@]} targets, ${SECS}s each, no crash"
