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


def add_auto_gain_option(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--auto-gain",
        action="store_true",
        help="bring the speech to the model's training level first (the live sessions' causal gain stage): a quiet "
        "take moves the mouth as a loud one once its level has been heard, a few seconds in",
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
    params: np.ndarray,
    args: argparse.Namespace,
    fps: float = 30.0,
    *,
    mups: np.ndarray | None = None,
    model=None,
    command: str | None = None,
) -> np.ndarray:
    """``params (n, 4)`` at ``fps`` -> the same under ``args.expression`` (unchanged when none). With
    ``mups (n, A0)`` and an MLP ``model`` that has expression stages, paper 002's second-stage MLPs
    (:func:`realtime_core.mapping.expression.express`), as a live session does. ``command``: the command whose
    output ``params`` are; one warning line for each expression set at or after their end (never shown: a user's
    `--expression surprise@9` on a 3 s take was dropped without a word)."""
    alpha = expression_intensities(args, len(params), fps)
    if alpha is None:
        return params
    if command is not None:
        _warn_if_after_the_end(command, args.expression, len(params) / fps)
    from realtime_core.mapping.expression import express

    return express(params, alpha, mups=mups, mapper=getattr(model, "expressions", None))


def _warn_if_after_the_end(command: str, specs: list[str], duration_s: float) -> None:
    import sys

    from realtime_core.expressions import parse_expression

    for spec in specs:
        at = parse_expression(spec)[2]
        if at >= duration_s:
            print(
                f"facecast {command}: warning: --expression {spec} starts at {at:g} s, after the speech ends "
                f"({duration_s:.2f} s): it is not shown",
                file=sys.stderr,
            )


QUIET_BY_DB = 10.0
"""A speech file whose speech level is more than this under the model's training level gets a warning: the shipped
model reads loudness as mouth opening; four read-speech files (-23 to -25 dBFS, LJ Speech, ARCTIC, LibriVox) scaled
by -12 dB gave r(mouth_open) 0.73-0.84 against their own output, by -20 dB 0.58-0.61 and about half the mean opening
(docs/animation.md, "Audio as it comes"). 10 dB: those files as they are (5-6 dB under) are not warned about."""


def shipped_model(args: argparse.Namespace) -> bool:
    """Whether ``--mapper``/``--model`` name a shipped model: the HMM models or the MLP mapper, all trained on GRID s1
    at :data:`S1_SPEECH_LEVEL_DBFS` (the MLP mapper is as level-sensitive:
    a take 20 dB under opened the mouth 0.46 as far)."""
    if args.model is None:
        return True
    return args.mapper == "hmm" and str(args.model) in ("default", "low-latency")


def quiet_speech_db(samples: np.ndarray, rate_hz: int) -> float | None:
    """The speech level (dBFS, :func:`realtime_core.features.gain.speech_level_db`) of ``samples`` (n,) float at
    ``rate_hz`` when it is more than :data:`QUIET_BY_DB` under the level the shipped models were trained at; None for
    a file at that level, louder, or without speech (silence animates a closed mouth at any level). Measured on the
    decoded samples, before the animation, so that they need not be kept for :func:`warn_if_quiet`."""
    from realtime_core.features.gain import S1_SPEECH_LEVEL_DBFS, speech_level_db

    level = speech_level_db(samples, rate_hz)
    return None if level is None or level >= S1_SPEECH_LEVEL_DBFS - QUIET_BY_DB else level


def warn_if_quiet(command: str, path, level_db: float | None, rows: np.ndarray) -> None:
    """Print one warning line to stderr when :func:`quiet_speech_db` gave ``level_db`` (not None), saying how to
    normalise the file. ``rows`` (F, 4): the file's mouth parameters from the live path, before expressions; those at
    the neutral face exactly (every parameter 0, which no model row is) are the ones the output noise gate faded as
    room noise (:mod:`realtime_core.features.noisegate`). When there are any, the line says how much of the file they
    are and does not call the rest speech: 5 s of white noise at -54 dBFS faded in over 0.1 s was warned about as
    "speech at -54.0 dBFS" (the faded start held both noise floors low for a while, so its first seconds counted as
    sound over it), while the gate rested the face for the last 45 % of it."""
    import sys

    from realtime_core.features.gain import S1_SPEECH_LEVEL_DBFS

    if level_db is None:
        return
    under = f"{S1_SPEECH_LEVEL_DBFS - level_db:.0f} dB under the level the model was trained at"
    under += f" ({S1_SPEECH_LEVEL_DBFS} dBFS)"
    fix = "give --auto-gain, or normalise it first, e.g. ffmpeg -i IN -af loudnorm=I=-20:TP=-1.5 OUT.wav"
    rows = np.asarray(rows)
    noise = float(np.mean(np.all(rows == 0.0, axis=1))) if len(rows) else 0.0
    if noise > 0:
        said = (
            f"the noise gate took {100 * noise:.0f} % of it for room noise (the face rests there); the sound taken "
            f"for speech elsewhere is at {level_db:.1f} dBFS, {under}: if it is speech, the mouth opens less than the "
            f"words call for; {fix}"
        )
    else:
        said = (
            f"speech at {level_db:.1f} dBFS, {under}: the mouth opens less than the words call for (about half at 20 "
            f"dB under); {fix}"
        )
    print(f"facecast {command}: warning: {path}: {said}", file=sys.stderr)


CLIPPED_SHARE = 0.01
"""A speech file with this share of its samples at full scale (|x| >= 0.999) gets a warning: ARCTIC/LibriVox read
speech has none; LibriVox 0870 driven into clipping, 1 % of samples clipped: r(mouth_open) 0.83 against the take
unclipped, 38 %: 0.46 (the auto gain only brings that to 0.53: what was cut off is gone)."""


def warn_if_clipped(command: str, path, samples: np.ndarray) -> None:
    """Print one warning line to stderr when :data:`CLIPPED_SHARE` or more of ``samples`` (n,) float in [-1, 1]
    sit at full scale."""
    import sys

    share = float(np.mean(np.abs(samples) >= 0.999)) if len(samples) else 0.0
    if share >= CLIPPED_SHARE:
        print(
            f"facecast {command}: warning: {path}: {100 * share:.1f} % of the samples are clipped (at full scale): the "
            "mouth follows clipped speech poorly; record it with less input gain",
            file=sys.stderr,
        )
