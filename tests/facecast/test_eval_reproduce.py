"""`facecast eval`'s report names the command that produced it: read back, it is the same run."""

from __future__ import annotations

import shlex

import pytest

from facecast.cli import build_parser
from facecast.commands import eval as eval_command

SCORED = ("model", "mapper", "grid_split", "grid_s1", "video_dir", "speech_dir", "synthetic")


def _parsed(argv: list[str]):
    args = build_parser().parse_args(argv)
    eval_command._default_folders(args)
    return args


@pytest.mark.parametrize("with_folders", [False, True])
def test_the_produced_by_command_reads_back_as_the_same_run(tmp_path, with_folders):
    """`eval --model my.npz --video-dir myheldout` was reported as "Produced by `facecast eval --model my.npz`":
    run again, that scores the other GRID talkers instead of the user's clips."""
    argv = ["eval", "--model", "my model.npz"]
    if with_folders:
        for name in ("my clips", "grid s1", "speech", "syn"):
            (tmp_path / name).mkdir()
        argv += ["--video-dir", str(tmp_path / "my clips"), "--grid-s1", str(tmp_path / "grid s1")]
        argv += ["--speech-dir", str(tmp_path / "speech"), "--synthetic", str(tmp_path / "syn")]
        argv += ["--mapper", "mlp", "--grid-split", "val"]
    args = _parsed(argv)
    produced = eval_command._reproduce(args)
    words = shlex.split(produced)
    assert words[:2] == ["facecast", "eval"]
    again = _parsed(words[1:])
    assert {k: getattr(again, k) for k in SCORED} == {k: getattr(args, k) for k in SCORED}, produced
    if not with_folders:  # the defaults are not spelled out
        assert produced == "facecast eval --model 'my model.npz'"


DIALLED = ("dial", "grid_split", "grid_s1", "lags", "kappas")


@pytest.mark.parametrize("swept", [False, True])
def test_the_dial_made_by_command_reads_back_as_the_same_run(tmp_path, swept):
    """`eval --dial default low-latency --grid-split test` (scripts/train_low_latency_model.sh's last step) said
    "made by `bash scripts/latency_dial.sh`", and the sweep's files were named by their stems (`tc3_wh2`), which
    no command finds: the line names the command as run, and the script only for the sweep's models."""
    (tmp_path / "grid s1").mkdir()
    models = ["default", "low-latency"] + ([str(tmp_path / "dial out" / "tc3_wh2.npz")] if swept else [])
    argv = ["eval", "--dial", *models, "--grid-s1", str(tmp_path / "grid s1"), "--grid-split", "val"]
    argv += ["--lags", "0,1", "--kappas", "0.1,0.2,0.5,1"]
    args = _parsed(argv)
    made_by = eval_command._dial_made_by(args)
    command = made_by.split("`")[-2]
    words = shlex.split(command)
    assert words[:2] == ["facecast", "eval"]
    again = _parsed(words[1:])
    assert {k: getattr(again, k) for k in DIALLED} == {k: getattr(args, k) for k in DIALLED}, command
    assert ("scripts/latency_dial.sh" in made_by) == swept, made_by


UNITS_SCORED = ("grid", "phones", "model", "n_best", "split", "recording", "only_extracted")


@pytest.mark.parametrize("with_options", [False, True])
def test_the_units_eval_section_names_the_command_that_reads_back_as_the_same_run(tmp_path, with_options):
    """`facecast units eval --split val --n-best 1,3,5,10` wrote "`facecast units eval --split val`", which run
    again scores n_best 1 and 10 only; --recording, --model, --phones, --grid were left out too."""
    from facecast.commands import units

    argv = ["units", "eval"]
    if with_options:
        argv += ["--split", "val", "--n-best", "1,3,5,10", "--recording", "0.5,0.4,0.3", "--only-extracted"]
        argv += ["--model", str(tmp_path / "my model.npz"), "--phones", str(tmp_path / "p.json")]
        argv += ["--grid", str(tmp_path / "grid s1"), "--output", str(tmp_path / "sec.md")]
    args = build_parser().parse_args(argv)
    produced = units._reproduce(args)
    words = shlex.split(produced)
    assert words[:3] == ["facecast", "units", "eval"]
    again = build_parser().parse_args(words[1:])
    assert {k: getattr(again, k) for k in UNITS_SCORED} == {k: getattr(args, k) for k in UNITS_SCORED}, produced
    if not with_options:
        assert produced == "facecast units eval"
