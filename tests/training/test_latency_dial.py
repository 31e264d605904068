"""The latency-dial section of docs/accuracy.md: replaced by `facecast eval --dial`, kept by a plain
`facecast eval --output`, and rendered from real scores."""

from __future__ import annotations

import numpy as np

from training.latency import (
    DIAL_BEGIN,
    DIAL_END,
    DialPoint,
    dial_markdown,
    existing_dial_section,
    plot_dial,
    splice_dial_section,
)
from training.reallips import score_lips


def _point(tc: float, delay: float, seed: int) -> DialPoint:
    rng = np.random.default_rng(seed)
    truth = np.abs(rng.standard_normal((90, 4))) * 0.1
    est = truth + rng.standard_normal((90, 4)) * 0.05
    scores = score_lips([("clip", truth, est, rng.standard_normal(90), [(0.5, 0.6, "b")])])
    return DialPoint(name=f"m{seed}", tc=tc, window_hops=2.0, lag=0, delay_ms=delay, scores=scores)


def test_section_is_replaced_in_place_and_carried_over(tmp_path):
    points = [_point(1, 78.3, 0), _point(3, 166.7, 1)]
    section = dial_markdown(points, split="val", png_name="accuracy_latency_dial.png")
    assert section.startswith(DIAL_BEGIN) and section.rstrip().endswith(DIAL_END)
    assert f"| m0 | 1 | 2 | 0 | 78.3 | 0.2 | {points[0].scores.r['upper_lip_raise']:.3f} |" in section
    doc = "# Accuracy\n\n## 1. s1\n\ntext\n"
    once = splice_dial_section(doc, section)
    assert once.startswith(doc.rstrip("\n")) and once.count(DIAL_BEGIN) == 1
    newer = dial_markdown(points[:1], split="val")
    twice = splice_dial_section(once, newer)
    assert twice.count(DIAL_BEGIN) == 1 and "166.7" not in twice and twice.startswith(doc.rstrip("\n"))
    # A regenerated accuracy.md keeps the section of the file it replaces.
    assert splice_dial_section("# new\n", existing_dial_section(twice)).endswith(newer)
    assert existing_dial_section(doc) is None and splice_dial_section(doc, None) == doc
    png = plot_dial(points, tmp_path / "dial.png", title="test")
    assert png.stat().st_size > 1000
