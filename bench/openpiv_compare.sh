#!/usr/bin/env bash
# spiv against OpenPIV (multi-pass windef) on the same simulated pairs:
# errors against the truth and times, in one table.
#
#   bash bench/openpiv_compare.sh --install   # first time: OpenPIV (Rust backend) into bench/.venv
#   bash bench/openpiv_compare.sh             # the table
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=bench/.venv
if [[ "${1:-}" == "--install" ]]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet "openpiv[rust]==0.26.1" imageio
  shift
fi
[[ -x "$VENV/bin/python" ]] || { echo "no $VENV: run $0 --install" >&2; exit 1; }
cargo build --release --quiet -p spiv-host
SPIV=target/release/spiv
CASES=target/openpiv-cases
rm -rf "$CASES"; mkdir -p "$CASES"
$SPIV simulate --scene uniform --shift 0.3,0.15 --out "$CASES/uniform-0.3px" --seed 1 >/dev/null
$SPIV simulate --scene uniform --shift 3.3,-1.7 --out "$CASES/uniform-3.3px" --seed 2 >/dev/null
$SPIV simulate --scene paper-linear --out "$CASES/paper-linear" --seed 3 >/dev/null
$SPIV simulate --scene vortex --out "$CASES/vortex" --seed 4 >/dev/null
$SPIV simulate --scene uniform --shift 2.6,1.4 --width 1024 --height 1024 --out "$CASES/uniform-1024" --seed 5 >/dev/null
# Eddies below the window and displacements beyond its quarter rule, where
# window PIV fails as a whole (spiv reports its dense stage's field there).
$SPIV simulate --scene turbulence --out "$CASES/turbulence" --seed 1 >/dev/null
$SPIV simulate --scene large-shift --out "$CASES/large-shift" --seed 1 >/dev/null
# The same turbulence through the spike camera: TFP n=8 frames at the
# pair's ticks, the frame camera's truth.
spike_case() {
  local from="$CASES/$1" to="$CASES/$1-tfp"
  mkdir -p "$to"
  cp "$from/truth.csv" "$from/truth.flo" "$to/"
  read -r ka kb < <("$VENV/bin/python" -c "import json,sys; print(*json.load(open(sys.argv[1]))['pair'])" "$from/scene.json")
  $SPIV reconstruct "$from/spikes.dat" --method tfp --at "$ka" -o "$to/frame_a.png" >/dev/null
  $SPIV reconstruct "$from/spikes.dat" --method tfp --at "$kb" -o "$to/frame_b.png" >/dev/null
}
spike_case turbulence
# One thread, then two, each for both engines (and numpy under OpenPIV).
for t in 1 2; do
  RAYON_NUM_THREADS=$t OMP_NUM_THREADS=$t OPENBLAS_NUM_THREADS=$t \
    "$VENV/bin/python" bench/openpiv_compare.py "$CASES"/* --spiv "$SPIV" \
    --json "target/openpiv-compare-$t.json" "$@"
done
