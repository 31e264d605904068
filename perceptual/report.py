"""``facecast perceptual report DB``: a Markdown report with plots and a ``results.json``.

Reads the database alone (it holds a copy of the stimulus manifest). Plots are matplotlib PNGs:
notched boxplots of C_A (grey), C_S (solid black), C_N (dashed black) per SNR in the style of
seed 000 Fig. 11 (box: quartiles; line: median; circle: mean; notches: a 95 % interval of the median,
so non-overlapping notches suggest different medians at the 5 % level), confusion matrices, and the
per-consonant recognition rates of Fig. 12.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from perceptual.analysis import analyse
from perceptual.design import CONSONANTS, DIGITS, EMOTIONS, EXPRESSIONS, LETTERS, SYLLABLES
from perceptual.errors import StoreError
from perceptual.store import Store

_STYLE = {
    "A": {"facecolor": "0.75", "linestyle": "-"},
    "S": {"facecolor": "white", "linestyle": "-"},
    "Sn": {"facecolor": "white", "linestyle": "-."},
    "N": {"facecolor": "white", "linestyle": "--"},
}


def write_report(db: str | Path, out_dir: str | Path, *, include_incomplete: bool = False) -> Path:
    """Analyse ``db`` into ``out_dir`` (report.md, results.json, PNGs); returns the Markdown path."""
    store = Store.open_existing(db)
    try:
        manifest = store.manifest()
        people = [p for p in store.participants() if include_incomplete or p.completed_utc is not None]
        answers = store.answers()
        events = store.events()
    finally:
        store.close()
    if not manifest.get("blocks"):
        raise StoreError(f"{db}: the database holds no stimulus manifest")
    if not people:
        raise StoreError(
            f"{db}: no participant has finished the test yet (use --include-incomplete to analyse partial sessions)"
        )
    res = analyse(answers, manifest["blocks"], participants=[p.id for p in people])
    res["test_id"] = manifest["test_id"]
    res["database"] = str(db)
    res["events"] = {
        k: sum(1 for e in events if e["kind"] == k) for k in ("duplicate", "conflict", "id_reused", "reload", "pause")
    }
    from assets.files import atomic_write_bytes, check_writable_folder

    out = check_writable_folder(out_dir)  # one line naming it (a FileNotFoundError traceback in /proc)

    atomic_write_bytes(out / "results.json", (json.dumps(res, indent=1) + "\n").encode())
    md = _markdown(res, out)
    path = out / "report.md"
    atomic_write_bytes(path, md.encode("utf-8"))
    return path


def _fmt(v: float | None, spec: str = ".3f") -> str:
    return "n/a" if v is None else format(v, spec)


def _p(v: float | None) -> str:
    if v is None:
        return "n/a"
    return "< 0.0001" if v < 1e-4 else f"{v:.4f}"


def _markdown(res: dict[str, Any], out: Path) -> str:
    lines = [
        f"# Perceptual test {res['test_id']}",
        "",
        (
            f"Database `{res['database']}`: {len(res['participants'])} participants, {res['n_answers']} scored "
            f"answers (practice excluded). Events: {res['events']}."
        ),
        "",
    ]
    for name, r in res["intelligibility"].items():
        lines += [
            f"## Intelligibility: block `{name}` "
            f"({'GRID letter+digit keywords' if r['kind'] == 'keywords' else 'CV syllables'})",
            "",
        ]
        conds = r["conditions"]
        head = "| SNR (dB) | " + " | ".join(f"C_{c}" for c in conds)
        syn = [c for c in conds if c.startswith("S")]
        cv_cols = [f"C_V({c}) eq. 13" for c in syn] if "N" in conds else []
        lines += [head + "".join(f" | {c}" for c in cv_cols) + " |", "|" + "---|" * (1 + len(conds) + len(cv_cols))]
        for s in r["snrs"]:
            row = f"| {s} | " + " | ".join(_fmt(r["means"][s].get(c)) for c in conds)
            for c in syn if cv_cols else []:
                row += f" | {_fmt(r['c_v'].get(s, {}).get(c, {}).get('from_means'))}"
            lines.append(row + " |")
        lines += [
            "",
            (
                "Means over participants; C_V from the mean scores as in seed 000 Table 2 "
                "(the mean of per-participant C_V is in results.json)."
            ),
            "",
        ]
        lines += [
            "Per participant:",
            "",
            "| participant | SNR | " + " | ".join(f"C_{c}" for c in conds) + " |",
            "|" + "---|" * (2 + len(conds)),
        ]
        for p, per in r["per_participant"].items():
            for s in r["snrs"]:
                lines.append(f"| {p} | {s} | " + " | ".join(_fmt(per[s].get(c)) for c in conds) + " |")
        lines += [
            "",
            "Paired Wilcoxon signed-rank tests over participants (two-sided):",
            "",
            "| SNR | pair | n | median difference | p |",
            "|---|---|---|---|---|",
        ]
        for s, tests in r["tests"].items():
            for pair, t in tests.items():
                lines.append(
                    f"| {s} | {pair} | {t['n']} | {_fmt(t['median_difference'])} | {_p(t['p'])}"
                    f"{' (' + t['note'] + ')' if t['note'] else ''} |"
                )
        box = _boxplot(name, r, out)
        lines += ["", f"![{name} boxplots]({box.name})", ""]
        for key, mats in r["confusion"].items():
            png = _confusions(name, key, mats, out)
            lines += [f"![{name} {key} confusions]({png.name})", ""]
        if "by_consonant" in r:
            png = _by_consonant(name, r["by_consonant"], out)
            lines += [f"![{name} by consonant]({png.name})", ""]
    for name, e in res["emotion"].items():
        lines += [
            f"## Emotion perception: block `{name}`",
            "",
            "Counts of the reported emotion (rows) per shown expression (columns), as seed 002 Tables V-VII.",
            "",
            "| reported | " + " | ".join(EXPRESSIONS) + " |",
            "|" + "---|" * (1 + len(EXPRESSIONS)),
        ]
        for em in EMOTIONS:
            lines.append(f"| {em} | " + " | ".join(str(e["table"][em][x]) for x in EXPRESSIONS) + " |")
        lines += ["", f"Agreement with the intended emotion: {_fmt(e['accuracy'])}.", ""]
    for name, m in res["mos"].items():
        lines += [
            f"## Opinion scores: block `{name}`",
            "",
            (
                "Five-point scale (1 bad ... 5 excellent), mean and 95 % "
                "confidence interval over ratings, as seed 001 Table 1."
            ),
            "",
            "| system | n | accuracy | naturalness |",
            "|---|---|---|---|",
        ]
        for sysname, v in m.items():
            cells = [
                f"{v[s]['mean']:.2f} [{v[s]['ci95'][0]:.2f}, {v[s]['ci95'][1]:.2f}]"
                for s in ("accuracy", "naturalness")
            ]
            lines.append(f"| {sysname} | {v['n']} | {cells[0]} | {cells[1]} |")
        lines.append("")
    t = res["timing"]
    lines += ["## Presentation timing (measured in the participants' browsers)", ""]
    for key, label in (("click_to_start_ms", "click to stimulus start"), ("av_offset_ms", "audio/video offset")):
        v = t.get(key)
        lines.append(
            f"- {label}: "
            + (
                "not measured"
                if not v
                else f"median {v['median']:.1f} ms, 95th percentile {v['p95']:.1f} ms, "
                f"largest magnitude {v['max']:.1f} ms over {v['n']} trials"
            )
        )
    lines.append("")
    return "\n".join(lines)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _boxplot(name: str, r: dict[str, Any], out: Path) -> Path:
    plt = _plt()
    conds = [c for c in ("A", "S", "Sn", "N") if c in r["conditions"]]
    fig, ax = plt.subplots(figsize=(2.2 + 1.6 * len(r["snrs"]), 4.0))
    ticks, labels = [], []
    width = 0.8 / len(conds)
    for i, s in enumerate(r["snrs"]):
        for j, c in enumerate(conds):
            vals = [per[s][c] for per in r["per_participant"].values() if c in per[s]]
            if not vals:
                continue
            pos = i + (j - (len(conds) - 1) / 2) * width
            st = _STYLE[c]
            ax.boxplot(
                [vals],
                positions=[pos],
                widths=width * 0.8,
                notch=len(vals) > 1,
                showmeans=True,
                patch_artist=True,
                meanprops={"marker": "o", "markerfacecolor": "none", "markeredgecolor": "k"},
                boxprops={"facecolor": st["facecolor"], "linestyle": st["linestyle"], "edgecolor": "k"},
                whiskerprops={"linestyle": st["linestyle"]},
                medianprops={"color": "k"},
            )
        ticks.append(i)
        labels.append(f"{s} dB")
    ax.set_xticks(ticks, labels)
    ax.set_xlim(-0.6, len(r["snrs"]) - 0.4)
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel("intelligibility score C")
    ax.set_title(f"{name}: " + ", ".join(f"C_{c}" for c in conds) + " (left to right)")
    from matplotlib.patches import Patch

    ax.legend(
        handles=[
            Patch(
                facecolor=_STYLE[c]["facecolor"],
                edgecolor="k",
                linestyle=_STYLE[c]["linestyle"],  # type: ignore[arg-type]  # str from a style table
                label=f"C_{c}",
            )
            for c in conds
        ],
        loc="lower left",
        fontsize=8,
    )
    fig.tight_layout()
    path = out / f"{name}_boxplots.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _confusions(name: str, key: str, mats: dict[str, list[list[int]]], out: Path) -> Path:
    plt = _plt()
    labels = {"letter": LETTERS, "digit": DIGITS, "syllable": SYLLABLES}[key]
    conds = list(mats)
    size = 3.2 if len(labels) <= 10 else 5.2
    fig, axes = plt.subplots(1, len(conds), figsize=(size * len(conds), size + 0.4), squeeze=False)
    for ax, c in zip(axes[0], conds):
        m = np.asarray(mats[c], dtype=np.float64)
        rows = m.sum(1, keepdims=True)
        frac = np.divide(m, rows, out=np.zeros_like(m), where=rows > 0)
        ax.imshow(frac, cmap="Greys", vmin=0, vmax=1)
        ax.set_xticks(range(len(labels)), labels, fontsize=6, rotation=90)
        ax.set_yticks(range(len(labels)), labels, fontsize=6)
        ax.set_xlabel("reported")
        ax.set_ylabel("presented")
        ax.set_title(f"{key}: {c} (n={int(m.sum())})", fontsize=9)
    fig.tight_layout()
    path = out / f"{name}_{key}_confusions.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _by_consonant(name: str, by: dict[str, dict[str, float | None]], out: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.4))
    conds = list(by)
    w = 0.8 / len(conds)
    for j, c in enumerate(conds):
        vals = [np.nan if by[c][k] is None else by[c][k] for k in CONSONANTS]
        ax.bar(
            np.arange(len(CONSONANTS)) + (j - (len(conds) - 1) / 2) * w,
            vals,
            w,
            color=_STYLE.get(c, {"facecolor": "0.5"})["facecolor"],
            edgecolor="k",
            label=f"C_{c}",
        )
    ax.set_xticks(range(len(CONSONANTS)), [f"/{k}/" for k in CONSONANTS])
    ax.set_ylim(0, 1)
    ax.set_ylabel("recognition rate")
    ax.set_title(f"{name}: syllables by initial consonant (pooled over vowels, participants, SNRs)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / f"{name}_by_consonant.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
