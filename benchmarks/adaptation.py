"""Speaker adaptation on real faces: r(mouth_open) against MediaPipe lips before and after
``facecast adapt`` (MAP of the audio side), beside the loudness baseline.

Two measurements (``facecast bench adapt``):

1. **Other GRID talkers** (``../shared/data/video/grid``, every clip except s1's ``bbaf2n``):
   one 3 s clip per talker, so enrolment is on that clip's own audio, in two ways:
   * ``self``: enrol on the whole clip (3 s, audio only, no lips), score the same clip;
   * ``halves``: enrol on one half (1.5 s), score the other half, both ways; the baseline is
     scored on the same halves (a fresh front end per half).
2. **GRID s1 as a new voice** (as recorded, ``--speeds 1``, for a model not trained on s1; or
   speed-perturbed, e.g. ``--speeds 0.85,1.2``, a new voice for a model trained on s1): enrol on the
   first ``--enrol-seconds`` of s1 *train*-split sentences (audio only), score
   ``--val-sentences`` s1 *val*-split sentences (never the test split), for each relevance
   factor of ``--relevance-grid``: the place to choose it (never on the other-talker clips).

Truth: the mouth parameters measured by ``training.video.measure_video`` (MediaPipe).
Estimates: the live streaming path (``speech_to_params``). Prints a table and writes JSON
and a plot (``--out``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from assets.shared import shared_data_root

SHARED = shared_data_root()


def _r(truth: np.ndarray, est: np.ndarray) -> float:
    from training.evaluation import MOUTH_OPEN, pearson

    n = min(len(truth), len(est))
    return pearson(truth[:n, MOUTH_OPEN], est[:n, MOUTH_OPEN])


def _estimate(model, samples: np.ndarray, rate: int) -> np.ndarray:
    from realtime_core.features.resample import resample_audio as resample
    from realtime_core.pipeline import speech_to_params

    return speech_to_params(model, resample(samples, rate, model.sample_rate_hz))


def _at_model_rate(model, samples: np.ndarray, rate: int) -> np.ndarray:
    from realtime_core.features.resample import resample_audio as resample

    return resample(samples, rate, model.sample_rate_hz)


def _clips(clips_dir: Path) -> list[Path]:
    """The talking-face clips of ``clips_dir`` but s1's ``bbaf2n``; ConfigError naming the folder if there are none."""
    from training.errors import ConfigError

    if not clips_dir.is_dir():
        raise ConfigError(f"--clips {clips_dir}: folder not found")
    clips = sorted(p for p in clips_dir.iterdir() if p.suffix.lower() in (".mpg", ".mp4") and p.stem != "bbaf2n")
    if not clips:
        raise ConfigError(f"--clips {clips_dir}: no talking-face clips there (.mpg or .mp4)")
    return clips


def other_talkers(model, cfg, clips: list[Path], progress) -> list[dict]:
    from realtime_core.adaptation import adapt_av_model
    from training.evaluation import MOUTH_OPEN, loudness_db, pearson
    from training.video import measure_video

    rows = []
    for clip in progress(clips, desc="other talkers", unit="clip"):
        tr = measure_video(clip)
        x, rate, truth = tr.samples, tr.sample_rate_hz, tr.params
        row = {"clip": clip.stem, "seconds": round(len(x) / rate, 2), "frames": len(truth)}
        row["loudness"] = pearson(truth[:, MOUTH_OPEN], loudness_db(x, rate, len(truth)))
        row["before"] = _r(truth, _estimate(model, x, rate))
        adapted, _res = adapt_av_model(model, [_at_model_rate(model, x, rate)], config=cfg)
        row["self"] = _r(truth, _estimate(adapted, x, rate))
        row["self_visited"] = adapted.metadata["adaptation"]["components_visited"]
        # halves: frame boundary k, audio boundary k / 30 s
        k = len(truth) // 2
        cut = round(k / 30 * rate)
        parts = [(x[:cut], truth[:k]), (x[cut:], truth[k:])]
        base_est, ad_est, truths = [], [], []
        for i, (xs, ts) in enumerate(parts):
            enrol_x = parts[1 - i][0]
            ad_half, _ = adapt_av_model(model, [_at_model_rate(model, enrol_x, rate)], config=cfg)
            e0, e1 = _estimate(model, xs, rate), _estimate(ad_half, xs, rate)
            n = min(len(ts), len(e0), len(e1))
            base_est.append(e0[:n])
            ad_est.append(e1[:n])
            truths.append(ts[:n])
        t = np.concatenate(truths)
        row["halves_before"] = _r(t, np.concatenate(base_est))
        row["halves_after"] = _r(t, np.concatenate(ad_est))
        row["_tracks"] = (
            truth[:, MOUTH_OPEN],
            _estimate(model, x, rate)[:, MOUTH_OPEN],
            _estimate(adapted, x, rate)[:, MOUTH_OPEN],
        )
        rows.append(row)
    return rows


def s1_as_new_voice(
    model, relevances: list[float], root: Path, enrol_seconds: float, n_val: int, progress, *, speed: float = 1.0
) -> list[dict]:
    """One row per relevance factor: enrol on s1 train sentences, score s1 val sentences; with
    ``speed`` != 1 both played that much faster (``training.reallips.speed_perturb``: pitch,
    formants and tempo scale together, the lip track re-timed): a new voice for a model trained
    on s1 as recorded."""
    from assets.audio import read_audio
    from assets.grid import sentences
    from realtime_core.adaptation import adapt_av_model
    from realtime_core.hmm.adapt import AdaptConfig
    from training.evaluation import MOUTH_OPEN, loudness_db, pearson
    from training.reallips import speed_audio, speed_perturb, track_to_utterance
    from training.video import load_face_track

    # Enrolment is audio only: the train sentences' lips are never measured (the whole split was, 716 clips
    # through MediaPipe on an empty cache, for the first 16 sentences' audio). Only the scored val clips are.
    enrol, total = [], 0.0
    for s in sentences(root, split="train"):
        x, _ = read_audio(s.video, rate_hz=model.sample_rate_hz)
        enrol.append(speed_audio(x, speed))
        total += len(enrol[-1]) / model.sample_rate_hz
        if total >= enrol_seconds:
            break
    val = [
        speed_perturb(track_to_utterance(load_face_track(s.video, require_alignment=True), utt_id=s.sentence_id), speed)
        for s in progress(sentences(root, split="val")[:n_val], desc="s1 val lips", unit="clip")
    ]
    truth = np.concatenate([u.params[:, MOUTH_OPEN] for u in val])
    loud = np.concatenate([loudness_db(u.samples, u.sample_rate_hz, len(u.params)) for u in val])

    def score(m) -> float:
        est = []
        for u in progress(val, desc="scoring", unit="clip", leave=False):
            e = _estimate(m, u.samples, u.sample_rate_hz)[:, MOUTH_OPEN]
            est.append(np.pad(e, (0, max(0, len(u.params) - len(e))), mode="edge")[: len(u.params)])
        return pearson(truth, np.concatenate(est))

    base = score(model)
    rows = []
    for tau in relevances:
        adapted, _ = adapt_av_model(model, enrol, config=AdaptConfig(relevance=tau, weight_relevance=tau))
        info = adapted.metadata["adaptation"]
        rows.append(
            {
                "speed": speed,
                "relevance": tau,
                "enrol_files": len(enrol),
                "enrol_seconds": round(total, 1),
                "val_sentences": len(val),
                "frames": len(truth),
                "loudness": pearson(truth, loud),
                "before": base,
                "after": score(adapted),
                "visited": info["components_visited"],
                "audio_loglik_per_frame": info["audio_loglik_per_frame"],
            }
        )
    return rows


def _plot(rows: list[dict], png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(rows), 1, figsize=(10, 2.6 * len(rows)), squeeze=False)
    for ax, row in zip(axes[:, 0], rows):
        truth, before, after = row["_tracks"]
        t = np.arange(len(truth)) / 30
        ax.plot(t, truth, "k-", lw=2, label="MediaPipe lips")
        ax.plot(t[: len(before)], before[: len(t)], color="tab:blue", label=f"before (r={row['before']:.2f})")
        ax.plot(t[: len(after)], after[: len(t)], color="tab:red", label=f"after self-enrolment (r={row['self']:.2f})")
        ax.set_title(row["clip"])
        ax.set_ylabel("mouth_open (IOD)")
        ax.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="facecast bench adapt", description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=None, help="model file (default: the shipped model)")
    ap.add_argument("--clips", type=Path, default=SHARED / "video" / "grid", help="other-talker clips folder")
    ap.add_argument("--grid-s1", type=Path, default=SHARED / "video" / "grid_s1", help="GRID s1 folder")
    ap.add_argument("--enrol-seconds", type=float, default=45.0, help="s1 enrolment speech (train split)")
    ap.add_argument("--val-sentences", type=int, default=20, help="s1 val-split sentences scored")
    ap.add_argument("--no-s1", action="store_true", help="skip the s1-as-new-voice measurement")
    ap.add_argument(
        "--speeds",
        default="1",
        help="s1 speed factors (0.8-1.25) for the new-voice measurement: 1 = s1 as recorded (for a "
        "model not trained on s1), e.g. 0.85,1.2 for a model trained on s1",
    )
    ap.add_argument("--relevance", type=float, default=8.0, help="MAP relevance factor (frames) for the other talkers")
    ap.add_argument(
        "--relevance-grid",
        default="2,4,8,16,32",
        help="relevance factors tried on s1 (enrol on train, score val: the place to choose it)",
    )
    ap.add_argument("--out", type=Path, default=Path("adapt_report"), help="folder for JSON and plot")
    args = ap.parse_args(argv)

    from threadpoolctl import threadpool_limits

    from assets.modelfile import load_model
    from assets.progress import Progress
    from realtime_core.hmm.adapt import AdaptConfig

    model = load_model(args.model)
    # Both folders before any work: a missing --clips was a FileNotFoundError traceback, and a missing --grid-s1 was
    # refused only after the other talkers had been measured.
    clips = _clips(args.clips)
    if not args.no_s1:
        from assets.grid import sentences

        sentences(args.grid_s1)  # GridNotFoundError naming the folder
    cfg = AdaptConfig(relevance=args.relevance, weight_relevance=args.relevance)
    with threadpool_limits(1):  # small GEMMs: one BLAS thread is many times faster on 2 busy cores
        rows = other_talkers(model, cfg, clips, Progress)
    print(f"model: {args.model or 'shipped default'}; relevance {args.relevance:g} frames")
    print("| clip | s | loudness | before | after (self, 3 s) | halves before | halves after (1.5 s) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(
            f"| {r['clip']} | {r['seconds']:.1f} | {r['loudness']:.3f} | {r['before']:.3f} | {r['self']:.3f} | "
            f"{r['halves_before']:.3f} | {r['halves_after']:.3f} |"
        )
    keys = ("loudness", "before", "self", "halves_before", "halves_after")
    means = {k: float(np.mean([r[k] for r in rows])) for k in keys}
    print("| mean | | " + " | ".join(f"{means[k]:.3f}" for k in keys) + " |")
    report = {
        "model": args.model or "default",
        "relevance": args.relevance,
        "other_talkers": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows],
        "other_talkers_mean": means,
    }
    if not args.no_s1:
        grid = [float(v) for v in args.relevance_grid.split(",") if v]
        report["s1_new_voice"] = []
        for speed in [float(v) for v in args.speeds.split(",") if v]:
            with threadpool_limits(1):
                s1 = s1_as_new_voice(
                    model, grid, args.grid_s1, args.enrol_seconds, args.val_sentences, Progress, speed=speed
                )
            report["s1_new_voice"] += s1
            r0 = s1[0]
            print(
                f"s1 played x{speed:g} as a new voice: enrol {r0['enrol_seconds']} s ({r0['enrol_files']} train "
                f"sentences), {r0['val_sentences']} val sentences ({r0['frames']} frames); loudness "
                f"{r0['loudness']:.3f}; before {r0['before']:.3f}"
            )
            print("| relevance | r(mouth_open) after | components visited | enrolment audio log-lik/frame |")
            print("|---:|---:|---:|---|")
            for r in s1:
                print(
                    f"| {r['relevance']:g} | {r['after']:.3f} | {r['visited']} | "
                    f"{r['audio_loglik_per_frame'][0]:.2f} -> {r['audio_loglik_per_frame'][1]:.2f} |"
                )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "adaptation.json").write_text(json.dumps(report, indent=2) + "\n")
    _plot(rows, args.out / "adaptation.png")
    print(f"wrote {args.out / 'adaptation.json'} and {args.out / 'adaptation.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
