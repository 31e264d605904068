"""An output name the command cannot write usefully (a video no H.264 + AAC container fits, a rig not .npz)
is refused first: before the speech is read, a head rigged (minutes for a scan), frames rendered or a live
session watched, with one line and exit 2."""

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


def test_rig_refuses_an_output_that_is_not_npz_before_rigging(tmp_path, capsys):
    """A rig written as take.txt could never be given back as --head (heads are told apart by suffix)."""
    assert main(["rig", "builtin", "-o", str(tmp_path / "face.rig")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{tmp_path / 'face.rig'}: a rig file is written as .npz" in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "argv",
    [
        ["train", "{tmp}/corpus", "-o", "{tmp}/my.json"],
        ["readout", "default", "-o", "{tmp}/my.json"],
        ["adapt", "default", "{tmp}/missing.wav", "-o", "{tmp}/my.json"],
    ],
    ids=["train", "readout", "adapt"],
)
def test_a_model_output_that_is_not_npz_is_refused_before_any_work(argv, tmp_path, capsys):
    """`train -o my.json` trained for minutes, then wrote an npz archive under that name."""
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{tmp_path / 'my.json'}: a model file is written as .npz" in err, err
    assert list(tmp_path.iterdir()) == []


def test_record_refuses_arkit_morphs_on_a_mesh_head_before_watching(tmp_path, shared_data, capsys):
    """Was refused by the exporter only after the whole live take had been recorded."""
    head = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    out = tmp_path / "take.glb"
    argv = ["record", "http://127.0.0.1:9", "-o", str(out), "--glb-morphs", "arkit52", "--head", str(head)]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{out}: --glb-morphs arkit52 needs the built-in head" in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", ["--show-landmarks", "--png"])
def test_rig_refuses_a_picture_name_matplotlib_cannot_write(option, tmp_path, capsys):
    """Was a matplotlib traceback from savefig (after rigging, for --png)."""
    argv = ["rig", "builtin", option, str(tmp_path / "face.txt")]
    assert main([*argv, "-o", str(tmp_path / "face.npz")] if option == "--png" else argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{tmp_path / 'face.txt'}: not a picture file name; use .png" in err, err
    assert list(tmp_path.iterdir()) == []


def test_render_says_a_folder_cannot_be_made_before_any_work(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("hello")
    assert main(["render", str(tmp_path / "missing.wav"), "-o", str(tmp_path / "notes.txt" / "v.mp4")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "notes.txt is a file, not a folder" in err and "Traceback" not in err
    argv = [
        "render",
        str(tmp_path / "missing.wav"),
        "-o",
        str(tmp_path / "v.mp4"),
        "--png-dir",
        str(tmp_path / "notes.txt"),
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "notes.txt is a file, not a folder" in err and "Traceback" not in err


def test_rig_says_a_folder_cannot_be_made_before_rigging(tmp_path, capsys):
    """Was refused by save_rig only after the head had been rigged (minutes for a scan): the missing head
    shows the folder is checked first."""
    (tmp_path / "notes.txt").write_text("hello")
    assert main(["rig", str(tmp_path / "missing.glb"), "-o", str(tmp_path / "notes.txt" / "face.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "notes.txt is a file, not a folder" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_say_says_a_folder_cannot_be_made_before_any_work(tmp_path, capsys):
    """Was a NotADirectoryError traceback from the temporary folder beside an .mp4 (after synthesis); the
    missing --audio recording shows the folder is checked first."""
    (tmp_path / "notes.txt").write_text("hello")
    argv = ["say", "hello", "--audio", str(tmp_path / "missing.wav"), "-o", str(tmp_path / "notes.txt" / "hi.mp4")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "notes.txt is a file, not a folder" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


@pytest.mark.parametrize("out", ["take.avi", "notes.txt/take.mp4"])
def test_demo_refuses_a_video_it_cannot_write_before_streaming(out, tmp_path, capsys):
    """Was refused (.avi) or a traceback (a file for a folder) only after the whole live session had been
    streamed, ~15 s of real time."""
    (tmp_path / "notes.txt").write_text("hello")
    assert main(["demo", "--once", "--port", "0", "--out", str(tmp_path / out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and str(tmp_path / out.split("/")[0]) in err and "Traceback" not in err, err
    assert "streaming" not in captured.out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


@pytest.mark.parametrize(
    "argv",
    [
        ["record", "http://127.0.0.1:9", "--session", "s", "-o", "{tmp}/notes.txt/take.csv"],  # port 9: nothing listens
        ["view", "http://127.0.0.1:9", "--session", "s", "--record", "{tmp}/notes.txt/take.mp4"],
    ],
    ids=["record", "view"],
)
def test_a_take_whose_folder_cannot_be_made_is_refused_before_watching(argv, tmp_path, capsys):
    """Was found only when the take was written, after the whole session had been watched (the take lost);
    the closed port shows the folder is checked first."""
    (tmp_path / "notes.txt").write_text("hello")
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "notes.txt is a file, not a folder" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_train_on_a_folder_of_videos_says_how_to_make_a_corpus(tmp_path, capsys):
    """A studio's first try, `facecast train my_videos -o my.npz`, said only 'not a corpus folder'."""
    (tmp_path / "videos").mkdir()
    (tmp_path / "videos" / "take1.mp4").write_bytes(b"")
    assert main(["train", str(tmp_path / "videos"), "-o", str(tmp_path / "my.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not a corpus folder" in err and "facecast extract VIDEOS -o DIR" in err, err
    assert not (tmp_path / "my.npz").exists()
