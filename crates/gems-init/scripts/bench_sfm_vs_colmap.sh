#!/usr/bin/env bash
# Side-by-side benchmark: gems' built-in SfM vs COLMAP 3.8 (CPU SIFT, exhaustive matcher, mapper)
# on `gems synth --blur-levels` scenes (20 views, 240x160, 30 px blur for the full 11-frame burst).
# Not run in CI. Needs `colmap` on PATH (Debian: apt-get install colmap).
# Usage: crates/gems-init/scripts/bench_sfm_vs_colmap.sh [work_dir] [seeds...]
set -euo pipefail
work=${1:-/tmp/gems_sfm_bench}
shift || true
seeds=${*:-"1 2 3 4"}
cd "$(dirname "$0")/../../.."
mkdir -p "$work"
cargo build --release -p gems-init --example sfm_bench
# shellcheck disable=SC2086
./target/release/examples/sfm_bench "$work" $seeds | tee "$work/table.md"
