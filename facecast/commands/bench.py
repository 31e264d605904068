"""``facecast bench core``: per-frame cost of the real-time core (prints figures, never asserts)."""

from __future__ import annotations

import argparse

FORWARDED: dict[str, tuple[str, str]] = {
    "latency": (
        "benchmarks.server_latency",
        "per-stage and end-to-end latency of a live session vs the algorithmic delay: a table (--json: every "
        "figure); --short: the CI gate, exit 1 over the 24 ms per-frame budget",
    ),
    "capacity": ("benchmarks.server_capacity", "concurrent real-time sessions and viewers sustained"),
    "soak": ("benchmarks.server_soak", "RSS growth, frames lost, loop lag and latency over minutes (--hostile)"),
    "render": ("benchmarks.render", "rendering frames per second and the per-frame cost of applying a rig"),
    "units": (
        "benchmarks.units",
        "unit search on 20-phone targets, `facecast say` to MP4, first frame of a text session",
    ),
    "adapt": ("benchmarks.adaptation", "speaker adaptation: r(mouth_open) vs MediaPipe lips before/after enrolment"),
}
"""Benchmarks with their own argument parsers: name -> (module with main(argv), help)."""


def run_forwarded(name: str, argv: list[str]) -> int:
    import importlib

    return int(importlib.import_module(FORWARDED[name][0]).main(argv) or 0)


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser("bench", help="run a benchmark and print its figures", formatter_class=HelpFormatter)
    which = p.add_subparsers(dest="bench", required=True, metavar="BENCH")
    core = which.add_parser(
        "core",
        help="MFCC, context stacking, streaming and batch inversion, Baum-Welch vs hmmlearn",
        formatter_class=HelpFormatter,
    )
    core.add_argument("--json", action="store_true", help="print one JSON document instead of a table")
    core.add_argument("--quick", action="store_true", help="fewer repetitions and a smaller EM problem")
    core.add_argument("--no-hmmlearn", action="store_true", help="skip the (slow) hmmlearn EM comparison")
    core.add_argument("--mlp", default=None, help="a trained MLP mapper file (facecast mu) to time beside the others")
    core.set_defaults(run=_run_core)
    # The other benchmarks own their options (`facecast bench NAME --help` shows them): the
    # command line hands them everything after their name (see FORWARDED and facecast.cli).
    for name, (_module, text) in FORWARDED.items():
        which.add_parser(name, help=text, add_help=False)


def _run_core(args: argparse.Namespace) -> int:
    from benchmarks.core import CoreBenchConfig, run_core_benchmark

    cfg = CoreBenchConfig(quick=args.quick, hmmlearn=not args.no_hmmlearn, mlp_file=args.mlp)
    run_core_benchmark(cfg, as_json=args.json)
    return 0
