"""Unit selection core: EM-PCA vs SVD, Viterbi vs brute force, exact warping, self-selection."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from realtime_core.errors import ConfigError
from realtime_core.synthesis.concat import concatenate
from realtime_core.synthesis.corpus import FPS, MotionCorpus
from realtime_core.synthesis.empca import EmPcaConfig, fit_empca
from realtime_core.synthesis.search import (
    NoPathError,
    SearchConfig,
    build_graph,
    viterbi,
)
from realtime_core.synthesis.synthesizer import UnitSynthesizer, make_target
from realtime_core.synthesis.visemes import VISEME_ID, VISEMES, resolve, viseme_of


# ----------------------------------------------------------------------------- EM-PCA
def test_empca_spans_the_svd_subspace_and_picks_k_by_explained_variance():
    rng = np.random.default_rng(1)
    n, p = 600, 40
    scales = np.array([10.0, 6.0, 4.0, 2.5, 1.5, 1.0] + [0.05] * (p - 6))
    basis = np.linalg.qr(rng.standard_normal((p, p)))[0]
    y = (rng.standard_normal((n, p)) * scales) @ basis.T + rng.standard_normal(p) * 3
    pca = fit_empca(y, EmPcaConfig(max_components=12, explained=0.99, tolerance=1e-10))
    # the same rule on an ordinary SVD of the centred data
    yc = y - y.mean(0)
    _, sv, vt = np.linalg.svd(yc, full_matrices=False)
    var = sv**2 / (n - 1)
    k_svd = int(np.searchsorted(np.cumsum(var) / var.sum(), 0.99) + 1)
    assert pca.n_components == k_svd
    np.testing.assert_allclose(pca.variances, var[:k_svd], rtol=1e-6)
    np.testing.assert_allclose(pca.total_variance, var.sum(), rtol=1e-10)
    # principal angles between the subspaces ~ 0, and each axis equals the SVD's up to sign
    cosines = np.linalg.svd(pca.components @ vt[:k_svd].T, compute_uv=False)
    assert np.all(cosines > 1 - 1e-8)
    np.testing.assert_allclose(np.abs(np.sum(pca.components * vt[:k_svd], axis=1)), 1.0, atol=1e-6)
    # orthonormal rows; round trip within the discarded variance
    np.testing.assert_allclose(pca.components @ pca.components.T, np.eye(k_svd), atol=1e-10)
    err = np.mean(np.sum((pca.inverse_transform(pca.transform(y)) - y) ** 2, axis=1))
    np.testing.assert_allclose(err, var[k_svd:].sum() * (n - 1) / n, rtol=1e-6)


def test_empca_rejects_bad_data():
    with pytest.raises(ConfigError):
        EmPcaConfig(explained=1.5)
    with pytest.raises(ValueError, match="NaN"):
        fit_empca(np.array([[0.0, np.nan], [1.0, 2.0]]))


# ----------------------------------------------------------------------------- tiny corpora
def tiny_corpus(rng: np.random.Generator, visemes_per_sentence: list[list[str]], d: int = 3) -> MotionCorpus:
    """Sentences of random phone durations with smooth random motion (d coefficients + 1 channel)."""
    sentences = []
    for k, seq in enumerate(visemes_per_sentence):
        dur = rng.uniform(0.05, 0.2, len(seq))
        edges = np.concatenate([[0.0], np.cumsum(dur)])
        n_fr = int(np.ceil(edges[-1] * FPS)) + 1
        t = np.arange(n_fr) / FPS
        f = np.stack([np.sin(rng.uniform(2, 12) * t + rng.uniform(0, 6)) for _ in range(d + 1)], axis=1)
        phones = [(v, VISEME_ID[v], a, b) for v, a, b in zip(seq, edges[:-1], edges[1:])]
        sentences.append((f"s{k}", f, phones))
    return MotionCorpus.of_sentences(
        sentences,
        n_coefficients=d,
        dim_names=(*tuple(f"c{k}" for k in range(d)), "x"),
    )


class ReferenceCost:
    """The paper's path cost computed directly from its definition (independent of the search)."""

    def __init__(self, corpus: MotionCorpus, cfg: SearchConfig) -> None:
        self.corpus, self.cfg = corpus, cfg
        self.memo: dict = {}
        self.motions = [self._motion(q) for q in range(corpus.n_phones)]
        natural = [self.c_of(q, q, corpus.phone_end_s[q] - corpus.phone_start_s[q]) for q in range(corpus.n_phones)]
        self.c_ref = float(np.median(natural))

    def _motion(self, q):  # (L, K) motion vectors of phone q at L instants, np.interp per dim
        corpus = self.corpus
        f = corpus.sentence_frames(corpus.phone_sentence()[q])[:, : corpus.n_coefficients]
        tt = np.linspace(corpus.phone_start_s[q], corpus.phone_end_s[q], self.cfg.points)
        return np.stack([np.interp(tt * FPS, np.arange(len(f)), f[:, k]) for k in range(f.shape[1])], axis=1)

    def c_of(self, i, p, dur):
        key = (i, p, dur)
        if key not in self.memo:
            self.memo[key] = self._c_of(i, p, dur)
        return self.memo[key]

    def _c_of(self, i, p, dur):
        L = self.cfg.points
        dur = max(dur, self.cfg.min_blend_s)
        tau = np.linspace(0, 1, L)
        w = (3 * tau**2 - 2 * tau**3)[:, None]
        s = (1 - w) * self.motions[i] + w * self.motions[p]
        h = dur / (L - 1)
        acc = (s[:-2] - 2 * s[1:-1] + s[2:]) / h**2
        return float(np.sum(acc**2) * h / dur)

    def __call__(self, path, target, durations, mismatch=np.inf) -> float:
        return _reference_cost(self, path, target, durations, mismatch)


def _reference_cost(ref: ReferenceCost, path, target, durations, mismatch) -> float:
    corpus, cfg = ref.corpus, ref.cfg
    sent = corpus.phone_sentence()
    po = corpus.phone_offsets
    cost = 0.0
    for t, q in enumerate(path):
        if corpus.phone_visemes[q] != target[t]:
            return np.inf
        # the duration terms (not the paper's): w |ln(recorded / target duration)|, pauses their own w
        w = cfg.pause_duration_weight if VISEMES[target[t]] == "sil" else cfg.duration_weight
        cost += w * abs(np.log((corpus.phone_end_s[q] - corpus.phone_start_s[q]) / max(durations[t], 1e-3)))
        if t == 0:
            continue
        i = path[t - 1]
        par = q - 1 if q > po[sent[q]] else -1
        if par == i:
            continue
        if par < 0:
            return np.inf
        recorded = any(
            corpus.phone_visemes[j] == target[t] and j > po[sent[j]] and corpus.phone_visemes[j - 1] == target[t - 1]
            for j in range(corpus.n_phones)
        )
        # the paper's G; the finite stand-in only at a step whose diviseme the corpus never recorded
        g = 0.0 if corpus.phone_visemes[par] == corpus.phone_visemes[i] else (np.inf if recorded else mismatch)
        if not np.isfinite(g):
            return np.inf
        cost += 1.0 + cfg.beta * ref.c_of(i, par, durations[t - 1]) / ref.c_ref + g
    return cost


@pytest.mark.slow  # enumerates every state sequence
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_viterbi_equals_brute_force_on_a_tiny_graph(seed):
    rng = np.random.default_rng(seed)
    cls = ["PBM", "AA", "IY"]
    sents = [["sil", *list(rng.choice(cls, 4)), "sil"] for _ in range(4)]
    corpus = tiny_corpus(rng, sents)
    cfg = SearchConfig(beta=0.7, max_active=None)
    graph = build_graph(corpus, cfg)
    ref = ReferenceCost(corpus, cfg)
    vis = corpus.phone_visemes
    strict = 0
    for trial in range(8):
        if trial % 2 == 0:  # a random walk over admissible transitions: a finite path exists
            q = [int(rng.integers(corpus.n_phones))]
            for _ in range(4):
                ok = [j for j in range(corpus.n_phones) if graph.parent[j] >= 0 and vis[graph.parent[j]] == vis[q[-1]]]
                q.append(int(rng.choice(ok)) if ok else q[-1])
            target = vis[q].astype(np.int64)
        else:  # anything: often infeasible under the paper's G
            target = np.array([VISEME_ID[v] for v in rng.choice(cls, 5)])
        durations = rng.uniform(0.04, 0.25, len(target))
        # brute force over every state sequence showing the target's visemes (all others cost inf)
        pools = [np.flatnonzero(vis == v) for v in target]
        costs = {path: ref(path, target, durations) for path in itertools.product(*pools)}
        best = min(costs.values())
        if np.isfinite(best):
            sel = viterbi(graph, target, durations)
            strict += 1
            np.testing.assert_allclose(sel.cost, best, rtol=1e-6, atol=1e-9)
            np.testing.assert_allclose(costs[tuple(sel.states)], sel.cost, rtol=1e-6, atol=1e-9)
        else:
            with pytest.raises(NoPathError):
                viterbi(graph, target, durations)
        relaxed = {path: ref(path, target, durations, mismatch=20.0) for path in costs}
        sel = viterbi(graph, target, durations, mismatch_cost=20.0)
        np.testing.assert_allclose(sel.cost, min(relaxed.values()), rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(relaxed[tuple(sel.states)], sel.cost, rtol=1e-6, atol=1e-9)
    assert strict >= 4


def test_fewest_units_win_with_beta_zero():
    rng = np.random.default_rng(5)
    # the target is sentence 0's middle run; two other sentences can only give it in pieces
    sents = [["sil", "PBM", "AA", "IY", "FV", "sil"], ["sil", "PBM", "AA", "sil"], ["sil", "IY", "FV", "sil"]]
    corpus = tiny_corpus(rng, sents)
    # the paper's costs only (no duration terms): staying in a recording is free
    graph = build_graph(corpus, SearchConfig(beta=0.0, max_active=None, duration_weight=0, pause_duration_weight=0))
    target = np.array([VISEME_ID[v] for v in ["PBM", "AA", "IY", "FV"]])
    sel = viterbi(graph, target, np.full(4, 0.1))
    assert sel.n_units == 1 and sel.cost == 0.0
    np.testing.assert_array_equal(sel.states, [1, 2, 3, 4])


# ----------------------------------------------------------------------------- warping, self-selection
def test_warping_maps_every_unit_exactly_onto_its_target_phone():
    rng = np.random.default_rng(3)
    corpus = tiny_corpus(rng, [["sil", "PBM", "AA", "IY", "sil"]])
    # replace the motion by the sentence's own clock: frame k holds k / 30 s in every dim
    frames = np.repeat((np.arange(len(corpus.frames)) / FPS)[:, None], corpus.n_dims, axis=1)
    corpus = MotionCorpus(**{**corpus.__dict__, "frames": frames})
    graph = build_graph(corpus, SearchConfig(max_active=None))
    states = np.arange(5)
    starts = np.array([0.0, 0.31, 0.45, 0.9, 1.2])
    ends = np.append(starts[1:], 1.51)
    out = concatenate(corpus, states, starts, ends, parent=graph.parent)
    assert len(out) == int(np.ceil(1.51 * FPS))
    t = np.arange(len(out)) / FPS
    m = np.searchsorted(ends, t, side="right")
    tau = (t - starts[m]) / (ends[m] - starts[m])
    want = corpus.phone_start_s[states[m]] + tau * (corpus.phone_end_s - corpus.phone_start_s)[states[m]]
    np.testing.assert_allclose(out[:, 0], want, atol=1e-12)
    # a target boundary instant reads the source boundary exactly: the durations are hit exactly
    b = concatenate(
        corpus,
        states,
        starts * 0 + np.array([0, 0.2, 0.4, 0.6, 0.8]),
        np.array([0.2, 0.4, 0.6, 0.8, 1.0]),
        parent=graph.parent,
    )
    np.testing.assert_allclose(b[[6, 12, 18, 24], 0], corpus.phone_start_s[1:5], atol=1e-12)


def test_a_corpus_sentence_from_its_own_phones_selects_itself_and_reproduces_its_motion():
    rng = np.random.default_rng(4)
    sents = [
        ["sil", "PBM", "AA", "IY", "FV", "AA", "sil"],
        ["sil", "FV", "AA", "PBM", "IY", "sil"],
        ["sil", "PBM", "AA", "IY", "sil"],
    ]
    corpus = tiny_corpus(rng, sents)
    synth = UnitSynthesizer(corpus, SearchConfig())
    s = 0
    a, b = corpus.phone_offsets[s], corpus.phone_offsets[s + 1]
    phones = [(VISEMES[corpus.phone_visemes[q]], corpus.phone_start_s[q], corpus.phone_end_s[q]) for q in range(a, b)]
    # viseme names are not phone labels: use ARPAbet stand-ins of each class
    stand_in = {"sil": "sil", "PBM": "p", "AA": "aa", "IY": "iy", "FV": "f"}
    res = synth.synthesize(
        [(stand_in[v], x, y) for v, x, y in phones], "arpabet", n_frames=int(np.diff(corpus.frame_offsets)[s])
    )
    np.testing.assert_array_equal(res.selection.states, np.arange(a, b))
    assert res.selection.n_units == 1 and res.selection.cost == 0.0
    covered = np.arange(len(res.frames)) / FPS <= corpus.phone_end_s[b - 1]  # later frames hold the last value
    np.testing.assert_allclose(res.frames[covered], corpus.sentence_frames(s)[covered], atol=1e-9)


def test_target_fills_gaps_and_reports_unknown_phones():
    avail = frozenset(VISEMES) - {"OY"}
    tgt = make_target(
        [("p", 0.1, 0.2), ("oy", 0.2, 0.4), ("zzz", 0.5, 0.6), ("sil", 0.6, 0.7), ("sp", 0.7, 0.8)], "arpabet", avail
    )
    assert tgt.labels == ("sil", "p", "oy", "sil", "zzz", "sil", "sp")  # the input's own pauses stay
    np.testing.assert_allclose(tgt.starts_s, [0, 0.1, 0.2, 0.4, 0.5, 0.6, 0.7])
    gap = make_target([("p", 0.0, 0.1), ("sil", 0.1, 0.2), ("p", 0.3, 0.4)], "arpabet", avail)
    assert gap.labels == ("p", "sil", "p") and gap.ends_s[1] == pytest.approx(0.3)  # the gap joins the pause
    np.testing.assert_allclose(tgt.ends_s[-1], 0.8)
    assert VISEMES[tgt.visemes[2]] == "AO" and tgt.substituted == 1
    assert tgt.unknown == ("zzz",)
    with pytest.raises(ConfigError):
        make_target([], "arpabet", avail)


def test_target_gives_an_espeak_link_to_the_vowel_before_it():
    """espeak-ng writes ``;`` between two vowels ("my umbrella": maI; Vmbr'El@): no phone of its own
    and no unknown phone, its time belongs to the vowel before."""
    avail = frozenset(VISEMES)
    tgt = make_target([("m", 0.0, 0.05), ("aI", 0.05, 0.1), (";", 0.1, 0.15), ("V", 0.15, 0.2)], "espeak-en", avail)
    assert tgt.labels == ("m", "aI", "V") and tgt.unknown == ()
    np.testing.assert_allclose(tgt.ends_s, [0.05, 0.15, 0.2])
    assert [VISEMES[v] for v in tgt.visemes] == ["PBM", "AY", "AH"]
    first = make_target([(";", 0.0, 0.05), ("a", 0.05, 0.1)], "espeak-es", avail)
    assert first.labels == ("sil", "a") and first.unknown == ()


def test_viseme_table_covers_the_inventories_and_fallbacks_resolve():
    assert viseme_of("AH0", "arpabet") == "AH" and viseme_of("aI", "espeak-en") == "AY"
    assert viseme_of("**", "espeak-es") == "TDNL" and viseme_of("B", "espeak-es") == "PBM"
    with pytest.raises(ConfigError, match="xx"):
        viseme_of("xx", "arpabet")
    assert resolve("OY", frozenset({"OW", "AA"})) == "OW"
    with pytest.raises(ConfigError):
        resolve("AA", frozenset())


def test_n_best_averages_sequences_from_other_recordings_even_past_a_unique_diviseme():
    rng = np.random.default_rng(6)
    # PBM -> FV is recorded only in sentence 0: the second sequence must cross it without it
    sents = [
        ["sil", "AA", "PBM", "FV", "IY", "sil"],
        ["sil", "AA", "PBM", "AA", "sil"],
        ["sil", "FV", "IY", "sil"],
        ["sil", "IY", "AA", "PBM", "sil"],
    ]
    corpus = tiny_corpus(rng, sents)
    synth = UnitSynthesizer(corpus, SearchConfig(max_active=None))
    phones = [
        ("sil", 0.0, 0.2),
        ("aa", 0.2, 0.35),
        ("p", 0.35, 0.45),
        ("f", 0.45, 0.55),
        ("iy", 0.55, 0.7),
        ("sil", 0.7, 0.9),
    ]
    one = synth.synthesize(phones, "arpabet")
    two = synth.synthesize(phones, "arpabet", n_best=2, ensemble_gain=1.0)
    assert one.selection.n_units == 1 and one.selection.n_mismatched == 0
    (alt,) = two.alternatives
    sent = corpus.phone_sentence()
    assert 0 not in set(sent[alt.states]) and alt.n_mismatched >= 1
    other = concatenate(
        corpus,
        alt.states,
        one.target.starts_s,
        one.target.ends_s,
        parent=synth.graph.parent,
        anchored=np.array([-1, 0, 0, 0, 0, 1], dtype=np.int8),
    )
    np.testing.assert_allclose(two.frames, 0.5 * (one.frames + other), atol=1e-12)
    # the ensemble's range gain scales the deviation from the rest frame; one sequence is never scaled
    rest = np.linspace(-0.1, 0.1, corpus.n_dims)
    gained = UnitSynthesizer(corpus, SearchConfig(max_active=None), rest=rest)
    np.testing.assert_allclose(
        gained.synthesize(phones, "arpabet", n_best=2, ensemble_gain=1.3).frames,
        rest + 1.3 * (two.frames - rest),
        atol=1e-12,
    )
    np.testing.assert_array_equal(gained.synthesize(phones, "arpabet", ensemble_gain=1.3).frames, one.frames)
    with pytest.raises(ConfigError, match="ensemble_gain"):
        synth.synthesize(phones, "arpabet", n_best=2, ensemble_gain=0.0)
    with pytest.raises(ConfigError, match="rest"):
        UnitSynthesizer(corpus, rest=np.zeros(corpus.n_dims + 1))


def test_in_place_jump_costs_equal_the_smoothness_cost_they_price():
    from realtime_core.synthesis.search import _jump_costs, smoothness

    rng = np.random.default_rng(11)
    corpus = tiny_corpus(rng, [["sil", "PBM", "AA", "IY", "sil"], ["sil", "AA", "PBM", "IY", "sil"]])
    graph = build_graph(corpus, SearchConfig(beta=0.3))
    i, p = np.array([1, 2, 6]), np.array([2, 3, 5, 7])
    phi = rng.uniform(0, 3, len(i))
    for dur in (0.01, 0.12):  # below and above min_blend_s
        want = phi[:, None] + 1.0 + 0.3 * smoothness(graph, i, p, dur)
        np.testing.assert_allclose(_jump_costs(graph, i, p, phi, dur), want, rtol=1e-12)


def test_a_junction_leaves_one_recording_and_arrives_on_the_next_without_a_step():
    rng = np.random.default_rng(12)
    corpus = tiny_corpus(rng, [["sil", "PBM", "AA", "IY", "sil"], ["sil", "AA", "IY", "FV", "sil"]])
    graph = build_graph(corpus, SearchConfig(max_active=None))
    states = np.array([1, 2, 7])  # PBM AA of sentence 0, then IY of sentence 1 (its parent 6 is an AA)
    assert graph.parent[7] == 6 and corpus.phone_visemes[6] == corpus.phone_visemes[2]
    starts, ends = np.array([0.0, 0.1, 0.25]), np.array([0.1, 0.25, 0.4])
    fps = 3000.0  # dense: a step would show as one large difference
    out = concatenate(corpus, states, starts, ends, parent=graph.parent, fps=fps)
    d = np.abs(np.diff(out, axis=0)).max(axis=1)
    k0, k1 = int(0.1 * fps), int(0.25 * fps)  # the two target boundaries (the second is the junction)
    typical = np.median(d)
    assert d[k0 - 1] < 10 * typical + 1e-9 and d[k1 - 1] < 10 * typical + 1e-9
    # the blended phone starts exactly on its own unit and ends exactly on the next unit's parent
    single = concatenate(corpus, np.array([1, 2, 3]), starts, ends, parent=graph.parent, fps=fps)
    np.testing.assert_allclose(out[:k0], single[:k0], atol=1e-12)  # before the junction's phone: unchanged
    np.testing.assert_allclose(out[k0], single[k0], atol=1e-12)  # w = 0 at the phone's start
    into = concatenate(corpus, np.array([5, 6, 7]), starts, ends, parent=graph.parent, fps=fps)
    np.testing.assert_allclose(out[k1 - 1], into[k1 - 1], atol=1e-3)  # w = 1 at its end
    np.testing.assert_allclose(out[k1:], into[k1:], atol=1e-12)  # then the recording continues as is


def test_loading_the_shipped_corpus_imports_neither_the_speech_model_nor_scipy_optimize():
    """`facecast say` loads the unit corpus on every run: reading its .npz must not import realtime_core.avmodel
    (the HMM, the front end, scipy.cluster: ~90 ms of its "corpus + graph" stage) for a container helper, nor
    scipy.optimize (0.3-0.7 s) for the Motion Units' nonnegative fit that a load never runs."""
    import subprocess
    import sys
    from pathlib import Path

    from assets.unitcorpus import SHIPPED

    if not SHIPPED.is_file():
        pytest.skip("no shipped unit corpus")
    code = (
        "import sys\n"
        "from assets.unitcorpus import SHIPPED, load_unit_corpus\n"
        "assert len(load_unit_corpus(SHIPPED).corpus.frames) > 0\n"
        "heavy = ('realtime_core.avmodel', 'realtime_core.hmm', 'scipy.optimize')\n"
        "print(sorted(m for m in sys.modules if m in heavy))\n"
    )
    root = Path(__file__).resolve().parents[3]
    out = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
