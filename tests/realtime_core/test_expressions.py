"""Expressions at run time: parsing, scheduling and easing on the media clock, the closure-keeping
composition, bad requests; and a rendered-geometry check on the built-in head's rig."""

from __future__ import annotations

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.expressions import (
    EXPRESSIONS,
    SPEECH_REACH,
    ExpressionConfig,
    ExpressionError,
    ExpressionTrack,
    add_expression,
    apply_expression,
    parse_expression,
)
from realtime_core.fitted_maps import EXPRESSION_PARAMS

SMILE = EXPRESSIONS.index("smile")


def test_parse() -> None:
    assert parse_expression("smile:0.7@1.2") == ("smile", 0.7, 1.2)
    assert parse_expression("sad") == ("sad", 1.0, 0.0)
    assert parse_expression("neutral@3") == ("neutral", 1.0, 3.0)
    for bad, msg in (
        ("grin", "unknown expression 'grin'"),
        ("smile:1.5", r"in \[0, 1\]"),
        ("smile:-0.1", r"in \[0, 1\]"),
        ("smile:x", "must be a number"),
        ("smile@soon", "seconds"),
        ("smile@-2", ">= 0"),
    ):
        with pytest.raises(ExpressionError, match=msg):
            parse_expression(bad)


def test_easing_and_cross_fade() -> None:
    tr = ExpressionTrack(ExpressionConfig(ease_s=0.5))
    tr.schedule("smile", 0.8, 1.0)
    tr.schedule("sad", 1.0, 3.0)
    t = np.arange(0, 5, 1 / 30)
    a = tr.intensities(t)
    assert np.all(a[t < 1.0] == 0)
    np.testing.assert_allclose(a[(t >= 1.5) & (t < 3.0), SMILE], 0.8)
    assert 0 < a[np.searchsorted(t, 1.25), SMILE] < 0.8  # mid-ease
    assert np.all(np.diff(a[(t >= 1) & (t < 3), SMILE]) >= -1e-12)  # monotone ease-in
    sad = EXPRESSIONS.index("sad")
    np.testing.assert_allclose(a[t >= 3.5, sad], 1.0)
    np.testing.assert_allclose(a[t >= 3.5, SMILE], 0.0, atol=1e-12)
    # Cross-fade: at 3.25 s smile is fading out while sad fades in.
    i = np.searchsorted(t, 3.25)
    assert 0 < a[i, SMILE] < 0.8 and 0 < a[i, sad] < 1
    # A pure function of time: any split of the frame times gives the same intensities.
    np.testing.assert_array_equal(np.concatenate([tr.intensities(c) for c in np.array_split(t, 7)]), a)


def test_bad_requests_leave_the_track_unchanged() -> None:
    tr = ExpressionTrack(ExpressionConfig(max_ahead_s=60, late_tolerance_s=0.5))
    tr.schedule("smile", 1.0, 10.0, now_s=10.0)
    before = tr.events
    with pytest.raises(ExpressionError, match="in the past"):
        tr.schedule("sad", 1.0, 2.0, now_s=10.0)
    with pytest.raises(ExpressionError, match="more than 60 s ahead"):
        tr.schedule("sad", 1.0, 1e9, now_s=10.0)
    with pytest.raises(ExpressionError, match="unknown expression"):
        tr.schedule("joy", 1.0, 11.0, now_s=10.0)
    with pytest.raises(ExpressionError, match=r"\[0, 1\]"):
        tr.schedule("sad", 2, 11.0, now_s=10.0)
    with pytest.raises(ExpressionError, match="number of seconds"):
        tr.schedule("sad", 1, float("nan"), now_s=10.0)
    assert tr.events == before
    with pytest.raises(ConfigError):
        ExpressionConfig(ease_s=-1)


def test_composition_keeps_closures_and_rounding() -> None:
    rng = np.random.default_rng(0)
    speech = np.column_stack(
        [
            rng.normal(0, 0.02, 300),
            rng.normal(0, 0.05, 300),
            np.clip(rng.normal(0.1, 0.1, 300), 0, None),
            rng.normal(0, 0.02, 300),
        ]
    )
    speech[::10, 2] = 0.0  # closures
    alpha = np.zeros((300, len(EXPRESSIONS)))
    alpha[:, SMILE] = 1.0
    out = apply_expression(speech, alpha, EXPRESSION_PARAMS)
    np.testing.assert_array_equal(out[::10, 2], 0.0)  # a closed mouth stays closed under a full smile
    # Rounding excursions survive: lip_stretch moves by a constant offset only where speech rounds the lips...
    d = EXPRESSION_PARAMS[SMILE, 1]
    rounded = speech[:, 1] < 0
    assert rounded.sum() > 100
    np.testing.assert_allclose(out[rounded, 1] - speech[rounded, 1], d)
    # ...and spread lips saturate: no wider than the smile alone, speech's widest or this frame's speech.
    want = np.minimum(speech[:, 1] + d, np.maximum(max(SPEECH_REACH[1][1], d), speech[:, 1]))
    np.testing.assert_allclose(out[:, 1], want)
    assert (out[:, 1] < speech[:, 1] + d - 1e-3).sum() > 50
    assert EXPRESSION_PARAMS[SMILE, 1] > 0.1 and EXPRESSION_PARAMS[SMILE, 3] < -0.05  # wider, corners up
    assert np.corrcoef(out[:, 2], speech[:, 2])[0, 1] > 0.99
    np.testing.assert_array_equal(apply_expression(speech, np.zeros_like(alpha), EXPRESSION_PARAMS), speech)


def test_an_expression_on_speech_saturates_at_the_reach_of_speech_or_of_the_expression() -> None:
    # A full smile on the spread /i/ (the close front target) and on speech's own ends: each parameter goes no
    # further than the furthest of SPEECH_REACH, the speech and the smile alone; speech alone is left as it is,
    # even beyond the reach (a model's frame is never clipped by this rule).
    smile = EXPRESSION_PARAMS[SMILE]
    i_vowel = np.array([[0.007, 0.089, 0.136, -0.027]])
    out = add_expression(i_vowel, smile[None])[0]
    assert np.isclose(out[1], smile[1])  # as wide as the smile alone (0.159; summed 0.248)
    assert np.isclose(out[3], SPEECH_REACH[3][0])  # corners up: -0.027 - 0.086 past the -0.103 speech reaches
    assert np.isclose(out[0], 0.007 + smile[0]) and np.isclose(out[2], 0.136 + smile[2])  # inside: summed
    raised = add_expression(np.array([[SPEECH_REACH[0][1], 0.0, 0.0, 0.0]]), smile[None])[0]
    assert np.isclose(raised[0], SPEECH_REACH[0][1])  # the upper lip raised as far as speech raises it
    beyond = np.array([[0.07, 0.2, 0.5, -0.12]])
    np.testing.assert_array_equal(add_expression(beyond, np.zeros((1, 4))), beyond)


@pytest.mark.parametrize("name", EXPRESSIONS)
def test_each_expression_moves_the_mouth_corners_of_the_builtin_head(name: str) -> None:
    """What `facecast render --expression` draws: the rig's vertices under the expression differ
    visibly from neutral at the mouth corners (>= 0.02 IOD, about 1.3 mm on a 65 mm IOD)."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigfile import builtin_rig
    from realtime_core.face import MouthLandmarks, face_frame

    rig, _ = builtin_rig()
    head = load_builtin_head()
    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    iod = face_frame(head.mesh.vertices, lm).iod
    speech = np.array([[0.0, 0.0, 0.12, 0.0]])  # mid-vowel, mouth open
    alpha = np.zeros((1, len(EXPRESSIONS)))
    alpha[0, EXPRESSIONS.index(name)] = 1.0
    neutral = rig.deformed(speech[0])
    expressive = rig.deformed(apply_expression(speech, alpha, EXPRESSION_PARAMS)[0])
    corners = [lm.corner_left, lm.corner_right]
    moved = np.linalg.norm(expressive[corners] - neutral[corners], axis=1) / iod
    assert moved.min() >= 0.02, (name, moved)


@pytest.mark.parametrize("name", EXPRESSIONS)
def test_the_shipped_mlp_mappers_second_stages_move_the_mouth_corners(name: str) -> None:
    """The shipped MLP mapper carries paper 002's second stage for every expression, and what it does
    at run time (Upsilon_k of the frame's UMUPs) is visible on the built-in head: the mouth corners of
    the most open frame of a speech-like signal move >= 0.02 IOD from neutral."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.rigfile import builtin_rig
    from assets.modelfile import load_speech_model
    from realtime_core.face import MouthLandmarks, face_frame
    from realtime_core.mapping import MlpSpeechModel
    from realtime_core.mapping.expression import express
    from realtime_core.pipeline import speech_to_params_and_mups
    from tests.speech import speechlike

    model = load_speech_model("mlp")
    assert isinstance(model, MlpSpeechModel) and model.expressions is not None
    assert set(model.expressions.stages) == set(EXPRESSIONS)
    speech, mups = speech_to_params_and_mups(model, speechlike(2.0, 16000))
    assert mups is not None
    k = int(np.argmax(speech[:, 2]))
    alpha = np.zeros((1, len(EXPRESSIONS)))
    alpha[0, EXPRESSIONS.index(name)] = 1.0
    out = express(speech[k : k + 1], alpha, mups=mups[k : k + 1], mapper=model.expressions)
    rig, _ = builtin_rig()
    head = load_builtin_head()
    lm = MouthLandmarks(**{f: head.landmarks[f] for f in MouthLandmarks.__dataclass_fields__})
    iod = face_frame(head.mesh.vertices, lm).iod
    corners = [lm.corner_left, lm.corner_right]
    moved = np.linalg.norm(rig.deformed(out[0])[corners] - rig.deformed(speech[k])[corners], axis=1) / iod
    assert moved.min() >= 0.02, (name, moved)


def test_face_shapes_are_the_recipe_less_what_the_mouth_parameters_carry():
    """Every shape of a recipe is either carried by the four parameters (mouth*, jaw*: the expression's fitted
    parameter change, EXPRESSION_PARAMS, is non-zero where the recipe has one) or a face shape a renderer adds from
    the head's own targets, never both; the perceptual kit's faces are these (it had a recipe of its own)."""
    from realtime_core.expressions import EXPRESSION_RECIPES, EXPRESSIONS, ExpressionError, face_shapes
    from realtime_core.fitted_maps import EXPRESSION_PARAMS

    assert face_shapes("neutral") == {}
    for k, name in enumerate(EXPRESSIONS):
        face = face_shapes(name)
        mouth = {n: w for n, w in EXPRESSION_RECIPES[name].items() if n not in face}
        assert face.keys() | mouth.keys() == EXPRESSION_RECIPES[name].keys() and not face.keys() & mouth.keys()
        assert all(n.startswith(("mouth", "jaw")) for n in mouth)
        assert all(not n.startswith(("mouth", "jaw")) for n in face) and face
        assert (np.abs(EXPRESSION_PARAMS[:, k]).max() > 0.005) == bool(mouth), name
    with pytest.raises(ExpressionError, match="unknown expression 'grin'"):
        face_shapes("grin")
