"""What `facecast bench core` and `facecast bench latency` print for a person: aligned tables; the latency
benchmark's JSON only with --json (its help said "prints JSON; asserts nothing" while --short is the CI gate)."""

from __future__ import annotations

import io
import json
import re

import pytest

from facecast.cli import main

pytestmark = pytest.mark.slow  # a real benchmark run each (seconds)


def test_bench_core_table_columns_line_up():
    """The row "live shipped N=16,M=3,D=88,float32 numpy reference" was wider than the stage column and pushed
    its figures right of the others'. The stage rows as `bench core` names them (running it took 16 s)."""
    from benchmarks.core import _print_stages

    fig = {"median_us": 57.2, "p99_us": 88.1}
    r = {
        "features": {"mfcc": fig, "context": fig},
        "streaming_inversion": {"N=16,M=3,D=88,float32": fig},
        "live_samples_to_params": {
            "shipped N=16,M=3,D=88,float32": fig,
            "shipped N=16,M=3,D=88,float32 numpy reference": fig,
        },
    }
    out = io.StringIO()
    _print_stages(r, out)
    stages = out.getvalue().splitlines()
    assert stages[0].startswith("stage ")
    assert any("numpy reference" in line for line in stages)
    # every row's p99 figure ends in the same column as the header's "p99"
    ends = {len(re.sub(r"\s+\(goal.*\)$", "", line)) for line in stages}
    assert ends == {len(stages[0])}, stages


@pytest.mark.system  # a server process and its clients over loopback
def test_bench_latency_prints_a_summary_and_the_json_only_when_asked(capsys):
    from benchmarks.server_latency import print_summary

    assert main(["bench", "latency", "--seconds", "1", "--no-head", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)  # the whole output is the one JSON document
    assert result["per_frame_work_p99_ms"] > 0 and result["budget_ms"] == 24.0
    table = io.StringIO()
    print_summary(result, table)
    text = table.getvalue()
    assert f"per-frame server work p99 {result['per_frame_work_p99_ms']:.2f} ms" in text, text
    assert len(text.splitlines()) < 30 and "{" not in text
    p99 = result["viewers"]["params"]["end_to_end_after_last_needed_sample_ms"]["p99_ms"]
    row = next(line for line in text.splitlines() if line.startswith("viewer params: after the last sample"))
    assert row.split()[-2] == f"{p99:.2f}", row
    assert main(["bench", "latency", "--seconds", "1", "--no-head"]) == 0  # no --json: the table
    out = capsys.readouterr().out
    assert out.startswith("facecast server latency:") and "{" not in out, out
