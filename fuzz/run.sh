#!/usr/bin/env bash
# Runs every fuzz target (cargo-fuzz, libFuzzer, stable Rust with
# `--sanitizer none`) over its committed corpus in fuzz/corpus/<target>.
#
#   fuzz/run.sh --seconds 15        a short budget per target
#   fuzz/run.sh --runs 10000000     10^7 executions per target (about 15 min
#                                   on one core of the CI machine)
#   fuzz/run.sh --runs N TARGET...  some targets only
#   fuzz/run.sh --grow --runs N     keep what the run adds in fuzz/corpus
#                                   (then minimise it with `cargo fuzz cmin`)
#   fuzz/run.sh --dev --seconds 10  targets at opt-level 1: half the
#                                   optimised build's time from a cold cache
#                                   (223 s against 424 s on 2 cores)
#
# Each target's checks are in harness/<target>.rs; `cargo test --workspace`
# replays every committed corpus input through them
# (tests/tests/fuzz_corpora.rs).
#
# Without --grow the inputs a run adds go to a temporary folder, so a
# short run leaves the checkout as it was (the committed corpus is read,
# not written).
# Prints each target's executions, speed and coverage; exits non-zero on
# the first crash, leak or timeout (the input is in fuzz/artifacts/<target>).
# Needs cargo-fuzz: `cargo install cargo-fuzz --locked`.
set -euo pipefail
cd "$(dirname "$0")"

budget=(-max_total_time=15)
grow=0
profile=()
if [ "${1:-}" = "--dev" ]; then profile=(--dev); shift; fi
if [ "${1:-}" = "--grow" ]; then grow=1; shift; fi
case "${1:-}" in
  --seconds) budget=(-max_total_time="$2"); shift 2 ;;
  --runs) budget=(-runs="$2" -max_total_time=3600); shift 2 ;;
esac
targets=("$@")
[ "${#targets[@]}" -gt 0 ] || targets=(wire_stream tile_decode downlink live_wire dat_reader npz_reader image_loader dense_reader)

cargo fuzz build -s none "${profile[@]}"
for t in "${targets[@]}"; do
  log=$(mktemp)
  # libFuzzer writes new inputs into the first corpus folder it is given.
  if [ "$grow" = 1 ]; then
    corpora=("corpus/$t")
  else
    fresh=$(mktemp -d)
    corpora=("$fresh" "corpus/$t")
  fi
  if ! cargo fuzz run -s none "${profile[@]}" "$t" "${corpora[@]}" -- "${budget[@]}" -rss_limit_mb=2048 -print_final_stats=1 >"$log" 2>&1; then
    tail -n 40 "$log"
    echo "!! fuzz target $t failed"
    exit 1
  fi
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
  speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log")
  cov=$(grep -E '^#[0-9]+.*(DONE|pulse|NEW|REDUCE)' "$log" | tail -n 1 | sed -n 's/.*cov: \([0-9]*\) ft: \([0-9]*\).*corp: \([0-9]*\).*/cov \1, features \2, corpus \3/p')
  printf '%-13s %10s executions, %7s/s, %s: clean\n' "$t" "$runs" "$speed" "$cov"
  rm -f "$log"
  [ "$grow" = 1 ] || rm -rf "$fresh"
done
