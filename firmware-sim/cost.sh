#!/usr/bin/env bash
# Exact cost of spiv-core's sidecar kernels, on the emulated Cortex-M4F
# (Thumb-2, counted from QEMU's one-instruction-per-block execution trace)
# and on the host (x86-64, callgrind), for the committed 128x64 px strip
# (firmware-sim/cortex-m4/data): ingest of 141 spike planes, two adaptive
# frames (n_max = 128), and sending them (Rice tiles, COBS, CRC-32); then
# the same strip with motion-compensated frames (refine on) after hearing
# the committed control message (cortex-m4/data/control.bin); then the last
# frame coded by each tile codec (Rice, Context, Sparse, SparseContext);
# then the static-light model with its event ring over the strip's bottom
# 32 stored rows (the glare band) and first 104 planes, and the rung frames
# of 4, 8, 16 and 32 ticks warped along a uniform flow.
# Also: the firmware's RAM, its parity line, and what the counts mean for a
# 400 MHz Cortex-M7-class MCU at 20 kHz.
#
#   firmware-sim/cost.sh            print the table
#   firmware-sim/cost.sh --check    also fail when a Thumb-2 count rises more
#                                   than 10 % above cortex-m4/cost-baseline.txt
#
# Needs qemu-system-arm, the thumbv7em-none-eabihf target, valgrind, awk.
set -euo pipefail
cd "$(dirname "$0")"
check=0
[ "${1:-}" = "--check" ] && check=1

m4=$PWD/cortex-m4
(cd "$m4" && cargo build --release -q)
bin=$m4/target/thumbv7em-none-eabihf/release/spiv-firmware-m4
qemu=(qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic
      -semihosting-config enable=on,target=native)
# One instruction per translation block (the option's name changed in 8.1).
ver=$(qemu-system-arm --version | sed -n 's/.*version \([0-9]*\)\.\([0-9]*\).*/\1 \2/p')
read -r vmaj vmin <<<"$ver"
if [ "$vmaj" -gt 8 ] || { [ "$vmaj" -eq 8 ] && [ "$vmin" -ge 1 ]; }; then
  one=(-accel tcg,one-insn-per-tb=on)
else
  one=(-singlestep)
fi

run=$(timeout 120 "${qemu[@]}" -kernel "$bin")
echo "$run"
parity=$(grep '^planes=' <<<"$run")
mc_parity=$(sed -n 's/^mc //p' <<<"$run")
get() { sed -n "s/.*\b$1=\([0-9a-f]*\).*/\1/p" <<<"$parity"; }
planes=$(get planes); frames=$(get frames); bytes=$(get bytes)
px=$((128 * 64))
# The final status message: 66 bytes (header, 32-byte status, CRC), 67
# after COBS, plus the delimiter.
frame_bytes=$((bytes - 68))

fifo=$(mktemp -u)
mkfifo "$fifo"
trap 'rm -f "$fifo"' EXIT
counts=$(mktemp)
awk '
  { s = $NF }
  s == "spiv_mark_ingest_begin" { st = "ingest"; next }
  s == "spiv_mark_frame_begin"  { st = "frame";  next }
  s == "spiv_mark_send_begin"   { st = "send";   next }
  s == "spiv_mark_mc_ingest_begin" { st = "mc_ingest"; next }
  s == "spiv_mark_mc_frame_begin"  { st = "mc_frame";  next }
  s == "spiv_mark_mc_send_begin"   { st = "mc_send";   next }
  s == "spiv_mark_hear_begin"      { st = "hear";      next }
  s == "spiv_mark_rice_begin"      { st = "rice";      next }
  s == "spiv_mark_context_begin"   { st = "context";   next }
  s == "spiv_mark_sparse_begin"    { st = "sparse";    next }
  s == "spiv_mark_sparse_context_begin" { st = "sparse_context"; next }
  s == "spiv_mark_light_begin"     { st = "light";     next }
  s == "spiv_mark_rungs_begin"     { st = "rungs";     next }
  s == "spiv_mark_link_begin"   { saved = st; st = "link"; next }
  s == "spiv_mark_link_end"     { st = saved; next }
  s ~ /^spiv_mark_.*_end$/      { st = ""; next }
  st != ""                      { n[st]++ }
  END { printf "%d %d %d %d %d %d %d %d %d %d %d %d %d %d\n", n["ingest"], n["frame"], n["send"], n["link"],
        n["mc_ingest"], n["mc_frame"], n["mc_send"], n["hear"],
        n["rice"], n["context"], n["sparse"], n["sparse_context"], n["light"], n["rungs"] }
' <"$fifo" >"$counts" &
timeout 900 "${qemu[@]}" "${one[@]}" -d exec,nochain -D "$fifo" -kernel "$bin" >/dev/null
wait
read -r t_ingest t_frame t_send t_link t_mc_ingest t_mc_frame t_mc_send t_hear \
  t_rice t_context t_sparse t_sparse_context t_light t_rungs <"$counts"
codec_line=$(grep '^codecs ' <<<"$run")
codec_bytes() { sed -n "s/.*\b$1=\([0-9]*\).*/\1/p" <<<"$codec_line"; }
mc_bytes=$(sed -n 's/.*\bbytes=\([0-9]*\).*/\1/p' <<<"$mc_parity")
mc_frame_bytes=$((mc_bytes - 68))
control_bytes=$(stat -c %s "$m4/data/control.bin")

# Host: the same loop, callgrind bracketing each stage the loop keeps out of
# line (spiv_core::sidecar::Sidecar::{ingest,make_frame,send_frame}).
(cd .. && cargo build --release -q -p spiv-firmware-sim --example strip_kernels)
host=../target/release/examples/strip_kernels
host_parity=$("$host")
host_mc_parity=$("$host" mc)
host_light_parity=$("$host" light)
light_parity=$(sed -n 's/^light //p' <<<"$run")
callgrind() {
  valgrind --tool=callgrind --toggle-collect="$1" \
    --callgrind-out-file=/dev/null "$host" ${2:-} 2>&1 | sed -n 's/.*I *refs: *//p' | tr -d ,
}
x_ingest=$(callgrind spiv_core::sidecar::Sidecar::ingest)
x_frame=$(callgrind spiv_core::sidecar::Sidecar::make_frame)
x_send=$(callgrind spiv_core::sidecar::Sidecar::send_frame)
x_mc_frame=$(callgrind spiv_core::sidecar::Sidecar::make_frame mc)
x_mc_send=$(callgrind spiv_core::sidecar::Sidecar::send_frame mc)
x_refine=$(callgrind spiv_core::motion::refine mc)
x_light=$(callgrind spiv_core::rungs::EventRing::push light)
x_rungs=$(callgrind spiv_core::rungs::rung_frames light)
light_events=$(sed -n 's/.*\bevents=\([0-9]*\).*/\1/p' <<<"$light_parity")
light_px=$((128 * 32)); light_planes=104
rung_px=$((light_px * 8))

ratio() { awk -v a="$1" -v b="$2" -v d="$3" 'BEGIN { printf "%.*f", d, a / b }'; }
echo
echo "strip 128x64 px: $planes planes ingested, $frames adaptive frames (n_max 128), $frame_bytes bytes of frame messages"
printf '%-34s %16s %16s %16s\n' kernel "Thumb-2 (M4)" "x86-64" unit
printf '%-34s %16s %16s %16s\n' "ingest" "$(ratio "$t_ingest" $((px * planes)) 3)" "$(ratio "$x_ingest" $((px * planes)) 3)" "per pixel-plane"
printf '%-34s %16s %16s %16s\n' "adaptive frame" "$(ratio "$t_frame" $((px * frames)) 1)" "$(ratio "$x_frame" $((px * frames)) 1)" "per pixel"
printf '%-34s %16s %16s %16s\n' "send (Rice, COBS, CRC-32)" "$(ratio "$t_send" "$frame_bytes" 1)" "$(ratio "$x_send" "$frame_bytes" 1)" "per wire byte"
printf '%-34s %16s %16s %16s\n' "send" "$(ratio "$t_send" $((px * frames)) 1)" "$(ratio "$x_send" $((px * frames)) 1)" "per pixel"
printf '%-34s %16s %16s %16s\n' "motion-compensated frame" "$(ratio "$t_mc_frame" $((px * frames)) 1)" "$(ratio "$x_mc_frame" $((px * frames)) 1)" "per pixel"
printf '%-34s %16s %16s %16s\n' "  of which refine (host)" "" "$(ratio "$x_refine" $((px * frames)) 1)" "per pixel"
printf '%-34s %16s %16s %16s\n' "  its send" "$(ratio "$t_mc_send" $((px * frames)) 1)" "$(ratio "$x_mc_send" $((px * frames)) 1)" "per pixel"
printf '%-34s %16s %16s %16s\n' "  its wire bytes per frame" "$((mc_frame_bytes / frames))" "" "(adaptive $((frame_bytes / frames)))"
printf '%-34s %16s %16s %16s\n' "hear one control ($control_bytes B)" "$(ratio "$t_hear" "$control_bytes" 1)" "" "per control byte"
echo "tile codecs on the last motion-compensated frame (one 128x64 tile, payload only):"
for c in rice context sparse sparse_context; do
  t=$(eval echo "\$t_$c"); b=$(codec_bytes "$c")
  printf '%-34s %16s %16s %16s\n' "codec $c" "$(ratio "$t" "$px" 1)" "" "per pixel ($(ratio "$t" "$b" 0) per coded byte; $b B = $(ratio $((8 * b)) "$px" 2) bits/px)"
done
printf '%-34s %16s %16s %16s\n' "static light + event ring" "$(ratio "$t_light" $((light_px * light_planes)) 1)" "$(ratio "$x_light" $((light_px * light_planes)) 1)" "per pixel-plane ($light_events events)"
printf '%-34s %16s %16s %16s\n' "rung frames (4, 8, 16, 32 ticks)" "$(ratio "$t_rungs" "$rung_px" 1)" "$(ratio "$x_rungs" "$rung_px" 1)" "per frame pixel (8 frames)"
printf '%-34s %16s %16s %16s\n' "  per event" "$(ratio "$t_rungs" "$light_events" 1)" "$(ratio "$x_rungs" "$light_events" 1)" "per event held"
printf '%-34s %16s\n' "(parity CRC of the stream)" "$(ratio "$t_link" "$bytes" 1) per byte"
echo "totals: Thumb-2 ingest $t_ingest, frame $t_frame, send $t_send, mc_frame $t_mc_frame, mc_send $t_mc_send, hear $t_hear, codecs rice $t_rice context $t_context sparse $t_sparse sparse_context $t_sparse_context, light $t_light, rungs $t_rungs; x86-64 ingest $x_ingest, frame $x_frame, send $x_send, mc_frame $x_mc_frame (refine $x_refine), mc_send $x_mc_send, light $x_light, rungs $x_rungs"

# Static RAM of the firmware image.
sec() {
  local hex
  hex=$(readelf -S -W "$bin" | sed 's/^ *\[ *[0-9]*\] *//' | awk -v n="$1" '$1 == n { print $5 }')
  echo $((16#${hex:-0}))
}
echo "static RAM: .data $(sec .data) B, .bss $(sec .bss) B (flash .text $(sec .text) B, .rodata $(sec .rodata) B)"

# What it means at 20 kHz on a 400 MHz MCU retiring ~1 instruction per cycle:
# ingest runs every tick; two frames and their sending every pair period
# M = 4*dt = 52 ticks (2.6 ms).
awk -v i="$t_ingest" -v f="$t_frame" -v s="$t_send" -v mf="$t_mc_frame" -v ms="$t_mc_send" -v px=$px -v pl="$planes" -v fr="$frames" 'BEGIN {
  ipp = i / (px * pl);
  for (k = 0; k < 2; k++) {
    name = k == 0 ? "adaptive" : "motion-compensated";
    fpp = (k == 0 ? f : mf) / (px * fr); spp = (k == 0 ? s : ms) / (px * fr);
    per_px_s = ipp * 20000 + (fpp + spp) * 2 * 20000 / 52;
    maxpx = 400e6 / per_px_s;
    printf "400 MHz MCU at 20 kHz, M = 52 ticks, %s: %.0f instructions per pixel per second (ingest %.0f, frames %.0f) -> at most %.0f px (%.1f%% of 400x250, %.2f%% of 1000x1000 at 40 kHz: %.0f px)\n",
      name, per_px_s, ipp * 20000, (fpp + spp) * 2 * 20000 / 52, maxpx, 100 * maxpx / 100000,
      100 * (400e6 / (ipp * 40000 + (fpp + spp) * 2 * 40000 / 52)) / 1e6, 400e6 / (ipp * 40000 + (fpp + spp) * 2 * 40000 / 52)
  }
}'

# Parity: the firmware under QEMU, the host kernels, the native firmware
# loop (`spiv-firmware-sim --checksum`) and the committed line agree.
(cd .. && cargo build --release -q -p spiv-firmware-sim --bin spiv-firmware-sim)
native=$(../target/release/spiv-firmware-sim --input "$m4/data/strip.dat" --pairs 1 --checksum)
committed=$(cat "$m4/expected.txt")
native_mc=$(../target/release/spiv-firmware-sim --input "$m4/data/strip.dat" --pairs 1 --checksum \
  --method mc --control "$m4/data/control.bin")
committed_mc=$(cat "$m4/expected-mc.txt")
same() {
  local what=$1 m4line=$2; shift 2
  for other in "$@"; do
    if [ "$m4line" != "$other" ]; then
      echo "!! parity ($what): the Cortex-M4 and the host differ"
      echo "   m4:        $m4line"
      echo "   kernels:   $1"
      echo "   native:    $2"
      echo "   committed: $3"
      exit 1
    fi
  done
}
same adaptive "$parity" "$host_parity" "$native" "$committed"
same motion-compensated "$mc_parity" "$host_mc_parity" "$native_mc" "$committed_mc"
committed_light=$(cat "$m4/expected-light.txt")
same light "$light_parity" "$host_light_parity" "$committed_light" "$committed_light"
echo "parity: Cortex-M4, host kernels, native firmware loop and cortex-m4/expected.txt (adaptive) and expected-mc.txt (motion-compensated) identical; light and rungs: Cortex-M4, host kernels and expected-light.txt identical"

if [ "$check" = 1 ]; then
  base=$m4/cost-baseline.txt
  fail=0
  for k in ingest frame send mc_frame mc_send rice context sparse sparse_context light rungs; do
    want=$(sed -n "s/^$k=//p" "$base")
    got=$(eval echo "\$t_$k")
    if [ "$got" -gt $((want + want / 10)) ]; then
      echo "!! $k: $got Thumb-2 instructions, more than 10 % above the committed $want ($base)"
      fail=1
    else
      echo "cost gate $k: $got instructions (committed $want, limit +10 %)"
    fi
  done
  exit $fail
fi
