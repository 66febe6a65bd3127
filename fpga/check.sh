#!/usr/bin/env bash
# The RTL against spiv-core, frame for frame and event for event:
# verilates fpga/rtl with the C++ testbenches fpga/tb/tb_tfp.cpp (the TFP
# frame), fpga/tb/tb_light.cpp (the static-light model and its events) and
# fpga/tb/tb_rungs.cpp (the live mode's rung frames, scattered along a
# flow), fpga/tb/tb_ring.cpp (the event ring and its reader),
# fpga/tb/tb_live.cpp (the live mode's pipeline: spiv_live.sv, the light
# model, the ring and the rung frames chained) and fpga/tb/tb_rice.cpp
# (the Rice tile coder) and fpga/tb/tb_context.cpp (the Context tile
# coder), linked to spiv-core's C
# ABI (the spiv-ffi static library), and runs them
# on the committed strip and on a paper-linear and a vortex-array
# recording that `spiv simulate` makes, at several windows and schedules;
# the light model also on a synthetic recording of every light level. CI
# runs it (.ci/run); it needs verilator (Debian: apt-get install
# verilator) and the `spiv` binary (cargo build --bin spiv; SPIV_BIN names
# another). Each run's result is taken before it is printed, so a failing
# run ends the script.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$PWD"
target="${CARGO_TARGET_DIR:-$root/target}"
spiv="${SPIV_BIN:-$target/debug/spiv}"
cargo build --quiet -p spiv-ffi
[ -x "$spiv" ] || cargo build --quiet -p spiv-host --bin spiv
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# verilate DIR "PARAMETERS" "DEFINES" FILE...: one testbench, its RTL
# and C++ FILEs, built into $work/DIR against the C ABI's static library,
# with the model's parameters (-G) and the testbench's matching defines
# (-D); the build's log is shown when it fails.
verilate() {
  local dir=$1 params=$2 defines=$3
  shift 3
  # shellcheck disable=SC2086
  verilator --cc --exe --build -O2 -j 2 -Wall -Wno-DECLFILENAME -Wno-UNUSEDSIGNAL \
    --Mdir "$work/$dir" $params -CFLAGS "$defines -I$root/ffi/include" \
    -LDFLAGS "$target/debug/libspiv_ffi.a -lpthread -ldl -lm" \
    "$@" >"$work/verilator-$dir.log" 2>&1 || {
    tail -30 "$work/verilator-$dir.log"
    exit 1
  }
}
rtl="$root/fpga/rtl" tbs="$root/fpga/tb"

# The model: 128 x 64 px, 32 pixels per clock, windows up to 16 ticks.
W=128 H=64 P=32 NMAX=16
verilate obj "-GW=$W -GH=$H -GP=$P -GNMAX=$NMAX" "-DTB_W=$W -DTB_H=$H -DTB_P=$P" \
  "$rtl/spiv_tfp.sv" "$tbs/tb_tfp.cpp"
tb="$work/obj/Vspiv_tfp"

# The static-light model: 8 pixels per clock, and 32 (as placed).
for LP in 8 32; do
  verilate "light$LP" "-GW=$W -GH=$H -GP=$LP" "-DTB_W=$W -DTB_H=$H -DTB_P=$LP" \
    "$rtl/spiv_light.sv" "$tbs/tb_light.cpp"
done

# The rung frames: eight lanes (a pair's most rungs), fed the core ring's
# events, on the sensor's 400x250 (a frame that is no power of two, node
# grids up to 128 across); on the model's size they are fed by the RTL's
# light model and ring (spiv_live: 8 pixels per clock into the light
# model, 524,288 events over 1,023 ticks, so that noise evicts ticks).
verilate rungs400 "-GW=400 -GH=250 -GNR=8 -GNXB=7 -GNYB=7" "-DTB_W=400 -DTB_H=250 -DTB_NR=8" \
  "$rtl/spiv_rungs.sv" "$tbs/tb_rungs.cpp"
verilate live "--top-module spiv_live -GW=$W -GH=$H -GP=8 -GNR=8 -GNXB=6 -GNYB=6 -GCAPB=19 -GDEPB=10" \
  "-DTB_W=$W -DTB_H=$H -DTB_P=8 -DTB_NR=8 -DTB_CAPB=19 -DTB_DEPB=10" \
  "$rtl/spiv_live.sv" "$rtl/spiv_light.sv" "$rtl/spiv_pair.sv" "$rtl/spiv_ring.sv" \
  "$rtl/spiv_rungs.sv" "$tbs/tb_live.cpp"

# The Rice and Context tile coders, rows up to 512 samples.
verilate rice "-GWMAX=512" "-DTB_WMAX=512" "$rtl/spiv_rice.sv" "$tbs/tb_rice.cpp"
verilate context "-GWMAX=512" "-DTB_WMAX=512" "$rtl/spiv_context.sv" "$tbs/tb_context.cpp"

# The event ring: 4,096 events over 31 ticks, small enough that the
# recordings evict ticks and the synthetic ones lose events.
verilate ring "-GCAPB=12 -GDEPB=5" "-DTB_W=$W -DTB_H=$H -DTB_CAPB=12 -DTB_DEPB=5" \
  "$rtl/spiv_ring.sv" "$tbs/tb_ring.cpp"

for scene in paper-linear vortex-array; do
  "$spiv" simulate --scene "$scene" --seed 7 --width $W --height $H --ticks 300 \
    --out "$work/$scene" >/dev/null
done
# Long enough for a pair of 255-tick rungs.
"$spiv" simulate --scene paper-linear --seed 9 --width $W --height $H --ticks 560 \
  --out "$work/paper-linear-long" >/dev/null
# The sensor's size, long enough for the live loop's rungs.
"$spiv" simulate --scene paper-linear --seed 101 --ticks 560 --out "$work/paper-linear-400" >/dev/null

# The worst case: every pixel spiking on every tick (every count at the
# window's length, every gray level at full scale).
head -c $((W * H / 8 * 64)) /dev/zero | tr '\0' '\377' >"$work/all.dat"

# FILE WINDOW FIRST DT EVERY: the sidecar's default TFP schedule (window
# 8, the first frame at 4, pairs 13 ticks apart every 52), the longest
# window, odd windows, frames clipped at the start, overlapping windows.
runs=(
  "firmware-sim/cortex-m4/data/strip.dat 8 4 13 52"
  "firmware-sim/cortex-m4/data/strip.dat 16 0 3 5"
  "firmware-sim/cortex-m4/data/strip.dat 3 1 1 2"
  "$work/paper-linear/spikes.dat 8 4 13 52"
  "$work/paper-linear/spikes.dat 15 2 10 40"
  "$work/vortex-array/spikes.dat 8 4 10 40"
  "$work/vortex-array/spikes.dat 16 8 16 16"
  "$work/all.dat 16 0 5 9"
)
for r in "${runs[@]}"; do
  # shellcheck disable=SC2086
  got=$($tb $r)
  printf '%-40s %s\n' "$(basename "$(dirname ${r%% *})")/$(basename ${r%% *}) ${r#* }" "$got"
done

# FILE FIRST [pause]: the first plane's tick 0, or near 2^16 (the last
# spike's 16-bit tick wraps); planes back to back, or with in_valid low
# every third clock. synth:9000 spans periods past the longest the model
# holds (4,095 ticks). The 32-lane model (fpga/synth.sh places it) runs
# the recording and the synthetic planes again.
light_runs=(
  "firmware-sim/cortex-m4/data/strip.dat 0"
  "firmware-sim/cortex-m4/data/strip.dat 65530 pause"
  "$work/paper-linear/spikes.dat 0"
  "$work/vortex-array/spikes.dat 65400 pause"
  "$work/all.dat 3"
  "synth:9000 65000"
)
for r in "${light_runs[@]}"; do
  # shellcheck disable=SC2086
  got=$("$work/light8/Vspiv_light" $r)
  printf 'light/8  %-31s %s\n' "$(basename ${r%% *}) ${r#* }" "$got"
done
for r in "$work/vortex-array/spikes.dat 65400 pause" "synth:9000 65000"; do
  # shellcheck disable=SC2086
  got=$("$work/light32/Vspiv_light" $r)
  printf 'light/32 %-31s %s\n' "$(basename ${r%% *}) ${r#* }" "$got"
done

# FILE: pairs of rung frames along still, uniform, rotating, one-node,
# full-range and gathering flows, at separations up to what the recording
# holds (255 ticks on the long one); noise:N is N planes of pixels
# spiking at random, half of them each tick (most events); dim:N pixels
# spiking at random at their own rates, 1 in 500 to 1 in 10 ticks (every
# static rate, and the rounding of its blocks). Each pair made is asked
# again a tick late, which the core and the RTL refuse.
for r in firmware-sim/cortex-m4/data/strip.dat "$work/paper-linear/spikes.dat" \
  "$work/vortex-array/spikes.dat" "$work/paper-linear-long/spikes.dat" "$work/all.dat" noise:200 \
  dim:560; do
  got=$("$work/live/Vspiv_live" "$r")
  printf 'live     %-31s %s\n' "$(basename "$(dirname "$r")")/$(basename "$r")" "$got"
done
got=$(TB_FRAMES="$work/rung-frames.u16" "$work/rungs400/Vspiv_rungs" "$work/paper-linear-400/spikes.dat")
printf 'rungs    %-31s %s\n' "400x250 paper-linear/spikes.dat" "$got"

# Tiles of TFP-like frames of each recording, then the synthetic tiles
# (tb_rice.cpp and tb_context.cpp list them), each back to back and with
# pauses, through both coders.
for coder in rice context; do
  got=$("$work/$coder/Vspiv_$coder")
  printf '%-8s %-31s %s\n' "$coder" "synthetic tiles" "$got"
  for r in "firmware-sim/cortex-m4/data/strip.dat $W $H" "$work/paper-linear/spikes.dat $W $H" \
    "$work/vortex-array/spikes.dat $W $H" "$work/paper-linear-400/spikes.dat 400 250"; do
    # shellcheck disable=SC2086
    got=$("$work/$coder/Vspiv_$coder" $r)
    printf '%-8s %-31s %s\n' "$coder" "$(basename "$(dirname ${r%% *})")/$(basename ${r%% *}) ${r#* }" "$got"
  done
done
# The live mode's rung frames of the 400x250 run above, as it sends them.
got=$("$work/context/Vspiv_context" frames "$work/rung-frames.u16" 400 250)
printf 'context  %-31s %s\n' "400x250 rung frames" "$got"

# FILE | noise:N | burst:N | slow:N (tb_ring.cpp): every plane's ring
# state and, every fifth plane, six reads.
for r in firmware-sim/cortex-m4/data/strip.dat "$work/paper-linear/spikes.dat" \
  "$work/vortex-array/spikes.dat" noise:120 burst:100 slow:1500; do
  got=$("$work/ring/Vspiv_ring" "$r")
  printf 'ring     %-31s %s\n' "$(basename "$(dirname "$r")")/$(basename "$r")" "$got"
done
