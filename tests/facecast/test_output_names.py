"""A video output whose name no H.264 + AAC container fits is refused first: before the speech is read, a head
rigged (minutes for a scan), frames rendered or a live session watched, with one line and exit 2."""

from __future__ import annotations

import pytest

from facecast.cli import main


@pytest.mark.parametrize(
    "argv",
    [
        ["render", "{tmp}/missing.wav", "-o", "{tmp}/take.txt"],
        ["view", "http://127.0.0.1:9", "--record", "{tmp}/take.webm"],  # port 9: nothing listens
    ],
)
def test_a_bad_video_name_is_refused_before_any_work(argv, tmp_path, capsys):
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not a video file name: use .mp4" in err, err
    assert str(tmp_path / "take.") in err
    assert list(tmp_path.iterdir()) == []
