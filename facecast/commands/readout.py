"""``facecast readout MODEL -o MODEL``: fit a model's learned readout on GRID s1 or a corpus folder (any HMM)."""

from __future__ import annotations

import argparse
from pathlib import Path


def _specs(text: str) -> list:
    """``TAPS:POSTERIORS:HIDDEN[xENSEMBLE]:ALPHA[:audio|noaudio]`` candidates, comma-separated."""
    from training.readout import ReadoutSpec

    out = []
    for item in (t for t in text.split(",") if t):
        parts = item.split(":")
        if len(parts) not in (4, 5) or (len(parts) == 5 and parts[4] not in ("audio", "noaudio")):
            raise argparse.ArgumentTypeError(f"candidate {item!r} is not TAPS:POSTERIORS:HIDDEN:ALPHA[:audio|noaudio]")
        try:
            hidden, _, ensemble = parts[2].partition("x")
            out.append(
                ReadoutSpec(
                    taps=int(parts[0]),
                    posteriors=parts[1],
                    hidden=int(hidden),
                    ensemble=int(ensemble or 1),
                    alpha=float(parts[3]),
                    audio=len(parts) == 4 or parts[4] == "audio",
                )
            )
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"candidate {item!r}: {exc}") from None
    return out


def _pair(text: str) -> tuple[float, float]:
    """``LOW,HIGH`` -> (low, high)."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not LOW,HIGH") from None
    return lo, hi


def _weights(text: str) -> dict[str, float]:
    """``NAME=W[,NAME=W...]`` -> {name: weight} (names and values are checked by ``ReadoutSpec``)."""
    out = {}
    for item in (t for t in text.split(",") if t):
        name, eq, value = item.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"loss weight {item!r} is not NAME=WEIGHT") from None
        if not eq:
            raise argparse.ArgumentTypeError(f"loss weight {item!r} is not NAME=WEIGHT")
    return out


DEFAULT_CANDIDATES = (
    "5:state:0:1,5:state:32:1e-3,5:state:64:1e-3,5:state:128:1e-3,8:state:64:1e-3,5:component:64:1e-3,5:state:64x3:1e-3"
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter
    from facecast.commands.teacher_options import add_teacher_options

    p = sub.add_parser(
        "readout",
        help="fit a model's learned readout after the HMM inversion on real lips: GRID s1 (train fits, val chooses) "
        "or --corpus DIR (a studio's own talker)",
        formatter_class=HelpFormatter,
        description=(
            "Runs MODEL's live path (lag 0, no readout) over the GRID s1 train and val sentences, fits every\n"
            "candidate readout (realtime_core.readout: causal taps of the eq. 7 estimate, the frame's audio\n"
            "context and posteriors -> the four parameters; linear ridge or one ReLU layer) on train, keeps the\n"
            "best on val (mean r of the four parameters), re-chooses the closure band on val and writes MODEL\n"
            "with it. Re-runnable on any HMM; an existing readout of MODEL is replaced. The test split is never read.\n"
            "With --corpus DIR (a folder made by `facecast extract`, as `train` reads) the corpus stands in for\n"
            "GRID s1: its utterances are split by sentence (in order of id, every 1/F-th chooses: F =\n"
            "--choose-fraction) into a part that fits and one that chooses, each of 4 utterances or more. The\n"
            "band is chosen on the closures of the utterances' /p b m/ phone labels where they have them, else\n"
            "on the measured lips' own closures (frames inside speech at the closed pose): a proxy, see\n"
            "docs/training.md."
        ),
    )
    p.add_argument("model", metavar="MODEL", help="model file (.npz) or a shipped name (default, low-latency)")
    p.add_argument("-o", "--output", type=Path, required=True, help="model file to write (.npz)")
    p.add_argument(
        "--grid-s1",
        type=Path,
        default=None,
        help="the GRID s1 corpus (default: the shared data's video/grid_s1); not with --corpus, which replaces it",
    )
    p.add_argument(
        "--corpus",
        type=Path,
        default=None,
        metavar="DIR",
        help="fit and choose on this corpus folder (made by `facecast extract`) instead of GRID s1",
    )
    p.add_argument(
        "--choose-fraction",
        type=float,
        # None: training.readout.CHOOSE_FRACTION (not imported here: see --candidates)
        default=None,
        metavar="F",
        help="with --corpus: the share of its utterances that choose the readout and the band, the rest fit "
        "(default 0.2: one in five)",
    )
    p.add_argument("--cache-dir", default=None, help="face-track cache (default $FACECAST_CACHE or ~/.cache/facecast)")
    p.add_argument(
        "--candidates",
        type=_specs,
        # A string default: argparse parses it only when the option is not given, so building the
        # parser (every facecast command's start-up) does not import training.readout (scipy.signal, ~2 s).
        default=DEFAULT_CANDIDATES,
        metavar="K:POST:H[xE]:ALPHA,...",
        help="readouts to try: taps, posteriors (none/state/component), hidden units (0 = linear ridge; 64x3: three "
        "64-unit MLPs of seeds 0-2 averaged), L2 alpha, optionally ':noaudio'",
    )
    p.add_argument(
        "--loss-weight",
        type=_weights,
        default={},
        metavar="NAME=W,...",
        help="per-parameter weights of the fit's squared error, applied to every candidate (default: 1 each; e.g. "
        "lip_stretch=4; names: upper_lip_raise, lip_stretch, mouth_open, lip_corner_depress): the targets are scaled "
        "by sqrt(W) for the fit and the output layer scaled back, so the readout's form and the live path are the "
        "same; stored in the model's readout metadata",
    )
    p.add_argument(
        "--bands",
        type=lambda t: tuple(float(v) for v in t.split(",") if v),
        default=(0.02, 0.025, 0.03, 0.035, 0.04, 0.045, 0.05),
        help="closure bands (IOD) to choose from on val (or --corpus's choose part) after the readout",
    )
    p.add_argument(
        "--min-closure",
        type=float,
        default=0.915,
        help="share of the val closures a band must keep: the goal is 0.90; with val's 110 closures 0.915 asks for "
        "one closure of margin (101 of 110)",
    )
    p.add_argument(
        "--vtlp-copies",
        type=int,
        default=4,
        help="vocal-tract-length copies of every train sentence added to the fit (the filterbank warped, the lips "
        "kept; issue 10: one training talker, chosen on val and its voice-changed copies); 0 = none",
    )
    p.add_argument(
        "--vtlp-range",
        type=_pair,
        default=(0.85, 1.18),
        metavar="LOW,HIGH",
        help="the copies' filterbank warps, drawn uniformly per copy and sentence (> 1: a shorter vocal tract)",
    )
    p.add_argument("--vtlp-seed", type=int, default=1, help="seeds the copies' warps")
    # (the default model uses 250 + 250, eleventh round)
    add_teacher_options(p, "the readout's fit")
    p.add_argument("--report", type=Path, default=None, help="write the val scores of every candidate here (JSON)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from threadpoolctl import threadpool_limits

    # One BLAS thread: on the shared 2-core machine multi-threaded BLAS made small fits slower, and
    # one thread keeps the result fixed.
    with threadpool_limits(1):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from assets.modelfile import check_model_output, load_model, save_model
    from assets.progress import Progress
    from facecast.commands.teacher_options import teacher_config
    from training.corpus import write_json
    from training.errors import ConfigError
    from training.readout import VtlpConfig, choose_readout, trace_clips, vtlp_copies
    from training.reallips import s1_clips
    from training.teacher import teacher_clips

    check_model_output(args.output)
    # --corpus replaces GRID s1 (its own utterances fit and choose): a --grid-s1 beside it would be ignored, and
    # a --choose-fraction without it (GRID s1's train and val are fixed); either is a mistake the user should see.
    if args.corpus is not None and args.grid_s1 is not None:
        raise ConfigError(
            f"--corpus {args.corpus} and --grid-s1 {args.grid_s1}: --corpus replaces GRID s1 (its utterances both fit "
            "and choose the readout); give one of them"
        )
    if args.corpus is None and args.choose_fraction is not None:
        raise ConfigError(
            f"--choose-fraction {args.choose_fraction} splits a --corpus folder; GRID s1 fits on its train split "
            "and chooses on val"
        )
    from assets.grid import default_root

    grid_s1 = args.grid_s1 if args.grid_s1 is not None else default_root()
    vtlp = VtlpConfig(copies=args.vtlp_copies, warp_range=args.vtlp_range, seed=args.vtlp_seed)
    teacher = teacher_config(args)
    if args.corpus is not None and (teacher.espeak or teacher.festival):
        raise ConfigError(
            f"--corpus {args.corpus} with teacher sentences: the teacher labels with GRID s1's lips, not the corpus "
            "talker's; give --teacher-espeak/--teacher-festival only with GRID s1"
        )
    # Checked here, before the corpus is read: an unknown name or a weight <= 0 is a ConfigError naming it.
    candidates = [replace(spec, loss_weight=args.loss_weight) for spec in args.candidates]
    model = replace(load_model(args.model), readout=None)
    sets = {}
    source: dict = {}
    parts = _corpus_parts(args) if args.corpus is not None else {}
    for split in ("train", "val"):
        if parts:
            clips = parts[split]
        else:
            clips = s1_clips(split, root=grid_s1, cache_dir=args.cache_dir, progress=Progress)
        if not clips:
            raise ConfigError(f"no GRID s1 {split} sentences (video + .align) under {grid_s1}")
        sets[split] = trace_clips(model, clips, progress=Progress)
        if split == "train" and vtlp.copies:
            sets[split] += vtlp_copies(model, clips, vtlp, progress=Progress)
        if split == "train" and not parts:
            taught = teacher_clips(teacher, grid_s1, cache_dir=args.cache_dir, progress=Progress)
            sets[split] += trace_clips(model, taught, progress=Progress)
    if parts:
        source = {"corpus": str(args.corpus), **parts["source"]}
    fit, choose = ("fit", "choose") if parts else ("train", "val")
    extra = f", {teacher.espeak} + {teacher.festival} teacher sentences" if teacher.espeak or teacher.festival else ""
    print(
        f"{len(sets['train'])} {fit} traces ({vtlp.copies} VTLP copies{extra}) and {len(sets['val'])} {choose} "
        "sentences"
    )
    fitted, report = choose_readout(
        model,
        sets["train"],
        sets["val"],
        candidates,
        bands=args.bands,
        min_closure=args.min_closure,
        log=Progress.write,
    )
    report["chosen"]["vtlp"] = vtlp.as_json()
    if teacher.espeak or teacher.festival:  # a file fitted without teacher sentences stays as it was
        report["chosen"]["teacher"] = teacher.as_json()
    # Only a corpus run records where it was fitted: the GRID s1 recipe's file stays as it was.
    report["chosen"].update(source)
    fitted = replace(fitted, metadata={**fitted.metadata, "readout": report["chosen"]})
    if args.report is not None:
        write_json(args.report, report)
    print(f"wrote {save_model(args.output, fitted)} (closure band {fitted.closure_band})")
    return 0


def _corpus_parts(args: argparse.Namespace) -> dict:
    """--corpus: {"train": fit clips, "val": choose clips, "source": what the model records}, printed as `train`
    prints its data."""
    from training.corpus import load_corpus
    from training.readout import CHOOSE_FRACTION, corpus_clips, split_corpus

    fraction = CHOOSE_FRACTION if args.choose_fraction is None else args.choose_fraction
    fit, choose = split_corpus(load_corpus(args.corpus), choose_fraction=fraction, where=str(args.corpus))
    fit_clips, _ = corpus_clips(fit)
    choose_clips, kinds = corpus_clips(choose)
    where = {"phones": "from /p b m/ phone labels", "lips": "from the measured lips at the closed pose (a proxy)"}
    closures = "; ".join(f"{n} utterance(s) {where[k]}" for k, n in kinds.items() if n)
    n_events = sum(len(spans) for _, _, spans in choose_clips)
    print(
        f"readout on {args.corpus}: {len(fit)} utterances fit, {len(choose)} choose "
        f"({sum(u.duration_s for u in fit + choose) / 60:.1f} min of audio); the band is chosen on {n_events} "
        f"closures, {closures}"
    )
    return {
        "train": fit_clips,
        "val": choose_clips,
        "source": {"fit": len(fit), "choose": len(choose), "choose_fraction": fraction, "closures": kinds},
    }
