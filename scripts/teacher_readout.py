"""Teacher labels for the readout, scored (issue 10, eleventh round; docs/default_model.md "Teacher labels").

    python scripts/teacher_readout.py labels --espeak N --festival N [--n-best K]   # synthesise + label, cached
    python scripts/teacher_readout.py score NAME ...    # shipped | R0 | C1 | C2 | C3: one JSON line each
    python scripts/teacher_readout.py score --model low-latency shipped FILE.npz   # on another shipped HMM

The shipped HMM is traced over the 716 train sentences plus the shipped recipe's 4 vocal-tract-length copies
(warps 0.85-1.18, seed 1) and, per candidate, the teacher clips (``training.teacher``: GRID-grammar
sentences spoken by espeak-ng and/or Festival voices, labelled with s1's lips by unit selection over the
train split). Each candidate is the shipped readout form (5:state:64x3:1e-3) with its band re-chosen on val
(>= 91.5 % of the 110 closures). Scored: s1 val; the four Praat voice-changed copies of val (pitch x1.4;
formants x1.15; formants x0.9; formants x1.18 with pitch x1.8) and P, their mean r(mouth_open); the real
speech of other voices with the rules truth (6 clips) and with the teacher truth (the ARPAbet-labelled 5:
unit-selection lips on their own phone timings, recorded pauses kept). Never the test split nor the
other-talker GRID clips. ``--model NAME`` (a shipped name or file; default: the default model) is the HMM
every refitted row is traced with and "shipped" is its readout as stored (the low-latency model's teacher
candidate was scored this way, its readout fitted by ``facecast readout``). A FILE.npz row is scored with its own
readout and band through its own HMM: the val, Praat and real-speech sets are traced again when its HMM is not
``--model``'s (issue 10's twelfth round: teacher clips in the HMM's training).
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from assets.modelfile import load_model
from assets.shared import shared_data_root
from realtime_core import VISUAL_PARAMS
from training.readout import ReadoutSpec, VtlpConfig, choose_band, estimates, fit_readout, trace_clips, vtlp_copies
from training.reallips import (
    LipScores,
    phone_bilabial_spans,
    real_speech_clips,
    s1_clips,
    score_lips,
    score_real_speech,
    track_to_utterance,
    voice_perturb,
)
from training.teacher import TeacherClip, espeak_clips, festival_clips, load_clips, save_clips, teacher_params

OUT = Path("/tmp/i10teach")
SHARED = shared_data_root()
BANDS = (0.02, 0.025, 0.03, 0.035, 0.04, 0.045, 0.05)
MIN_CLOSURE = 0.915
PRAAT = {"pitch1.4": (1.0, 1.4), "formants1.15": (1.15, 1.0), "formants0.9": (0.9, 1.0), "female": (1.18, 1.8)}
SPEC = ReadoutSpec(taps=5, posteriors="state", hidden=64, ensemble=3, alpha=1e-3)
CANDIDATES = {
    "R0": (),
    "C1": (("espeak", 1500),),
    "C2": (("festival", 1500),),
    "C3": (("espeak", 1500), ("festival", 1500)),
    # added after C1 was scored (val r(mouth_open) -0.008 with 50 min of teacher speech): a third of each
    "C4": (("espeak", 500), ("festival", 500)),
    # added after C1-C4 and R0 were scored: smaller teacher shares
    "C5": (("espeak", 500),),
    "C6": (("espeak", 250), ("festival", 250)),
}


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def synth():
    from training.teacher import train_synthesizer

    return train_synthesizer(SHARED / "video" / "grid_s1", say=log)


def labels(espeak_n: int, festival_n: int, n_best: int) -> None:
    from assets.progress import Progress

    s = synth()
    for engine, n, make, seed in (("espeak", espeak_n, espeak_clips, 0), ("festival", festival_n, festival_clips, 1)):
        if not n:
            continue
        t = time.time()
        clips = make(s, n, seed=seed, n_best=n_best, progress=Progress)
        save_clips(OUT / f"teacher_{engine}.npz", clips)
        log(
            f"{engine} {len(clips)} clips, {sum(len(c[1].params) for c in clips) / 1800:.1f} min, "
            f"{time.time() - t:.0f} s"
        )


def summary(s: LipScores) -> dict:
    return {
        "r": {p: round(float(s.r[p]), 4) for p in VISUAL_PARAMS},
        "closures": f"{round(s.closure_rate * s.n_closures)}/{s.n_closures}",
        "nu_mouth_open": round(float(s.nu["mouth_open"]), 3),
    }


def praat_sets(val_clips: list) -> dict:
    out = {}
    for name, (formant, pitch) in PRAAT.items():
        clips = []
        for sid, track, spans in val_clips:
            u = voice_perturb(track_to_utterance(track, utt_id=sid), formant_ratio=formant, pitch_ratio=pitch)
            clips.append((sid, TeacherClip(u.samples, u.sample_rate_hz, track.params), spans))
        out[name] = clips
    return out


def teacher_truth_speech(s, speech_root: Path) -> tuple[list, list]:
    """The ARPAbet-aligned real-speech clips with the teacher's lips on their own phone timings (recorded
    pauses kept: the speaker's breath is in the recording), and the names of those skipped."""
    from assets.audio import read_audio
    from training.alignments import find_aligned_audio
    from training.params import n_frames_for

    out, skipped = [], []
    for wav, align in find_aligned_audio(speech_root):
        if align.inventory != "arpabet":
            skipped.append(f"{wav.stem} ({align.inventory})")
            continue
        x, rate = read_audio(wav)
        x = np.asarray(x, np.float64)
        x = x.mean(axis=1) if x.ndim > 1 else x
        n = n_frames_for(len(x) / rate)
        phones = [(p.phoneme, p.start_s, p.end_s) for p in align.phones]
        truth = teacher_params(s, phones, "arpabet", n, n_best=5, rest_pauses=None)
        out.append((wav.stem, TeacherClip(x.astype(np.float32), rate, truth), phone_bilabial_spans(align.phones)))
    return out, skipped


def same_hmm(a, b) -> bool:
    """Whether two models share the HMM, front end and CMVN statistics (a readout refit leaves these)."""
    return (
        a.frontend == b.frontend
        and a.likelihood_scale == b.likelihood_scale
        and all(np.array_equal(x, y) for x, y in ((a.cmvn_mean, b.cmvn_mean), (a.cmvn_var, b.cmvn_var)))
        and all(
            np.array_equal(getattr(a.hmm, f), getattr(b.hmm, f))
            for f in ("startprob", "transmat", "weights", "means", "covars")
        )
    )


def score(names: list[str], model: str | None = None) -> None:
    t0 = time.time()
    shipped = load_model(model)
    s = synth()
    val_clips = s1_clips("val")
    praat_clips = praat_sets(val_clips)
    rules = real_speech_clips(SHARED / "speech")
    tclips, skipped = teacher_truth_speech(s, SHARED / "speech")
    log(f"teacher-truth real speech: {[c[0] for c in tclips]}, skipped {skipped}")

    def traced(m) -> tuple:
        """(HMM without readout, val, Praat sets, teacher-truth speech) traced through ``m``'s HMM."""
        b = replace(m, readout=None)
        out = (
            b,
            trace_clips(b, val_clips),
            {k: trace_clips(b, v) for k, v in praat_clips.items()},
            trace_clips(b, tclips),
        )
        log(f"val, Praat and real-speech sets traced ({time.time() - t0:.0f} s)")
        return out

    shipped_sets: list = []  # traced on first use: a run of FILE rows with their own HMMs never needs them
    train: list = []
    for name in names:
        row: dict = {"name": name}
        m = shipped
        if name.endswith(".npz"):
            while not Path(name).is_file():  # `facecast readout` may still be fitting it
                time.sleep(20)
            m = load_model(name)
        if same_hmm(m, shipped):
            shipped_sets[:] = shipped_sets or traced(shipped)
            base, val, praat, teach = shipped_sets
        else:  # its own HMM (teacher clips in Baum-Welch): its own traces
            base, val, praat, teach = traced(m)
            row["own_hmm"] = True
        if name == "shipped" or name.endswith(".npz"):  # a model file's own readout and band, as stored
            ro, band = m.readout, m.closure_band
            sv = score_lips(estimates(base, val, ro, band))
        else:
            if not train:
                clips = s1_clips("train")
                train = trace_clips(base, clips) + vtlp_copies(
                    base, clips, VtlpConfig(copies=4, warp_range=(0.85, 1.18), seed=1)
                )
                log(
                    f"train traced: {len(train)} clips, {sum(len(c.truth) for c in train)} frames "
                    f"({time.time() - t0:.0f} s)"
                )
            extra: list = []
            for kind, n in CANDIDATES[name]:
                while not (OUT / f"teacher_{kind}.npz").is_file():  # `labels` may still be writing it
                    time.sleep(20)
                extra += trace_clips(base, load_clips(OUT / f"teacher_{kind}.npz")[:n])
            fit = train + extra
            row["fit_frames"] = int(sum(len(c.truth) for c in fit))
            row["teacher_frames"] = int(sum(len(c.truth) for c in extra))
            ro = fit_readout(base, fit, SPEC)
            row["epochs"] = ro.metadata["epochs"]
            band, sv = choose_band(
                lambda b, ro=ro, base=base, val=val: score_lips(estimates(base, val, ro, b)),
                bands=BANDS,
                min_closure=MIN_CLOSURE,
            )
        ps = {k: score_lips(estimates(base, v, ro, band)) for k, v in praat.items()}
        rs = score_real_speech(replace(base, readout=ro, closure_band=band), rules)
        ts = score_lips(estimates(base, teach, ro, band))
        row.update(
            band=band,
            val=summary(sv),
            praat={
                k: [round(float(v.r["mouth_open"]), 4), f"{round(v.closure_rate * v.n_closures)}/{v.n_closures}"]
                for k, v in ps.items()
            },
            P=round(float(np.mean([v.r["mouth_open"] for v in ps.values()])), 4),
            real_speech_rules=summary(rs),
            real_speech_teacher=summary(ts),
            seconds=round(time.time() - t0),
        )
        if name in CANDIDATES:
            from assets.modelfile import save_model

            save_model(OUT / f"model_{name}.npz", replace(base, readout=ro, closure_band=band))
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    with threadpool_limits(1):
        if sys.argv[1] == "labels":
            import argparse

            a = argparse.ArgumentParser()
            a.add_argument("cmd")
            a.add_argument("--espeak", type=int, default=0)
            a.add_argument("--festival", type=int, default=0)
            a.add_argument("--n-best", type=int, default=5)
            args = a.parse_args()
            labels(args.espeak, args.festival, args.n_best)
        else:
            args_ = sys.argv[2:]
            model_ = None
            if args_[:1] == ["--model"]:
                model_, args_ = args_[1], args_[2:]
            score(args_, model_)
