"""The options every speech-driven command shares: which mapper (``--mapper hmm|mlp``) and which
expressions (``--expression smile:0.7@1.2``), and turning them into library objects."""

from __future__ import annotations

import argparse

import numpy as np


def add_mapper_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--mapper",
        choices=("hmm", "mlp"),
        default="hmm",
        help="audio-to-visual mapper: the HMM inverter (paper 000) or the GMM-selected MLP bank "
        "(paper 002; --model is then a mapper file written by `facecast mu`, default the shipped one)",
    )


def add_expression_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--expression",
        action="append",
        default=[],
        metavar="NAME[:INTENSITY][@SECONDS]",
        help="expression from a media time on, e.g. smile:0.7@1.2 (smile, sad, surprise, anger, neutral; "
        "intensity 0..1, default 1; time default 0); repeat for changes over time",
    )
    p.add_argument("--expression-ease", type=float, default=0.3, help="seconds an expression takes to ease in/out")


def expression_intensities(args: argparse.Namespace, n_frames: int, fps: float = 30.0) -> np.ndarray | None:
    """``(n_frames, len(EXPRESSIONS))`` intensities of ``args.expression`` at ``fps``, None when none is given."""
    if not args.expression:
        return None
    from realtime_core.expressions import ExpressionConfig, ExpressionTrack, parse_expression

    # A file's whole length is known: a change may be set anywhere in it. The live limit (600 s ahead of the
    # newest frame) refused `--expression smile@700` on a 13-minute file.
    ahead = min(86400.0, max(ExpressionConfig.max_ahead_s, n_frames / fps))
    track = ExpressionTrack(ExpressionConfig(ease_s=args.expression_ease, max_ahead_s=ahead))
    for spec in args.expression:
        name, intensity, at = parse_expression(spec)
        track.schedule(name, intensity, at)
    return track.intensities(np.arange(n_frames) / fps)


def apply_expressions(
    params: np.ndarray, args: argparse.Namespace, fps: float = 30.0, *, mups: np.ndarray | None = None, model=None
) -> np.ndarray:
    """``params (n, 4)`` at ``fps`` -> the same under ``args.expression`` (unchanged when none). With
    ``mups (n, A0)`` and an MLP ``model`` that has expression stages, paper 002's second-stage MLPs
    (:func:`realtime_core.mapping.expression.express`), as a live session does."""
    alpha = expression_intensities(args, len(params), fps)
    if alpha is None:
        return params
    from realtime_core.mapping.expression import express

    return express(params, alpha, mups=mups, mapper=getattr(model, "expressions", None))
