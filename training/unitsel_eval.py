"""Objective evaluation of unit selection on real lips (seed 001 Sec. 4.1), beside the audio-driven
HMM and the articulatory rules.

Held-out GRID s1 sentences (the test split of :func:`assets.grid.split_of`; the unit corpus holds
only train + val) are synthesised from the phones of their text with the real phone timings (the
GRID phone boundaries: by default the talker-specific HMM labels, :data:`training.grid_phones.HMM_PATH`),
and compared with the lips measured on their video:

- **r** per mouth parameter, frames of all sentences pooled (the protocol of
  :func:`training.reallips.score_lips`, whole clips including pauses), and r(mouth_open) over the
  speech span only (first to last non-pause phone);
- the paper's **normalised lip height, width and protrusion errors**: each measure divided by its
  maximum over all evaluated frames (the real track's maximum for the real lips, the system's own
  for the system), then the mean absolute difference in percent. Height = distance of the outer
  upper- and lower-lip midpoints (MediaPipe 0 and 17), width = distance of the mouth corners (61,
  291), protrusion = distance of the upper-lip midpoint from a fixed point between the jaw roots
  (the neutral face's 234 and 454, beside the ears). Unit selection produces landmarks (PCA
  coefficients), so all three are measured on points. The HMM and the rules produce only the
  four parameters, so for them height = neutral height + mouth_open and width = neutral width +
  lip_stretch (the definitions of those parameters); protrusion has no parameter.

Baselines: the audio-driven HMM (a model file, default the shipped one) on the sentence's real
audio by the live path, and the articulatory rules (:func:`training.articulatory.render_params`)
on the same real phone timings.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from realtime_core import VISUAL_PARAMS
from realtime_core.synthesis.closure import CLOSED_IOD, bilabials_closed
from realtime_core.synthesis.corpus import StoredCorpus
from realtime_core.synthesis.recording import RecordingBlend
from realtime_core.synthesis.synthesizer import ENSEMBLE_GAIN, UnitSynthesizer
from training.facetrack import FaceTrack
from training.unit_corpus import PhoneRows, phone_rows

UPPER_MID, LOWER_MID, CORNER_R, CORNER_L, JAW_ROOT_R, JAW_ROOT_L = 0, 17, 61, 291, 234, 454
MEASURES = ("height", "width", "protrusion")
MOUTH_OPEN = VISUAL_PARAMS.index("mouth_open")
LIP_STRETCH = VISUAL_PARAMS.index("lip_stretch")


def lip_measures(points: Callable[[int], np.ndarray], reference: np.ndarray) -> np.ndarray:
    """(n, 3) lip height, width, protrusion (IOD) from ``points(index) -> (n, 3)`` landmark tracks
    and the protrusion reference point (3,)."""
    h = np.linalg.norm(points(UPPER_MID) - points(LOWER_MID), axis=1)
    w = np.linalg.norm(points(CORNER_R) - points(CORNER_L), axis=1)
    p = np.linalg.norm(points(UPPER_MID) - reference, axis=1)
    return np.stack([h, w, p], axis=1)


def real_measures(track: FaceTrack) -> np.ndarray:
    ref = 0.5 * (track.neutral[JAW_ROOT_R] + track.neutral[JAW_ROOT_L]).astype(np.float64)
    return lip_measures(lambda i: track.landmarks[:, i].astype(np.float64), ref)


def unit_measures(stored: StoredCorpus, coefficients: np.ndarray, track: FaceTrack) -> np.ndarray:
    """Measures of synthesised PCA coefficients (n, K) placed on the test clip's neutral face."""
    pos = {int(j): k for k, j in enumerate(stored.landmark_indices)}
    offsets = stored.landmark_offsets(coefficients)
    neutral = track.neutral.astype(np.float64)
    ref = 0.5 * (neutral[JAW_ROOT_R] + neutral[JAW_ROOT_L])
    return lip_measures(lambda i: neutral[i] + offsets[:, pos[i]], ref)


def param_measures(params: np.ndarray, track: FaceTrack) -> np.ndarray:
    """Height and width from the parameters on the clip's neutral face; protrusion NaN."""
    n = track.neutral.astype(np.float64)
    h0 = np.linalg.norm(n[UPPER_MID] - n[LOWER_MID])
    w0 = np.linalg.norm(n[CORNER_R] - n[CORNER_L])
    return np.stack([h0 + params[:, MOUTH_OPEN], w0 + params[:, LIP_STRETCH], np.full(len(params), np.nan)], axis=1)


@dataclass
class SystemScore:
    """Pooled scores of one system: r per parameter, r(mouth_open) over speech spans, normalised
    measure errors (%) and the per-sentence outputs kept for plots."""

    name: str
    params: list = field(default_factory=list)
    measures: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)

    def finish(self, truth_params: list, truth_measures: list, speech: list, targets: list) -> dict:
        tp, ep = np.concatenate(truth_params), np.concatenate(self.params)
        closed = np.concatenate([_closed(p, t) for p, t in zip(self.params, targets)])
        real = np.concatenate([_closed(p, t) for p, t in zip(truth_params, targets)])
        tm, em = np.concatenate(truth_measures), np.concatenate(self.measures)
        sp = np.concatenate(speech)
        r = {n: float(np.corrcoef(tp[:, j], ep[:, j])[0, 1]) for j, n in enumerate(VISUAL_PARAMS)}
        r_speech = float(np.corrcoef(tp[sp, MOUTH_OPEN], ep[sp, MOUTH_OPEN])[0, 1])
        err = {}
        for j, m in enumerate(MEASURES):
            if np.all(np.isnan(em[:, j])):
                err[m] = float("nan")
                continue
            err[m] = float(100 * np.mean(np.abs(em[:, j] / np.max(em[:, j]) - tm[:, j] / np.max(tm[:, j]))))
        return {
            "system": self.name,
            "r": r,
            "r_speech_mouth_open": r_speech,
            "error_pct": err,
            "bilabials": len(closed),
            "bilabials_closed_pct": float(100 * np.mean(closed)),
            "bilabials_closed_real_pct": float(100 * np.mean(real)),
            **self.extra,
        }


def _closed(params: np.ndarray, target) -> np.ndarray:
    """(n_pbm,) bool: the /p b m/ of a synthesis target whose mouth_open (params (n, 4)) closes."""
    return bilabials_closed(params[:, MOUTH_OPEN], target.visemes, target.starts_s, target.ends_s)


def evaluate(
    stored: StoredCorpus,
    tests: Sequence[tuple[str, FaceTrack, PhoneRows]],
    *,
    model=None,
    n_best: Sequence[int] = (1, 10),
    synthesizer: UnitSynthesizer | None = None,
    model_label: str = "shipped model",
    progress: Callable | None = None,
    leave_one_out: bool = False,
    recording: RecordingBlend | None = RecordingBlend(),
) -> tuple[list[dict], dict]:
    """Scores of unit selection (one row per ``n_best``), the HMM (``model``, skipped if None) and the
    rules on ``tests`` = [(sentence id, real face track, real ARPAbet phones)]. Returns (rows,
    curves) where curves holds the first test sentence's measures for the Fig. 8 plot.

    leave_one_out: the sentences are in the corpus (the val split): each is synthesised with its
    own recording excluded, so no unit of the sentence itself is used.

    recording: with a ``model``, also score **text + recording** (one row per ``n_best``): the unit
    selection output with the audio-driven model's output on the same real audio mixed in
    (:meth:`UnitSynthesizer.with_recording`); None = pure text rows only. These rows use the audio
    and are labelled so; the pure text rows never do."""
    import time

    from realtime_core.phones import PhonemeSegment
    from training.articulatory import render_params

    synth = synthesizer or UnitSynthesizer(stored.corpus, rest=stored.rest_frame())
    k = stored.corpus.n_coefficients
    systems = [
        SystemScore(f"unit selection, n_best={n}" + (f", range x{ENSEMBLE_GAIN:g}" if n > 1 else "")) for n in n_best
    ]
    rules = SystemScore("articulatory rules (same phones)")
    blend = recording if model is not None else None
    mixed = (
        [
            SystemScore(
                f"text + recording: n_best={n}, audio-driven model mixed in (lead {blend.lead:g} / speech "
                f"{blend.speech:g} / trail {blend.trail:g})"
            )
            for n in n_best
        ]
        if blend is not None
        else []
    )
    hmm = SystemScore(f"audio-driven HMM, {model_label} (real audio)") if model is not None else None
    truth_p, truth_m, speech, targets = [], [], [], []
    search_ms: dict[int, list[float]] = {n: [] for n in n_best}
    units: dict[int, list[int]] = {n: [] for n in n_best}
    curves: dict = {}
    wrap = progress or (lambda it, **_: it)
    for idx, (sid, track, rows) in enumerate(wrap(list(tests), desc="eval", unit="sentence")):
        rows = phone_rows(rows)
        n = track.n_frames
        t = np.arange(n) / 30.0
        spoken = [r for r in rows if r[0].lower() not in ("sil", "sp")]
        speech.append((t >= spoken[0][1]) & (t < spoken[-1][2]) if spoken else np.zeros(n, bool))
        truth_p.append(track.params)
        truth_m.append(real_measures(track))
        targets.append(synth.target(rows, "arpabet"))
        hp = None
        if hmm is not None:
            from realtime_core.pipeline import speech_to_params

            hp = np.asarray(speech_to_params(model, track.samples, track.sample_rate_hz))[:n]
            if len(hp) < n:
                hp = np.concatenate([hp, np.repeat(hp[-1:], n - len(hp), axis=0)])
            hmm.params.append(hp)
            hmm.measures.append(param_measures(hp, track))
        for j, (sys_, nb) in enumerate(zip(systems, n_best)):
            t0 = time.perf_counter()
            res = synth.synthesize(rows, "arpabet", n_frames=n, n_best=nb, exclude=(sid,) if leave_one_out else ())
            search_ms[nb].append(1000 * (time.perf_counter() - t0))
            units[nb].append(res.selection.n_units)
            sys_.params.append(res.frames[:, k:])
            sys_.measures.append(unit_measures(stored, res.frames[:, :k], track))
            if idx == 0:
                curves[sys_.name] = sys_.measures[-1]
            if blend is not None and hp is not None:
                both = synth.with_recording(res, hp, blend)
                mixed[j].params.append(both[:, k:])
                mixed[j].measures.append(unit_measures(stored, both[:, :k], track))
        segs = [PhonemeSegment(lab, a, b) for lab, a, b in rows]
        rp = render_params(segs, n, inventory="arpabet")
        rules.params.append(rp)
        rules.measures.append(param_measures(rp, track))
        if idx == 0:
            curves.update({"sentence": sid, "real": truth_m[-1]})
    rows_out = []
    for sys_, nb in zip(systems, n_best):
        sys_.extra = {
            "units_per_sentence": float(np.mean(units[nb])),
            "synth_ms_median": float(np.median(search_ms[nb])),
        }
        rows_out.append(sys_.finish(truth_p, truth_m, speech, targets))
    for other in (*mixed, hmm, rules):
        if other is not None:
            rows_out.append(other.finish(truth_p, truth_m, speech, targets))
    return rows_out, curves


def fig8(curves: dict, png: Path) -> Path:
    """Fig. 8 of the paper: lip width, height and protrusion of one held-out sentence, real vs synthesised
    (each normalised by its maximum over the sentence)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    real = curves["real"]
    t = np.arange(len(real)) / 30.0
    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for ax, j, title in zip(axes, (1, 0, 2), ("(a) lip width", "(b) lip height", "(c) lip protrusion")):
        ax.plot(t, real[:, j] / real[:, j].max(), "k-", lw=2, label="real lips (video)")
        for name, col in zip([k for k in curves if k.startswith("unit selection")], ("tab:red", "tab:blue")):
            m = curves[name][:, j]
            ax.plot(t, m / m.max(), color=col, lw=1.4, label=name)
        ax.set_title(title, fontsize=10)
        ax.set_ylabel("normalised")
    axes[0].legend(fontsize=8, loc="lower right")
    axes[-1].set_xlabel(f"time (s), GRID s1 sentence {curves['sentence']} (held out), text + real phone timings")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return png


def _pct(x: float) -> str:
    return "-" if np.isnan(x) else f"{x:.2f}"


def markdown(
    rows: Sequence[dict], *, n_sentences: int, corpus_meta: Mapping, command: str, figure: str, split: str = "test"
) -> str:
    """The docs/accuracy.md section (``split``: "test", or "val" for the leave-one-out run)."""
    which = (
        "held-out GRID s1 test sentences (never in the unit corpus)"
        if split == "test"
        else "GRID s1 val sentences, each with its own recording excluded from the unit corpus (leave-one-out)"
    )
    lines = [
        "## Unit selection (text -> visible speech, seed 001) on real lips",
        "",
        (
            f"`{command}`. {n_sentences} {which}; text from the "
            "sentence id, the real phone timings (GRID phone boundaries by the talker-specific HMM aligner, "
            "`facecast phones --method hmm`), lips measured on the video. Unit corpus: "
            f"{corpus_meta.get('n_sentences')} train+val sentences, {corpus_meta.get('n_phones')} phones, "
            f"{corpus_meta.get('n_components')} EM-PCA components ({100 * corpus_meta.get('explained', 0):.1f} % of "
            "the lower-face landmark variance). r: Pearson, frames of all sentences pooled, whole clips (as the "
            "real-lips scores); r speech: mouth_open over the speech spans only. Errors: the paper's normalised lip "
            "height / width / protrusion (each divided by its maximum, mean |difference|, %); for the HMM and the "
            "rules height and width come from mouth_open and lip_stretch on the clip's neutral face, protrusion has "
            "no parameter."
        ),
        "",
        (
            "| system | r upper_lip_raise | r lip_stretch | r mouth_open | r lip_corner_depress "
            "| r speech (mouth_open) | height err % | width err % | protrusion err % | units/sentence "
            "| synthesis ms (median) | /p b m/ closed % |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        e = r["error_pct"]
        cells = " | ".join(f"{r['r'][n]:.3f}" for n in VISUAL_PARAMS)
        errs = " | ".join(_pct(e[m]) for m in MEASURES)
        tail = f"{r['units_per_sentence']:.2f} | {r['synth_ms_median']:.0f}" if "units_per_sentence" in r else "- | -"
        lines.append(
            f"| {r['system']} | {cells} | {r['r_speech_mouth_open']:.3f} | {errs} | {tail} "
            f"| {r['bilabials_closed_pct']:.1f} |"
        )
    if rows:
        lines += [
            "",
            (
                f"/p b m/ closed: the share of the {rows[0]['bilabials']} target /p b m/ whose mouth_open comes to "
                f"<= {CLOSED_IOD:g} IOD inside the phone label (the real lips: "
                f"{rows[0]['bilabials_closed_real_pct']:.1f} %)."
            ),
        ]
    if any(r["system"].startswith("text + recording") for r in rows):
        lines += [
            "",
            (
                "Text + recording rows use the sentence's real audio beyond its phone timings: the audio-driven "
                "model's output on it mixed into the unit selection output with the weights shown, for the leading "
                "pause, speech and the trailing pause (`realtime_core.synthesis.recording`, `facecast say --audio`). "
                "The unit selection rows are text with timings only."
            ),
        ]
    lines += ["", f"![Fig. 8 style: lip width, height, protrusion]({figure})", ""]
    return "\n".join(lines)
