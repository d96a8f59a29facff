#!/usr/bin/env bash
# The paper's whole schedule timed on a GPU (issue 33, item 2): a `gems synth` scene at 400x270
# with 25 views (the medium preset: 45 px of blur), then `gems train` with its defaults (7000
# steps, n = 15, the built-in SfM, the first pass and the SfM on its renders, evaluation with
# test-time pose refinement). Wall time per phase comes from the run's own log (`gems.log`
# timestamps) and metrics.json; peak GPU memory from the driver (nvidia-smi sampled every 100 ms,
# less what was in use before the run). Results go to $OUT (or /tmp/schedule-out).
#
# Usage, on a machine with an NVIDIA GPU: GEMS=path/to/gems bash bench/schedule/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
gems="${GEMS:-target/release/gems}"
out="${OUT:-/tmp/schedule-out}"
work="${WORK:-/tmp/schedule}"
mkdir -p "$out"
rm -rf "$work"
mkdir -p "$work"

# SYNTH_ARGS / TRAIN_ARGS change the scene or the run (a short smoke test: "--preset tiny", "--steps 20").
"$gems" synth ${SYNTH_ARGS:---preset medium --views 25} --no-events --seed 1 -o "$work/scene"

before=$(nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits | head -1)
nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -lms 100 >"$work/gpu_memory_mib.txt" &
sampler=$!
start=$(date +%s.%N)
# TRAIN_TIMEOUT (seconds) stops the run there and summarises what it logged so far.
timeout "${TRAIN_TIMEOUT:-0}" "$gems" train "$work/scene" -o "$work/run" --device gpu ${TRAIN_ARGS:-} -v \
    >"$work/train.log" 2>&1 || echo "gems train ended with status $?"
end=$(date +%s.%N)
kill "$sampler"

cp "$work/run/gems.log" "$out/"
# With TRAIN_ARGS=--gpu-profile: where each training pass's step time went, per kernel.
[[ -f "$work/run/gpu_profile.txt" ]] && cp "$work/run/gpu_profile.txt" "$out/"
[[ -f "$work/run/first_pass/gpu_profile.txt" ]] && cp "$work/run/first_pass/gpu_profile.txt" "$out/gpu_profile_first_pass.txt"
cp "$work/run/metrics.json" "$out/" || true
python3 - "$out" "$work" "$before" "$start" "$end" <<'PY' | tee "$out/schedule.md"
import datetime, json, sys
out, work = sys.argv[1], sys.argv[2]
before, start, end = (float(x) for x in sys.argv[3:6])
peak = max(float(x) for x in open(f"{work}/gpu_memory_mib.txt") if x.strip())
stamps = []
for line in open(f"{out}/gems.log"):
    parts = line.split(None, 3)
    if len(parts) == 4 and parts[1] == "INFO":
        t = datetime.datetime.fromisoformat(parts[0].rstrip("Z"))
        stamps.append((t, parts[3].strip()))
t0 = stamps[0][0]
print("| since start (s) | event |\n|---|---|")
for t, msg in stamps:
    print(f"| {(t - t0).total_seconds():.1f} | {msg[:160]} |")
try:
    m = json.load(open(f"{out}/metrics.json"))
except OSError:
    m = {}
print()
print(f"- whole command: {end - start:.1f} s")
print(f"- training (both passes and the SfM between, metrics 'seconds'): {m.get('seconds')}")
print(f"- evaluation (metrics 'eval_seconds'): {m.get('eval_seconds')}")
print(f"- GPU memory in use: {before:.0f} MiB before, {peak:.0f} MiB at the peak, "
      f"so {peak - before:.0f} MiB for the run (driver, nvidia-smi every 100 ms)")
PY
