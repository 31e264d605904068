"""The numbers of a perceptual test, from the answers in its database (no I/O here).

Intelligibility (seed 000 Sec. 6.2): for each participant, block, SNR and condition the score
``C = correct units / scored units`` (GRID: the letter and digit keywords are two units per sentence;
a syllable is one unit). Means over participants give C_A, C_N, C_S; the relative visual contribution
(eq. 13) is ``C_V = 1 - (C_N - C_S) / (1 - C_A)``, computed, as in the paper's Table 2, from the mean
scores, and also per participant (undefined where C_A = 1). Paired differences between conditions
over participants are tested with the Wilcoxon signed-rank test (scipy; two-sided). Confusion
matrices pool participants and SNRs per condition (rows: presented, columns: reported).

Emotion (seed 002 Tables V-VII): counts of reported emotion per shown expression. Opinion scores
(seed 001 Table 1): mean accuracy and naturalness per condition (or clip system) with a 95 %
Student-t confidence interval over the individual ratings.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np
from scipy import stats

from perceptual.design import (
    CONSONANTS,
    DIGITS,
    EMOTIONS,
    EXPRESSIONS,
    LETTERS,
    MOS_SCALES,
    SYLLABLES,
    snr_label,
)


def relative_visual_contribution(c_a: float, c_n: float, c_s: float) -> float | None:
    """Seed 000 eq. 13: ``1 - (C_N - C_S) / (1 - C_A)``; None when C_A = 1 (no room for the face)."""
    if c_a >= 1.0:
        return None
    return 1.0 - (c_n - c_s) / (1.0 - c_a)


def mean_ci95(x: list[float]) -> tuple[float, float, float]:
    """(mean, lower, upper) of a 95 % Student-t interval; the bounds equal the mean for n < 2 or no spread."""
    a = np.asarray(x, dtype=np.float64)
    m = float(a.mean())
    if len(a) < 2 or float(a.std(ddof=1)) == 0.0:
        return m, m, m
    lo, hi = stats.t.interval(0.95, len(a) - 1, loc=m, scale=stats.sem(a))
    return m, float(lo), float(hi)


def paired_test(x: list[float], y: list[float]) -> dict[str, Any]:
    """Wilcoxon signed-rank test of paired scores (two-sided); p None when it cannot be computed
    (fewer than two pairs, or every difference zero), with the reason."""
    d = np.asarray(x, dtype=np.float64) - np.asarray(y, dtype=np.float64)
    out: dict[str, Any] = {"n": len(d), "median_difference": float(np.median(d)) if len(d) else None}
    if len(d) < 2:
        return {**out, "statistic": None, "p": None, "note": "fewer than two participants"}
    if np.all(d == 0):
        return {**out, "statistic": None, "p": None, "note": "all differences are zero"}
    res = stats.wilcoxon(x, y, zero_method="wilcox", alternative="two-sided")
    return {**out, "statistic": float(res.statistic), "p": float(res.pvalue), "note": ""}


def _labels(kind: str, key: str) -> tuple[str, ...]:
    return {"letter": LETTERS, "digit": DIGITS, "syllable": SYLLABLES, "emotion": EMOTIONS}[key]


def analyse(answers: list[dict[str, Any]], blocks: list[dict[str, Any]], *, participants: list[str]) -> dict[str, Any]:
    """Everything the report shows, as plain JSON-able data. ``answers``: rows of the database's
    answers table (truth/response decoded); ``blocks``: the manifest's blocks; ``participants``: whose
    answers count (practice trials never do)."""
    keep = set(participants)
    rows = [a for a in answers if a["participant"] in keep and not a["practice"]]
    out: dict[str, Any] = {
        "participants": sorted(keep),
        "n_answers": len(rows),
        "intelligibility": {},
        "emotion": {},
        "mos": {},
        "timing": {},
    }
    for b in blocks:
        if b.get("practice"):
            continue
        mine = [a for a in rows if a["block"] == b["name"]]
        if b["kind"] in ("keywords", "syllable"):
            out["intelligibility"][b["name"]] = _intelligibility(b, mine, sorted(keep))
        elif b["kind"] == "emotion":
            out["emotion"][b["name"]] = _emotion(mine)
        elif b["kind"] == "mos":
            out["mos"][b["name"]] = _mos(b, mine)
    out["timing"] = _timing(rows)
    return out


def _intelligibility(block: dict[str, Any], rows: list[dict[str, Any]], people: list[str]) -> dict[str, Any]:
    conds = block["conditions"]
    snrs = [snr_label(s) for s in block["snrs_db"]]
    correct: dict = defaultdict(lambda: [0, 0])
    for a in rows:
        k = (a["participant"], snr_label(a["snr_db"]), a["condition"])
        correct[k][0] += a["correct"]
        correct[k][1] += a["scored"]
    per: dict[str, dict[str, dict[str, float]]] = {}
    for p in people:
        per[p] = {
            s: {c: correct[(p, s, c)][0] / correct[(p, s, c)][1] for c in conds if correct[(p, s, c)][1]} for s in snrs
        }
    means: dict[str, dict[str, float]] = {}
    cv: dict[str, dict[str, Any]] = {}
    tests: dict[str, dict[str, Any]] = {}
    synthetic = [c for c in conds if c.startswith("S")]
    for s in snrs:
        means[s] = {}
        for c in conds:
            vals = [per[p][s][c] for p in people if c in per[p][s]]
            if vals:
                means[s][c] = float(np.mean(vals))
        if "A" in means[s] and "N" in means[s]:
            cv[s] = {}
            for sc in synthetic:
                if sc not in means[s]:
                    continue
                each = [
                    relative_visual_contribution(per[p][s]["A"], per[p][s]["N"], per[p][s][sc])
                    for p in people
                    if all(c in per[p][s] for c in ("A", "N", sc))
                ]
                defined = [v for v in each if v is not None]
                cv[s][sc] = {
                    "from_means": relative_visual_contribution(means[s]["A"], means[s]["N"], means[s][sc]),
                    "per_participant": each,
                    "mean_of_participants": float(np.mean(defined)) if defined else None,
                }
        tests[s] = {}
        for i, c1 in enumerate(conds):
            for c2 in conds[i + 1 :]:
                pairs = [(per[p][s][c1], per[p][s][c2]) for p in people if c1 in per[p][s] and c2 in per[p][s]]
                tests[s][f"{c1} vs {c2}"] = paired_test([x for x, _ in pairs], [y for _, y in pairs])
    keys = ("letter", "digit") if block["kind"] == "keywords" else ("syllable",)
    confusion: dict[str, dict[str, list[list[int]]]] = {}
    for key in keys:
        labels = _labels(block["kind"], key)
        index = {v: i for i, v in enumerate(labels)}
        confusion[key] = {}
        for c in conds:
            m = np.zeros((len(labels), len(labels)), dtype=np.int64)
            for a in rows:
                if a["condition"] == c:
                    m[index[a["truth"][key]], index[a["response"][key]]] += 1
            confusion[key][c] = m.tolist()
    result: dict[str, Any] = {
        "kind": block["kind"],
        "conditions": conds,
        "snrs": snrs,
        "per_participant": per,
        "means": means,
        "c_v": cv,
        "tests": tests,
        "confusion": confusion,
    }
    if block["kind"] == "syllable":
        by_consonant: dict[str, dict[str, float | None]] = {}
        for c in conds:
            by_consonant[c] = {}
            for cons in CONSONANTS:
                hits = [a["correct"] for a in rows if a["condition"] == c and a["truth"]["syllable"][:-1] == cons]
                by_consonant[c][cons] = float(np.mean(hits)) if hits else None
        result["by_consonant"] = by_consonant
    return result


def _emotion(rows: list[dict[str, Any]]) -> dict[str, Any]:
    table = {e: {x: 0 for x in EXPRESSIONS} for e in EMOTIONS}
    for a in rows:
        table[a["response"]["emotion"]][a["condition"]] += 1
    n = {x: sum(table[e][x] for e in EMOTIONS) for x in EXPRESSIONS}
    hits = sum(a["correct"] for a in rows)
    return {"table": table, "shown": n, "accuracy": hits / len(rows) if rows else None}


def _mos(block: dict[str, Any], rows: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    systems = sorted({(a["item"].split("/")[0] if a["condition"] == "clip" else a["condition"]) for a in rows})
    for sysname in systems:
        mine = [a for a in rows if (a["item"].split("/")[0] if a["condition"] == "clip" else a["condition"]) == sysname]
        out[sysname] = {"n": len(mine)}
        for scale in MOS_SCALES:
            m, lo, hi = mean_ci95([a["response"][scale] for a in mine])
            out[sysname][scale] = {"mean": m, "ci95": [lo, hi]}
    return out


def _timing(rows: list[dict[str, Any]]) -> dict[str, Any]:
    def summary(v: list[float]) -> dict[str, float] | None:
        if not v:
            return None
        a = np.asarray(v)
        return {
            "n": len(a),
            "median": float(np.median(a)),
            "p95": float(np.percentile(a, 95)),
            "max": float(np.max(np.abs(a))),
        }

    lat = [a["latency_ms"] for a in rows if a["latency_ms"] is not None]
    av = [a["av_offset_ms"] for a in rows if a["av_offset_ms"] is not None]
    return {"click_to_start_ms": summary(lat), "av_offset_ms": summary(av)}
