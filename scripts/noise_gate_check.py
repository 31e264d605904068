"""Room noise alone against the shipped model, with and without the output noise gate
(realtime_core/features/noisegate.py), and what the gate costs speech.

Prints mouth_open (IOD) over 8 s of each noise at -60 / -54 / -48 dBFS RMS (white, pink, brown, a fan: 50 Hz
harmonics over band-limited hiss, and GRID s1's leading silences, the first 40 train sentences' spans before
the first word, looped); for noises that step up 4 s into a take (a fan switched on), how long after the step the
mouth still moves; the share of frames of long read speech (LJ Speech's 32 clips back to back, 3.7 min; LibriVox,
15 s) the gate fades (gain < 1), clean and under noise; then r(mouth_open) and closures on GRID s1 **val** (never
test) and on the other GRID talkers, gate off and on.

    python scripts/noise_gate_check.py [--skip noise,step,speech,val,other] [--model default]
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.signal import butter, lfilter, sosfilt

from assets.audio import read_audio
from assets.grid import align_for_video, read_words, sentences
from assets.modelfile import load_model
from assets.shared import shared_data_root
from realtime_core.features import NoiseGate, NoiseGateConfig
from realtime_core.pipeline import speech_to_params
from training.reallips import MOUTH_OPEN, other_talker_clips, s1_clips, score_lips

RATE = 16000
SECONDS = 8.0


def noises(seconds: float = SECONDS, seed: int = 0) -> dict[str, np.ndarray]:
    """Room-like noises (n,) at RATE, not yet at any level."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    t = np.arange(n) / RATE
    # pink: Kellet's 3-pole approximation of 1/f; brown: integrated white, 20 Hz high-passed (no DC drift)
    pink = lfilter(
        [0.049922035, -0.095993537, 0.050612699, -0.004408786],
        [1, -2.494956002, 2.017265875, -0.522189400],
        rng.standard_normal(n),
    )
    brown = sosfilt(butter(2, 20, "hp", fs=RATE, output="sos"), np.cumsum(rng.standard_normal(n)))
    hum = sum(
        a * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        for f, a in [(50, 1), (100, 0.7), (150, 0.3), (200, 0.4), (300, 0.15)]
    )
    hiss = sosfilt(butter(2, [200, 2000], "bp", fs=RATE, output="sos"), rng.standard_normal(n))
    fan = hum / np.std(hum) + 0.5 * hiss / np.std(hiss)
    return {"white": rng.standard_normal(n), "pink": pink, "brown": brown, "fan": fan, "grid_sil": grid_silence(n)}


def grid_silence(n: int) -> np.ndarray:
    """GRID s1's leading pauses (up to 0.15 s before the first word: no speech onset), looped to ``n`` samples."""
    segs = []
    for s in sentences(split="train")[:40]:
        words = read_words(align_for_video(s.video))
        x = read_audio(s.video, rate_hz=RATE)[0].astype(np.float64)
        seg = x[int(0.05 * RATE) : int((words[0][1] - 0.15) * RATE)]
        if seg.size > RATE // 4:
            segs.append(seg)
    return np.resize(np.concatenate(segs), n)


def at_dbfs(x: np.ndarray, dbfs: float) -> np.ndarray:
    x = x - x.mean()
    return x * 10.0 ** (dbfs / 20.0) / np.sqrt(np.mean(x**2))


def steps(model) -> None:
    """Noise that steps up 4 s into a 16 s take: mouth_open's largest value after the step and the time after it of
    the last frame over 0.005 IOD, gate off and on."""
    print("| noise | step (dBFS) | gate | max after the step | moves until (s after the step) |")
    print("|---|---|---|---:|---:|")
    at = 4.0
    for name in ("white", "pink", "fan"):
        for lo, hi in ((-64.0, -54.0), (-74.0, -54.0), (-64.0, -48.0)):
            x = np.concatenate([at_dbfs(noises(at, 1)[name], lo), at_dbfs(noises(16.0 - at, 2)[name], hi)])
            for g, cfg in (("off", None), ("on", NoiseGateConfig())):
                mo = speech_to_params(model, x, RATE, noise_gate=cfg)[int(at * 30) :, MOUTH_OPEN]
                moving = np.flatnonzero(mo > 0.005)
                until = (moving[-1] + 1) / 30 if moving.size else 0.0
                end = " (the take's end)" if moving.size and moving[-1] >= len(mo) - 15 else ""
                print(f"| {name} | {lo:.0f} -> {hi:.0f} | {g} | {mo.max():.3f} | {until:.1f}{end} |", flush=True)


def read_speech(model) -> None:
    """The share of frames of long read speech the gate fades (gain < 1), from the warm-up to the take's last second
    (after the last word the gate may close), clean and under noise."""
    root = shared_data_root() / "speech"
    takes = {
        name: np.concatenate([read_audio(f, rate_hz=RATE)[0].astype(np.float64) for f in sorted(root.glob(pattern))])
        for name, pattern in (("LJ Speech, 32 clips", "ljspeech/*.wav"), ("LibriVox, 3 clips", "librivox/*.wav"))
    }
    cfg = NoiseGateConfig()
    print("| read speech | noise under it | seconds | frames faded (gain < 1) |")
    print("|---|---|---:|---:|")
    for name, x in takes.items():
        for noise, dbfs in (("none", None), ("white", -54.0), ("pink", -48.0)):
            y = x if dbfs is None else x + at_dbfs(noises(x.size / RATE, 3)[noise], dbfs)
            fe = model.front_end()
            fe.push(y)
            levels = fe.last_level_db
            fe.flush()
            gate = NoiseGate(cfg, lookahead=model.frontend.tc)
            gate.push_levels(np.concatenate([levels, fe.last_level_db]))
            gate.apply(np.ones((len(levels) + len(fe.last_level_db), 1)))
            g = gate.gain[cfg.warmup_frames : len(gate.gain) - 30]
            label = noise if dbfs is None else f"{noise} {dbfs:.0f} dBFS"
            print(f"| {name} | {label} | {x.size / RATE:.0f} | {np.mean(g < 1):.2%} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip", default="", help="comma list of: noise,step,speech,val,other")
    ap.add_argument("--model", default=None, help="model file or shipped name (default: default)")
    args = ap.parse_args()
    skip = set(args.skip.split(","))
    model = load_model(args.model)
    gates = {"off": None, "on": NoiseGateConfig()}
    if "noise" not in skip:
        print("| noise | dBFS | gate | mean | p95 | max | max after 1 s | frames > 0.02 |")
        print("|---|---:|---|---:|---:|---:|---:|---:|")
        for name, x in noises().items():
            for dbfs in (-60.0, -54.0, -48.0):
                for g, cfg in gates.items():
                    mo = speech_to_params(model, at_dbfs(x, dbfs), RATE, noise_gate=cfg)[:, MOUTH_OPEN]
                    print(
                        f"| {name} | {dbfs:.0f} | {g} | {mo.mean():.3f} | {np.percentile(mo, 95):.3f} | {mo.max():.3f} "
                        f"| {mo[30:].max():.3f} | {np.mean(mo > 0.02):.0%} |",
                        flush=True,
                    )
    if "step" not in skip:
        steps(model)
    if "speech" not in skip:
        read_speech(model)
    sets = {}
    if "val" not in skip:
        sets["GRID s1 val"] = s1_clips("val")
    if "other" not in skip:
        sets["other GRID talkers"] = other_talker_clips(shared_data_root() / "video" / "grid")
    for title, found in sets.items():
        clips = [(n, t.samples, t.sample_rate_hz, t.params, w) for n, t, w in found]
        for g, cfg in gates.items():
            # the live path as lip_items runs it, with the gate set; loudness is not scored here
            items = [
                (name, truth, speech_to_params(model, x, rate, noise_gate=cfg), np.zeros(len(truth)), spans)
                for name, x, rate, truth, spans in clips
            ]
            s = score_lips(items)
            r, closed = s.r["mouth_open"], f"{s.closure_rate:.0%} of {s.n_closures}"
            print(
                f"| {title} ({len(clips)} clips) | gate {g} | r(mouth_open) {r:.4f} | closures {closed} |", flush=True
            )


if __name__ == "__main__":
    main()
