"""The shipped model's sensitivity to the input level, with and without the run-time gain stage.

Prints r(mouth_open) / closures on GRID s1 **val** (never test) with the input scaled by each
--gains dB (float samples, not clipped), the 6 real-speech clips (rules truth), and the largest
mouth_open on white noise alone at -70 / -50 / -40 dBFS (3 s, seed 0). ``--gain-stage`` runs the
live path with ``FrontEndConfig.input_gain`` (realtime_core/features/gain.py) set.
``--measure-reference`` instead prints where the gain stage's speech-peak tracker settles on the
s1 train sentences (the constant ``S1_SPEECH_LEVEL_DBFS``).

    python scripts/input_gain_check.py [--gain-stage] [--gains -12,-6,-3,0,6]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from assets.audio import read_audio
from assets.grid import default_root, sentences
from assets.modelfile import load_model
from realtime_core.features import InputGainConfig, LevelTracker, loudness_db
from realtime_core.pipeline import speech_to_params
from training.reallips import MOUTH_OPEN, lip_items, real_speech_clips, s1_clips, score_lips, score_real_speech


def measure_reference(config: InputGainConfig, every: int) -> None:
    """The mean level of s1 train speech blocks (the gain stage's floor + speech rule): one stream of
    every ``every``-th train sentence back to back, as a live session would hear them."""
    xs = [read_audio(s.video, rate_hz=16000)[0] for s in sentences(split="train")[::every]]
    x = np.concatenate(xs).astype(np.float64)
    b = config.block_len(16000)
    n = len(x) // b
    lv = 10.0 * np.log10(np.maximum(np.mean(x[: n * b].reshape(n, b) ** 2, axis=1), 1e-12))
    _, floor = LevelTracker(config.tracker).track(lv)
    speech = lv > floor + config.tracker.speech_above_floor_db
    print(f"{len(xs)} train sentences, {speech.sum()} speech blocks: mean level {lv[speech].mean():.2f} dBFS")


def one_stream_items(model, clips: list) -> list:
    """:func:`lip_items` of the val clips run back to back as one live session (each padded with
    digital silence to whole frames, 1600 samples = 3 frames at 16 kHz, so the clips keep their own
    frame grids), cut back into clips: the gain stage then carries its level from clip to clip."""
    step = 1600
    assert all(r == 16000 for _, _, r, _, _ in clips)
    xs = [np.concatenate([x, np.zeros(-len(x) % step)]) for _, x, _, _, _ in clips]
    est = speech_to_params(model, np.concatenate(xs), 16000)
    out, k = [], 0
    for (name, x, rate, truth, spans), xp in zip(clips, xs):
        n = 3 * len(xp) // step
        out.append((name, truth, est[k : k + n], loudness_db(x, rate, len(truth)), list(spans)))
        k += n
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gain-stage", action="store_true")
    ap.add_argument("--gains", default="-12,-6,-3,0,6")
    ap.add_argument("--prior", type=int, default=None, help="InputGainConfig.prior_blocks")
    ap.add_argument("--memory", type=int, default=None, help="InputGainConfig.memory_blocks")
    ap.add_argument("--reference", type=float, default=None, help="InputGainConfig.reference_db")
    ap.add_argument("--measure-reference", action="store_true")
    ap.add_argument("--every", type=int, default=3, help="with --measure-reference: every n-th train sentence")
    ap.add_argument("--one-stream", action="store_true", help="val clips back to back as one live stream")
    ap.add_argument("--skip", default="", help="comma list of: val,real,noise")
    args = ap.parse_args()
    cfg = InputGainConfig()
    if args.prior is not None:
        cfg = replace(cfg, prior_blocks=args.prior)
    if args.memory is not None:
        cfg = replace(cfg, memory_blocks=args.memory)
    if args.reference is not None:
        cfg = replace(cfg, reference_db=args.reference)
    if args.measure_reference:
        measure_reference(cfg, args.every)
        return
    model = load_model(None)
    if args.gain_stage:
        model = replace(model, frontend=replace(model.frontend, input_gain=cfg))
    print(f"gain stage: {cfg if args.gain_stage else 'off'}")
    skip = set(args.skip.split(","))
    if "val" not in skip:
        clips = [(n, t.samples, t.sample_rate_hz, t.params, w) for n, t, w in s1_clips("val")]
        for g in [float(v) for v in args.gains.split(",")]:
            k = 10.0 ** (g / 20.0)
            scaled = [(n, x.astype(np.float64) * k, r, p, w) for n, x, r, p, w in clips]
            s = score_lips(one_stream_items(model, scaled) if args.one_stream else lip_items(model, scaled))
            print(f"| val {g:+.0f} dB | {s.r['mouth_open']:.3f} / {s.closure_rate:.0%} |", flush=True)
    if "real" not in skip:
        speech = real_speech_clips(str(default_root().parent.parent / "speech"))
        s = score_real_speech(model, speech)
        print(f"| real speech | {s.r['mouth_open']:.3f} / {s.closure_rate:.0%} of {s.n_closures} |", flush=True)
        # the user's check: the same file quieter against its own output at the original level
        own = [speech_to_params(model, x, r)[:, MOUTH_OPEN] for _, x, r, _, _ in speech]
        for g in (-3.0, -6.0, -12.0):
            est = [speech_to_params(model, x * 10.0 ** (g / 20.0), r)[:, MOUTH_OPEN] for _, x, r, _, _ in speech]
            a, b = np.concatenate(own), np.concatenate(est)
            r_own, diff = np.corrcoef(a, b)[0, 1], np.abs(a - b).max()
            print(f"| real speech {g:+.0f} dB against its own 0 dB output | r {r_own:.3f}, max diff {diff:.3f} IOD |")
    if "noise" not in skip:
        rng = np.random.default_rng(0)
        white = rng.standard_normal(3 * 16000)
        out = []
        for dbfs in (-70.0, -50.0, -40.0):
            est = speech_to_params(model, white * 10.0 ** (dbfs / 20.0), 16000)
            out.append(f"{float(est[:, MOUTH_OPEN].max()):.3f}")
        print(f"| noise alone -70/-50/-40 dBFS, max mouth_open (IOD) | {' / '.join(out)} |")


if __name__ == "__main__":
    main()
