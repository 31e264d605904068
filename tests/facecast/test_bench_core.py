"""``facecast bench core``'s Baum-Welch comparison prints nothing on its own: hmmlearn's log line about
its deliberately small timing subset no longer leaks onto stderr."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from tests.prerequisites import require_module

pytestmark = pytest.mark.slow  # one Baum-Welch iteration over 20,000 frames, and hmmlearn on one sequence


def test_baum_welch_comparison_is_quiet_and_restores_the_log_level(caplog, capfd):
    require_module("hmmlearn")
    from benchmarks.core import bench_baum_welch

    before = logging.getLogger("hmmlearn").level
    with caplog.at_level(logging.WARNING):
        out = bench_baum_welch(np.random.default_rng(0), hmmlearn_seqs=1, run_hmmlearn=True)
    assert out["hmmlearn_measured_on_sequences"] == 1 and out["speedup"] > 0
    assert not [r for r in caplog.records if r.name.startswith("hmmlearn")]
    assert "degenerate" not in capfd.readouterr().err
    assert logging.getLogger("hmmlearn").level == before
