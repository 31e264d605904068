"""Accuracy of a model against truth tracks, beside a loudness baseline (``facecast eval``).

Three kinds of truth:
  1. held-out synthetic utterances (espeak voices never used in training): the articulatory
     rules' own tracks -> eps (eq. 11), rho (eq. 12), Pearson r per parameter;
  2. real speech with phone alignments: the same rules applied to the real phone timings;
  3. real lips (GRID s1 held-out sentences and other talkers' clips, measured by ``facecast
     extract``): scored by :mod:`training.reallips` (per parameter r, best lag, nu, closures).

The **loudness baseline** predicts mouth opening from the frame's RMS level in dB on the
same 30 fps frame grid; any model must clearly beat it.

Estimates always come from the live streaming path (:func:`speech_to_params`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.features import loudness_db
from realtime_core.mapping import SpeechModel
from realtime_core.metrics import acc, amse, pearson_per_param
from realtime_core.pipeline import speech_to_params

MOUTH_OPEN = VISUAL_PARAMS.index("mouth_open")


def pearson(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson r of two ``(T,)`` tracks (0 if either is constant)."""
    return float(pearson_per_param(np.asarray(a)[:, None], np.asarray(b)[:, None])[0])


def best_lag(truth: np.ndarray, est: np.ndarray, max_lag: int = 3) -> tuple[int, float]:
    """Lag in frames (positive = estimate late) in ``[-max_lag, max_lag]`` maximising r."""
    best = (0, -2.0)
    for lag in range(-max_lag, max_lag + 1):
        if lag >= 0:
            r = pearson(truth[: len(truth) - lag], est[lag:])
        else:
            r = pearson(truth[-lag:], est[: len(est) + lag])
        if r > best[1]:
            best = (lag, r)
    return best


@dataclass(frozen=True)
class ClipScore:
    """One clip: Pearson r per parameter (lag 0), loudness-baseline r for mouth_open, the best
    lag of mouth_open and its r, frames compared."""

    name: str
    kind: str
    r: dict
    r_loudness: float
    lag: int
    r_at_lag: float
    n_frames: int


@dataclass(frozen=True)
class SetScore:
    """Pooled scores of a set of clips (eps/rho over all frames), with the clips."""

    kind: str
    eps: float
    rho: float
    r: dict
    r_loudness: float
    clips: list = field(default_factory=list)


def score_clip(
    model: SpeechModel, name: str, kind: str, samples: np.ndarray, rate_hz: int, truth: np.ndarray
) -> tuple[ClipScore, np.ndarray, np.ndarray]:
    """Run the live path on ``samples`` and compare with ``truth (n_frames, 4)``.

    Returns the score, the estimate ``(T, 4)`` and the loudness track ``(T,)`` dB."""
    est = speech_to_params(model, samples, rate_hz)
    T = min(len(est), len(truth))
    est, truth = est[:T], truth[:T]
    loud = loudness_db(samples, rate_hz, T)
    lag, r_lag = best_lag(truth[:, MOUTH_OPEN], est[:, MOUTH_OPEN])
    r = pearson_per_param(truth, est)
    return (
        ClipScore(
            name=name,
            kind=kind,
            r=dict(zip(VISUAL_PARAMS, map(float, r))),
            r_loudness=pearson(truth[:, MOUTH_OPEN], loud),
            lag=lag,
            r_at_lag=r_lag,
            n_frames=T,
        ),
        est,
        loud,
    )


def score_set(model: SpeechModel, kind: str, items: Sequence[tuple[str, np.ndarray, int, np.ndarray]]) -> SetScore:
    """``items``: (name, samples, rate_hz, truth (n_frames, 4)). Pools frames for eps/rho."""
    clips, truths, ests, louds = [], [], [], []
    for name, samples, rate, truth in items:
        clip, est, loud = score_clip(model, name, kind, samples, rate, truth)
        clips.append(clip)
        truths.append(truth[: len(est)])
        ests.append(est)
        louds.append(loud)
    t, e, lv = np.concatenate(truths), np.concatenate(ests), np.concatenate(louds)
    return SetScore(
        kind=kind,
        eps=amse(t, e),
        rho=acc(t, e),
        r=dict(zip(VISUAL_PARAMS, map(float, pearson_per_param(t, e)))),
        r_loudness=pearson(t[:, MOUTH_OPEN], lv),
        clips=clips,
    )


def real_speech_items(
    root: str | Path, *, lead_s: float | None = None
) -> list[tuple[str, np.ndarray, int, np.ndarray]]:
    """Real recordings with phone alignments under ``root``, truth from the articulatory rules."""
    from assets.audio import read_audio
    from training.alignments import find_aligned_audio
    from training.articulatory import ArticulatoryConfig, render_params
    from training.params import n_frames_for

    cfg = ArticulatoryConfig() if lead_s is None else ArticulatoryConfig(lead_s=lead_s)
    items = []
    for wav, align in find_aligned_audio(root):
        samples, rate = read_audio(wav)
        n = n_frames_for(len(samples) / rate)
        truth = render_params(align.phones, n, inventory=align.inventory, config=cfg)
        items.append((wav.stem, samples, rate, truth))
    return items


def format_markdown(results: Sequence[tuple[str, SetScore]], command: str) -> str:
    """The accuracy table for ``docs/accuracy.md``."""
    lines = [
        "# facecast accuracy",
        "",
        f"Produced by `{command}`.",
        "",
        "r = Pearson correlation with the truth track, lag 0; loudness = the frame's RMS level (dB) "
        "as a mouth_open predictor.",
        "",
    ]
    for title, s in results:
        lines += [
            f"## {title}",
            "",
            f"pooled over {sum(c.n_frames for c in s.clips)} frames: eps = {s.eps:.3f}, rho = {s.rho:.3f}; "
            f"r(mouth_open) = {s.r['mouth_open']:.3f} vs loudness {s.r_loudness:.3f}",
            "",
            "| clip | frames | "
            + " | ".join(f"r {p}" for p in VISUAL_PARAMS)
            + " | r loudness (mouth_open) | best lag (frames) | r at best lag |",
            "|---|---:|" + "---:|" * (len(VISUAL_PARAMS) + 3),
        ]
        for c in s.clips:
            lines.append(
                f"| {c.name} | {c.n_frames} | "
                + " | ".join(f"{c.r[p]:.3f}" for p in VISUAL_PARAMS)
                + f" | {c.r_loudness:.3f} | {c.lag:+d} | {c.r_at_lag:.3f} |"
            )
        mean_r = np.mean([c.r["mouth_open"] for c in s.clips])
        mean_l = np.mean([c.r_loudness for c in s.clips])
        lines += [
            "",
            f"mean over clips: r(mouth_open) = {mean_r:.3f}, loudness {mean_l:.3f}, margin {mean_r - mean_l:+.3f}",
            "",
        ]
    return "\n".join(lines) + "\n"


EVAL_VARIANTS: tuple[str, ...] = ("f5", "m7")
"""espeak voice variants kept out of the default model's training, for held-out evaluation."""
