"""``facecast readout MODEL -o MODEL``: fit a model's learned readout on GRID s1 real lips (any HMM)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

SHARED = Path(os.environ.get("FACECAST_SHARED_DATA") or Path(__file__).resolve().parents[2].parent / "shared" / "data")


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

    p = sub.add_parser(
        "readout",
        help="fit a model's learned readout after the HMM inversion on GRID s1 real lips (train fits, val chooses)",
        formatter_class=HelpFormatter,
        description=(
            "Runs MODEL's live path (lag 0, no readout) over the GRID s1 train and val sentences, fits every\n"
            "candidate readout (realtime_core.readout: causal taps of the eq. 7 estimate, the frame's audio\n"
            "context and posteriors -> the four parameters; linear ridge or one ReLU layer) on train, keeps the\n"
            "best on val (mean r of the four parameters), re-chooses the closure band on val and writes MODEL\n"
            "with it. Re-runnable on any HMM; an existing readout of MODEL is replaced. The test split is never read."
        ),
    )
    p.add_argument("model", metavar="MODEL", help="model file (.npz) or a shipped name (default, low-latency)")
    p.add_argument("-o", "--output", type=Path, required=True, help="model file to write (.npz)")
    p.add_argument("--grid-s1", type=Path, default=SHARED / "video" / "grid_s1", help="the GRID s1 corpus")
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
        help="closure bands (IOD) to choose from on val after the readout",
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

    from tqdm import tqdm

    from assets.modelfile import check_model_output, load_model, save_model
    from training.corpus import write_json
    from training.errors import ConfigError
    from training.readout import VtlpConfig, choose_readout, trace_clips, vtlp_copies
    from training.reallips import s1_clips

    check_model_output(args.output)
    vtlp = VtlpConfig(copies=args.vtlp_copies, warp_range=args.vtlp_range, seed=args.vtlp_seed)
    # Checked here, before the corpus is read: an unknown name or a weight <= 0 is a ConfigError naming it.
    candidates = [replace(spec, loss_weight=args.loss_weight) for spec in args.candidates]
    model = replace(load_model(args.model), readout=None)
    sets = {}
    for split in ("train", "val"):
        clips = s1_clips(split, root=args.grid_s1, cache_dir=args.cache_dir, progress=tqdm)
        if not clips:
            raise ConfigError(f"no GRID s1 {split} sentences (video + .align) under {args.grid_s1}")
        sets[split] = trace_clips(model, clips, progress=tqdm)
        if split == "train" and vtlp.copies:
            sets[split] += vtlp_copies(model, clips, vtlp, progress=tqdm)
    print(f"{len(sets['train'])} train traces ({vtlp.copies} VTLP copies) and {len(sets['val'])} val sentences")
    fitted, report = choose_readout(
        model,
        sets["train"],
        sets["val"],
        candidates,
        bands=args.bands,
        min_closure=args.min_closure,
        log=tqdm.write,
    )
    report["chosen"]["vtlp"] = vtlp.as_json()
    fitted = replace(fitted, metadata={**fitted.metadata, "readout": report["chosen"]})
    if args.report is not None:
        write_json(args.report, report)
    print(f"wrote {save_model(args.output, fitted)} (closure band {fitted.closure_band})")
    return 0
