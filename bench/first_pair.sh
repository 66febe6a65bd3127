#!/usr/bin/env bash
# The live loop's first pair on a fast flow: the vortex array at 1 px/tick
# (600 planes), `spiv flow --start 40` so that no warm-up pair fits before
# the first (the loop starts cold, as a sidecar does); per seed, the first
# pair's share of valid vectors and its EPE (px per pair, measured
# vectors, against truth.csv) beside the later pairs' mean.
#
#   bench/first_pair.sh 101 102 ... 110      (SPIV=path/to/spiv to choose the binary)
set -euo pipefail
spiv=${SPIV:-spiv}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for seed in "$@"; do
  d=$work/$seed
  "$spiv" simulate --scene vortex-array --speed 1.0 --seed "$seed" --ticks 600 --out "$d" >/dev/null
  "$spiv" flow "$d/spikes.dat" --start 40 --out "$d/flow" >/dev/null
  python3 - "$d" "$seed" <<'PY'
import csv, glob, math, sys
d, seed = sys.argv[1], sys.argv[2]
truth = {(r['x'], r['y']): (float(r['u']), float(r['v'])) for r in csv.DictReader(open(d + '/truth.csv'))}
res = []
for f in sorted(glob.glob(d + '/flow/vectors_0*.csv')):
    rows = list(csv.DictReader(open(f)))
    valid = sum(r['flag'] == '0' for r in rows)
    e = [math.hypot(float(r['u']) - truth[(r['x'], r['y'])][0], float(r['v']) - truth[(r['x'], r['y'])][1])
         for r in rows if r['flag'] in ('0', '1')]
    res.append((valid / len(rows), sum(e) / len(e)))
later = sum(r[1] for r in res[1:]) / len(res[1:])
print(f"seed {seed}: first pair {100 * res[0][0]:.0f} % valid, EPE {res[0][1]:.3f}; later pairs {later:.3f}; ratio {res[0][1] / later:.2f}")
PY
done
