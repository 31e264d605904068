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


@pytest.mark.parametrize(
    "argv",
    [
        ["render", "{tmp}/missing.wav", "-o", "{tmp}/take.mp4", "--width", "641"],
        ["say", "Hello.", "-o", "{tmp}/take.mp4", "--height", "481"],
        ["view", "http://127.0.0.1:9", "--record", "{tmp}/take.mp4", "--width", "641"],  # port 9: nothing listens
    ],
    ids=["render", "say", "view"],
)
def test_an_odd_video_size_is_refused_before_any_work(argv, tmp_path, capsys):
    """x264 refuses an odd width or height for 4:2:0 video, but only once the frames arrive: `render --width 641` failed
    with ffmpeg's lines after the model, the rig and the frames; `view --record` after the whole live session."""
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "needs an even width and height" in err, err
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


def test_record_refuses_head_options_without_head_before_watching(tmp_path, capsys):
    """Without --head a .glb is the server's head as served: --head-mode, --landmarks ... shape a head resolved
    here and would do nothing, so they are refused (port 9: nothing listens; the options are refused first)."""
    out = tmp_path / "take.glb"
    assert main(["record", "http://127.0.0.1:9", "-o", str(out), "--head-mode", "retarget", "--landmarks", "l"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--landmarks and --head-mode need --head" in err, err
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


def _speech(path) -> str:
    """A 1.5 s speech-like WAV at 16 kHz (the commands read it; what it says does not matter here)."""
    from assets.audio import write_wav
    from tests.speech import speechlike

    write_wav(path, speechlike(1.5, 16000, seed=1), 16000)
    return str(path)


PROC = "folder /proc is not writable (its file system takes no new files); give a path in another folder"
PROC_D = f"folder /proc/d is missing and cannot be made: {PROC}"


@pytest.mark.parametrize(
    ("argv", "want"),
    [
        (["say", "hi there", "-o", "{tmp}/ok.csv", "-o", "{tmp}/folder.mp4"], "folder.mp4: is a folder"),
        (["say", "hi there", "-o", "{tmp}/ok.csv", "-o", "/proc/x.mp4"], f"/proc/x.mp4: cannot write here: {PROC}"),
        (["say", "hi there", "-o", "/proc/d/x.mp4"], f"/proc/d/x.mp4: cannot write here: {PROC_D}"),
        (
            ["animate", "{wav}", "--csv", "{tmp}/ok.csv", "--glb", "/proc/x.glb"],
            f"/proc/x.glb: cannot write here: {PROC}",
        ),
        (["animate", "{wav}", "--csv", "{tmp}/ok.csv", "--tsv", "{tmp}/folder.tsv"], "folder.tsv: is a folder"),
        (["render", "{wav}", "-o", "{tmp}/folder.mp4"], "folder.mp4: is a folder"),
        (["render", "{wav}", "-o", "/proc/x.mp4"], f"/proc/x.mp4: cannot write here: {PROC}"),
        (["record", "http://127.0.0.1:9", "-o", "/proc/x.csv"], f"/proc/x.csv: cannot write here: {PROC}"),
        (["view", "http://127.0.0.1:9", "--record", "/proc/x.mp4"], f"/proc/x.mp4: cannot write here: {PROC}"),
        (["rig", "builtin", "-o", "/proc/x.npz"], f"/proc/x.npz: cannot write here: {PROC}"),
        (["adapt", "default", "{wav}", "-o", "/proc/m.npz"], f"/proc/m.npz: cannot write here: {PROC}"),
        (["train", "{tmp}/corpus", "-o", "/proc/m.npz"], f"/proc/m.npz: cannot write here: {PROC}"),
        (["readout", "default", "-o", "/proc/m.npz"], f"/proc/m.npz: cannot write here: {PROC}"),
        (["fit-maps", "-o", "/proc/x.py"], f"/proc/x.py: cannot write here: {PROC}"),
        (["phones", "-o", "/proc/x.json"], f"/proc/x.json: cannot write here: {PROC}"),
        (["units", "eval", "--output", "/proc/x.md"], f"/proc/x.md: cannot write here: {PROC}"),
        (["mu", "-o", "/proc/d"], f"/proc/d: cannot write here: {PROC_D}"),
        (["extract", "{wav}", "-o", "/proc/d"], f"/proc/d: cannot write here: {PROC_D}"),
        (["perceptual", "build", "-o", "/proc/d"], f"/proc/d: cannot write here: {PROC_D}"),
        (["corpus", "/proc/d"], f"/proc/d: cannot write here: {PROC_D}"),
    ],
    ids=[
        *("say-folder", "say-proc", "say-missing-folder", "animate-proc", "animate-folder", "render-folder"),
        *("render-proc", "record-proc", "view-proc", "rig-proc", "adapt-proc", "train-proc", "readout-proc"),
        *(
            "fit-maps-proc",
            "phones-proc",
            "units-eval-proc",
            "mu-proc",
            "extract-proc",
            "perceptual-proc",
            "corpus-proc",
        ),
    ],
)
def test_an_output_that_cannot_be_written_is_refused_before_any_work(argv, want, tmp_path, capsys):
    """`say -o ok.csv -o /proc/x.mp4` wrote ok.csv, then failed with a FileNotFoundError traceback (exit 1); a folder
    named as the video was an IsADirectoryError after the render; `rig`/`adapt -o /proc/...` failed only after the
    work; then "cannot write here: No such file or directory" of /proc, a folder that is there; `phones`, `units
    eval` and `fit-maps` failed after their work, `mu`, `corpus` and `perceptual build -o /proc/d` with a traceback.
    Each is now one line naming the output and its folder's problem, exit 2, before anything is written."""
    (tmp_path / "folder.mp4").mkdir()
    (tmp_path / "folder.tsv").mkdir()
    wav = _speech(tmp_path.parent / f"{tmp_path.name}_speech.wav")
    assert main([a.format(tmp=tmp_path, wav=wav) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and want in err and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.mp4", "folder.tsv"]  # nothing else written
    assert list((tmp_path / "folder.mp4").iterdir()) == []


@pytest.mark.parametrize(
    ("argv", "want"),
    [
        (["render", "{wav}", "-o", "{tmp}/x.mp4", "--fps", "1e6"], "argument --fps: 1e6 is outside 1..240 fps"),
        (["animate", "{wav}", "--csv", "{tmp}/x.csv", "--lag", "100000"], "--lag: 100000 is outside 0..30 frames"),
        (["animate", "{wav}", "--csv", "{tmp}/x.csv", "--lag", "nan"], "--lag: expected an integer, got 'nan'"),
        (["adapt", "default", "{wav}", "-o", "{tmp}/m.npz", "--iters", "0"], "--iters: 0 is outside 1..100"),
        (["eval", "--lags", "abc"], "--lags: expected comma-separated integers, got 'abc'"),
        (["eval", "--grid-s1", "{tmp}/nowhere"], "--grid-s1 {tmp}/nowhere: folder not found"),
        (["eval", "--speech-dir", "{tmp}/nowhere"], "--speech-dir {tmp}/nowhere: folder not found"),
        (["animate", "{wav}"], "give at least one output: -o OUT (.csv/.glb/.json/.tsv), --csv, --glb"),
        (["rig", "{tmp}", "-o", "{tmp}/r.npz"], "{tmp}: mesh file is a folder, not a file"),
        (["rig", "builtin", "--landmarks", "{tmp}", "-o", "{tmp}/r.npz"], "{tmp}: landmarks file is a folder"),
        (
            ["render", "{wav}", "--target-map", "map.json", "-o", "{tmp}/x.mp4"],
            "map.json: --target-map names a mesh file's own morph targets; builtin is not a mesh file",
        ),
        # matplotlib reads 'none' as a transparent colour; the video came out black
        (["render", "{wav}", "-o", "{tmp}/x.mp4", "--background", "none"], "'none' is transparent"),
        (["say", "hi", "-o", "{tmp}/x.mp4", "--background", "nocolour"], "expected a colour such as white"),
    ],
    ids=[
        *("fps", "lag", "lag-nan", "iters", "lags", "grid-s1", "speech-dir", "no-output", "mesh-dir", "landmarks-dir"),
        *("target-map-builtin", "background-none", "background-unknown"),
    ],
)
def test_absurd_options_and_folders_for_files_are_refused_in_one_line(argv, want, tmp_path, capsys):
    """`render --fps 1e6` rendered for minutes, `animate --lag 100000` announced a 55-minute delay, `adapt --iters 0`
    wrote an 'adapted' copy of its input, `eval --grid-s1 TYPO` skipped the section and exited 0, a folder given as
    a mesh or landmarks file was "not found", a --target-map for the built-in head was ignored unread: each is now
    one line naming the option, exit 2, nothing written."""
    wav = _speech(tmp_path.parent / f"{tmp_path.name}_speech.wav")
    try:
        code = main([a.format(tmp=tmp_path, wav=wav) for a in argv])
    except SystemExit as exc:  # argparse's own refusal: usage, then one error line
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert want.format(tmp=tmp_path) in err.splitlines()[-1] and "Traceback" not in err, err
    assert list(tmp_path.iterdir()) == []


def test_adapt_refuses_less_than_a_second_of_speech(tmp_path, capsys):
    """A session's enrol refused under a second of speech, `facecast adapt` took 0.2 s: one rule now."""
    from assets.audio import write_wav
    from realtime_core.adaptation import MIN_ENROL_S
    from tests.speech import speechlike

    write_wav(tmp_path / "short.wav", speechlike(0.5 * MIN_ENROL_S, 16000, seed=2), 16000)
    assert main(["adapt", "default", str(tmp_path / "short.wav"), "-o", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert "0.5 s of speech; at least 1 s is needed" in err, err
    assert not (tmp_path / "m.npz").exists()


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["animate", "missing.wav", "-o", "a.csv", "-o", "a.csv"], "a.csv: given twice as an output;"),
        (["animate", "missing.wav", "-o", "a.csv", "-o", "./a.csv"], "a.csv: given twice as an output;"),
        (["animate", "missing.wav", "--csv", "a.csv", "-o", "{tmp}/a.csv"], "given twice as an output (as a.csv);"),
        (["animate", "missing.wav", "-o", "a.json", "--json", "sub/../a.json"], "(as a.json);"),
        (["say", "Hello.", "-o", "a.mp4", "-o", "b.csv", "-o", "./a.mp4"], "a.mp4: given twice as an output;"),
    ],
    ids=["same", "dot-slash", "csv-flag", "json-flag", "say"],
)
def test_an_output_given_twice_is_refused_before_any_work(argv, said, tmp_path, monkeypatch, capsys):
    """`animate SPEECH -o a.csv -o a.csv` wrote a.csv twice (and `-o a.csv -o ./a.csv`, `--csv a.csv -o a.csv`);
    `say` rendered the same video twice. One line naming it, exit 2, before the speech is read or synthesised."""
    monkeypatch.chdir(tmp_path)
    assert main([a.format(tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and said in err and err.endswith("give each output once"), err
    assert list(tmp_path.iterdir()) == []
