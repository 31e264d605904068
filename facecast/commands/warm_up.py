"""``facecast warm-up``: compile (or load) the per-frame numba kernels and build the built-in head's morph rig
now, not in the first say/render/serve."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    from facecast.cli import HelpFormatter

    p = sub.add_parser(
        "warm-up",
        help="compile the per-frame numba kernels now (scripts/setup.sh, so ./go, runs it once per change of them)",
        formatter_class=HelpFormatter,
        description=(
            "The live path's front end and inverter, the morph-target keyframe solve and a server's morph-head\n"
            "vertex deltas are numba kernels (realtime_core/*/compiled.py), compiled on their first call and cached\n"
            "beside their source files (numba's cache=True; in the user's cache directory when the tree is\n"
            "read-only). On a fresh clone that first call would be the first say, render, animate or serve: some\n"
            "15 s of CPU, a minute or more of wall time on a busy machine. This runs them once on the default model\n"
            "and a small keyframe problem, with the argument types those commands use, and prints how long it took\n"
            "(about a second when cached). It then builds the built-in head's morph rig into the facecast cache\n"
            "(under a second; read back in ~10 ms by every command that animates the default head)."
        ),
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import time

    import numpy as np

    from assets.modelfile import load_speech_model
    from realtime_core.face.keyframes import KeyframeMap
    from server.session import warm_up

    t0 = time.perf_counter()
    # The live path (front end, inverter, readout, output stage) as a session runs it; render and
    # animate run the same chain (realtime_core.pipeline) with the same argument types.
    warm_up(load_speech_model())
    t1 = time.perf_counter()
    # The keyframe solve as a morph-target head (the built-in one) calls it, one frame and a batch;
    # a small random problem has the same argument types as any head's map.
    rng = np.random.default_rng(0)
    # With lip contact, as every own-target head's map has it (its compiled bounds check per frame).
    contact = (np.full(2, 0.01), rng.normal(size=(2, 30)))
    keymap = KeyframeMap.from_reference(rng.normal(size=(6, 30)), rng.normal(size=(4, 30)), contact=contact)
    keymap.weights(rng.normal(size=4))
    keymap.weights(rng.normal(size=(3, 4)))
    # A server's vertex frames of a morph head (server.session.morph_delta_payloads): the one-pass
    # product and the int16 quantisation, with the argument types (float32 rows, int16 out) it passes.
    from realtime_core.face.compiled import morph_displacements, morph_displacements_int16

    w, rows = rng.uniform(size=(2, 5)).astype(np.float32), rng.normal(size=(5, 30)).astype(np.float32)
    d = morph_displacements(w, rows, np.empty((2, 30), dtype=np.float32))
    morph_displacements_int16(w, rows, d, np.empty(d.shape, dtype="<i2"), np.empty(2))
    t2 = time.perf_counter()
    print(f"warm-up: numba kernels ready: live path {t1 - t0:.1f} s, keyframe solve {t2 - t1:.1f} s")
    # The built-in head's morph rig (the default head of say, render and serve) into the facecast cache: its
    # build solves the keyframe map at every speech pose, 0.7-0.9 s that the first such command would pay.
    from assets.errors import AssetError
    from assets.heads.head import builtin_morph_head

    try:
        builtin_morph_head()
    except AssetError as exc:  # offline on a fresh cache (the head is downloaded on first use): that command builds it
        print(f"warm-up: built-in head not prepared ({exc})")
    else:
        print(f"warm-up: built-in head's morph rig ready: {time.perf_counter() - t2:.1f} s")
    return 0
