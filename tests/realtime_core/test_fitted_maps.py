"""The fitted blendshape maps and the expression table: no drift from their recipe, and they do what
they claim on the built-in head (its own ARKit targets reproduce the requested mouth parameters)."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core import fitted_maps
from realtime_core.blendshapes import ARKIT_NAMES, OVR_NAMES, blendshape_weights
from realtime_core.expressions import EXPRESSIONS


@pytest.fixture(scope="module")
def head_and_rig():
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigfile import builtin_rig

    rig, _ = builtin_rig()
    return load_builtin_head(), rig


def test_generated_module_matches_a_fresh_fit(head_and_rig) -> None:
    from training.fit_maps import fit_maps

    fresh = fit_maps(*head_and_rig)
    for name, value in fresh.items():
        np.testing.assert_allclose(getattr(fitted_maps, name), value, atol=2e-5, rtol=1e-5, err_msg=name)


def test_the_module_is_written_as_ruff_formats_it() -> None:
    """`facecast fit-maps` wrote a layout CI's `ruff format --check` refused. Written again from its own
    values (printed at 6 significant digits, which re-print the same), the committed, ruff-formatted module
    comes back byte for byte; a row too long for 120 columns is split one value a line, as ruff splits it."""
    from pathlib import Path

    from training.fit_maps import ARRAY_NAMES, module_text

    names = (*ARRAY_NAMES, "EXPRESSION_POSES")
    text = module_text({n: getattr(fitted_maps, n) for n in names})
    assert text == Path(fitted_maps.__file__).read_text()
    long = module_text({**{n: getattr(fitted_maps, n) for n in names}, "OVR_KEYFRAMES": np.full((1, 14), 0.123456)})
    assert "        (\n            0.123456,\n" in long and max(map(len, long.splitlines())) <= 120


def _speech_poses(n: int = 60) -> np.ndarray:
    """``(n, 4)`` random poses over the range speech drives the four parameters (IOD), seed 0."""
    rng = np.random.default_rng(0)
    return np.column_stack(
        [
            rng.uniform(-0.03, 0.05, n),
            rng.uniform(-0.10, 0.08, n),
            rng.uniform(0, 0.35, n),
            rng.uniform(-0.05, 0.04, n),
        ]
    )


def test_arkit_weights_reproduce_the_parameters_on_the_head(head_and_rig) -> None:
    from realtime_core.face import MouthLandmarks
    from realtime_core.face.model import measure_mouth

    head, _ = head_and_rig
    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    v0 = head.mesh.vertices
    targets = np.stack([head.targets[n] for n in ARKIT_NAMES])
    p = _speech_poses()
    w = blendshape_weights(p, "arkit52").astype(np.float64)
    got = np.array([measure_mouth(v0, v0 + np.tensordot(wi, targets, 1), lm) for wi in w])
    r = [np.corrcoef(p[:, i], got[:, i])[0, 1] for i in range(4)]
    assert min(r) > 0.8, r
    assert np.abs(got[:, 2] - p[:, 2]).max() < 0.08  # the gap: within 0.08 IOD over 0..0.35, mixed with the rest


def test_ovr_visemes_pick_the_expected_shape() -> None:
    def top(p):
        w = blendshape_weights(np.array(p, dtype=float), "ovr15")
        return OVR_NAMES[int(np.argmax(w))], w

    assert top([0, 0, 0, 0])[0] == "sil"
    assert top([0.015, 0.02, 0.33, -0.005])[0] == "aa"
    assert top([0.015, -0.09, 0.09, 0.025])[0] == "U"
    assert top([0.005, 0.065, 0.10, -0.02])[0] == "I"
    assert top([0.025, 0.0, 0.025, 0.005])[0] == "FF"
    w = blendshape_weights(np.random.default_rng(1).normal(0, 0.1, (20, 4)), "ovr15")
    assert w.shape == (20, 15) and w.min() >= 0 and w.max() <= 1


def test_expressions_carry_into_arkit() -> None:
    e = np.zeros(len(EXPRESSIONS))
    e[EXPRESSIONS.index("smile")] = 1.0
    w = dict(zip(ARKIT_NAMES, blendshape_weights(np.zeros(4), "arkit52", expression=e)))
    assert w["mouthSmileLeft"] == pytest.approx(0.5) and w["cheekSquintRight"] == pytest.approx(0.5)
    e[:] = 0
    e[EXPRESSIONS.index("surprise")] = 0.5
    w = dict(zip(ARKIT_NAMES, blendshape_weights(np.zeros(4), "arkit52", expression=e)))
    assert w["browOuterUpLeft"] == pytest.approx(0.35)


def test_a_lowered_upper_lip_keeps_the_built_in_heads_lips_closed(head_and_rig) -> None:
    """Streamed weights on the head's own targets, at every checked pose with the mouth closed (mouth_open 0)
    and the upper lip lowered (/m b p/ and what speech reaches beside them): the inner lips never cross, and
    stay within the closure limit (0.01 IOD) unless the lips are also spread or the corners raised (directions
    fitted as before, up to 0.012). Fitted to the rig's whole-region motion alone, the lowered upper lip came
    with jawOpen and mouthFunnel: 0.028 IOD apart at the pressed bilabial pose, 0.123 at -0.084, 0.128 at most."""
    from realtime_core.face import MouthLandmarks, face_frame
    from realtime_core.face.checks import BILABIAL_POSES, EXTREME_POSES

    head, _ = head_and_rig
    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    v0 = head.mesh.vertices
    fr = face_frame(v0, lm)
    targets = np.stack([head.targets[n] for n in ARKIT_NAMES])

    def gaps(poses: np.ndarray) -> np.ndarray:
        w = blendshape_weights(poses, "arkit52").astype(np.float64)
        v = v0 + np.tensordot(w, targets, 1)  # (k, n, 3)
        return (v[:, lm.upper_inner] - v[:, lm.lower_inner]) @ fr.axes[1] / fr.iod

    closed = np.array([p for p in EXTREME_POSES if p[2] == 0.0 and p[0] < 0])
    assert len(closed) >= 10
    g = gaps(closed)
    assert g.min() >= 0.0 and g.max() < 0.015, dict(zip(map(tuple, closed), g))
    neither = closed[(closed[:, 1] <= 0) & (closed[:, 3] >= 0)]  # not spread, corners not raised
    assert len(neither) >= 3 and gaps(neither).max() < 0.01
    assert gaps(np.array(BILABIAL_POSES)).max() < 0.01


def test_antagonists_never_act_together_and_keep_their_net(head_and_rig) -> None:
    """Summed over the four parameters, the signed-unit maps drove mouthSmile and mouthFrown together (an open mouth's
    frown and a raised upper lip's smile: 21 % of 900 GRID s1 frames both above 0.1; mouthStretch with mouthPucker
    7.6 %). At every speech pose the checks use and at random ones, one side of each antagonist pair is 0, and the
    pair's net size (weights x each target's displacement norm on the head, computed here from the head's targets and
    the linear map) is what the linear map gives; the head's targets then give back the parameters closer than before
    (RMS over these 60 poses 0.0276 IOD before, 0.0196 after)."""
    from realtime_core.blendshapes import ARKIT_ANTAGONISTS
    from realtime_core.face import MouthLandmarks
    from realtime_core.face.checks import EXTREME_POSES
    from realtime_core.face.model import measure_mouth

    head, _ = head_and_rig
    random = _speech_poses()
    p = np.vstack([np.asarray(EXTREME_POSES, dtype=np.float64), [[0.04, 0.0, 0.25, 0.0]], random])
    w = blendshape_weights(p, "arkit52").astype(np.float64)
    linear = np.maximum(p, 0) @ fitted_maps.ARKIT_POS.T + np.maximum(-p, 0) @ fitted_maps.ARKIT_NEG.T
    size = {n: float(np.linalg.norm(head.targets[n])) for n in ARKIT_NAMES}
    col = {n: i for i, n in enumerate(ARKIT_NAMES)}

    def sizes(weights: np.ndarray, side: tuple[str, ...]) -> np.ndarray:
        return sum(weights[:, col[n]] * size[n] for n in side)

    frowning = 0
    for a, b in ARKIT_ANTAGONISTS:
        ua, ub = sizes(w, a), sizes(w, b)
        assert not np.any((ua > 0) & (ub > 0)), (a, b, p[(ua > 0) & (ub > 0)][:3])
        # Net kept where the map stays within [0, 1] (the clip acts after the netting).
        inside = (linear[:, [col[n] for n in a + b]] <= 1).all(axis=1)
        net = sizes(linear, a) - sizes(linear, b)
        np.testing.assert_allclose((ua - ub)[inside], net[inside], atol=2e-4)
        frowning += int(np.sum((sizes(linear, a) > 0.1) & (sizes(linear, b) > 0.1)))
    assert frowning > 50  # the linear map alone does drive the pairs together at these poses

    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    v0 = head.mesh.vertices
    targets = np.stack([head.targets[n] for n in ARKIT_NAMES])
    got = np.array([measure_mouth(v0, v0 + np.tensordot(wi, targets, 1), lm) for wi in w[-60:]])
    assert np.sqrt(np.mean((got - random) ** 2)) < 0.022
