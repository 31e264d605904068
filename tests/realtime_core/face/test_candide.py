from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ModelFormatError
from realtime_core.face import parse_wfm
from tests.prerequisites import missing


def _read(shared_data, name):
    p = shared_data / "candide3" / name
    if not p.is_file():
        missing(f"Candide-3 file not found: {p}")
    return p.read_text(encoding="latin-1")


def test_candide_316_counts(shared_data):
    m = parse_wfm(_read(shared_data, "candide3-3.1.6.wfm"))
    assert m.vertices.shape == (113, 3)
    assert m.triangles.shape == (184, 3)
    assert len(m.animation_units) == 65
    assert len(m.shape_units) == 14
    assert m.uvs is None  # the TEXTURE section is empty in this file
    jaw = m.animation_units["AUV11 Jaw drop (AU26/27)"]
    # Vertex 8 (lower lip) drops by 0.26 per unit in the file.
    np.testing.assert_allclose(jaw[8], [0.0, -0.26, -0.05])
    assert np.count_nonzero(jaw.any(axis=1)) == 12


def test_candide_uv_variant_counts(shared_data):
    m = parse_wfm(_read(shared_data, "candide3-uv-variant.wfm"))
    assert m.vertices.shape == (113, 3)
    assert m.triangles.shape == (184, 3)
    assert m.uvs is not None and m.uvs.shape == (113, 2)
    assert len(m.animation_units) == 14
    assert len(m.shape_units) == 38
    assert "Jaw drop" in m.animation_units and "Lip stretcher" in m.animation_units
    np.testing.assert_allclose(m.uvs[-1], [0.496314, 0.547489])


def test_bad_wfm_names_section():
    with pytest.raises(ModelFormatError, match="FACE LIST"):
        parse_wfm("# VERTEX LIST:\n1\n0 0 0\n")
    with pytest.raises(ModelFormatError, match="VERTEX LIST"):
        parse_wfm("# VERTEX LIST:\n3\n0 0 0\n# FACE LIST:\n0\n")


def test_candide_uv_variant_calibration(shared_data):
    from realtime_core.face import calibrate_mouth, measure_mouth
    from realtime_core.face.candide import candide3_mouth_landmarks

    m = parse_wfm(_read(shared_data, "candide3-uv-variant.wfm"))
    lm = candide3_mouth_landmarks()
    # Jaw drop by hand: vertex 40 (lower inner lip) drops 0.26 per unit, 87 stays; IOD = 0.6.
    p = measure_mouth(m.vertices, m.deform({"Jaw drop": 1.0}), lm)
    iod = np.linalg.norm(0.5 * (m.vertices[20] + m.vertices[23]) - 0.5 * (m.vertices[53] + m.vertices[56]))
    assert p[2] == pytest.approx(0.26 / iod, rel=0.05)
    cal = calibrate_mouth(
        m, lm, groups=[("Upper lip raiser",), ("Lip stretcher",), ("Jaw drop",), ("Lip corner depressor",)]
    )
    target = np.array([0.02, 0.05, 0.15, -0.03])
    moved = m.deform(cal.weights(target))
    np.testing.assert_allclose(measure_mouth(m.vertices, moved, lm), target, atol=1e-9)
