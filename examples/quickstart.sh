#!/usr/bin/env bash
# The README's quick start: simulate the paper's sec. 4.2 roof, fit it, write the report.
#   bash examples/quickstart.sh [OUTDIR] [METHOD]     # METHOD: auto (default, ~70 s) or casadi (~40 s)
set -euo pipefail
scene="$(dirname "$0")/scenes/roof_frame.toml"
out=${1:-quickstart}
method=${2:-auto}
mkdir -p "$out"
vibinverse simulate "$scene" --set noise.sigma=0.6 --seed 3 -o "$out/frame.csv" --plot "$out/frame.png"
vibinverse fit "$out/frame.csv" --scene "$scene" --method "$method" --no-progress \
    -o "$out/result.nc" --summary "$out/result.json"
vibinverse report "$out/result.nc" -o "$out/report"
