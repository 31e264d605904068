"""Start-up of every facecast command: building the parser imports no command's heavy modules."""

from __future__ import annotations

import subprocess
import sys

from facecast.cli import build_parser
from training.readout import ReadoutSpec


def test_building_the_parser_imports_no_training_scipy_signal_or_numba():
    # A fresh interpreter: this test process has imported everything already. Each of these cost
    # seconds of every command's start-up when the parser built them (training.readout pulled in
    # scipy.signal: `facecast --help` took 2.9 s instead of 0.6 s).
    code = (
        "import sys; from facecast.cli import build_parser; build_parser(); "
        "print(sorted(m for m in ('training.readout', 'scipy.signal', 'numba') if m in sys.modules))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert r.stdout.strip() == "[]", r.stdout + r.stderr


def test_readout_candidates_default_still_parses_to_specs():
    args = build_parser().parse_args(["readout", "default", "-o", "out.npz"])
    assert len(args.candidates) == 7 and all(isinstance(c, ReadoutSpec) for c in args.candidates)
    assert args.candidates[0] == ReadoutSpec(taps=5, posteriors="state", hidden=0, ensemble=1, alpha=1.0, audio=True)
    assert args.candidates[-1].ensemble == 3
    given = build_parser().parse_args(["readout", "default", "-o", "o.npz", "--candidates", "3:none:0:0.5"])
    assert [(c.taps, c.posteriors, c.alpha) for c in given.candidates] == [(3, "none", 0.5)]
