"""The latency dial: accuracy against algorithmic delay over models and smoothing lags.

Each point is one model (its t_c and analysis window, fixed at training) run by the live path with a
fixed-lag smoothing ``lag`` (chosen at run time), scored on real lips with
:func:`training.reallips.evaluate_lips`, at the delay of the one formula
(:meth:`realtime_core.features.FrontEndConfig.algorithmic_delay_ms`). ``facecast eval --dial`` writes
the table and the plot into ``docs/accuracy.md`` as a marked section that a plain ``facecast eval
--output`` keeps (:func:`splice_dial_section`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from pathlib import Path

from realtime_core import VISUAL_PARAMS
from realtime_core.avmodel import AvModel
from training.reallips import LipScores, evaluate_lips

DIAL_BEGIN = "<!-- latency-dial: written by `facecast eval --dial`, kept by `facecast eval --output` -->"
DIAL_END = "<!-- /latency-dial -->"


@dataclass(frozen=True)
class DialPoint:
    """One setting of the dial: ``name`` (how the model was given), its t_c and window (hops), the
    smoothing lag (frames), the algorithmic delay (ms) and the lip scores."""

    name: str
    tc: int
    window_hops: float
    lag: int
    delay_ms: float
    scores: LipScores
    likelihood_scale: float = 0.2

    def as_json(self) -> dict:
        return {
            "name": self.name,
            "tc": self.tc,
            "window_hops": self.window_hops,
            "lag": self.lag,
            "delay_ms": round(self.delay_ms, 2),
            "likelihood_scale": self.likelihood_scale,
            "scores": self.scores.as_json(),
        }


MIN_CLOSURE_RATE = 0.9
"""Issue 10's closure goal: with ``likelihood_scales``, a kappa is only chosen if it keeps this share."""


def score_dial(
    models: Sequence[tuple[str, AvModel]],
    clips: Sequence,
    *,
    lags: Sequence[int] = (0,),
    likelihood_scales: Sequence[float] | None = None,
    keep_own: Collection[str] = (),
    progress: Callable | None = None,
) -> list[DialPoint]:
    """``models``: [(name, AvModel)]; ``clips``: [(name, FaceTrack, bilabial spans)] (e.g.
    :func:`training.reallips.s1_clips`). Every model at every lag -> points sorted by delay.

    ``likelihood_scales``: also choose each model's audio-likelihood exponent kappa per lag on these
    clips: the kappa with the highest r(mouth_open) among those reaching :data:`MIN_CLOSURE_RATE` of the
    closures (the highest r when none does). The right kappa depends on the context size (2 t_c + 1
    stacked frames make the likelihoods over-confident by about that factor), so comparing settings at
    one kappa would favour the setting it was tuned for. None: the kappa stored in each model, as for
    the models named in ``keep_own`` (the shipped ones, scored as they ship).
    """
    from dataclasses import replace

    jobs = [(name, m, lag) for name, m in models for lag in lags]
    points = []
    for name, m, lag in progress(jobs, desc="dial", unit="setting") if progress else jobs:
        tried = []
        for kappa in likelihood_scales if likelihood_scales and name not in keep_own else (m.likelihood_scale,):
            scores, _ = evaluate_lips(replace(m, likelihood_scale=kappa), clips, lag=lag)
            tried.append((scores.closure_rate >= MIN_CLOSURE_RATE, scores.r["mouth_open"], kappa, scores))
        _, _, kappa, scores = max(tried, key=lambda x: x[:2])
        points.append(
            DialPoint(
                name=name,
                tc=m.frontend.tc,
                window_hops=float(m.frontend.mfcc.window_hops),
                lag=lag,
                delay_ms=m.algorithmic_delay_ms(lag),
                scores=scores,
                likelihood_scale=kappa,
            )
        )
    return sorted(points, key=lambda p: (p.delay_ms, p.lag))


def dial_markdown(points: Sequence[DialPoint], *, split: str, png_name: str | None = None, note: str = "") -> str:
    """The marked section: a table per point (delay, settings, r per parameter, closures, nu) and the plot."""
    short = {"upper_lip_raise": "ulr", "lip_stretch": "ls", "mouth_open": "mo", "lip_corner_depress": "lcd"}
    lines = [DIAL_BEGIN, f"## Latency dial: accuracy against algorithmic delay (GRID s1 {split} split)", ""]
    if note:
        lines += [note, ""]
    lines += [
        (
            "delay = (t_c + lag) / 30 s + window (`FrontEndConfig.algorithmic_delay_ms`); kappa = the audio-"
            "likelihood exponent of the live path; r at lag 0 against the measured lips; closures = share of "
            "/p b m/ phones where mouth_open reaches the closed pose; nu = std(est) / std(true) for mouth_open."
        ),
        "",
        "| model | t_c | window (hops) | lag | delay (ms) | kappa | "
        + " | ".join(f"r {short[p]}" for p in VISUAL_PARAMS)
        + " | closures | nu mo |",
        "|---|---:|---:|---:|---:|---:|" + "---:|" * len(VISUAL_PARAMS) + "---:|---:|",
    ]
    for p in points:
        s = p.scores
        lines.append(
            f"| {p.name} | {p.tc} | {p.window_hops:g} | {p.lag} | {p.delay_ms:.1f} | {p.likelihood_scale:g} | "
            + " | ".join(f"{s.r[q]:.3f}" for q in VISUAL_PARAMS)
            + f" | {s.closure_rate:.0%} of {s.n_closures} | {s.nu['mouth_open']:.2f} |"
        )
    if png_name:
        lines += ["", f"![latency dial]({png_name})"]
    return "\n".join([*lines, DIAL_END]) + "\n"


def splice_dial_section(doc: str, section: str | None) -> str:
    """``doc`` with its marked dial section replaced by ``section`` (appended when it has none;
    ``section`` None keeps ``doc`` as it is)."""
    if section is None:
        return doc
    pattern = re.compile(re.escape(DIAL_BEGIN) + r".*?" + re.escape(DIAL_END) + r"\n?", re.DOTALL)
    if pattern.search(doc):
        return pattern.sub(lambda _: section, doc, count=1)
    return doc.rstrip("\n") + "\n\n" + section


def existing_dial_section(doc: str) -> str | None:
    """The marked dial section of ``doc`` (to carry over into a regenerated file), or None."""
    m = re.search(re.escape(DIAL_BEGIN) + r".*?" + re.escape(DIAL_END) + r"\n?", doc, re.DOTALL)
    return m.group(0) if m else None


def plot_dial(
    points: Sequence[DialPoint], png: Path, *, title: str, shipped: Collection[str] = ("default", "low-latency")
) -> Path:
    """PNG, two panels against the algorithmic delay: r per parameter (mouth_open labelled with
    t_c / window / lag, its best-so-far frontier as a step line, shipped models ringed) and the
    share of closures reached (with the 90 % goal)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, gridspec_kw={"height_ratios": [2.2, 1]})
    xs = [p.delay_ms for p in points]
    mo = [p.scores.r["mouth_open"] for p in points]
    for name, marker, color in (
        ("lip_stretch", "s", "tab:green"),
        ("upper_lip_raise", "^", "tab:purple"),
        ("lip_corner_depress", "v", "tab:brown"),
    ):
        ax.plot(xs, [p.scores.r[name] for p in points], marker, color=color, ms=4, alpha=0.7, label=f"r({name})")
    ax.plot(xs, mo, "o", color="tab:red", label="r(mouth_open)")
    best, frontier = -1.0, []
    for x, r in sorted(zip(xs, mo)):
        best = max(best, r)
        frontier.append((x, best))
    ax.step(*zip(*frontier), where="post", color="tab:red", lw=0.8, alpha=0.6)
    for p in points:
        ring = p.name in shipped and p.lag == 0
        if ring:
            ax.plot(p.delay_ms, p.scores.r["mouth_open"], "o", mfc="none", mec="black", ms=11)
        ax.annotate(
            f"{p.tc}/{p.window_hops:g}/{p.lag}" + (f" {p.name}" if ring else ""),
            (p.delay_ms, p.scores.r["mouth_open"]),
            textcoords="offset points",
            xytext=(4, -10 if p.lag else 4),
            fontsize=7,
            fontweight="bold" if ring else "normal",
        )
    for a in (ax, bx):
        a.axvline(80, color="grey", ls=":", lw=1)
    ax.set_ylabel("r against measured lips (lag 0)")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(title + " (labels: t_c / window hops / smoothing lag; ringed: shipped)", fontsize=9)
    bx.plot(xs, [100 * p.scores.closure_rate for p in points], "x", color="tab:blue")
    bx.axhline(90, color="tab:blue", ls="--", lw=0.8)
    bx.text(xs[0] if xs else 0, 90.5, "goal 90 %", fontsize=7, color="tab:blue", va="bottom")
    bx.set_ylabel("/p b m/ closures (%)")
    bx.set_xlabel("algorithmic delay (ms); dotted: 80 ms")
    bx.set_ylim(min([80.0] + [100 * p.scores.closure_rate - 3 for p in points if p.scores.n_closures]), 101)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return png
