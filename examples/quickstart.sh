#!/usr/bin/env bash
# The README's quick start: simulate the paper's sec. 4.2 roof, fit it, write the report, all in one
# output directory: OUTDIR/series.csv, series.png, result.nc, summary.json, result.chain.h5, report.html.
#   bash examples/quickstart.sh [OUTDIR] [METHOD]     # METHOD: auto (default, ~70 s) or casadi (~40 s)
set -euo pipefail
scene="$(dirname "$0")/scenes/roof_frame.toml"
out=${1:-quickstart}
method=${2:-auto}
vibinverse simulate "$scene" --set noise.sigma=0.6 --seed 3 -o "$out" --plot
vibinverse fit "$out/series.csv" --scene "$scene" --method "$method" --no-progress -o "$out"
vibinverse report "$out/result.nc"
