from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ModelFormatError
from realtime_core.face import parse_wfm


def _read(shared_data, name):
    p = shared_data / "candide3" / name
    if not p.is_file():
        pytest.skip(f"Candide-3 file not found: {p}")
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
