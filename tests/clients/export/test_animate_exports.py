"""``facecast animate --csv/--glb/--json/--tsv`` on one file: every output holds the same curves."""

from __future__ import annotations

import functools
import json
import operator

import numpy as np
import pytest

from assets.tracks import decode_csv, decode_json
from clients.export.rhubarb import Cue, read_tsv
from facecast.cli import main
from tests.prerequisites import require_module
from tests.speech import speechlike

# `facecast animate` in a subprocess.
pytestmark = pytest.mark.system


def _animated_weights(g) -> np.ndarray:
    """(frames, targets) float32: the morph weights a facecast glb's one animation sampler holds (pygltflib GLTF2)."""
    acc = g.accessors[g.animations[0].samplers[0].output]
    view = g.bufferViews[acc.bufferView]
    n = len(g.meshes[0].extras["targetNames"])
    return np.frombuffer(g.binary_blob(), "<f4", acc.count, view.byteOffset + (acc.byteOffset or 0)).reshape(-1, n)


def test_animate_writes_every_export_with_equal_curves(tmp_path):
    pygltflib = require_module("pygltflib")
    from assets.audio import write_wav
    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = tmp_path / "s.wav"
    write_wav(wav, speechlike(1.0, 16000), 16000)
    out = {s: tmp_path / f"take.{s}" for s in ("csv", "glb", "json", "tsv")}
    # The retargeted built-in head: its glb animates the 4 parameter targets with the curves themselves
    # (then one lip-contact target per lip column, weighted by that column's crossing).
    rc = main(
        [
            "animate",
            str(wav),
            "--model",
            str(model),
            "--head-mode",
            "retarget",
            *functools.reduce(operator.iadd, ([f"--{s}", str(p)] for s, p in out.items()), []),
        ]
    )
    assert rc == 0
    csv_t = decode_csv(out["csv"].read_bytes())
    js = decode_json(out["json"].read_bytes())
    assert csv_t.n_frames == js.n_frames == 30
    np.testing.assert_allclose(js.values, csv_t.values, rtol=1e-8, atol=1e-12)  # CSV: 9 significant digits
    g = pygltflib.GLTF2().load(str(out["glb"]))
    w = _animated_weights(g)
    # The glb drives the head within the checked poses (a viewer of the file must not see a fold): its
    # curves are the parameters' nearest checked poses, the parameters themselves wherever they lie inside.
    # (This test model's untrained output reaches 9 IOD: far outside.)
    from assets.heads.head import resolve_head

    bound = resolve_head("builtin", mode="retarget").rig.bound  # the head's: its checked poses, its closure reach
    np.testing.assert_allclose(w[:, :4], bound(js.values), rtol=1e-6, atol=1e-7)
    inside = bound.contains(js.values)
    np.testing.assert_allclose(w[inside, :4], js.values[inside], rtol=1e-6, atol=1e-7)
    assert (tmp_path / "take.wav").is_file()
    assert read_tsv(out["tsv"].read_bytes())[-1].shape == "X"


def test_animate_o_writes_by_suffix_the_same_files_as_the_format_flags(tmp_path, capsys):
    """`animate x.wav -o x.csv` failed with the top-level usage (say and record take -o): -o (repeatable) picks
    the format by the suffix and writes byte for byte what --csv/--json/--tsv write; an unknown suffix is
    refused in one line before any work."""
    from assets.audio import write_wav
    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = write_wav(tmp_path / "s.wav", speechlike(1.0, 16000), 16000)
    (tmp_path / "o").mkdir()
    (tmp_path / "f").mkdir()
    formats = ("csv", "json", "tsv")
    by_o = [a for s in formats for a in ("-o", str(tmp_path / "o" / f"take.{s}"))]
    by_flag = [a for s in formats for a in (f"--{s}", str(tmp_path / "f" / f"take.{s}"))]
    for argv in (by_o, by_flag):
        assert main(["animate", str(wav), "--model", str(model), *argv]) == 0, capsys.readouterr().err
    for s in (*formats, "wav"):  # the .wav beside the .json too
        assert (tmp_path / "o" / f"take.{s}").read_bytes() == (tmp_path / "f" / f"take.{s}").read_bytes(), s
    capsys.readouterr()
    assert main(["animate", str(wav), "--model", str(model), "-o", str(tmp_path / "take.mp4")]) == 2
    err = capsys.readouterr().err.strip()
    assert "take.mp4: unknown output format '.mp4'" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "take.mp4").exists()


def test_animate_needs_an_output(tmp_path, capsys):
    assert main(["animate", str(tmp_path / "missing.wav")]) == 2  # one line through the error root (was exit 1)
    assert "give at least one output" in capsys.readouterr().err


def test_animate_arkit_glb_carries_the_expression_shapes(tmp_path):
    """``--glb-morphs arkit52 --expression smile:0.7@1.2``: the exported weights, read back from the glb,
    are the speech's ARKit weights plus the smile's recipe at 0.7 from 1.2 s on (eased over 0.3 s), and
    exactly the speech's before it; the CSV carries the four parameters under the expression."""
    pygltflib = require_module("pygltflib")
    from assets.audio import write_wav
    from assets.modelfile import save_model
    from realtime_core.blendshapes import ARKIT_NAMES, blendshape_weights
    from realtime_core.expressions import EXPRESSION_RECIPES
    from realtime_core.pipeline import speech_to_params
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = tmp_path / "s.wav"
    x = speechlike(2.0, 16000)
    write_wav(wav, x, 16000)
    glb, csv = tmp_path / "take.glb", tmp_path / "take.csv"
    argv = ["animate", str(wav), "--model", str(model), "--glb", str(glb), "--csv", str(csv)]
    assert main([*argv, "--glb-morphs", "arkit52", "--expression", "smile:0.7@1.2"]) == 0
    g = pygltflib.GLTF2().load(str(glb))
    assert g.meshes[0].extras["targetNames"] == list(ARKIT_NAMES)
    w = _animated_weights(g)
    from assets.audio import read_audio

    samples, _ = read_audio(wav)
    speech = speech_to_params(small_model(), samples)
    t = np.arange(len(w)) / 30
    np.testing.assert_allclose(w[t < 1.2], blendshape_weights(speech[t < 1.2], "arkit52"), atol=1e-6)
    late = t >= 1.5  # eased in fully
    for name, v in EXPRESSION_RECIPES["smile"].items():
        j = ARKIT_NAMES.index(name)
        base = blendshape_weights(speech[late], "arkit52")[:, j]
        np.testing.assert_allclose(w[late, j], np.clip(base + 0.7 * v, 0, 1), atol=1e-6)
    assert w[late, ARKIT_NAMES.index("mouthSmileLeft")].min() >= 0.35 - 1e-6
    assert w[t < 1.2, ARKIT_NAMES.index("cheekSquintLeft")].max() == 0.0
    # The four parameters carry the expression too (not only the ARKit weights).
    p = decode_csv(csv.read_bytes()).values
    np.testing.assert_allclose(p[t < 1.2], speech[t < 1.2], rtol=1e-8, atol=1e-12)  # CSV: 9 significant digits
    assert np.abs(p[late] - speech[late]).max() > 1e-3


def test_animate_curves_writes_the_blendshape_weights_an_engine_drives_as_csv_and_json(tmp_path, capsys):
    """An engine's own ARKit face (a VTuber's "perfect sync" avatar, a MetaHuman) takes per-frame ARKit weights, which
    only a glb carried: ``--curves arkit52`` writes them as the CSV / JSON, the same numbers as the ``--glb-morphs
    arkit52`` glb of the same run animates, expression included; ``ovr15`` the visemes; the TSV stays the mouth
    shapes. Without a .csv/.json to hold them the option is refused in one line."""
    pygltflib = require_module("pygltflib")
    from assets.audio import write_wav
    from assets.modelfile import save_model
    from realtime_core.expressions import EXPRESSION_RECIPES
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = write_wav(tmp_path / "s.wav", speechlike(2.0, 16000), 16000)
    run = ["animate", str(wav), "--model", str(model), "--expression", "smile:0.7@1.0"]
    outs = [tmp_path / f"w.{s}" for s in ("csv", "json", "glb", "tsv")]
    assert (
        main([*run, "--curves", "arkit52", "--glb-morphs", "arkit52", *(a for o in outs for a in ("-o", str(o)))]) == 0
    )
    assert main([*run, "-o", str(tmp_path / "p.tsv"), "-o", str(tmp_path / "p.csv")]) == 0
    g = pygltflib.GLTF2().load(str(outs[2]))
    names = g.meshes[0].extras["targetNames"]
    w = _animated_weights(g)
    csv_t, js = decode_csv(outs[0].read_bytes()), decode_json(outs[1].read_bytes())
    assert csv_t.names == js.names == tuple(names) and len(set(names)) == 52  # the glb's names and order
    assert js.fps == 30.0 and csv_t.n_frames == len(w) == 60 and csv_t.times()[0] == 0.0
    np.testing.assert_allclose(csv_t.values, w, rtol=1e-7, atol=1e-9)  # float32 weights, 9 significant digits
    np.testing.assert_allclose(js.values, csv_t.values, rtol=1e-8, atol=1e-12)  # CSV: 9 significant digits
    assert w.min() >= 0.0 and w.max() <= 1.0
    assert "blendshape weight" in json.loads(outs[1].read_bytes())["units"]
    smile = names.index("cheekSquintLeft")  # the expression's own shape, in no speech weight
    assert w[:30, smile].max() == 0.0 and w[-1, smile] == pytest.approx(
        0.7 * EXPRESSION_RECIPES["smile"]["cheekSquintLeft"]
    )
    assert outs[3].read_bytes() == (tmp_path / "p.tsv").read_bytes()  # cues of the parameters, not of weights
    assert decode_csv((tmp_path / "p.csv").read_bytes()).names[2] == "mouth_open"  # the default is unchanged
    assert main([*run, "--curves", "ovr15", "--csv", str(tmp_path / "v.csv")]) == 0
    v = decode_csv((tmp_path / "v.csv").read_bytes())
    assert v.names[:3] == ("sil", "PP", "FF") and len(v.names) == 15 and 0.0 <= v.values.min() <= v.values.max() <= 1
    capsys.readouterr()
    assert main([*run, "--curves", "arkit52", "-o", str(tmp_path / "only.tsv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--curves arkit52" in err and not (tmp_path / "only.tsv").exists()


def test_animate_fps_writes_the_model_rates_cues_on_its_own_frames(tmp_path):
    """`animate --fps 24 -o x.tsv` writes the cues of the 30 fps parameters placed on 24 fps frames (cues of curves
    interpolated onto 24 fps lost one-frame closures): the same bytes as the exporter's from the 30 fps CSV."""
    from assets.audio import write_wav
    from assets.modelfile import save_model
    from clients.export.rhubarb import tsv_bytes
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = write_wav(tmp_path / "s.wav", speechlike(2.0, 16000), 16000)
    assert main(["animate", str(wav), "--model", str(model), "-o", str(tmp_path / "p.csv")]) == 0
    at30 = decode_csv((tmp_path / "p.csv").read_bytes())
    for fps in (24, 60):
        out = tmp_path / f"p{fps}.tsv"
        assert main(["animate", str(wav), "--model", str(model), "--fps", str(fps), "-o", str(out)]) == 0
        assert out.read_bytes() == tsv_bytes(at30, fps=fps)
        got = read_tsv(out.read_bytes())
        assert all(abs(c.start_s * fps - round(c.start_s * fps)) <= 0.005 * fps + 1e-9 for c in got)  # 2 decimals


def test_animate_refuses_before_writing_anything(tmp_path, capsys):
    """Every refusal is one line, exit 2, and leaves no file: the .wav beside a .glb/.json would be the input
    speech itself (a stereo recording would be replaced by its mono copy), an export whose suffix is not its
    option's format, --glb-morphs arkit52 on a head without ARKit targets, a head that is not a mesh."""
    import wave

    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = tmp_path / "take.wav"
    with wave.open(str(wav), "wb") as w:  # stereo: the mono copy that would replace it differs
        w.setnchannels(2)
        w.setsampwidth(2)
        w.setframerate(16000)
        x = np.round(speechlike(1.0, 16000) * 16000).astype("<i2")
        w.writeframes(np.stack([x, x // 2], axis=1).tobytes())
    before = wav.read_bytes()
    not_a_head = tmp_path / "notes.txt"
    not_a_head.write_text("hello")
    cases = {
        "take.wav": ["--csv", "o.csv", "--glb", "take.glb"],
        "o.csv": ["--csv", "o.csv", "--json", "o.csv"],
        "arkit": ["--csv", "o.csv", "--glb", "o.glb", "--glb-morphs", "arkit52", "--head", str(not_a_head)],
        "notes.txt": ["--csv", "o.csv", "--glb", "o.glb", "--head", str(not_a_head)],
    }
    for named, outs in cases.items():
        argv = [str(tmp_path / o) if o.startswith(("o.", "take.")) else o for o in outs]
        assert main(["animate", str(wav), "--model", str(model), *argv]) == 2, named
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and named in err and "Traceback" not in err, err
        assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz", "notes.txt", "take.wav"], named
    assert wav.read_bytes() == before


def test_too_short_speech_names_the_file(tmp_path, capsys):
    """20 ms of speech (less than one analysis window) is refused by animate and render with one line that
    names the file and both durations, exit 2, nothing written."""
    from assets.audio import write_wav
    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = tmp_path / "blip.wav"
    write_wav(wav, speechlike(1.0, 16000)[:320], 16000)
    capsys.readouterr()
    for argv in (
        ["animate", str(wav), "--csv", str(tmp_path / "o.csv")],
        ["render", str(wav), "-o", str(tmp_path / "o.mp4")],
    ):
        assert main([*argv, "--model", str(model)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and f"{wav}: audio too short: 20 ms" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blip.wav", "m.npz"]


def test_a_silent_take_animates_a_closed_mouth(tmp_path):
    """Digital silence is a take (a pause line), not an error: every frame the rest pose, one rest cue."""
    from assets.audio import write_wav

    wav = tmp_path / "pause.wav"
    write_wav(wav, np.zeros(16000, dtype=np.float32), 16000)
    rc = main(["animate", str(wav), "--csv", str(tmp_path / "p.csv"), "--tsv", str(tmp_path / "p.tsv")])
    assert rc == 0
    track = decode_csv((tmp_path / "p.csv").read_bytes())
    assert track.n_frames == 30
    assert np.all(track.values == track.values[0])  # no motion at all
    assert track.values[0, 2] == 0.0  # mouth_open at the closed pose
    assert read_tsv((tmp_path / "p.tsv").read_bytes()) == [Cue(0.0, "X"), Cue(1.0, "X")]  # rest, and its end


_PROBES: list[str] = []
_LISTENING: list[bool] = []


def _probes_made(event: str, args: tuple) -> None:
    """An audit hook (Python's own events: the files made, not a stand-in): the probe files check_writable makes."""
    if _LISTENING and event == "tempfile.mkstemp" and str(args[0]).endswith(".probe"):
        _PROBES.append(str(args[0]))


def test_a_commands_exports_are_probed_once(tmp_path):
    """`facecast animate --json --tsv`: check_outputs probes each output before the work (a file made and removed
    beside it), and export_track probed it again when writing it; a command now hands its check over."""
    import sys

    from assets.audio import write_wav
    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = write_wav(tmp_path / "s.wav", speechlike(1.0, 16000), 16000)
    if not _LISTENING:
        sys.addaudithook(_probes_made)  # hooks cannot be removed: it records only while _LISTENING is set
    _PROBES.clear()
    _LISTENING.append(True)
    try:
        rc = main(
            [
                "animate",
                str(wav),
                "--model",
                str(model),
                "--json",
                str(tmp_path / "a.json"),
                "--tsv",
                str(tmp_path / "a.tsv"),
            ]
        )
    finally:
        _LISTENING.clear()
    assert rc == 0 and (tmp_path / "a.json").is_file() and (tmp_path / "a.tsv").is_file()
    probed = sorted(p.split("/")[-1].split(".")[1] for p in _PROBES)  # ".a.json.XXXX.probe" -> "a"
    assert len(_PROBES) == 2 and probed == ["a", "a"], _PROBES
