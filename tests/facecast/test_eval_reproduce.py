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
