"""Plots of training reports: the paper's Fig. 7 (eps, rho over N and M) and Fig. 8 (tracks).

Uses matplotlib's Agg backend (no display needed); figures are written as PNG atomically.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from assets.files import atomic_write_bytes
from realtime_core import VISUAL_PARAMS


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


def plot_selection(rows: Sequence[dict], path: Path) -> Path:
    """Fig. 7: eps and rho against N, one line per M, full and diagonal side by side.

    ``rows``: dicts with keys n_states, n_mix, covariance_type, tc, eps, rho.
    """
    plt = _figure()
    covs = sorted({r["covariance_type"] for r in rows})
    fig, axes = plt.subplots(2, len(covs), figsize=(5.5 * len(covs), 7), squeeze=False)
    for ci, cov in enumerate(covs):
        sub = [r for r in rows if r["covariance_type"] == cov]
        for mi in sorted({r["n_mix"] for r in sub}):
            pts = sorted((r["n_states"], r["eps"], r["rho"]) for r in sub if r["n_mix"] == mi)
            n = [p[0] for p in pts]
            axes[0, ci].plot(n, [p[1] for p in pts], "o-", label=f"M={mi}")
            axes[1, ci].plot(n, [p[2] for p in pts], "o-", label=f"M={mi}")
        best = min(sub, key=lambda r: r["eps"])
        axes[0, ci].plot(best["n_states"], best["eps"], "o", ms=16, mfc="none", mec="k")
        best = max(sub, key=lambda r: r["rho"])
        axes[1, ci].plot(best["n_states"], best["rho"], "o", ms=16, mfc="none", mec="k")
        axes[0, ci].set_title(f"{cov} covariance: AMSE eps (eq. 11)")
        axes[1, ci].set_title(f"{cov} covariance: ACC rho (eq. 12)")
        for ax in axes[:, ci]:
            ax.set_xlabel("states N")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    fig.suptitle("Held-out accuracy over N and M (cf. paper Fig. 7)")
    fig.subplots_adjust(hspace=0.35)
    out = _save(fig, path)
    plt.close(fig)
    return out


def plot_tracks(tracks: Sequence[tuple[str, np.ndarray, np.ndarray]], path: Path, *, max_utts: int = 3) -> Path:
    """Fig. 8: true (dashed) and estimated (solid) parameters for a few held-out utterances."""
    plt = _figure()
    tracks = list(tracks)[:max_utts]
    truth = np.concatenate([t for _, t, _ in tracks])
    est = np.concatenate([e for _, _, e in tracks])
    t = np.arange(len(truth)) / 30.0
    fig, axes = plt.subplots(4, 1, figsize=(11, 8), sharex=True)
    for i, name in enumerate(VISUAL_PARAMS):
        axes[i].plot(t, truth[:, i], "--", color="0.35", label="true")
        axes[i].plot(t, est[:, i], "-", color="C0", label="estimated")
        axes[i].set_ylabel(f"{name}\n(IOD)", fontsize=8)
        axes[i].grid(alpha=0.3)
    pos = 0
    for uid, tt, _ in tracks:
        axes[0].axvline(pos / 30.0, color="0.8")
        axes[0].text(pos / 30.0, axes[0].get_ylim()[1], f" {uid}", fontsize=7, va="top")
        pos += len(tt)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle("True and estimated mouth parameters, held-out utterances (cf. paper Fig. 8)")
    out = _save(fig, path)
    plt.close(fig)
    return out


def carry_over_sections(new: str, old: str, *, skip: str | None = None) -> str:
    """``new`` markdown with every ``## `` section of ``old`` that ``new`` does not have (by title) appended in
    ``old``'s order: sections other commands write into the same file (``facecast eval --mu``, ``facecast units
    eval``) survive a regeneration. ``skip``: a marked block of ``old`` (e.g. the latency dial, spliced in
    separately) left out first."""
    if skip:
        old = old.replace(skip, "")
    titles = {line for line in new.splitlines() if line.startswith("## ")}
    kept = []
    for part in old.split("\n## ")[1:]:
        title = "## " + part.splitlines()[0]
        if title not in titles:
            kept.append("## " + part.rstrip("\n") + "\n")
    return new.rstrip("\n") + "\n\n" + "\n".join(kept) if kept else new
