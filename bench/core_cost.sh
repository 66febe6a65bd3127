#!/usr/bin/env bash
# Exact instruction counts of the core's kernels on the host (x86-64-v2),
# from callgrind: deterministic on a busy machine, unlike timings.
# Ingest: 160 planes of 400x250 px; frame: one adaptive frame, n_max = 128,
# on the default paper-linear scene. Needs valgrind.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p spiv-host --example core_kernels
bin=target/release/examples/core_kernels
count() {
  valgrind --tool=callgrind --toggle-collect="core_kernels::$1" \
    --callgrind-out-file=/dev/null "$bin" 2>&1 | sed -n 's/.*I *refs: *//p' | tr -d ,
}
px=$((400 * 250))
ingest=$(count ingest_all)
frame=$(count frame_once)
printf '%-34s %14s %12s\n' kernel instructions per-unit
printf '%-34s %14d %12.3f  per pixel-sample\n' "ingest (160 planes)" "$ingest" "$(echo "$ingest / ($px * 160)" | bc -l)"
printf '%-34s %14d %12.1f  per pixel\n' "adaptive frame (n_max 128)" "$frame" "$(echo "$frame / $px" | bc -l)"
