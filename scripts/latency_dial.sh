#!/usr/bin/env bash
# The latency dial of docs/accuracy.md, reproducibly: trains one model per (t_c, window) setting into
# OUT_DIR with one recipe, the s1-only recipe of the low-latency model (scripts/train_low_latency_model.sh:
# 716 GRID s1 train sentences, no speed copies, N=16, M=3, 12 iterations, seed 0; "3 2" is the recipe of
# the previous, s1-only default model), only t_c and the window changed,
# then scores them all, with the shipped default and low-latency models as they ship, on the GRID s1 *val*
# split at smoothing lags 0 and 1 (each trained model at its best kappa of 0.1, 0.2, 0.5, 1 on val) and
# rewrites the latency-dial section of docs/accuracy.md (plot beside it):
#   bash scripts/latency_dial.sh [GRID_S1_ROOT] [OUT_DIR]
# Each training takes 1-3 minutes on 2 shared cores (12 iterations); already trained settings are skipped.
# GRID: Cooke, Barker, Cunningham, Shao (2006), CC BY 4.0.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
grid="${1:-${FACECAST_SHARED_DATA:-$(cd .. && pwd)/shared/data}/video/grid_s1}"
out="${2:-${TMPDIR:-/tmp}/facecast_latency_dial}"
run() { if command -v facecast >/dev/null; then facecast "$@"; else .venv/bin/facecast "$@"; fi; }
mkdir -p "$out"
models=()
# (t_c, window hops): delay = (t_c + window) / 30 s (+ lag / 30 s at run time).
for setting in "3 2" "2 2" "1 2" "0 2.4" "0 2" "2 1.35" "0 1.35"; do
    set -- $setting
    model="$out/tc$1_wh$2.npz"
    [ -f "$model" ] || run train --grid-s1 "$grid" --grid-split train -o "$model" \
        --states 16 --mix 3 --covariance full --tc "$1" --window-hops "$2" --iters 12 --tol 3e-4 --seed 0 \
        --likelihood-scale 0.2 --closure-band 0.03
    models+=("$model")
done
run eval --dial default low-latency "${models[@]}" --grid-s1 "$grid" --grid-split val --lags 0,1 --kappas 0.1,0.2,0.5,1 \
    --output docs/accuracy.md
