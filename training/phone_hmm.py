"""Talker-specific forced alignment: monophone HMMs trained by embedded re-estimation on the
talker's own MFCCs (HTK-style ``HCompV``/``HERest``/``HVite``), for the GRID s1 phone labels.

Why
---
The default GRID labels (:mod:`training.grid_phones`, method ``pocketsphinx``) come from a
US-English acoustic model and are then stretched linearly onto GRID's word spans, so every phone
edge inherits both the foreign model's error and GRID's word edges (10 ms grid, ~40 ms from
pocketsphinx's in the median). Here the phone models are trained on the talker's own speech.

How
---
* **Features**: 12 MFCCs + c0 at 100 frames/s (25 ms window, the project's
  :func:`realtime_core.features.mfcc.mfcc`), deltas and accelerations (HTK regression, +-2
  frames), mean-normalised per sentence: ``(T, 39)``.
* **Models**: every ARPAbet phone of the GRID pronunciations and ``SIL``: 3 emitting states,
  left to right, one diagonal Gaussian per state; ``SP`` (a short pause) is one state tied to
  SIL's middle state, optional between words.
* **Sentence graph**: ``SIL``, the words' phones with an optional ``SP`` after each word but the
  last, ``SIL``; it must start in the first and end in the last SIL state. A word's states may
  only be occupied within ``word_slack_s`` of its GRID word span (the GRID alignments are right to
  within that; it keeps a noisy pause from swallowing a word), the rest is free.
* **Flat start inside the word alignments**: the first estimates come from each GRID word span
  cut uniformly into its phones' states (pauses into SIL's); then ``n_iter`` Baum-Welch passes over
  whole sentences (embedded re-estimation: all phones of a sentence at once, the occupation
  probabilities from the project's forward-backward kernels), then a Viterbi alignment.
* **Boundaries**: frame ``k``'s window starts at ``k * 10 ms``; the boundary between frames ``k-1``
  and ``k`` is placed midway between their window centres, ``k * 10 ms + 7.5 ms``.

The per-sentence log-likelihood never falls across iterations (EM); tests check that and that the
aligner recovers known boundaries of synthetic sentences.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.special import logsumexp

from realtime_core.features.mfcc import MfccConfig, mfcc
from realtime_core.hmm.kernels import expected_transitions, forward_backward, viterbi
from training.alignments import Phone
from training.errors import ConfigError

SILENCE = "SIL"
SHORT_PAUSE = "SP"
SILENCE_WORDS = frozenset({"sil", "sp"})
Words = Sequence[tuple[float, float, str]]
"""GRID word alignment: [(start_s, end_s, word)] including ``sil``/``sp``."""


@dataclass(frozen=True, kw_only=True)
class PhoneHmmConfig:
    """frame_rate_hz: feature rows per second; window_hops: analysis window in hops (2.5: 25 ms at
    100 Hz); n_ceps: MFCCs besides c0; states: emitting states per phone; n_iter: Baum-Welch
    passes; var_floor: variance floor as a fraction of the global variance; self_loop_init: first
    self-loop probability; word_slack_s: how far outside its GRID span a word may be placed (None:
    unconstrained); min_count: a state seen in fewer frames keeps its previous estimate; n_mix:
    Gaussians per state, reached by splitting (HTK ``HHEd MU``: each component's mean moved +-0.2
    standard deviations) after the single-Gaussian passes, each split followed by ``mix_iter``
    passes."""

    sample_rate_hz: int = 16000
    frame_rate_hz: int = 100
    window_hops: float = 2.5
    n_ceps: int = 12
    states: int = 3
    n_iter: int = 5
    var_floor: float = 0.01
    self_loop_init: float = 0.6
    word_slack_s: float | None = 0.1
    min_count: float = 3.0
    n_mix: int = 1
    mix_iter: int = 4

    def __post_init__(self) -> None:
        if self.states < 1 or self.n_iter < 0:
            raise ConfigError(f"states must be >= 1 and n_iter >= 0, got {self.states}, {self.n_iter}")
        if not 0.0 < self.self_loop_init < 1.0:
            raise ConfigError(f"self_loop_init must be in (0, 1), got {self.self_loop_init}")
        if not 0.0 < self.var_floor < 1.0:
            raise ConfigError(f"var_floor must be in (0, 1), got {self.var_floor}")
        if self.n_mix < 1 or self.n_mix & (self.n_mix - 1) or self.mix_iter < 0:
            raise ConfigError(f"n_mix must be a power of two >= 1 and mix_iter >= 0, got {self.n_mix}, {self.mix_iter}")
        if self.word_slack_s is not None and self.word_slack_s < 0:
            raise ConfigError(f"word_slack_s must be >= 0 or None, got {self.word_slack_s}")

    @property
    def frame_s(self) -> float:
        return 1.0 / self.frame_rate_hz

    @property
    def boundary_offset_s(self) -> float:
        """Time of the boundary before frame 0's successor minus one frame: half the window's excess
        over the hop (the midpoint of consecutive window centres)."""
        return 0.5 * (self.window_hops - 1.0) * self.frame_s


def features(samples: np.ndarray, config: PhoneHmmConfig) -> np.ndarray:
    """``(n,)`` audio at ``config.sample_rate_hz`` -> ``(T, 3 (n_ceps + 1)) float64``: MFCCs with c0,
    deltas and accelerations, mean-normalised over the sentence."""
    mc = MfccConfig(
        sample_rate_hz=config.sample_rate_hz,
        frame_rate_hz=config.frame_rate_hz,
        window_hops=config.window_hops,
        n_ceps=config.n_ceps,
        include_c0=True,
        lifter=22.0,
    )
    c = mfcc(samples, mc)
    c = c - c.mean(axis=0)
    d = _deltas(c)
    return np.concatenate([c, d, _deltas(d)], axis=1)


def _deltas(x: np.ndarray, width: int = 2) -> np.ndarray:
    """HTK regression deltas over +-``width`` frames (edges repeated)."""
    pad = np.concatenate([np.repeat(x[:1], width, 0), x, np.repeat(x[-1:], width, 0)])
    n = len(x)
    num = sum(k * (pad[width + k : width + k + n] - pad[width - k : width - k + n]) for k in range(1, width + 1))
    return num / (2.0 * sum(k * k for k in range(1, width + 1)))


@dataclass(frozen=True)
class SentenceGraph:
    """The states of one sentence's HMM. ``tied``: (N,) model state index of each graph state;
    ``phone``: (N,) index into ``labels`` of the phone instance a state belongs to; ``labels``: the
    phone instances' labels (SIL / SP / ARPAbet); ``word``: (n_instances,) word index or -1;
    ``log_start``, ``log_trans``: (N,), (N, N); ``window``: (N, 2) allowed frame range [lo, hi)."""

    tied: np.ndarray
    phone: np.ndarray
    labels: tuple[str, ...]
    log_start: np.ndarray
    log_trans: np.ndarray
    window: np.ndarray


@dataclass
class PhoneHmmSet:
    """Monophone models: ``names`` (phone labels, SIL included), per state (``len(names) * states``
    of them) ``weights`` (n_states, M), ``means``/``vars`` (n_states, M, D) of M diagonal Gaussians
    and ``self_loop`` (n_states,)."""

    names: tuple[str, ...]
    states: int
    weights: np.ndarray
    means: np.ndarray
    vars: np.ndarray
    self_loop: np.ndarray
    history: list[float] = field(default_factory=list)
    """Total log-likelihood per frame after each Baum-Welch pass's E-step (EM: never falls)."""

    def state(self, phone: str, k: int) -> int:
        """Model state index of ``phone``'s k-th state (SP: SIL's middle state)."""
        if phone == SHORT_PAUSE:
            return self.names.index(SILENCE) * self.states + self.states // 2
        return self.names.index(phone) * self.states + k

    def component_log_densities(self, x: np.ndarray) -> np.ndarray:
        """``(T, D)`` -> ``(T, n_states, M)``: log(weight) + diagonal Gaussian log density."""
        s, m, d = self.means.shape
        mu, var = self.means.reshape(s * m, d), self.vars.reshape(s * m, d)
        iv = 1.0 / var
        const = -0.5 * (d * np.log(2 * np.pi) + np.log(var).sum(axis=1))
        quad = (x * x) @ iv.T - 2.0 * x @ (mu * iv).T + ((mu**2) * iv).sum(axis=1)
        with np.errstate(divide="ignore"):
            lw = np.log(self.weights).reshape(s * m)
        return (const - 0.5 * quad + lw).reshape(len(x), s, m)

    def log_emissions(self, x: np.ndarray) -> np.ndarray:
        """``(T, D)`` -> ``(T, n_states)`` log densities of the state mixtures."""
        return logsumexp(self.component_log_densities(x), axis=2)

    def split(self) -> PhoneHmmSet:
        """Every component split in two, means moved +-0.2 standard deviations, weights halved."""
        sd = np.sqrt(self.vars)
        return PhoneHmmSet(
            names=self.names,
            states=self.states,
            weights=np.repeat(self.weights / 2.0, 2, axis=1),
            means=np.concatenate([self.means - 0.2 * sd, self.means + 0.2 * sd], axis=1),
            vars=np.concatenate([self.vars, self.vars], axis=1),
            self_loop=self.self_loop.copy(),
            history=list(self.history),
        )


def build_graph(
    model: PhoneHmmSet,
    words: Sequence[tuple[str, tuple[str, ...]]],
    n_frames: int,
    *,
    spans: Sequence[tuple[float, float]] | None = None,
    config: PhoneHmmConfig,
) -> SentenceGraph:
    """The sentence HMM of ``words`` = [(word, its phones)] between SIL and SIL, an optional SP after
    every word but the last. ``spans``: each word's GRID span (s), limiting where its states may be
    occupied to within ``config.word_slack_s``."""
    s = model.states
    tied: list[int] = []
    phone: list[int] = []
    labels: list[str] = []
    window: list[tuple[int, int]] = []
    # (first state, last state, skippable) per element in order
    elements: list[tuple[int, int, bool]] = []

    def add(label: str, n_states: int, win: tuple[int, int], skippable: bool) -> None:
        first = len(tied)
        labels.append(label)
        for k in range(n_states):
            tied.append(model.state(label, k))
            phone.append(len(labels) - 1)
            window.append(win)
        elements.append((first, len(tied) - 1, skippable))

    full = (0, n_frames)
    add(SILENCE, s, full, False)
    for w, (_, pron) in enumerate(words):
        win = full
        if spans is not None and config.word_slack_s is not None:
            a, b = spans[w]
            lo = max(0, int(np.floor((a - config.word_slack_s) * config.frame_rate_hz)))
            hi = min(n_frames, int(np.ceil((b + config.word_slack_s) * config.frame_rate_hz)))
            win = (lo, max(hi, lo + 1))
        for p in pron:
            add(p, s, win, False)
        if w < len(words) - 1:
            add(SHORT_PAUSE, 1, full, True)
    add(SILENCE, s, full, False)
    n = len(tied)
    loop = model.self_loop[np.array(tied)]
    trans = np.zeros((n, n))
    for i in range(n):
        trans[i, i] = loop[i]
    # Within an element: state k -> k + 1. Between elements: the last state goes to the next
    # element's first state, and past a skippable element (SP) with half of the exit mass.
    for e, (first, last, _) in enumerate(elements):
        for i in range(first, last):
            trans[i, i + 1] = 1.0 - loop[i]
        if e + 1 < len(elements):
            exit_p = 1.0 - loop[last]
            nxt_first, _, skippable = elements[e + 1]
            if skippable and e + 2 < len(elements):
                trans[last, nxt_first] = 0.5 * exit_p
                trans[last, elements[e + 2][0]] = 0.5 * exit_p
            else:
                trans[last, nxt_first] = exit_p
        else:
            trans[last, last] = 1.0
    with np.errstate(divide="ignore"):
        log_trans = np.log(trans)
    log_start = np.full(n, -np.inf)
    log_start[0] = 0.0
    return SentenceGraph(
        tied=np.array(tied),
        phone=np.array(phone),
        labels=tuple(labels),
        log_start=log_start,
        log_trans=log_trans,
        window=np.array(window),
    )


def _graph_log_b(model: PhoneHmmSet, graph: SentenceGraph, x: np.ndarray) -> np.ndarray:
    return _restrict(model.log_emissions(x)[:, graph.tied], graph)


def _restrict(lb: np.ndarray, graph: SentenceGraph) -> np.ndarray:
    """(T, N) graph log emissions with the word windows and the final state enforced (in place)."""
    t = np.arange(len(lb))[:, None]
    lb[(t < graph.window[None, :, 0]) | (t >= graph.window[None, :, 1])] = -np.inf
    lb[-1, :-1] = -np.inf  # end in the final SIL state
    return lb


def uniform_segmentation(
    pron_words: Sequence[tuple[str, tuple[str, ...]]], words: Words, n_frames: int, config: PhoneHmmConfig
) -> list[tuple[str, int, int, int]]:
    """Flat start inside the word alignments: [(phone, state k, first frame, end frame)]: each GRID
    word span cut evenly into its phones' states, pauses into SIL's."""
    out: list[tuple[str, int, int, int]] = []
    spoken = iter(pron_words)
    for a, b, w in words:
        f0 = min(n_frames, int(round(a * config.frame_rate_hz)))
        f1 = min(n_frames, int(round(b * config.frame_rate_hz)))
        units = [(SILENCE, k) for k in range(config.states)] if w in SILENCE_WORDS else None
        if units is None:
            _, pron = next(spoken)
            units = [(p, k) for p in pron for k in range(config.states)]
        edges = np.linspace(f0, f1, len(units) + 1).round().astype(int)
        for (p, k), e0, e1 in zip(units, edges[:-1], edges[1:]):
            if e1 > e0:
                out.append((p, k, int(e0), int(e1)))
    return out


def init_models(
    data: Sequence[tuple[np.ndarray, list[tuple[str, int, int, int]]]], names: Sequence[str], config: PhoneHmmConfig
) -> PhoneHmmSet:
    """Means and variances from segmented features (``[(features (T, D), segmentation)]``); states
    never seen start at the global mean and variance."""
    allx = np.concatenate([x for x, _ in data])
    gmean, gvar = allx.mean(axis=0), allx.var(axis=0)
    n = len(names) * config.states
    idx = {p: i for i, p in enumerate(names)}
    cnt = np.zeros(n)
    s1 = np.zeros((n, allx.shape[1]))
    s2 = np.zeros_like(s1)
    for x, seg in data:
        for p, k, e0, e1 in seg:
            j = idx[p] * config.states + k
            cnt[j] += e1 - e0
            s1[j] += x[e0:e1].sum(axis=0)
            s2[j] += (x[e0:e1] ** 2).sum(axis=0)
    means = np.tile(gmean, (n, 1))
    vars_ = np.tile(gvar, (n, 1))
    seen = cnt >= config.min_count
    means[seen] = s1[seen] / cnt[seen, None]
    vars_[seen] = s2[seen] / cnt[seen, None] - means[seen] ** 2
    vars_ = np.maximum(vars_, config.var_floor * gvar)
    return PhoneHmmSet(
        names=tuple(names),
        states=config.states,
        weights=np.ones((n, 1)),
        means=means[:, None, :],
        vars=vars_[:, None, :],
        self_loop=np.full(n, config.self_loop_init),
    )


def baum_welch_pass(
    model: PhoneHmmSet,
    data: Sequence[tuple[np.ndarray, SentenceGraph]],
    config: PhoneHmmConfig,
    floor_var: np.ndarray,
) -> tuple[PhoneHmmSet, float]:
    """One embedded re-estimation pass over ``[(features, graph)]``. Returns (new model, total
    log-likelihood per frame of the old model: the EM objective)."""
    n, m, d = model.means.shape
    occ = np.zeros((n, m))
    s1 = np.zeros((n, m, d))
    s2 = np.zeros((n, m, d))
    stay = np.zeros(n)
    out = np.zeros(n)
    total, frames = 0.0, 0
    for x, g in data:
        comp = model.component_log_densities(x)  # (T, n, m)
        state_ll = logsumexp(comp, axis=2)  # (T, n)
        lb = _restrict(state_ll[:, g.tied], g)
        gamma, ll, la, lbeta = forward_backward(g.log_start, g.log_trans, lb)
        if not np.isfinite(ll):
            continue  # no path through this sentence's graph (too short for its phones): skipped
        total += ll
        frames += len(x)
        xi = expected_transitions(la, lbeta, g.log_trans, lb, ll)
        # occupation of each model state (graph states tied to it summed), then of its components
        w = np.zeros((len(x), n))
        np.add.at(w.T, g.tied, gamma.T)
        used = np.flatnonzero(w.sum(axis=0) > 0)
        r = np.exp(comp[:, used] - state_ll[:, used, None]) * w[:, used, None]  # (T, u, m)
        occ[used] += r.sum(axis=0)
        s1[used] += np.einsum("tum,td->umd", r, x)
        s2[used] += np.einsum("tum,td->umd", r, x * x)
        np.add.at(stay, g.tied, np.diag(xi))
        np.add.at(out, g.tied, gamma[:-1].sum(axis=0))
    seen = occ >= config.min_count
    means = model.means.copy()
    vars_ = model.vars.copy()
    means[seen] = s1[seen] / occ[seen][:, None]
    vars_[seen] = np.maximum(s2[seen] / occ[seen][:, None] - means[seen] ** 2, floor_var)
    weights = model.weights.copy()
    tot = occ.sum(axis=1)
    ok_w = tot >= config.min_count
    weights[ok_w] = np.maximum(occ[ok_w] / tot[ok_w, None], 1e-4)
    weights /= weights.sum(axis=1, keepdims=True)
    loop = model.self_loop.copy()
    ok = out > config.min_count
    loop[ok] = np.clip(stay[ok] / out[ok], 0.01, 0.99)
    new = PhoneHmmSet(
        names=model.names,
        states=model.states,
        weights=weights,
        means=means,
        vars=vars_,
        self_loop=loop,
        history=[*model.history, total / max(frames, 1)],
    )
    return new, total / max(frames, 1)


def align_states(model: PhoneHmmSet, graph: SentenceGraph, x: np.ndarray) -> tuple[list[tuple[str, int, int]], float]:
    """Viterbi: [(label, first frame, end frame)] per phone instance visited (SP / SIL included),
    and the path's log-likelihood (-inf: no path)."""
    lb = _graph_log_b(model, graph, x)
    path, ll = viterbi(graph.log_start, graph.log_trans, lb)
    if not np.isfinite(ll):
        return [], ll
    inst = graph.phone[path]
    cuts = np.flatnonzero(np.diff(inst)) + 1
    starts = np.concatenate([[0], cuts])
    ends = np.concatenate([cuts, [len(x)]])
    return [(graph.labels[inst[a]], int(a), int(b)) for a, b in zip(starts, ends)], ll


def segments_to_phones(
    segs: Sequence[tuple[str, int, int]], duration_s: float, config: PhoneHmmConfig
) -> tuple[Phone, ...]:
    """Frame segments -> phones in seconds tiling [0, duration_s]; SP and SIL become SIL (merged)."""
    off = config.boundary_offset_s
    out: list[Phone] = []
    for i, (lab, a, b) in enumerate(segs):
        lab = SILENCE if lab in (SILENCE, SHORT_PAUSE) else lab
        t0 = 0.0 if i == 0 else a * config.frame_s + off
        t1 = duration_s if i == len(segs) - 1 else b * config.frame_s + off
        t1 = min(t1, duration_s)
        if t1 <= t0:
            continue
        if out and out[-1].phoneme == SILENCE and lab == SILENCE:
            out[-1] = Phone(SILENCE, out[-1].start_s, t1)
        else:
            out.append(Phone(lab, t0, t1))
    return tuple(out)


def train(
    sentences: Sequence[tuple[np.ndarray, Sequence[tuple[str, tuple[str, ...]]], Words]],
    config: PhoneHmmConfig,
    *,
    progress: Callable[[int, float], None] | None = None,
) -> PhoneHmmSet:
    """Models from ``[(features (T, D), [(word, phones)], GRID words incl. pauses)]``: flat start inside
    the word spans, then ``config.n_iter`` embedded Baum-Welch passes."""
    if not sentences:
        raise ConfigError("no sentences to train phone models on")
    names = sorted({p for _, pw, _ in sentences for _, pron in pw for p in pron} | {SILENCE})
    segs = [(x, uniform_segmentation(pw, words, len(x), config)) for x, pw, words in sentences]
    model = init_models(segs, names, config)
    allx = np.concatenate([x for x, _, _ in sentences])
    floor_var = config.var_floor * allx.var(axis=0)
    schedule = [config.n_iter] + [config.mix_iter] * int(np.log2(config.n_mix))
    it = 0
    for stage, passes in enumerate(schedule):
        if stage > 0:
            model = model.split()
        for _ in range(passes):
            # transitions live in the graphs: rebuild them from the current self-loops each pass
            graphs = [
                (x, build_graph(model, pw, len(x), spans=_spans(words), config=config)) for x, pw, words in sentences
            ]
            model, ll = baum_welch_pass(model, graphs, config, floor_var)
            if progress is not None:
                progress(it, ll)
            it += 1
    return model


def _spans(words: Words) -> list[tuple[float, float]]:
    return [(a, b) for a, b, w in words if w not in SILENCE_WORDS]


def align(
    model: PhoneHmmSet,
    x: np.ndarray,
    pron_words: Sequence[tuple[str, tuple[str, ...]]],
    words: Words,
    duration_s: float,
    config: PhoneHmmConfig,
) -> tuple[Phone, ...] | None:
    """Phones of one sentence (tiling [0, duration_s]), or None when no path fits the constraints."""
    g = build_graph(model, pron_words, len(x), spans=_spans(words), config=config)
    segs, _ = align_states(model, g, x)
    if not segs:
        return None
    return segments_to_phones(segs, duration_s, config)


# ----------------------------------------------------------------------------- the GRID corpus
def _features_of(args: tuple[str, str, PhoneHmmConfig]) -> tuple[str, np.ndarray | None, float, str]:
    from pathlib import Path

    from training.errors import FileProblem
    from training.video import decode_audio

    sid, video, config = args
    try:
        samples = decode_audio(Path(video), config.sample_rate_hz)
        return sid, features(samples, config), len(samples) / config.sample_rate_hz, ""
    except (FileProblem, OSError, ValueError) as exc:
        return sid, None, 0.0, str(exc)


GridFeatures = dict[str, tuple[np.ndarray, list[tuple[str, tuple[str, ...]]], list[tuple[float, float, str]], float]]
"""{sentence id: (features (T, D), [(word, phones)], GRID words incl. pauses, audio duration s)}."""


def grid_features(
    sents: Sequence, *, config: PhoneHmmConfig, workers: int = 2, progress: Callable | None = None
) -> tuple[GridFeatures, list[tuple[str, str]]]:
    """Features, pronunciations and word spans of GRID sentences (:class:`assets.grid.GridSentence`;
    audio decoded by ffmpeg in ``workers`` processes). Returns (data, skipped [(file, reason)])."""
    from concurrent.futures import ProcessPoolExecutor

    from assets.grid import read_words
    from training.errors import FileProblem
    from training.grid_phones import pronunciation

    wrap = progress or (lambda it, **_: it)
    skipped: list[tuple[str, str]] = []
    words_of = {}
    for s in sents:
        try:
            words_of[s.sentence_id] = read_words(s.align)
        except (FileProblem, OSError, ValueError) as exc:
            skipped.append((str(s.align), str(exc)))
    jobs = [(s.sentence_id, str(s.video), config) for s in sents if s.sentence_id in words_of]
    data: GridFeatures = {}
    with ProcessPoolExecutor(max_workers=workers) as pool:
        for sid, x, dur, err in wrap(pool.map(_features_of, jobs, chunksize=8), total=len(jobs), desc="mfcc"):
            if x is None:
                skipped.append((sid, err))
                continue
            words = words_of[sid]
            pw = [(w.lower(), pronunciation(w)) for _, _, w in words if w not in SILENCE_WORDS]
            data[sid] = (x, pw, words, dur)
    return data, skipped


def label_grid_corpus(
    data: GridFeatures,
    *,
    train_ids: frozenset[str] | None = None,
    config: PhoneHmmConfig | None = None,
    progress: Callable | None = None,
    say: Callable[[str], None] = lambda _: None,
) -> tuple[list, list[tuple[str, str]], PhoneHmmSet]:
    """Phones of GRID sentences (``data`` from :func:`grid_features`) by this talker's own monophone
    HMMs, trained on ``train_ids`` (default: every sentence not in the test split, so held-out
    sentences are aligned by models that never saw them). Returns (labelled
    :class:`training.grid_phones.SentencePhones`, skipped [(sentence id, reason)], the models)."""
    from assets.grid import split_of
    from training.grid_phones import SentencePhones

    config = config or PhoneHmmConfig()
    wrap = progress or (lambda it, **_: it)
    if train_ids is None:
        train_ids = frozenset(sid for sid in data if split_of(sid) != "test")
    train_set = [(x, pw, words) for sid, (x, pw, words, _) in data.items() if sid in train_ids]
    model = train(train_set, config, progress=lambda it, ll: say(f"Baum-Welch pass {it + 1}: {ll:.3f} per frame"))
    labelled = []
    skipped: list[tuple[str, str]] = []
    for sid, (x, pw, words, dur) in wrap(sorted(data.items()), desc="align"):
        phones = align(model, x, pw, words, dur, config)
        if phones is None:
            skipped.append((sid, "no alignment within the word spans"))
            continue
        labelled.append(SentencePhones(sentence_id=sid, phones=phones, method="hmm"))
    return labelled, skipped, model
