"""A GRID s1 folder that holds no sentence (missing, mistyped, the shared data elsewhere): every command that reads
GRID s1 says so in one line naming the folder and how to proceed, exit 2."""

from __future__ import annotations

import pytest

from assets.errors import GridNotFoundError
from assets.grid import sentences, split_of
from assets.shared import ENV
from facecast.cli import main


@pytest.mark.parametrize(
    "argv",
    [
        ["units", "build"],  # said "no sentences to build a unit corpus from"
        ["units", "eval"],
        [
            "train",
            "--grid-s1",
            "-o",
            "{tmp}/m.npz",
        ],  # said "no utterances left to train on (check ... --exclude-source)"
        ["readout", "default", "-o", "{tmp}/m.npz"],
    ],
    ids=lambda a: " ".join(a[:2]),
)
def test_commands_name_the_grid_folder_they_found_empty(argv, tmp_path, monkeypatch, capsys):
    shared = tmp_path / "shared"  # a shared data folder without video/grid_s1: the default root is missing
    shared.mkdir()
    monkeypatch.setenv(ENV, str(shared))
    rc = main([a.format(tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err.strip()
    root = shared / "video" / "grid_s1"
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert f"error: {root}: no GRID s1 sentences (no such folder)" in err and ENV in err, err
    assert not (tmp_path / "m.npz").exists()


def test_a_folder_with_sentences_is_read_and_one_without_is_named(tmp_path):
    root = tmp_path / "grid_s1"
    (root / "video").mkdir(parents=True)
    (root / "align").mkdir()
    with pytest.raises(GridNotFoundError, match=r"no video/\*\.mp4 with its align/\*\.align in it") as exc:
        sentences(root)
    assert exc.value.path == root
    # a video without its alignment is not a sentence; one with it is, in its split only
    for sid in ("bbaf2n", "bbaf3s", "pgae1a"):
        (root / "video" / f"{sid}.mp4").write_bytes(b"")
    with pytest.raises(GridNotFoundError):
        sentences(root)
    (root / "align" / "bbaf2n.align").write_text("0 1000 sil\n")
    assert [s.sentence_id for s in sentences(root)] == ["bbaf2n"]
    other = next(s for s in ("train", "val", "test") if s != split_of("bbaf2n"))
    assert sentences(root, split=other) == []  # the folder holds sentences: an empty split is not an error
