"""``facecast train``: train the audio-visual HMM on corpora, or select N, M, tc on held-out data."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from facecast.commands.argtypes import ints


def _ratio_range(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH (two numbers), got {text!r}") from None
    return lo, hi


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.teacher_options import add_teacher_options

    p = sub.add_parser(
        "train",
        help="train the audio-visual HMM on corpus folders",
        formatter_class=HelpFormatter,
        description="Train the joint audio-visual HMM (full covariances, Baum-Welch) on one or more corpus "
        "folders (made by `facecast corpus` or `facecast extract`). Training is resumable: a checkpoint "
        "beside the output (OUTPUT.checkpoint.npz) is updated after every EM iteration and picked up when the same "
        "command runs again; a finished OUTPUT renamed to it continues with more --iters, exactly as one run of "
        "that many iterations. With --select, trains a grid of models on 80% of the utterances and reports "
        "held-out accuracy.",
    )
    p.add_argument("corpus", nargs="*", type=Path, help="corpus folders (each with manifest.json)")
    p.add_argument(
        "--grid-s1",
        nargs="?",
        const="",
        default=None,
        metavar="ROOT",
        help="add the real lips of GRID s1 (default ROOT: ../shared/data/video/grid_s1 or "
        "$FACECAST_SHARED_DATA/video/grid_s1), face tracks from the extraction cache (measured if missing)",
    )
    p.add_argument(
        "--grid-split",
        choices=("train", "val", "test", "all"),
        default="train",
        help="which GRID s1 sentences (assets.grid.split_of); never 'test' for a reported model",
    )
    p.add_argument(
        "--speed",
        type=lambda t: tuple(float(v) for v in t.split(",") if v),
        default=(),
        help="speed-perturbation factors for the GRID utterances, e.g. 0.9,1.1 (one copy each: pitch, "
        "formants and tempo scaled, lip track re-timed)",
    )
    p.add_argument(
        "--formant-range",
        type=_ratio_range,
        default=None,
        metavar="LOW,HIGH",
        help="with --speed: also change the voice of every speed copy, formants scaled by a ratio drawn "
        "log-uniformly from LOW..HIGH (a shorter/longer vocal tract; Praat via parselmouth, tempo kept)",
    )
    p.add_argument(
        "--pitch-range",
        type=_ratio_range,
        default=None,
        metavar="LOW,HIGH",
        help="with --formant-range: the median pitch of every speed copy scaled by a ratio drawn from LOW..HIGH",
    )
    p.add_argument(
        "--mic-copies",
        type=int,
        default=0,
        help="copies of every GRID utterance (and speed copy) through noise/reverberation/level/rate",
    )
    add_teacher_options(p, "the HMM's training (with --grid-s1; each clip once, no speed copies)")
    p.add_argument("--cache-dir", default=None, help="face-track cache (default $FACECAST_CACHE or ~/.cache/facecast)")
    p.add_argument("-o", "--output", type=Path, required=True, help="model file to write (.npz)")
    p.add_argument("--states", type=int, default=16, help="HMM states N")
    p.add_argument("--mix", type=int, default=3, help="Gaussian mixtures per state M")
    p.add_argument("--covariance", choices=("full", "diag"), default="full", help="covariance structure")
    p.add_argument("--tc", type=int, default=3, help="co-articulation context frames on each side")
    p.add_argument(
        "--window-hops",
        type=float,
        default=2.0,
        help="MFCC analysis window in video hops (1-4); with --tc it sets the algorithmic delay, "
        "(tc + window_hops) / 30 s (docs/architecture.md, Delay)",
    )
    p.add_argument("--rate", type=int, default=16000, help="model sample rate in Hz (audio is resampled)")
    p.add_argument(
        "--no-energy",
        dest="energy",
        action="store_false",
        help="leave c0 (log energy) out of the audio features (the paper's c1..c11 only)",
    )
    p.add_argument(
        "--level-norm",
        action="store_true",
        help="c0 and the silence/CMVN gates relative to the talker's own tracked speech level "
        "(realtime_core.features.level): features invariant to the recording gain",
    )
    p.add_argument(
        "--likelihood-scale",
        type=float,
        default=0.1,
        help="audio-likelihood exponent kappa stored in the model for the live path (0 < kappa <= 1; "
        "softens the over-confident posteriors of the 7 overlapping context frames)",
    )
    p.add_argument(
        "--closure-band",
        type=float,
        default=0.0,
        metavar="IOD",
        help="output stage: mouth_open estimates within this of the closed pose close (realtime_core.output; "
        "choose on held-out data, 0 = off); stored in the model",
    )
    p.add_argument("--iters", type=int, default=25, help="maximum Baum-Welch iterations")
    p.add_argument("--tol", type=float, default=5e-4, help="stop when the objective gains less per frame")
    p.add_argument("--seed", type=int, default=0, help="seed of the k-means initialisation and the split")
    p.add_argument(
        "--exclude-source",
        default="",
        help="comma-separated corpus sources to leave out "
        "(espeak, real, video), e.g. to keep evaluation speech out of training",
    )
    p.add_argument(
        "--select",
        action="store_true",
        help="model-selection mode over --grid-states/--grid-mix/"
        "--grid-tc, full and diagonal; writes Fig. 7/8 PNGs and a JSON report to --report-dir",
    )
    p.add_argument("--grid-states", type=ints, default=[4, 8, 16, 28], help="N values for --select")
    p.add_argument("--grid-mix", type=ints, default=[1, 3, 5], help="M values for --select")
    p.add_argument("--grid-tc", type=ints, default=[3], help="tc values for --select")
    p.add_argument(
        "--report-dir",
        type=Path,
        default=None,
        help="where --select writes plots and report (default: OUTPUT's folder)",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from threadpoolctl import threadpool_limits

    # One BLAS thread: on 2 cores multi-threaded OpenBLAS made this small-matrix EM many times
    # slower under load, and one thread keeps the summation order (and the result) fixed.
    with threadpool_limits(1):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from typing import Any

    from assets.modelfile import check_model_output, load_model, save_model
    from assets.progress import Progress
    from facecast.commands.teacher_options import teacher_config
    from realtime_core.hmm import TrainConfig
    from training.corpus import load_corpus
    from training.trainer import TrainRecipe, train_av_model

    check_model_output(args.output)  # before minutes of training (an -o my.json was written as an npz)
    teacher = teacher_config(args)
    if (teacher.espeak or teacher.festival) and args.grid_s1 is None:
        from training.errors import ConfigError

        raise ConfigError(
            "--teacher-espeak/--teacher-festival label with GRID s1's lips (its train split's units): give --grid-s1"
        )
    exclude = {s for s in args.exclude_source.split(",") if s}
    utts = [u for c in args.corpus for u in load_corpus(c) if u.source not in exclude]
    data: dict[str, Any] = {"corpora": [str(c) for c in args.corpus]}
    if args.grid_s1 is not None:
        from training.reallips import Variety, add_variety, grid_utterances

        split = None if args.grid_split == "all" else args.grid_split
        grid = grid_utterances(
            split,
            root=args.grid_s1 or None,
            cache_dir=args.cache_dir,
            progress=Progress,
            log=Progress.write,
        )
        variety = Variety(
            speeds=args.speed,
            formant_range=args.formant_range,
            pitch_range=args.pitch_range,
            mic_copies=args.mic_copies,
            seed=args.seed,
        )
        utts += add_variety(grid, variety)
        data["grid_s1"] = {
            "split": args.grid_split,
            "sentences": len(grid),
            "speeds": list(args.speed),
            **(
                {"formant_range": list(args.formant_range), "pitch_range": list(args.pitch_range)}
                if args.formant_range is not None and args.pitch_range is not None
                else {}
            ),
            "mic_copies": args.mic_copies,
        }
        if teacher.espeak or teacher.festival:
            from training.teacher import teacher_clips, teacher_utterances

            # Once each, after the speed copies: the same clips `facecast readout` adds with these options.
            # Baum-Welch weighs every frame alike, so a teacher frame counts as much as an s1 frame; the CMVN
            # warm-start statistics are over all the training audio, teacher clips included.
            taught = teacher_utterances(
                teacher_clips(
                    teacher, args.grid_s1 or None, cache_dir=args.cache_dir, progress=Progress, say=Progress.write
                )
            )
            utts += taught
            data["teacher"] = {
                **teacher.as_json(),
                "utterances": len(taught),
                "frames": int(sum(len(u.params) for u in taught)),
            }
    if not utts:
        from training.errors import ConfigError

        raise ConfigError("no utterances left to train on (check the corpus folders and --exclude-source)")
    print(f"training on {len(utts)} utterances, {sum(u.duration_s for u in utts) / 60:.1f} min of audio")

    level: dict[str, Any] = {}
    if args.level_norm:
        from realtime_core.features import CmvnConfig, LevelNormConfig

        ln = LevelNormConfig()
        # with level normalisation the CMVN gate is relative to the speech peak: the silence gate
        level = {"level_norm": ln, "cmvn": CmvnConfig(gate_db=-ln.silence_below_peak_db)}

    def recipe(n: int, m: int, cov: str, tc: int) -> TrainRecipe:
        return TrainRecipe(
            **level,
            sample_rate_hz=args.rate,
            tc=tc,
            window_hops=args.window_hops,
            energy=args.energy,
            likelihood_scale=args.likelihood_scale,
            hmm=TrainConfig(n_states=n, n_mix=m, covariance_type=cov, n_iter=args.iters, tol=args.tol, seed=args.seed),
        )

    if args.select:
        return _select(args, utts, recipe)

    rec = recipe(args.states, args.mix, args.covariance, args.tc)
    ckpt = args.output.with_name(args.output.name + ".checkpoint.npz")
    start, done = None, 0
    # The objective per frame of every model so far (history[i]: after i iterations); a checkpoint
    # carries it, so a resumed run's file records the same history as an uninterrupted one.
    history: list[float] = []
    if ckpt.exists():
        prev = load_model(ckpt)
        same = {k: v for k, v in prev.metadata.get("recipe", {}).items() if k not in ("n_iter", "tol")} == {
            k: v for k, v in rec.as_json().items() if k not in ("n_iter", "tol")
        }
        if same and {k: prev.metadata.get(k) for k in data} == data:
            start, done = prev.hmm, int(prev.metadata.get("iteration", 0))
            # The resumed run scores the checkpoint's model again as its first objective.
            history = [float(v) for v in prev.metadata.get("em_history", [])][:done]
            print(f"resuming from {ckpt} (iteration {done})")
    bar = Progress(total=args.iters, initial=done, desc="Baum-Welch", unit="iter")

    def on_iteration(it: int, objective: float, model) -> None:
        # Called after every E-step; the first scores the starting model (no iteration yet).
        history.append(objective)
        bar.set_postfix(objective=f"{objective:.4f}")
        if it > 0:
            bar.update(1)
            meta = {**model.metadata, "iteration": done + it, "em_history": list(history)}
            save_model(ckpt, replace(model, metadata=meta))

    rec_run = replace(rec, hmm=replace(rec.hmm, n_iter=max(args.iters - done, 0))) if start is not None else rec
    model, result = train_av_model(utts, rec_run, start=start, on_iteration=on_iteration, metadata=data)
    bar.close()
    # A finished file is also a checkpoint: renamed to OUTPUT.checkpoint.npz, it continues with more --iters.
    # A history that does not reach back to iteration 0 (a checkpoint without one) is kept as this run's.
    meta = {
        **model.metadata,
        "recipe": rec.as_json(),
        "iteration": done + len(result.history) - 1,
        **({"em_history": history} if len(history) == done + len(result.history) else {}),
    }
    model = replace(model, closure_band=args.closure_band, metadata=meta)
    save_model(args.output, model)
    ckpt.unlink(missing_ok=True)
    h = model.metadata.get("em_history", result.history)  # an old checkpoint: this run's part only
    print(
        f"wrote {args.output}: objective per frame {h[0]:.3f} -> {h[-1]:.3f} in {len(h) - 1} iterations"
        f"{' (converged)' if result.converged else ''}"
    )
    return 0


def _select(args: argparse.Namespace, utts: list, recipe) -> int:
    from assets.modelfile import save_model
    from assets.progress import Progress
    from training.corpus import write_json
    from training.report import plot_selection, plot_tracks
    from training.trainer import evaluate, split_by_utterance, train_av_model

    train, test = split_by_utterance(utts, seed=args.seed)
    grid = [
        (n, m, cov, tc)
        for tc in args.grid_tc
        for cov in ("full", "diag")
        for n in args.grid_states
        for m in args.grid_mix
    ]
    rows, best = [], None
    for n, m, cov, tc in Progress(grid, desc="model selection", unit="model"):
        model, _ = train_av_model(train, recipe(n, m, cov, tc))
        ev = evaluate(model, test)
        row = {
            "n_states": n,
            "n_mix": m,
            "covariance_type": cov,
            "tc": tc,
            "eps": round(ev.eps, 4),
            "rho": round(ev.rho, 4),
            "r_per_param": {k: round(v, 4) for k, v in ev.r_per_param.items()},
            "stream_cost_MN2": m * n * n,
        }
        rows.append(row)
        Progress.write(json.dumps(row))
        if cov == "full" and (best is None or ev.rho > best[0]):
            best = (ev.rho, model, ev, row)
    if best is None:
        raise SystemExit("facecast train: no full-covariance model in the grid")
    out_dir = args.report_dir or args.output.parent
    out_dir.mkdir(parents=True, exist_ok=True)
    plot_selection(rows, out_dir / "selection_fig7.png")
    plot_tracks(best[2].tracks, out_dir / "tracks_fig8.png")
    report = {"train_utterances": len(train), "test_utterances": len(test), "grid": rows, "best_full": best[3]}
    write_json(out_dir / "selection_report.json", report)
    save_model(args.output, best[1])
    print(f"best full-covariance model {best[3]} -> {args.output}; plots and report in {out_dir}")
    return 0
