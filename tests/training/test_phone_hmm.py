"""The talker-specific aligner (training.phone_hmm) on synthetic sentences with known boundaries."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from training.phone_hmm import (
    SILENCE,
    PhoneHmmConfig,
    align_states,
    build_graph,
    features,
    segments_to_phones,
    train,
)

# Four phones and silence, each a 3-state model with its own means in 6 dimensions.
PHONES = ("AA", "B", "IY", "M", SILENCE)
WORDS = {"bee": ("B", "IY"), "ma": ("M", "AA"), "am": ("AA", "M")}
CONFIG = PhoneHmmConfig(n_iter=6, word_slack_s=0.1)


def _truth_means(rng: np.random.Generator, spread: float) -> dict[tuple[str, int], np.ndarray]:
    return {(p, k): rng.normal(0.0, spread, 6) for p in PHONES for k in range(3)}


def _sentence(rng: np.random.Generator, means: dict, word_seq: list[str]):
    """Features (T, 6), the GRID-style word alignment (s) and the true phone edges (frames)."""
    frames: list[np.ndarray] = []
    edges: list[tuple[str, int, int]] = []
    words: list[tuple[float, float, str]] = []
    fr = CONFIG.frame_rate_hz

    def emit(p: str, lo: int, hi: int) -> None:
        start = sum(len(f) for f in frames)
        for k in range(3):
            n = int(rng.integers(lo, hi))
            frames.append(means[(p, k)] + rng.normal(0.0, 1.0, (n, 6)))
        edges.append((p, start, sum(len(f) for f in frames)))

    emit(SILENCE, 10, 20)
    words.append((0.0, edges[-1][2] / fr, "sil"))
    for w in word_seq:
        w0 = edges[-1][2]
        for p in WORDS[w]:
            emit(p, 2, 6)
        words.append((w0 / fr, edges[-1][2] / fr, w))
    w0 = edges[-1][2]
    emit(SILENCE, 10, 20)
    words.append((w0 / fr, edges[-1][2] / fr, "sil"))
    return np.concatenate(frames), words, edges


def _corpus(seed: int, n: int, spread: float = 3.0):
    """``n`` sentences; ``spread``: standard deviation of the state means (noise: 1)."""
    rng = np.random.default_rng(seed)
    means = _truth_means(rng, spread)
    out = []
    for _ in range(n):
        seq = list(rng.choice(list(WORDS), size=int(rng.integers(2, 5))))
        x, words, edges = _sentence(rng, means, seq)
        # The word alignment given to the aligner is coarse: every inner word edge off by up to 4 frames.
        jitter = [0.0] + [float(rng.integers(-4, 5)) / CONFIG.frame_rate_hz for _ in words[1:]] + [0.0]
        given = [(a + jitter[i], b + jitter[i + 1], w) for i, (a, b, w) in enumerate(words)]
        given[0] = (0.0, given[0][1], given[0][2])
        given[-1] = (given[-1][0], words[-1][1], given[-1][2])
        out.append((x, [(w, WORDS[w]) for _, _, w in words if w != "sil"], given, edges))
    return out


def test_aligner_recovers_known_boundaries_and_em_never_falls() -> None:
    data = _corpus(0, 60)
    model = train([(x, pw, words) for x, pw, words, _ in data], CONFIG)
    h = np.array(model.history)
    assert len(h) == CONFIG.n_iter
    assert np.all(np.diff(h) >= -1e-6), h  # embedded Baum-Welch: the likelihood never falls
    errors = []
    for x, pw, words, truth in data:
        g = build_graph(model, pw, len(x), spans=[(a, b) for a, b, w in words if w != "sil"], config=CONFIG)
        segs, ll = align_states(model, g, x)
        assert np.isfinite(ll)
        got = [(lab, a, b) for lab, a, b in segs if lab != "SP"]
        assert [lab for lab, _, _ in got] == [lab for lab, _, _ in truth]
        errors += [abs(a - ta) for (_, a, _), (_, ta, _) in zip(got[1:], truth[1:])]
    errors_arr = np.array(errors)
    # The flat start had word edges up to 4 frames off and phones cut evenly; the trained models place
    # nearly every boundary on its true frame.
    assert np.mean(errors_arr == 0) > 0.9, np.bincount(errors_arr)
    assert errors_arr.max() <= 2


def test_untrained_flat_start_is_worse_than_trained() -> None:
    """The re-estimation is what finds the boundaries: without it (n_iter 0) far fewer are exact."""
    data = _corpus(1, 40, spread=1.0)
    sents = [(x, pw, words) for x, pw, words, _ in data]
    exact = {}
    for n_iter in (0, CONFIG.n_iter):
        cfg = PhoneHmmConfig(n_iter=n_iter, word_slack_s=0.1)
        model = train(sents, cfg)
        hits = []
        for x, pw, words, truth in data:
            g = build_graph(model, pw, len(x), spans=[(a, b) for a, b, w in words if w != "sil"], config=cfg)
            segs, _ = align_states(model, g, x)
            got = [(lab, a) for lab, a, _ in segs if lab != "SP"]
            hits += [a == ta for (_, a), (_, ta, _) in zip(got[1:], truth[1:])]
        exact[n_iter] = float(np.mean(hits))
    assert exact[CONFIG.n_iter] > exact[0] + 0.1, exact


def test_segments_to_seconds_tile_the_recording_and_merge_pauses() -> None:
    segs = [(SILENCE, 0, 50), ("B", 50, 56), ("IY", 56, 70), ("SP", 70, 75), ("M", 75, 80), (SILENCE, 80, 120)]
    phones = segments_to_phones(segs, 1.21, CONFIG)
    assert phones[0].start_s == 0.0 and phones[-1].end_s == pytest.approx(1.21)
    assert all(abs(p.end_s - q.start_s) < 1e-12 for p, q in itertools.pairwise(phones))
    assert [p.phoneme for p in phones] == [SILENCE, "B", "IY", SILENCE, "M", SILENCE]
    # boundary between frames 49 and 50: midway between their 25 ms windows' centres
    assert phones[1].start_s == pytest.approx(0.50 + 0.0075)


def test_features_shape_and_mean_normalised() -> None:
    rng = np.random.default_rng(0)
    x = features(rng.normal(0, 0.1, 16000).astype(np.float32), CONFIG)
    assert x.shape == (100, 39)
    assert np.allclose(x[:, :13].mean(axis=0), 0.0, atol=1e-9)


def test_two_gaussian_mixtures_keep_em_monotone_and_boundaries() -> None:
    """Splitting to two Gaussians per state (HHEd MU style): within each stage the likelihood never
    falls, the split model scores at least the single-Gaussian one, and boundaries stay found."""
    data = _corpus(2, 40)
    cfg = PhoneHmmConfig(n_iter=4, n_mix=2, mix_iter=3, word_slack_s=0.1)
    model = train([(x, pw, words) for x, pw, words, _ in data], cfg)
    assert model.means.shape[1] == 2 and np.allclose(model.weights.sum(axis=1), 1.0)
    h = np.array(model.history)
    assert len(h) == 7
    assert np.all(np.diff(h[:4]) >= -1e-6) and np.all(np.diff(h[4:]) >= -1e-6), h
    assert h[-1] >= h[3] - 1e-6
    exact = []
    for x, pw, words, truth in data:
        g = build_graph(model, pw, len(x), spans=[(a, b) for a, b, w in words if w != "sil"], config=cfg)
        segs, _ = align_states(model, g, x)
        got = [(lab, a) for lab, a, _ in segs if lab != "SP"]
        exact += [a == ta for (_, a), (_, ta, _) in zip(got[1:], truth[1:])]
    assert np.mean(exact) > 0.9


def test_free_word_edge_check_accepts_aligned_and_names_problems() -> None:
    from training.alignments import Phone
    from training.grid_phones import check_free_sentence

    words = [(0.0, 0.5, "sil"), (0.5, 0.8, "bin"), (0.8, 1.0, "sil")]
    good = (Phone(SILENCE, 0.0, 0.52), Phone("B", 0.52, 0.6), Phone("IH", 0.6, 0.7), Phone("N", 0.7, 0.85))
    good += (Phone(SILENCE, 0.85, 1.0),)
    assert check_free_sentence(good, words).problems == ()
    late = (Phone(SILENCE, 0.0, 0.65), Phone("B", 0.65, 0.7), Phone("IH", 0.7, 0.8), Phone("N", 0.8, 0.95))
    assert any("outside GRID" in p for p in check_free_sentence(late, words, slack_s=0.1).problems)
    wrong = (Phone(SILENCE, 0.0, 0.5), Phone("P", 0.5, 0.6), Phone("IH", 0.6, 0.7), Phone("N", 0.7, 1.0))
    assert check_free_sentence(wrong, words).problems
