#!/usr/bin/env bash
# Interleaved speed comparison on one machine: ffdic (and optionally an older ffdic binary) against
# OpenCorr's FFTCC + ICGN2D1 on the same noisy pairs and the same points, 1 and 2 threads.
#   bench/opencorr/compare.sh ROUNDS
# env STEP: the grid's step, px (default 5; the paper's grid, where the engine's fixed cost per pair
# dominates, is 20).
# env: FFDIC (default target/release/ffdic), FFDIC_OLD (optional second binary), OCBENCH (the
# ocbench binary, see README.md), PAIRS (folder with ref.tif, trans.tif, stretchrot.tif from
# make_pair.py), OUT (scratch folder). Prints per-case medians and per-round ratios.
set -euo pipefail
R=${1:-5}
STEP=${STEP:-5}
FFDIC=${FFDIC:-target/release/ffdic}
OCBENCH=${OCBENCH:-../opencorr-bench/build/ocbench}
PAIRS=${PAIRS:-/tmp/ffdic-speed-pairs}
OUT=${OUT:-$(mktemp -d)}
# OpenCorr's FFTCC needs a window of 2x64 px to catch the 64 px move; +50 grey on both images keeps
# its "interpolated value < 0 means outside" test from rejecting subsets at dark dots (ZNSSD is
# unchanged by an offset).
export OCBENCH_FFTCC_R=64 OCBENCH_INIT=fftcc OCBENCH_OFFSET=50
tools=(new)
[ -n "${FFDIC_OLD:-}" ] && tools+=(old)
tools+=(opencorr)
mkdir -p "$OUT"
RES=$OUT/runs.tsv; : > "$RES"
now() { date +%s.%N; }
for pair in trans stretchrot; do
  # The points: ffdic's own grid at the step, handed to OpenCorr as a CSV.
  "$FFDIC" analyze "$PAIRS/ref.tif" "$PAIRS/$pair.tif" --step "$STEP" --json --out "$OUT/points_$pair" > /dev/null
done
for ((r = 1; r <= R; r++)); do
  for pair in trans stretchrot; do
    for T in 1 2; do
      for tool in "${tools[@]}"; do
        t0=$(now)
        case $tool in
          opencorr)
            "$OCBENCH" "$PAIRS/ref.tif" "$PAIRS/$pair.tif" "$OUT/points_$pair/points.csv" "$T" 20 10 0.001 > "$OUT/o.json" 2> /dev/null
            t1=$(now)
            read -r valid compute icgn < <(python3 -c "import json;d=json.load(open('$OUT/o.json'));print(d['valid'],d['compute_ms']/1000,d['icgn_ms']/1000)") ;;
          *)
            bin=$FFDIC; [ "$tool" = old ] && bin=$FFDIC_OLD
            "$bin" analyze "$PAIRS/ref.tif" "$PAIRS/$pair.tif" --step "$STEP" --threads "$T" --json > "$OUT/f.json"
            t1=$(now)
            read -r valid compute icgn < <(python3 -c "import json;d=json.load(open('$OUT/f.json'));print(d['valid'],d['elapsed_s'],'nan')") ;;
        esac
        echo -e "$r\t$pair\t$T\t$tool\t$(python3 -c "print($t1 - $t0)")\t$valid\t$compute\t$icgn" >> "$RES"
      done
    done
  done
  echo "round $r done" >&2
done
python3 - "$RES" "$OUT" <<'PY'
import sys, statistics as st
from collections import defaultdict
runs = defaultdict(list)
for line in open(sys.argv[1]):
    r, p, T, tool, wall, valid, comp, icgn = line.split('\t')
    runs[(p, int(T), tool)].append((float(wall), int(valid), float(comp), float(icgn)))
# The points of the grid (one header line in each pair's points.csv; the same grid for both).
n = sum(1 for _ in open(f"{sys.argv[2]}/points_trans/points.csv")) - 1
tools = sorted({k[2] for k in runs}, key=['new', 'old', 'opencorr'].index)
print("| pair | threads | tool | compute s median [min-max] | POI/s | valid |")
print("|---|---|---|---|---|---|")
for p in ('trans', 'stretchrot'):
    for T in (1, 2):
        for tool in tools:
            x = runs[(p, T, tool)]; c = [a[2] for a in x]
            extra = ''
            if tool == 'opencorr':
                ic = st.median(a[3] for a in x); extra = f" (IC-GN step alone {n/ic:,.0f})"
            print(f"| {p} | {T} | {tool} | {st.median(c):.3f} [{min(c):.3f}-{max(c):.3f}] | {n/st.median(c):,.0f}{extra} | {min(a[1] for a in x)} |")
        new = [a[2] for a in runs[(p, T, 'new')]]
        for tool in tools[1:]:
            other = [a[2] for a in runs[(p, T, tool)]]
            ratios = [o / m for m, o in zip(new, other)]
            print(f"ratio {p} T{T} new vs {tool} end to end: median {st.median(ratios):.2f} [{min(ratios):.2f}-{max(ratios):.2f}]")
PY
