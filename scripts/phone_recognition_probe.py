"""Do recognised phones serve other talkers better than the MFCC HMM? (issue 10, fourteenth round;
docs/unit_selection.md "Recognised phones for other voices")

    python scripts/phone_recognition_probe.py --out DIR [--data ROOT] [--sets val,real] [--lm-weights 1,2,3]
    python scripts/phone_recognition_probe.py --out DIR --sets other,test --lm-weights 2   # reported only

Per clip of each set: (c) the shipped default model's live path on the audio; (a) pocketsphinx's allphone
phones (``training.force_align.recognise_phones``, no transcript; one run per language-model weight) -> unit
selection over the shipped corpus (``--n-best`` sequences, s1 val leave-one-out); (b) (a) mixed with (c) by
region as ``facecast say --audio`` does (``UnitSynthesizer.with_recording``). Information rows: one sequence
instead of ``--n-best``, and the reference phones in place of the recognised ones (the other-talker clips'
from their GRID sentence force-aligned: the text + recording route).
Scored as the model card scores its sets (``training.reallips.score_lips``: r(mouth_open) at lag 0, frames
pooled, /p b m/ closures). Sets: ``val`` (s1 val, real lips), ``real`` (real speech of other voices, rules
truth), ``other`` (the other-talker GRID clips, real lips), ``test`` (s1 test). Writes ``DIR/probe.md`` (the
tables) and ``DIR/probe.json``; reads the data under ``--data`` only.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from assets.grid import Split, sentence_text
from assets.modelfile import load_model
from assets.progress import Progress
from assets.unitcorpus import find_unit_corpus, load_unit_corpus
from realtime_core.features import loudness_db
from realtime_core.pipeline import speech_to_params
from realtime_core.synthesis.synthesizer import UnitSynthesizer
from realtime_core.synthesis.visemes import viseme_of
from training.alignments import Alignment, find_aligned_audio
from training.force_align import force_align, recognise_phones
from training.grid_phones import HMM_PATH, read_grid_phones
from training.reallips import LipScores, other_talker_clips, real_speech_clips, s1_clips, score_lips

SETS = {
    "val": "s1 val (decision, real lips)",
    "real": "real speech of other voices (decision, rules truth)",
    "other": "other-talker GRID clips (reported only, real lips)",
    "test": "s1 test (reported only, real lips)",
}
VISEME_RATE_HZ = 100
"""Frame rate of the viseme agreement between recognised and reference phones (pocketsphinx's 10 ms frames)."""


@dataclass(frozen=True, kw_only=True)
class Clip:
    """One scored clip: ``samples`` (n,) float at ``rate`` Hz, ``truth`` (T, 4) mouth parameters at 30 fps (IOD),
    /p b m/ ``spans`` [(start_s, end_s, label)], ``reference`` phones (None where the set has none) and the corpus
    sentences to leave out (``exclude``: a s1 val sentence's own recording)."""

    name: str
    samples: np.ndarray
    rate: int
    truth: np.ndarray
    spans: list
    reference: Alignment | None
    exclude: tuple[str, ...] = ()


def _filmed(name: str, track, spans: list, reference: Alignment | None, exclude: tuple[str, ...] = ()) -> Clip:
    """A clip of a filmed talker from its face track (``training.video.FaceTrack``: audio and real lips)."""
    return Clip(
        name=name,
        samples=track.samples,
        rate=track.sample_rate_hz,
        truth=track.params,
        spans=spans,
        reference=reference,
        exclude=exclude,
    )


def load_set(name: str, data: Path) -> list[Clip]:
    if name in ("val", "test"):
        # closures on the shipped labels (the model card's 110 of val); the reference phones are the
        # talker-specific HMM labels the unit corpus and `facecast units eval` use
        labels = read_grid_phones(HMM_PATH)
        split: Split = "val" if name == "val" else "test"
        return [
            _filmed(sid, t, spans, labels.get(sid), exclude=(sid,) if name == "val" else ())
            for sid, t, spans in s1_clips(split, root=data / "video" / "grid_s1")
        ]
    if name == "real":
        refs = {wav.stem: al for wav, al in find_aligned_audio(data / "speech")}
        return [
            Clip(name=n, samples=x, rate=r, truth=truth, spans=spans, reference=refs[n])
            for n, x, r, truth, spans in real_speech_clips(data / "speech")
        ]
    if name == "other":
        # Their reference phones: the GRID sentence named by the clip's code (its last six letters) force-aligned
        # to the clip by pocketsphinx, as `facecast say TEXT --audio CLIP` does (text + recording).
        return [
            _filmed(n, t, spans, force_align(t.samples, t.sample_rate_hz, sentence_text(n[-6:]), source=n))
            for n, t, spans in other_talker_clips(data / "video" / "grid")
        ]
    raise ValueError(f"unknown set {name!r} (one of {', '.join(SETS)})")


def viseme_frames(alignment: Alignment, n: int) -> np.ndarray:
    """(n,) the viseme class of each 10 ms frame (pauses and unlabelled frames "sil")."""
    out = np.full(n, "sil", dtype=object)
    for p in alignment.phones:
        a, b = int(round(p.start_s * VISEME_RATE_HZ)), int(round(p.end_s * VISEME_RATE_HZ))
        out[a:b] = viseme_of(p.phoneme, alignment.inventory, default="sil") if p.phoneme else "sil"
    return out


def fit_length(x: np.ndarray, n: int) -> np.ndarray:
    """``x`` (m, D) cut or padded (last frame held) to n frames, as `facecast units eval` treats the HMM."""
    x = np.asarray(x)[:n]
    return np.concatenate([x, np.repeat(x[-1:], n - len(x), axis=0)]) if len(x) < n else x


def run_set(name: str, clips: list[Clip], model, stored, synth, lm_weights, n_best: int) -> dict:
    k = stored.corpus.n_coefficients
    items: dict[str, list] = {}
    agree: dict[str, list] = {}
    n_phones: dict[str, list] = {}

    def add(system: str, clip: Clip, est: np.ndarray, loud: np.ndarray) -> None:
        items.setdefault(system, []).append((clip.name, clip.truth, est, loud, clip.spans))

    def units(phones, clip: Clip, hp: np.ndarray, tag: str, loud: np.ndarray) -> None:
        n = len(clip.truth)
        for nb in sorted({1, n_best}):
            res = synth.synthesize(phones, "arpabet", n_frames=n, n_best=nb, exclude=clip.exclude)
            add(f"(a) {tag}, n_best {nb}", clip, res.frames[:, k:], loud)
            add(f"(b) {tag} + HMM blend, n_best {nb}", clip, synth.with_recording(res, hp)[:, k:], loud)

    for clip in Progress(clips, desc=name, unit="clip", file=sys.stderr):
        n = len(clip.truth)
        loud = loudness_db(clip.samples, clip.rate, n)
        hp = fit_length(speech_to_params(model, clip.samples, clip.rate), n)
        add("(c) HMM (shipped default, live path)", clip, hp, loud)
        n10 = int(np.ceil(len(clip.samples) / clip.rate * VISEME_RATE_HZ))
        for lw in lm_weights:
            rec = recognise_phones(clip.samples, clip.rate, lm_weight=lw, source=clip.name)
            tag = f"allphone lw {lw:g}"
            n_phones.setdefault(tag, []).append(sum(p.phoneme != "SIL" for p in rec.phones))
            if clip.reference is not None and clip.reference.inventory == "arpabet":
                ref = viseme_frames(clip.reference, n10)
                agree.setdefault(tag, []).append((viseme_frames(rec, n10) == ref).astype(float))
            units([(p.phoneme, p.start_s, p.end_s) for p in rec.phones], clip, hp, tag, loud)
        if clip.reference is not None and clip.reference.inventory == "arpabet":
            ref_phones = [(p.phoneme or "SIL", p.start_s, p.end_s) for p in clip.reference.phones]
            units(ref_phones, clip, hp, "reference phones", loud)
            n_phones.setdefault("reference phones", []).append(
                sum(viseme_of(p[0], "arpabet", default="sil") != "sil" for p in ref_phones)
            )
    scores = {system: score_lips(its) for system, its in items.items()}
    return {
        "set": name,
        "clips": len(clips),
        "scores": {s: v.as_json() for s, v in scores.items()},
        "viseme_agreement": {t: float(np.concatenate(v).mean()) for t, v in agree.items()},
        "phones_per_clip": {t: float(np.mean(v)) for t, v in n_phones.items()},
        "_scores": scores,
    }


def markdown(result: dict) -> str:
    scores: dict[str, LipScores] = result["_scores"]
    per_clip = result["set"] in ("other", "real")
    head = "| system | r(mouth_open) | closures | nu(mouth_open) | r best lag |"
    if per_clip:
        head += " per clip r(mouth_open) |"
    lines = [f"### {SETS[result['set']]}: {result['clips']} clips", "", head, "|---" * (head.count("|") - 1) + "|"]
    for system, s in scores.items():
        hits = round(s.closure_rate * s.n_closures) if s.n_closures else 0
        label = system if len(s.per_clip) == result["clips"] else f"{system} ({len(s.per_clip)} clips)"
        row = (
            f"| {label} | {s.r['mouth_open']:.3f} | {hits} of {s.n_closures} | {s.nu['mouth_open']:.2f} | "
            f"{s.r_best['mouth_open']:.3f} ({s.best_lag['mouth_open']:+d}) |"
        )
        if per_clip:
            row += " " + " / ".join(f"{v['r_mouth_open']:.3f}" for v in s.per_clip.values()) + " |"
        lines.append(row)
    if per_clip:
        lines.append("")
        lines.append("Clips: " + ", ".join(next(iter(scores.values())).per_clip))
    if result["viseme_agreement"]:
        lines.append("")
        lines.append(
            "Frames whose recognised viseme agrees with the reference phones' (10 ms): "
            + ", ".join(f"{t} {v:.2f}" for t, v in result["viseme_agreement"].items())
        )
    lines.append("")
    lines.append("Spoken phones per clip: " + ", ".join(f"{t} {v:.1f}" for t, v in result["phones_per_clip"].items()))
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--out", type=Path, required=True, help="folder for probe.md and probe.json (created)")
    ap.add_argument("--data", type=Path, default=Path("/work/shared/data"), help="the shared data root")
    ap.add_argument("--sets", default="val,real", help=f"comma-separated, of {', '.join(SETS)}")
    ap.add_argument("--lm-weights", default="1,2,3", help="allphone language-model weights, comma-separated")
    ap.add_argument("--n-best", type=int, default=10, help="unit sequences averaged (one is also reported)")
    ap.add_argument("--limit", type=int, default=0, help="only the first N clips of each set (a smoke test)")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    lm_weights = [float(w) for w in args.lm_weights.split(",")]
    unknown = [s for s in args.sets.split(",") if s not in SETS]
    if unknown:
        ap.error(f"unknown set(s) {unknown} (of {', '.join(SETS)})")
    t0 = time.time()
    model = load_model(None)
    stored = load_unit_corpus(find_unit_corpus(None))
    out_md = [f"Command: `python scripts/phone_recognition_probe.py {' '.join(sys.argv[1:])}`\n"]
    out_json = []
    with threadpool_limits(1):
        synth = UnitSynthesizer(stored.corpus, rest=stored.rest_frame())
        for name in args.sets.split(","):
            clips = load_set(name, args.data)[: args.limit or None]
            print(f"{name}: {len(clips)} clips ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
            res = run_set(name, clips, model, stored, synth, lm_weights, args.n_best)
            md = markdown(res)
            print(md, flush=True)
            out_md.append(md)
            out_json.append({k: v for k, v in res.items() if not k.startswith("_")})
            (args.out / "probe.md").write_text("\n".join(out_md), encoding="utf-8")
            (args.out / "probe.json").write_text(json.dumps(out_json, indent=1), encoding="utf-8")
    print(f"done in {time.time() - t0:.0f} s; wrote {args.out / 'probe.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
