"""`facecast rig` and `facecast render` end to end through the CLI entry point."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from facecast.cli import main
from tests.prerequisites import missing, require_tool

# CLI subprocesses with real rendering and ffmpeg.
pytestmark = pytest.mark.system


def test_rig_command_writes_rig_and_picture(tmp_path, shared_data, builtin_head, own_cache, capsys):
    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    out = tmp_path / "mp.npz"
    # --keep-failing: the picture and file are written whatever the extreme-pose checks say
    # (tests/assets/test_rig_checks.py covers refusing a failing rig). --show-landmarks with -o: the
    # landmarks picture and the rig (it once drew the picture and exited without the rig asked for).
    landmarks = tmp_path / "landmarks.png"
    assert main(["rig", str(mp), "-o", str(out), "--keep-failing", "--show-landmarks", str(landmarks)]) == 0
    assert out.is_file() and out.with_suffix(".png").is_file() and landmarks.is_file()
    printed = capsys.readouterr().out
    assert "220 control points" in printed and "rig checks at" in printed
    # Rigging a scan takes seconds to minutes: it says which way it is rigging, and how long it took.
    assert re.search(r"^rig: rigging \(clean lips\) \(\d+ s\)$", printed, re.M), printed
    assert re.search(r"^rig: made in \d+ s$", printed, re.M)
    # It says how to use the file, and that --head MESH reads the same rig (test_rig_command_fills_the_rig_cache).
    assert f"--head {out} (every command; serve --rig {out} too); --head {mp} reads this rig from the cache" in printed
    from assets.heads.rigfile import load_rig

    rig, _mesh = load_rig(out)
    p = np.array([0.02, -0.05, 0.2, 0.03])
    assert rig.displacements(p).any()
    # The rig `facecast rig` writes is the one every other command builds from the same mesh (it once
    # defaulted to plain Sec. 5 interpolation while render/serve used the harmonic field).
    # (A head drives its rig within the checked poses; the file holds the rig itself: compare the fields.)
    from dataclasses import replace

    from assets.heads.head import resolve_head

    np.testing.assert_allclose(
        rig.displacements(p), replace(resolve_head(mp).rig, bound=None).displacements(p), atol=1e-9
    )


def test_save_landmarks_round_trips_through_landmarks(tmp_path, shared_data, own_cache, capsys):
    """docs/heads.md said "to correct a point, give a JSON file", which meant writing all 12 from scratch.
    `rig HEAD --save-landmarks L.json` writes the automatic landmarks (a mesh without a shipped file: MediaPipe's
    canonical face under another name) as the file --landmarks reads; rigging with it gives the same rig, and
    saving again from it gives the same file. The built-in head's are its vertex indices."""
    import shutil

    from assets.heads.landmarks import read_landmarks
    from assets.heads.rigfile import load_rig

    face = tmp_path / "face.obj"  # not a shipped name: its landmarks are found automatically
    shutil.copy(shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj", face)
    found, again = tmp_path / "found.json", tmp_path / "again.json"
    argv = ["rig", str(face), "--keep-failing"]
    assert main([*argv, "-o", str(tmp_path / "a.npz"), "--save-landmarks", str(found)]) == 0
    assert f"rig: landmarks {found}" in capsys.readouterr().out
    spec = read_landmarks(found)
    assert len(spec) == 12 and all(len(v) == 3 for v in spec.values())  # [x, y, z] points
    assert main([*argv, "--landmarks", str(found), "-o", str(tmp_path / "b.npz"), "--save-landmarks", str(again)]) == 0
    assert read_landmarks(again) == spec
    (a, _), (b, _) = load_rig(tmp_path / "a.npz"), load_rig(tmp_path / "b.npz")
    np.testing.assert_array_equal(a.control, b.control)
    p = np.array([0.02, -0.05, 0.2, 0.03])
    np.testing.assert_array_equal(a.displacements(p), b.displacements(p))
    # without -o: only the file (no rig), the built-in head's vertex indices
    assert main(["rig", "builtin", "--save-landmarks", str(tmp_path / "builtin.json")]) == 0
    from assets.heads.builtin import load_builtin_head

    assert read_landmarks(tmp_path / "builtin.json") == {k: int(v) for k, v in load_builtin_head().landmarks.items()}
    assert not list(tmp_path.glob("builtin*.npz"))


def test_rig_prints_paths_with_spaces_as_a_shell_reads_them(tmp_path, shared_data, own_cache, capsys):
    """`rig "my heads/my face.obj" -o "rigs ü/r.npz"` said "use it as --head rigs ü/r.npz ... --head my heads/my
    face.obj reads this rig": pasted into a shell, each path split in two. Now each is quoted as a shell reads it."""
    import shlex
    import shutil

    face = tmp_path / "my heads" / "my face.obj"
    face.parent.mkdir()
    shutil.copy(shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj", face)
    rig, lm = tmp_path / "rigs ü" / "r.npz", tmp_path / "rigs ü" / "l m.json"
    assert main(["rig", str(face), "--keep-failing", "-o", str(rig), "--save-landmarks", str(lm)]) == 0
    out = capsys.readouterr().out
    use = next(ln for ln in out.splitlines() if ln.startswith("rig: use it as "))
    words = shlex.split(use.replace("(", " ").replace(")", " ").replace(";", " "))
    assert [words[i + 1] for i, w in enumerate(words) if w in ("--head", "--rig")] == [str(rig), str(rig), str(face)]
    saved = next(ln for ln in out.splitlines() if ln.startswith("rig: landmarks "))
    assert shlex.split(saved.rstrip(")"))[-1] == str(lm)


def test_a_mesh_rigged_for_a_command_says_so_and_a_cached_one_does_not(tmp_path, shared_data, own_cache, capsys):
    """--head MESH rigs a mesh not in the rig cache before the command's work (seconds to minutes for a scan): each
    rig it makes is announced on stderr with the seconds so far; the next command reads the rig and says nothing."""
    import argparse

    from facecast.commands.headopts import resolve_from_args

    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    args = argparse.Namespace(head=str(mp), landmarks=None, head_mode="auto", target_map=None, head_part=[])
    capsys.readouterr()
    resolve_from_args(args)
    err = capsys.readouterr().err
    assert re.search(rf"^head {re.escape(str(mp))}: rigging \(clean lips\) \(\d+ s\)$", err, re.M), err
    resolve_from_args(args)
    assert "rigging" not in capsys.readouterr().err


def test_rig_command_fills_the_rig_cache(tmp_path, shared_data, own_cache, capsys):
    """`facecast rig MESH -o RIG` leaves the rig where `--head MESH` (say, render, serve) looks for it: the next
    command reads it instead of rigging the head again (it once rigged Lee Perry-Smith a second time). Rig options
    --head cannot give (--method) make a rig of their own, kept out of the cache."""
    import argparse

    from facecast.commands.headopts import resolve_from_args

    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    out = tmp_path / "mp.npz"
    assert main(["rig", str(mp), "-o", str(out), "--keep-failing"]) == 0
    kept = list((own_cache / "rigs").glob("*.npz"))
    assert len(kept) == 1
    before = kept[0].stat()
    args = argparse.Namespace(head=str(mp), landmarks=None, head_mode="auto", target_map=None, head_part=[])
    head = resolve_from_args(args)
    # Read, not rigged again: a new rig would have replaced the file (atomic write: a new inode).
    after = kept[0].stat()
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    assert list((own_cache / "rigs").glob("*.npz")) == kept
    from assets.heads.rigfile import load_rig

    rig, _ = load_rig(out)
    p = np.array([0.02, -0.05, 0.2, 0.03])
    np.testing.assert_allclose(head.rig.matrix.toarray(), rig.matrix.toarray(), atol=1e-7)
    np.testing.assert_allclose(head.rig.neutral, rig.neutral)
    assert head.rig.displacements(p).any()

    # The other way round (say --head MESH first, then rig): the rig command reads the kept rig, and its checks.
    capsys.readouterr()
    again = tmp_path / "again.npz"
    assert main(["rig", str(mp), "-o", str(again), "--keep-failing"]) == 0
    printed = capsys.readouterr().out
    assert f"read from the rig cache ({kept[0]})" in printed and "rig checks at" in printed
    after = kept[0].stat()
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    rig_again, _ = load_rig(again)
    np.testing.assert_array_equal(rig_again.matrix.toarray(), rig.matrix.toarray())
    assert rig_again.meta["checks"] == rig.meta["checks"]

    assert main(["rig", str(mp), "-o", str(tmp_path / "sec5.npz"), "--keep-failing", "--method", "sec5"]) == 0
    assert list((own_cache / "rigs").glob("*.npz")) == kept
    assert f"--head {mp} rigs it again" in capsys.readouterr().out

    # The same file given as another path (a copy in another folder; the rig cache key once held the path as typed)
    # is the same head: its rig is read from the cache, under the name given now (errors and pictures name the file
    # the user typed).
    import shutil

    other = tmp_path / "elsewhere" / mp.name
    other.parent.mkdir()
    shutil.copyfile(mp, other)
    args = argparse.Namespace(head=str(other), landmarks=None, head_mode="auto", target_map=None, head_part=[])
    head = resolve_from_args(args)
    assert list((own_cache / "rigs").glob("*.npz")) == kept
    after = kept[0].stat()
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns)
    assert head.mesh.name == str(other)


def test_rig_command_errors_name_the_file(tmp_path, shared_data, builtin_head, capsys):
    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    bad = tmp_path / "bad_landmarks.json"
    bad.write_text('{"landmarks": {"chin": 152}}')
    assert main(["rig", str(mp), "--landmarks", str(bad), "-o", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "bad_landmarks.json: missing landmarks" in err
    box = tmp_path / "box.obj"  # not a face: automatic landmarks find none
    box.write_text(
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n"
        "f 1 2 3\nf 1 3 4\nf 5 7 6\nf 5 8 7\nf 1 5 6\nf 1 6 2\nf 2 6 7\nf 2 7 3\nf 3 7 8\nf 3 8 4\n"
        "f 4 8 5\nf 4 5 1\n"
    )
    assert main(["rig", str(box), "-o", str(tmp_path / "y.npz")]) == 2
    err = capsys.readouterr().err
    assert "box.obj: no face-like region" in err and "--landmarks" in err and not (tmp_path / "y.npz").exists()
    empty = tmp_path / "empty.ply"
    empty.write_text(
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    )
    assert main(["rig", str(empty), "--landmarks", str(bad), "-o", str(tmp_path / "z.npz")]) == 2
    assert "empty.ply" in capsys.readouterr().err


def _bad_heads(tmp: Path) -> dict[str, tuple[list[str], str, str]]:
    """case -> (head arguments, the file the message must name, words of the message)."""
    import json

    import trimesh

    from assets.heads.glb import glb_container

    (tmp / "empty.obj").write_text("v 0 0 0\nv 1 0 0\n")
    (tmp / "nomesh.glb").write_bytes(
        glb_container({"asset": {"version": "2.0"}, "scenes": [{"nodes": []}], "scene": 0})
    )
    trimesh.creation.icosphere(3).export(str(tmp / "sphere.obj"))
    from assets.heads.rigging import REQUIRED_LANDMARKS

    far = {k: [1000.0, 1000.0, 1000.0 + i] for i, k in enumerate(REQUIRED_LANDMARKS)}
    (tmp / "far.json").write_text(json.dumps({"landmarks": far}))
    (tmp / "head.fbx").write_bytes(b"Kaydara FBX Binary  \x00")
    return {
        "no mesh (obj)": (["empty.obj"], "empty.obj", "no triangle mesh"),
        "no mesh (glb)": (["nomesh.glb"], "nomesh.glb", "no triangle mesh"),
        "no face-like region": (["sphere.obj"], "sphere.obj", "no face-like region"),
        "landmarks off the mesh": (["sphere.obj", "--landmarks", "far.json"], "far.json", "off the mesh"),
        "unsupported extension": (["head.fbx"], "head.fbx", "unsupported"),
    }


@pytest.mark.parametrize("command", ["rig", "render"])
def test_bad_heads_fail_with_one_line_exit_2_and_leave_nothing(tmp_path, own_cache, capfd, monkeypatch, command):
    """Each bad-input class of the issue: one line naming the file, the problem and what to do; exit
    code 2; no rig, picture, video or cache file left behind."""
    cases = _bad_heads(tmp_path)
    monkeypatch.chdir(tmp_path)
    from scipy.io import wavfile

    speech = tmp_path / "speech.wav"
    wavfile.write(speech, 16000, np.zeros(1600, np.int16))
    before_cache = set(own_cache.rglob("*"))
    before = set(tmp_path.iterdir())
    capfd.readouterr()
    for case, (head, named, words) in cases.items():
        if command == "rig":
            argv = ["rig", *head, "-o", "out.npz"]
        else:
            argv = ["render", str(speech), "--params", "p.csv", "--head", head[0], *head[1:], "-o", "out.mp4"]
            (tmp_path / "p.csv").write_text(  # the speech's 0.1 s: 3 frames (else a warning says they differ)
                "t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress\n"
                + "".join(f"{k / 30:.6f},0,0,0,0\n" for k in range(3))
            )
        assert main(argv) == 2, case
        err = capfd.readouterr().err.strip().splitlines()
        assert len(err) == 1, f"{case}: {err}"
        assert named in err[0] and words in err[0], f"{case}: {err[0]}"
        assert any(h in err[0] for h in ("give", "convert", "export")), f"{case}: no way forward in {err[0]!r}"
        (tmp_path / "p.csv").unlink(missing_ok=True)
        assert set(tmp_path.iterdir()) == before, f"{case}: left {set(tmp_path.iterdir()) - before}"
    assert set(own_cache.rglob("*")) == before_cache


def test_ply_round_trip(tmp_path, shared_data):
    import trimesh

    from assets.heads.mesh import load_mesh

    mp = shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    m = load_mesh(mp)
    ply = tmp_path / "face.ply"
    trimesh.Trimesh(m.vertices, m.triangles, process=False).export(ply)
    m2 = load_mesh(ply)
    np.testing.assert_allclose(m2.vertices, m.vertices, rtol=1e-6)
    np.testing.assert_array_equal(m2.triangles, m.triangles)


def _require_rendering(builtin_rig) -> None:
    """Skip (fail under CI) without ffmpeg/ffprobe or an OpenGL 3.3 context through EGL."""
    if shutil.which("ffmpeg") is None or shutil.which("ffprobe") is None:
        missing("ffmpeg/ffprobe not installed")
    from clients.errors import RenderError
    from clients.render.renderer import RenderConfig, renderer_for_rig

    try:
        renderer_for_rig(*builtin_rig, RenderConfig(width=32, height=32)).close()
    except RenderError as exc:
        missing(f"no OpenGL 3.3 context through EGL here: {exc}")


def test_render_command_with_params_csv(tmp_path, shared_data, builtin_rig, capsys):
    _require_rendering(builtin_rig)
    csv = tmp_path / "p.csv"
    t = np.arange(0, 0.3, 1 / 30)
    rows = ["t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress"]
    rows += [f"{x:.4f},0,0,{0.1 * np.sin(10 * x) ** 2:.4f},0" for x in t]
    csv.write_text("\n".join(rows) + "\n")
    wav = shared_data / "speech" / "arctic" / "arctic_a0009.wav"
    out = tmp_path / "v.mp4"
    args = ["render", str(wav), "--params", str(csv), "-o", str(out), "--width", "160", "--height", "120"]
    assert main([*args, "--background", "#ffe4c4", "--png-dir", str(tmp_path / "png")]) == 0
    assert out.is_file() and out.stat().st_size > 1000
    from PIL import Image

    corner = np.asarray(Image.open(tmp_path / "png" / "frame_00000.png").convert("RGB"))[2, 2]
    assert np.abs(corner.astype(int) - [0xFF, 0xE4, 0xC4]).max() <= 2, corner  # --background (bisque)
    captured = capsys.readouterr()
    assert f"{len(t)} frames at 30 fps" in captured.out
    # the frames counted as they render (a 10-minute file rendered for 10 minutes without a word)
    assert f"render: 100%|##########| {len(t)}/{len(t)}" in captured.err, captured.err


def test_render_params_longer_or_shorter_than_the_speech(tmp_path, builtin_rig, capsys):
    """`render SPEECH --params P` with P 2 s longer than the speech failed after the whole render with "ffmpeg failed
    (-1)" (ffmpeg ended the video with its sound and stopped reading frames); P much shorter ended the video there
    without a word. Now the video ends with the shorter of the two and one warning line says so."""
    _require_rendering(builtin_rig)
    from assets.audio import write_wav
    from assets.video import probe
    from tests.speech import speechlike

    wav = tmp_path / "s.wav"
    write_wav(wav, speechlike(0.5, 16000), 16000)  # 15 frames at 30 fps
    for seconds, frames, shorter in ((2.5, 15, "the speech, at 0.50 s"), (0.2, 6, "the parameters, at 0.20 s")):
        csv = tmp_path / f"p{seconds}.csv"
        t = np.arange(round(seconds * 30)) / 30
        rows = ["t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress"]
        csv.write_text("\n".join(rows + [f"{x:.6f},0,0,{0.1 * np.sin(10 * x) ** 2:.4f},0" for x in t]) + "\n")
        out = tmp_path / f"v{seconds}.mp4"
        assert main(["render", str(wav), "--params", str(csv), "-o", str(out), "--width", "96", "--height", "64"]) == 0
        got = capsys.readouterr()
        assert f"{frames} frames at 30 fps" in got.out
        warnings = [ln for ln in got.err.splitlines() if "warning" in ln]
        assert warnings == [
            f"facecast render: warning: {csv}: {seconds:.2f} s of mouth parameters for 0.50 s of speech in {wav}: "
            f"the video ends with {shorter}"
        ], got.err
        assert int(probe(out)["video"]["nb_frames"]) == frames
    # parameters of the speech's own length (an edited `animate` CSV): no warning
    csv = tmp_path / "same.csv"
    csv.write_text(
        "t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress\n"
        + "".join(f"{k / 30:.6f},0,0,0.05,0\n" for k in range(15))
    )
    assert (
        main(
            [
                "render",
                str(wav),
                "--params",
                str(csv),
                "-o",
                str(tmp_path / "same.mp4"),
                "--width",
                "96",
                "--height",
                "64",
            ]
        )
        == 0
    )
    assert "warning" not in capsys.readouterr().err


@pytest.mark.slow
def test_mu_stages_only_refuses_a_mapper_trained_on_other_clips(tmp_path, shared_data, capsys):
    """`facecast mu --stages-only` keeps the speech bank and refits only the second stages, so the Utterance MUs
    it refits must be the ones the bank was trained on: on 30 sentences they are not, and the shipped
    mapper is refused by name, with nothing written."""
    import assets
    from tests.prerequisites import require_data

    root = require_data("video/grid_s1")
    shipped = Path(assets.__file__).parent / "data" / "mlp_mapper.npz"
    out = tmp_path / "out"
    rc = main(["mu", "--root", str(root), "--limit", "30", "--stages-only", str(shipped), "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "mlp_mapper.npz" in err and "UMUP readout differs" in err, err
    assert not (out / "mlp_mapper.npz").exists()


def _grey_ramp_video(path: Path, *, fps: int, n: int, picture_delay_s: float) -> np.ndarray:
    """A 40x32 video whose frame j is uniformly grey (the returned (n,) levels), its picture starting
    ``picture_delay_s`` after its sound (a second of a tone), H.264 at qp 0."""
    import subprocess

    levels = 16 + 8 * np.arange(n)
    frames = np.repeat(levels.astype(np.uint8), 32 * 40 * 3).tobytes()
    cmd = ["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", "40x32", "-r", str(fps)]
    cmd += ["-i", "-", "-f", "lavfi", "-i", "sine=frequency=220:duration=1.2"]
    cmd += ["-vf", f"setpts=PTS+{picture_delay_s}/TB"]
    cmd += ["-c:v", "libx264", "-qp", "0", "-pix_fmt", "yuv444p", "-c:a", "aac", str(path)]
    subprocess.run(cmd, input=frames, check=True)
    return levels


def test_render_a_video_larger_than_the_render_as_its_speech(tmp_path, builtin_rig, ffmpeg, capsys):
    """`render clip.mp4 --beside clip.mp4` (docs/training.md) with a 1280x720 clip: ffmpeg, not told which input's
    picture to keep, took the clip's (the larger) and stopped reading the rendered frames: "ffmpeg failed (-1)",
    nothing written (at a render larger than the clip it worked). A --beside picture that ends away from the speech
    (a 1 s clip beside 2 s of it froze for a second) is said in one warning line."""
    import subprocess

    from assets.video import probe

    _require_rendering(builtin_rig)
    clip = tmp_path / "hd.mp4"
    cmd = [ffmpeg, "-v", "error", "-y", "-f", "lavfi", "-i", "testsrc=size=1280x720:rate=25:duration=2"]
    cmd += ["-f", "lavfi", "-i", "sine=frequency=220:duration=2", "-c:v", "libx264", "-preset", "ultrafast"]
    subprocess.run([*cmd, "-c:a", "aac", "-shortest", str(clip)], check=True)
    out = tmp_path / "v.mp4"
    assert main(["render", str(clip), "-o", str(out), "--width", "96", "--height", "64"]) == 0, capsys.readouterr()
    video, audio = probe(out)["video"], probe(out)["audio"]
    assert (int(video["width"]), int(video["height"])) == (96, 64) and audio is not None
    assert "warning" not in capsys.readouterr().err
    short = tmp_path / "one.mp4"
    subprocess.run([ffmpeg, "-v", "error", "-y", "-i", str(clip), "-t", "1", str(short)], check=True)
    args = ["render", str(clip), "--beside", str(short), "-o", str(tmp_path / "b.mp4"), "--width", "96"]
    assert main([*args, "--height", "64"]) == 0
    err = capsys.readouterr().err
    assert f"warning: {short}: 1.00 s of picture beside " in err and "its last picture is held to the end" in err
    # `-o` onto the clip it is made from replaced the user's recording by the render (`say --audio` refuses it)
    before = clip.read_bytes()
    for argv in (["render", str(clip)], ["render", str(tmp_path / "one.mp4"), "--beside", str(clip)]):
        assert main([*argv, "-o", str(tmp_path / "." / "hd.mp4")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "hd.mp4: the video would overwrite the " in err[0] and "give another name" in err[0]
    assert clip.read_bytes() == before


def test_render_beside_shows_the_recorded_picture_of_each_frames_instant(tmp_path, builtin_rig, capsys):
    """`render --beside VIDEO`: the video's picture on screen at each rendered frame's media time (on the
    audio's clock: this picture starts 0.2 s after its sound), scaled to the render's height, left of
    the head; a file that is not a video fails before any rendering."""
    _require_rendering(builtin_rig)
    clip = tmp_path / "talker.mp4"
    levels = _grey_ramp_video(clip, fps=25, n=25, picture_delay_s=0.2)
    csv = tmp_path / "p.csv"
    t = np.arange(0, 1.1, 1 / 30)
    csv.write_text(
        "t,upper_lip_raise,lip_stretch,mouth_open,lip_corner_depress\n" + "".join(f"{x:.4f},0,0,0,0\n" for x in t)
    )
    png = tmp_path / "png"
    args = ["render", str(clip), "--params", str(csv), "--beside", str(clip), "-o", str(tmp_path / "v.mp4")]
    assert main([*args, "--width", "160", "--height", "120", "--png-dir", str(png)]) == 0
    assert "310x120" in capsys.readouterr().out  # 40x32 scaled to 120 rows: 150 columns, then the head's 160
    from PIL import Image

    for k in range(len(t)):
        img = np.asarray(Image.open(png / f"frame_{k:05d}.png"), dtype=np.float64)
        assert img.shape == (120, 310, 3)
        j = min(max(int(np.floor((k / 30 - 0.2) * 25 + 1e-6)), 0), len(levels) - 1)  # the picture shown at k/30
        assert abs(img[:, :150].mean() - levels[j]) < 3, (k, j, img[:, :150].mean())
    text = tmp_path / "notes.txt"
    text.write_text("not a video\n")
    out = tmp_path / "bad.mp4"
    assert main(["render", str(clip), "--params", str(csv), "--beside", str(text), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "notes.txt: not a video" in err[0], err
    assert not out.exists()


def test_render_at_any_frame_rate_covers_the_whole_speech(tmp_path, own_cache):
    """`render --fps 29.97` of 3.095 s of speech wrote 92 frames (3.0697 s: its frames were put on the grid only up to
    the last 30 fps frame's time, not to that frame's end) and ffmpeg's -shortest cut the speech to the video. At 24,
    29.97 and 60 fps the video now lasts at least as long as the speech, less than one frame longer, and the audio
    stream is the whole speech (ffprobe's durations of both streams)."""
    require_tool("ffprobe", "apt package ffmpeg")
    from assets.audio import write_wav
    from assets.video import probe
    from tests.speech import speechlike

    rate = 16000
    n = int(3.095 * rate)  # 92.85 frames at 30 fps, 92.76 at 29.97: the last frame's end past the speech
    wav = write_wav(tmp_path / "s.wav", speechlike(n / rate, rate, seed=3)[:n], rate)
    for fps in (29.97, 24.0, 60.0):
        out = tmp_path / f"s{fps:g}.mp4"
        assert main(["render", str(wav), "-o", str(out), "--fps", f"{fps:g}", "--width", "96", "--height", "96"]) == 0
        streams = probe(out)
        video, audio = float(streams["video"]["duration"]), float(streams["audio"]["duration"])
        assert n / rate <= video < n / rate + 1 / fps + 1e-3, (fps, video)
        assert audio == pytest.approx(n / rate, abs=2e-3), (fps, audio)  # the whole speech, not cut at the video
        assert int(streams["video"]["nb_frames"]) == int(np.ceil(n / rate * fps))


def test_render_params_written_at_another_rate_covers_the_whole_speech(tmp_path, own_cache, capsys):
    """`animate SPEECH --fps 24 -o p.csv` then `render SPEECH --params p.csv --fps 30` (or 60) of 2.14 s of speech:
    the rows were put on the grid only up to the last row's time (2.125 s), a video of 64 frames (2.133 s) for the
    speech's 65 (at 60 fps 128 for 129). Now the video covers the speech, less than one frame longer, the audio
    stream is the whole speech, and no warning (the file covers the speech)."""
    require_tool("ffprobe", "apt package ffmpeg")
    from assets.audio import write_wav
    from assets.video import probe
    from tests.speech import speechlike

    rate = 16000
    n = int(2.14 * rate)  # 52 rows at 24 fps, the last at 2.125 s: short of the speech at 30 and 60 fps
    wav = write_wav(tmp_path / "s.wav", speechlike(n / rate, rate, seed=5)[:n], rate)
    csv = tmp_path / "p.csv"
    assert main(["animate", str(wav), "--fps", "24", "-o", str(csv)]) == 0
    capsys.readouterr()
    for fps in (30.0, 60.0):
        out = tmp_path / f"s{fps:g}.mp4"
        argv = ["render", str(wav), "--params", str(csv), "-o", str(out), "--fps", f"{fps:g}"]
        assert main([*argv, "--width", "96", "--height", "96"]) == 0
        assert "warning" not in capsys.readouterr().err
        streams = probe(out)
        video, audio = float(streams["video"]["duration"]), float(streams["audio"]["duration"])
        assert n / rate <= video < n / rate + 1 / fps + 1e-3, (fps, video)
        assert audio == pytest.approx(n / rate, abs=2e-3), (fps, audio)
        assert abs(video - audio) < 1 / fps, (fps, video, audio)
        assert int(streams["video"]["nb_frames"]) == int(np.ceil(n / rate * fps))
