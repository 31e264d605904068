"""``facecast animate --csv/--glb/--json/--tsv`` on one file: every output holds the same curves."""

from __future__ import annotations

import functools
import operator

import numpy as np
import pytest

from assets.tracks import decode_csv, decode_json
from clients.export.rhubarb import read_tsv
from facecast.cli import main
from tests.prerequisites import require_module
from tests.speech import speechlike

# `facecast animate` in a subprocess.
pytestmark = pytest.mark.system


def test_animate_writes_every_export_with_equal_curves(tmp_path):
    pygltflib = require_module("pygltflib")
    from assets.audio import write_wav
    from assets.modelfile import save_model
    from tests.speech import small_model

    model = save_model(tmp_path / "m.npz", small_model())
    wav = tmp_path / "s.wav"
    write_wav(wav, speechlike(1.0, 16000), 16000)
    out = {s: tmp_path / f"take.{s}" for s in ("csv", "glb", "json", "tsv")}
    # The retargeted built-in head: its glb animates the 4 parameter targets with the curves themselves.
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
    acc = g.accessors[g.animations[0].samplers[0].output]
    view = g.bufferViews[acc.bufferView]
    w = np.frombuffer(g.binary_blob(), "<f4", acc.count, view.byteOffset + (acc.byteOffset or 0)).reshape(-1, 4)
    np.testing.assert_allclose(w, js.values, rtol=1e-6, atol=1e-7)
    assert (tmp_path / "take.wav").is_file()
    assert read_tsv(out["tsv"].read_bytes())[-1].shape == "X"


def test_animate_needs_an_output(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["animate", str(tmp_path / "missing.wav")])
