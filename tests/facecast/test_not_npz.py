"""A file that is not an .npz given where a model, rig or unit corpus is expected: one line naming the file
and saying it is not an .npz, exit 2. numpy takes any such file for a pickle, and its message told the
user to load it unsafely with ``allow_pickle`` (which facecast never does)."""

from __future__ import annotations

import pytest

from assets.audio import write_wav
from facecast.cli import main
from tests.speech import speechlike


@pytest.mark.parametrize(
    "argv",
    [
        ["animate", "{speech}", "--csv", "{tmp}/out.csv", "--model", "{fake}"],
        ["adapt", "{fake}", "{speech}", "-o", "{tmp}/out.npz"],
        ["render", "{speech}", "-o", "{tmp}/out.mp4", "--head", "{fake}"],
        pytest.param(["say", "hello", "-o", "{tmp}/out.csv", "--corpus", "{fake}"], marks=pytest.mark.system),
    ],
    ids=["model", "adapt", "rig", "unit-corpus"],
)
def test_a_text_file_named_npz_is_one_line_without_the_pickle_advice(argv, tmp_path, capsys):
    fake = tmp_path / "fake.npz"
    fake.write_text("hello\n")
    speech = write_wav(tmp_path / "speech.wav", speechlike(1.0, 16000), 16000)
    assert main([a.format(tmp=tmp_path, fake=fake, speech=speech) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{fake}: " in err and "not an .npz file" in err, err
    assert "pickle" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fake.npz", "speech.wav"]
