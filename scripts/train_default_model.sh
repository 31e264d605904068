#!/usr/bin/env bash
# Trains the default model shipped in training/data/default_model.npz, reproducibly:
#   bash scripts/train_default_model.sh [WORK_DIR]
# 1. an espeak-ng corpus, English and Spanish, 600 sentences each (the 300-sentence lists with two
#    voices each), microphone augmentation, voice variants f5 and m7 left out (they are the
#    held-out voices of `facecast eval`);
# 2. a Festival corpus, English, 300 sentences over three voices (two diphone voices from real
#    recordings and one HTS voice) at three speaking rates, augmented: closer to human speech;
# 3. Baum-Welch, full covariances, N=16 states, M=3 mixtures, t_c=3, c0..c11 features, seed 0,
#    audio-likelihood scale 0.1.
# The training report (EM history, recipe) is kept in the model's metadata and in
# docs/default_model.md; `facecast eval` then writes docs/accuracy.md.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
work="${1:-${FACECAST_CACHE:-$HOME/.cache/facecast}/default-model-work}"
run() { if command -v facecast >/dev/null; then facecast "$@"; else .venv/bin/facecast "$@"; fi; }
run corpus "$work/corpus" --sentences 600 --languages en,es --augment --seed 7 \
    --variants base,m1,m2,m3,m4,m5,m6,f1,f2,f3,f4
run corpus "$work/festival" --engine festival --sentences 300 --augment --seed 11
run train "$work/corpus" "$work/festival" -o training/data/default_model.npz \
    --states 16 --mix 3 --covariance full --tc 3 --iters 30 --tol 3e-4 --seed 0 --likelihood-scale 0.1
