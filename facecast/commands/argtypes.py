"""Argument types shared by the commands: comma-separated lists and numbers within a range.

argparse turns an :class:`argparse.ArgumentTypeError` into one usage line and exit code 2, naming the option, so
an absurd value (``render --fps 1e6`` rendered for minutes, ``animate --lag 100000`` announced a 55-minute delay)
is refused before any work."""

from __future__ import annotations

import argparse
from collections.abc import Callable


def ints(text: str) -> list[int]:
    """``"0,1,3"`` -> [0, 1, 3] (at least one integer)."""
    try:
        out = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None
    if not out:
        raise argparse.ArgumentTypeError("expected at least one integer")
    return out


def floats(text: str) -> list[float]:
    """``"0.1,0.5"`` -> [0.1, 0.5] (at least one finite number)."""
    try:
        out = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None
    if not out or not all(abs(v) < float("inf") for v in out):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return out


def within(cast: type[int] | type[float], lo: float, hi: float, unit: str = "") -> Callable[[str], int | float]:
    """An argparse type: ``cast(text)`` within [lo, hi] (NaN refused), else one line giving the range."""
    span = f"{lo:g}..{hi:g}{' ' + unit if unit else ''}"

    def parse(text: str) -> int | float:
        try:
            value = cast(text)
        except ValueError:
            kind = "an integer" if cast is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {kind}, got {text!r}") from None
        if not lo <= value <= hi:  # NaN fails this too
            raise argparse.ArgumentTypeError(f"{text} is outside {span}")
        return value

    parse.__name__ = f"{cast.__name__} in {span}"  # what argparse names in its "invalid ... value" fallback
    return parse


def colour(text: str) -> tuple[float, float, float]:
    """A colour as matplotlib names it (``"white"``, ``"#1e2030"``, ``"0.5"`` for a grey) -> RGB in [0, 1]."""
    from matplotlib.colors import to_rgba

    try:
        r, g, b, a = to_rgba(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a colour such as white, #1e2030 or 0.5 (grey), got {text!r}"
        ) from None
    if a < 1.0:  # 'none' or '#rrggbb00': a video has no transparency (it came out black)
        raise argparse.ArgumentTypeError(f"{text!r} is transparent; a video background needs an opaque colour")
    return (float(r), float(g), float(b))


def add_background_option(p: argparse.ArgumentParser) -> None:
    """``--background COLOUR`` of the commands that write a video (render, say); None keeps the renderer's."""
    p.add_argument(
        "--background",
        type=colour,
        default=None,
        metavar="COLOUR",
        help="background colour of the video: a name (white), #RRGGBB or a grey level 0..1 (default dark slate)",
    )
