"""Paper 002's training helpers: the speaker -> built-in head correspondence (checked with the
MediaPipe canonical face, whose vertices are the face-mesh landmarks), closure windows and rates,
viseme keyframes from word alignments, and the score of eq. 6-8 against a hand computation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import assets
from training.motion_units import Clip, score
from training.mu_expressions import BILABIAL_WORDS, closure_rate, closure_windows, head_correspondence
from training.mu_keyframes import viseme_keyframes


@pytest.fixture(scope="module")
def mediapipe_canonical(shared_data: Path) -> tuple[np.ndarray, dict[str, int]]:
    """The MediaPipe canonical face's vertices ``(468, 3)`` and its shipped landmark indices by name."""
    from assets.heads.landmarks import read_landmarks
    from assets.heads.mesh import load_mesh

    canon = load_mesh(shared_data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj").vertices
    path = Path(assets.__file__).parent / "heads" / "landmarks" / "mediapipe_canonical.json"
    return canon, {k: int(v) for k, v in read_landmarks(path).items()}


def test_head_correspondence_lands_on_the_heads_own_landmarks(mediapipe_canonical, builtin_head) -> None:
    from realtime_core.face import MouthLandmarks, face_frame

    canon, mp = mediapipe_canonical
    head = builtin_head
    idx = [mp["corner_left"], mp["corner_right"], mp["upper_lip"], mp["lower_lip"], mp["chin"]]
    verts, sim = head_correspondence(canon, idx, head, mp)
    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    iod = face_frame(head.mesh.vertices, lm).iod
    want = [head.landmarks[n] for n in ("corner_left", "corner_right", "upper_lip", "lower_lip", "chin")]
    gap = np.linalg.norm(head.mesh.vertices[verts] - head.mesh.vertices[want], axis=1) / iod
    assert gap.max() < 0.05, gap  # within 5 % of the IOD of the head's own landmark vertex
    assert sim.scale > 0


def test_carried_jaw_drop_parts_the_speakers_lips_as_it_parts_the_heads(mediapipe_canonical, builtin_head) -> None:
    """Each inner-lip landmark takes a vertex of its own lip: the head's jawOpen carried onto the canonical
    face opens its lip gap (the mean of the three gap pairs, IOD) as much as it opens the head's at its
    own named inner-lip vertices, to within a quarter. (Matched to the nearest vertex of either lip, two
    of the three pairs of the GRID speaker's rest face landed on one lip, and its carried gap was a
    sixth of the head's.)"""
    from realtime_core.face import MouthLandmarks, face_frame
    from training.facetrack import LIP_GAP_PAIRS, LIPS_INNER, MU_LANDMARKS
    from training.mu_expressions import carried
    from training.video import lip_gap

    canon, mp = mediapipe_canonical
    head = builtin_head
    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    iod_head = face_frame(head.mesh.vertices, lm).iod
    # eye centres, as face_frame measures the IOD
    iod_canon = float(np.linalg.norm(canon[[33, 133]].mean(0) - canon[[362, 263]].mean(0)))
    face = canon / iod_canon
    idx = list(MU_LANDMARKS)
    verts, sim = head_correspondence(face, idx, head, mp)
    pos = {v: i for i, v in enumerate(idx)}
    for a, b in LIP_GAP_PAIRS:
        assert verts[pos[a]] != verts[pos[b]]
    # The head's jaw carries its lower lip, not its upper: away from the corners, every upper inner-lip
    # landmark's vertex moves with jawOpen less than every lower one's (unconstrained matching put two
    # upper inner-lip points of this face on the lower lip).
    jaw = np.linalg.norm(head.targets["jawOpen"][verts], axis=1)
    upper_moves = jaw[[pos[i] for i in LIPS_INNER[12:19]]]
    lower_moves = jaw[[pos[i] for i in LIPS_INNER[2:9]]]
    assert upper_moves.max() < lower_moves.min(), (upper_moves, lower_moves)
    w = 0.2
    opened = face.copy()
    opened[idx] += carried(head, verts, sim, {"jawOpen": w}).reshape(-1, 3)
    speaker = float(lip_gap(opened[None])[0] - lip_gap(face[None])[0])
    hv = head.mesh.vertices
    u, d = head.landmarks["upper_inner"], head.landmarks["lower_inner"]
    on_head = (
        np.linalg.norm(hv[u] + w * head.targets["jawOpen"][u] - hv[d] - w * head.targets["jawOpen"][d])
        - np.linalg.norm(hv[u] - hv[d])
    ) / iod_head
    assert on_head > 0.05
    assert speaker == pytest.approx(on_head, rel=0.25), (speaker, on_head)


def test_emu_readout_is_the_measured_change_of_the_parameters() -> None:
    """The affine EMUP -> mouth-parameter map reproduces :func:`training.video.mouth_params` of the EMU
    deformation, and a jaw drop from touching lips opens the mouth (positive mouth_open), which the
    Jacobian at rest cannot promise (the gap's gradient there points along the lips' tiny offset)."""
    from realtime_core.motion_units import fit_expression_units, fit_motion_units
    from training.facetrack import LIP_GAP_PAIRS, MU_LANDMARKS
    from training.mu_expressions import emu_readout, mouth_jacobian
    from training.video import mouth_params

    rng = np.random.default_rng(3)
    face = rng.standard_normal((468, 3)) * 0.3
    face[61], face[291] = (-0.4, 1.0, 0.0), (0.4, 1.0, 0.0)
    for a, b in LIP_GAP_PAIRS:
        face[b] = face[a] + (0.0, 1e-4, -1e-4)  # touching lips, the lower a hair above and behind
    idx = list(MU_LANDMARKS)
    pos = {v: i for i, v in enumerate(idx)}
    speech = rng.standard_normal((400, 3 * len(idx))) * 0.01
    mu = fit_motion_units(speech, n_units=4)
    drop = np.zeros(3 * len(idx))
    for b in (14, 87, 317, 17, 84, 314):
        drop[3 * pos[b] + 1] = -0.1  # the lower lip down (y up)
    frames = speech[:300] + rng.uniform(0.2, 1.0, (300, 1)) * drop
    ex = fit_expression_units(mu, frames, name="surprise", n_units=2)
    c = ex.basis.project(mu.residual(frames))
    p, q = emu_readout(face, idx, ex, c)
    assert p.shape == (4, 2) and q.shape == (4,)
    lm = np.repeat(face[None], len(c), axis=0)
    lm[:, idx] += ex.basis.reconstruct(c).reshape(len(c), -1, 3)
    measured = mouth_params(lm, face)
    fitted = c @ p.T + q
    assert np.mean(measured[:, 2]) > 0.05
    np.testing.assert_allclose(fitted[:, 2], measured[:, 2], atol=0.01)
    jac = mouth_jacobian(face, idx)  # at rest the gap grows along the lips' offset (up): a drop reads as closing
    assert np.mean((ex.basis.reconstruct(c) @ jac.T)[:, 2]) < 0


def test_closure_windows_and_rate() -> None:
    words = [(0.0, 0.5, "sil"), (0.5, 0.8, "bin"), (0.8, 1.0, "red"), (1.0, 1.3, "please")]
    w = closure_windows(words)
    assert len(w) == 2 and w[0][0] == int(np.floor((0.5 - 0.06) * 30))
    assert {"bin", "blue", "by", "place", "please"} <= BILABIAL_WORDS
    t = np.zeros((45, 4))
    t[:, 2] = 0.2
    t[16, 2] = 0.0  # closed in the first window only
    assert closure_rate([t], [w], 0.03) == pytest.approx(0.5)


def test_viseme_keyframes_take_the_named_word_parts() -> None:
    d = np.zeros((60, 6), dtype=np.float32)
    d[30:33] = 1.0  # the end of "three" spans 1.0..1.2 s -> frames 30..36
    clip = Clip("x", "train", np.zeros(16000, np.float32), 16000, d, np.zeros((60, 4)), np.zeros((468, 3)))
    vis = viseme_keyframes([clip], {"x": [(0.8, 1.1, "three"), (1.5, 1.9, "at")]})
    np.testing.assert_allclose(vis["i"], 1.0)
    np.testing.assert_allclose(vis["a"], 0.0)
    assert "u" not in vis


def test_score_matches_a_hand_computation() -> None:
    rng = np.random.default_rng(0)
    t = rng.standard_normal((200, 6))
    e = t + 0.3 * rng.standard_normal((200, 6))
    scale = np.abs(t).max(0)
    s = score(t, e, scale, t[:, :4], e[:, :4])
    tn, en = t / scale, e / scale
    tc, ec = tn - tn.mean(0), en - en.mean(0)
    assert s.r == pytest.approx((tc * ec).sum() / np.sqrt((tc**2).sum() * (ec**2).sum()))
    assert s.mse == pytest.approx(np.mean((tn - en) ** 2))
    assert s.nu_true == pytest.approx(np.mean(tn.std(0)))


def test_second_stage_weights_fold_the_standardisation() -> None:
    """The folded run-time weights of Upsilon_k reproduce the fitted network on fresh inputs (independent:
    scikit-learn's own predict of an identically seeded fit), and the stage's parameter change matches
    the readout of its outputs."""
    from sklearn.neural_network import MLPRegressor

    from realtime_core.mapping import ExpressionMapper
    from realtime_core.motion_units import analyse, fit_expression_units, fit_motion_units
    from training.mu_expressions import expression_stage, fit_second_stage, second_stage_predict

    rng = np.random.default_rng(0)
    d = rng.standard_normal((600, 4)) @ rng.standard_normal((4, 12)) * 0.1 + 0.01 * rng.standard_normal((600, 12))
    mu = fit_motion_units(d, n_units=3)
    dk = d + np.linspace(0.05, 0.1, 12)
    ex = fit_expression_units(mu, dk, name="smile", n_units=2)
    est = mu.project(d) + 0.02 * rng.standard_normal((600, 3))
    w = fit_second_stage(est, mu, ex, dk, hidden=8)
    c0, ck = analyse(mu, ex, dk)
    y = np.hstack([c0, ck])
    xm, xs, ym, ys = est.mean(0), est.std(0), y.mean(0), y.std(0)
    ref = MLPRegressor(
        hidden_layer_sizes=(8,),
        activation="tanh",
        alpha=1e-3,
        max_iter=200,
        early_stopping=True,
        n_iter_no_change=10,
        random_state=0,
    ).fit((est - xm) / xs, (y - ym) / ys)
    fresh = mu.project(d[:50]) + 0.3
    np.testing.assert_allclose(second_stage_predict(w, fresh), ref.predict((fresh - xm) / xs) * ys + ym, atol=1e-10)
    jac = rng.standard_normal((4, 12))
    st = expression_stage("smile", w, mu, ex, jac)
    readout = rng.standard_normal((4, 3))
    m = ExpressionMapper(readout=readout, readout_bias=np.zeros(4), stages={"smile": st})
    out = second_stage_predict(w, fresh)
    emu_disp = ex.basis.mean + out[:, 3:] @ ex.basis.units  # (50, 12): m_k0 + M_k c_k
    want = (out[:, :3] - fresh) @ readout.T + emu_disp @ jac.T
    np.testing.assert_allclose(m.stage_delta("smile", fresh), want, atol=1e-10)


def test_mouth_jacobian_matches_the_geometry() -> None:
    """J of the four mouth parameters at a rest face: a mouth corner moved along the corner-to-corner line
    widens the mouth one for one; the lower inner lip moved down opens it by a third (three gap pairs)."""
    from training.facetrack import MOUTH_CORNERS, MU_LANDMARKS
    from training.mu_expressions import mouth_jacobian

    rng = np.random.default_rng(1)
    face = rng.standard_normal((468, 3)) * 0.3
    face[MOUTH_CORNERS[0]] = (-0.4, 1.0, 0.0)
    face[MOUTH_CORNERS[1]] = (0.4, 1.0, 0.0)
    for a, b in ((13, 14), (82, 87), (312, 317)):
        face[b] = face[a] + (0.0, 0.05, 0.0)
    jac = mouth_jacobian(face, MU_LANDMARKS)
    pos = {v: i for i, v in enumerate(MU_LANDMARKS)}
    assert jac[1, 3 * pos[MOUTH_CORNERS[1]]] == pytest.approx(1.0, abs=1e-6)
    assert jac[1, 3 * pos[MOUTH_CORNERS[0]]] == pytest.approx(-1.0, abs=1e-6)
    assert jac[2, 3 * pos[14] + 1] == pytest.approx(1 / 3, abs=1e-6)
