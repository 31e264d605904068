from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError, ModelFormatError
from realtime_core.face import FaceModel, MouthLandmarks, calibrate_mouth, measure_mouth
from realtime_core.face.registration import fit_similarity


def toy_face() -> tuple[FaceModel, MouthLandmarks]:
    """A 10-vertex 'face': eyes at y=1, mouth at y=-1 (IOD = 2), with four simple units."""
    v = np.array(
        [
            [1.3, 1, 0],
            [0.7, 1, 0],
            [-1.3, 1, 0],
            [-0.7, 1, 0],  # eyes: outer L, inner L, outer R, inner R
            [0, -0.9, 0.1],
            [0, -1.1, 0.1],  # outer lips: upper, lower
            [0, -0.98, 0.05],
            [0, -1.02, 0.05],  # inner lips
            [0.5, -1, 0],
            [-0.5, -1, 0],  # corners L, R
        ],
        dtype=float,
    )
    tri = np.array([[0, 1, 4], [2, 3, 4], [4, 8, 9], [5, 8, 9]])
    z = np.zeros_like(v)
    jaw = z.copy()
    jaw[[5, 7], 1] = -0.2
    up = z.copy()
    up[[4, 6], 1] = 0.1
    st = z.copy()
    st[8, 0], st[9, 0] = 0.1, -0.1
    fr = z.copy()
    fr[[8, 9], 1] = -0.05
    m = FaceModel(vertices=v, triangles=tri, animation_units={"jaw": jaw, "up": up, "stretch": st, "frown": fr})
    lm = MouthLandmarks(
        upper_lip=4,
        lower_lip=5,
        upper_inner=6,
        lower_inner=7,
        corner_left=8,
        corner_right=9,
        eye_outer_left=0,
        eye_inner_left=1,
        eye_outer_right=2,
        eye_inner_right=3,
    )
    return m, lm


def test_measure_mouth_by_hand():
    m, lm = toy_face()
    iod = 2.0
    p = measure_mouth(m.vertices, m.deform({"jaw": 1.0}), lm)
    # Jaw: inner gap grows by 0.2; the lower lip drops 0.2 so the lip midline drops 0.1 relative to the
    # (unmoved) corners, i.e. the corners rise 0.1 relative to the midline: depress = -0.1.
    np.testing.assert_allclose(p, [0, 0, 0.2 / iod, -0.1 / iod], atol=1e-12)
    p = measure_mouth(m.vertices, m.deform({"stretch": 1.0}), lm)
    np.testing.assert_allclose(p, [0, 0.2 / iod, 0, 0], atol=1e-12)


def test_calibration_round_trip_and_zero():
    m, lm = toy_face()
    cal = calibrate_mouth(m, lm, groups=[("up",), ("stretch",), ("jaw",), ("frown",)])
    b = cal.basis(m)
    assert b.shape == (m.n_vertices * 3, 4)
    np.testing.assert_array_equal(b @ np.zeros(4), 0.0)
    target = np.array([0.03, -0.02, 0.1, 0.01])
    moved = m.vertices + (b @ target).reshape(-1, 3)
    np.testing.assert_allclose(measure_mouth(m.vertices, moved, lm), target, atol=1e-9)
    w = cal.weights(target)
    np.testing.assert_allclose(m.deform(w), moved, atol=1e-12)


def test_measurement_invariant_to_similarity():
    m, lm = toy_face()
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    moved = m.transformed(3.7, q, np.array([1.0, -2.0, 5.0]))
    w = {"jaw": 0.7, "stretch": -0.4, "up": 0.2}
    np.testing.assert_allclose(
        measure_mouth(moved.vertices, moved.deform(w), lm), measure_mouth(m.vertices, m.deform(w), lm), atol=1e-12
    )


def test_singular_calibration_and_bad_model():
    m, lm = toy_face()
    with pytest.raises(ConfigError, match="cannot produce"):
        calibrate_mouth(m, lm, groups=[("up",), ("up",), ("jaw",), ("frown",)])
    with pytest.raises(ModelFormatError):
        FaceModel(vertices=np.zeros((3, 2)), triangles=np.zeros((0, 3), int))
    with pytest.raises(ModelFormatError, match="out of range"):
        FaceModel(vertices=np.zeros((3, 3)), triangles=np.array([[0, 1, 3]]))


def test_fit_similarity_recovers_transform():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(8, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    b = 2.5 * a @ q.T + np.array([3.0, 0.0, -1.0])
    s = fit_similarity(a, b)
    assert s.scale == pytest.approx(2.5)
    np.testing.assert_allclose(s.rotation, q, atol=1e-10)
    np.testing.assert_allclose(s.apply(a), b, atol=1e-10)
    scale, rot, shift = s  # unpacks as (s, R, t) for `s * x @ R.T + t` (training.video's head-pose removal)
    np.testing.assert_allclose(scale * a @ rot.T + shift, b, atol=1e-10)
    # a reflected target is fitted by the best proper rotation, never a reflection
    assert np.linalg.det(fit_similarity(a, b * np.array([1, 1, -1])).rotation) == pytest.approx(1.0)
    with pytest.raises(ConfigError, match="collinear"):
        fit_similarity(np.outer(np.arange(4.0), [1, 1, 0]), b[:4])


def test_register_recovers_similarity_and_warp_hits_landmarks():
    from realtime_core.face import register

    m, _ = toy_face()
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.linalg.det(q))
    idx = np.arange(10)
    dst = 2.0 * m.vertices @ q.T + np.array([1.0, 2.0, 3.0])
    reg = register(m, idx, dst)
    assert reg.similarity.scale == pytest.approx(2.0)
    assert reg.rms < 1e-9
    bent = dst + rng.normal(scale=0.05, size=dst.shape)  # a head whose proportions differ
    plain = register(m, idx, bent)
    warped = register(m, idx, bent, warp_radius=0.5)
    assert plain.rms > 0.01
    np.testing.assert_allclose(warped.model.vertices[idx], bent, atol=1e-6)
