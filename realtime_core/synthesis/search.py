"""Unit selection by Viterbi search over the phonetic transition graph (seed 001 Sec. 3.7).

Theory of operation
-------------------
**Graph.** Every phone of every corpus sentence is a state ``j`` (index into the corpus's flat
phone arrays). Within a sentence, ``parent(j) = j - 1``; the first phone has no parent. A state
can follow state ``i`` (i) for free when ``i = parent(j)`` (the motion from ``i`` into ``j`` was
recorded: ``c_ij = 0``), or (ii) by a *jump* to any other sentence position, admissible only if
``parent(j)`` shows the same viseme as ``i``, because the real junction lies between ``i`` and
``parent(j)``: the output shows ``i`` blended into ``parent(j)`` during the target phone of ``i``
and then continues with ``j`` exactly as recorded. A jump costs

    c_ij = 1 + beta (C(i, parent(j)) + G(i, parent(j)))

with ``G = 0`` for equal visemes and ``+inf`` otherwise, and ``C`` the smoothness of the blended
trajectory: the time-normalised integral of its squared acceleration,

    C(i, p) = int_{t0}^{t1} ||S''(t)||^2 dt / (t1 - t0),   S = (1 - w) x_i + w x_p,

over the target phone (both units time-warped onto it, ``w`` the smoothstep crossfade that
:mod:`realtime_core.synthesis.concat` also renders). ``C`` is expressed relative to the median
value of natural recorded motion (``C(i, i)`` over the corpus), so ``beta`` is unit-free. The
observation cost ``d_j(o_t)`` is 0 when ``j`` shows the target phone's viseme, else ``+inf``.
Every jump costs at least 1 and staying costs 0, so the path with the fewest units (the longest
recorded stretches) wins; ``beta`` ranks paths with equally many units by smoothness.

**Quadratic form of C.** With the motion of each state resampled at ``L`` points of its phone
(normalised time ``tau``), the second difference is linear: ``D S = U_i + V_p`` with
``U_i = D diag(1 - w) X_i`` and ``V_p = D diag(w) X_p``, so ``C`` is ``a_i + b_p + 2 U_i . V_p``
divided by the target phone's duration to the fourth power (time scaling of an acceleration,
normalised by the interval). A search step is then one small matrix product.

**Search.** The recursion is the paper's; the states considered at step ``t`` are only those
that can be active (viseme of ``o_t``, and parent with the viseme of ``o_{t-1}``: one lookup in a
table of states by diviseme), and at most ``max_active`` of them are kept per step (the paper's
active-state threshold). The pruning ranks states by their cost minus ``lookahead`` times the
number of following target phones their own sentence goes on matching (capped at
``lookahead_phones``), so that a unit that has just started but will run long is not pruned
among the many equally cheap fresh starts. ``max_active=None`` searches exactly.

No admissible path exists when the target holds a diviseme (a pair of consecutive visemes) the
corpus never recorded, which is common for text outside the corpus's vocabulary or language. With
a finite ``mismatch_cost``, exactly those steps admit every state of the right viseme, ``G`` =
``mismatch_cost`` for a junction whose visemes differ (added outside ``beta``, so it outweighs
any smoothness difference), and the selection reports how many such junctions it used. Every
other step keeps the paper's ``G``; a strict path, where one exists, is found unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.synthesis.corpus import MotionCorpus, sample_motion
from realtime_core.synthesis.visemes import VISEME_ID

SIL = VISEME_ID["sil"]


class NoPathError(ConfigError):
    """No admissible unit sequence exists for the target (a diviseme absent from the corpus)."""


@dataclass(frozen=True, kw_only=True)
class SearchConfig:
    """beta: weight of the smoothness cost C (>= 0; 0 = fewest units only); points: samples ``L``
    per phone for C; cost_components: leading motion-vector dims C is measured on (the largest
    principal components carry nearly all the motion; fewer dims = faster search); min_blend_s:
    floor on the target phone duration in C (a 10 ms phone would
    otherwise make any blend infinitely costly); max_active: active-state cap per step (None =
    exact search); lookahead / lookahead_phones: pruning bonus per phone of future recorded
    match, and its cap; mismatch_cost: G for junctions between different visemes in the fallback
    search (inf = the paper, no fallback); duration_weight: an extension of the paper's 0/inf
    observation cost, ``d_j(o_t) += duration_weight * |ln(dur_j / dur_t)|`` for phones that are not
    pauses (prefers recorded tokens of about the target's duration: less warping, and a phone's
    length goes with how far its articulation goes; 0 = the paper); pause_duration_weight: the same
    term for pauses (a recorded pause of about the target's length carries an in-breath or a
    settling mouth of about the right pace; 0 = the paper)."""

    beta: float = 0.1
    points: int = 7
    cost_components: int = 6
    min_blend_s: float = 0.05
    max_active: int | None = 96
    lookahead: float = 0.9
    lookahead_phones: int = 8
    mismatch_cost: float = 20.0
    # chosen on the val split (leave-one-out, docs/accuracy.md): the pause term took r(mouth_open) from
    # 0.794 to 0.835 with one unit sequence and from 0.880 to 0.895 averaging ten; the phone term did
    # not help on the pocketsphinx labels (0.826 / 0.895 at 0.5) but does on the talker-specific HMM
    # labels the corpus is now built on (0.823 / 0.899 at 0 -> 0.847 / 0.901 at 0.5; 0.25: 0.899,
    # 1: 0.900 with ten; docs/unit_selection.md)
    duration_weight: float = 0.5
    pause_duration_weight: float = 2.0

    def __post_init__(self) -> None:
        if not self.beta >= 0 or not self.points >= 4 or not self.min_blend_s > 0:
            raise ConfigError("beta must be >= 0, points >= 4 and min_blend_s > 0")
        if self.cost_components < 1:
            raise ConfigError(f"cost_components must be >= 1, got {self.cost_components}")
        if self.max_active is not None and self.max_active < 1:
            raise ConfigError(f"max_active must be >= 1 or None, got {self.max_active}")
        if not 0 <= self.lookahead < 1 or self.lookahead_phones < 0:
            raise ConfigError("lookahead must be in [0, 1) and lookahead_phones >= 0")
        if not self.duration_weight >= 0 or not self.pause_duration_weight >= 0:
            raise ConfigError(
                f"duration weights must be >= 0, got {self.duration_weight}, {self.pause_duration_weight}"
            )
        if not self.mismatch_cost > 0:
            raise ConfigError("mismatch_cost must be > 0 (inf disables the fallback)")


def crossfade(tau: np.ndarray) -> np.ndarray:
    """Blend weight ``w(tau)`` for tau in [0, 1]: smoothstep 3 tau^2 - 2 tau^3 (zero slope at both
    ends, so the blended trajectory leaves ``i`` and joins ``parent(j)`` tangentially)."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau * tau * (3.0 - 2.0 * tau)


def second_difference(points: int) -> np.ndarray:
    """(L-2, L) second-derivative operator on L points spaced 1/(L-1) over [0, 1], scaled by
    sqrt(h) so that ||D x||^2 approximates int_0^1 ||x''||^2 dtau."""
    h = 1.0 / (points - 1)
    d = np.zeros((points - 2, points))
    for r in range(points - 2):
        d[r, r : r + 3] = (1.0, -2.0, 1.0)
    return d / h**2 * np.sqrt(h)


@dataclass(frozen=True, kw_only=True)
class UnitGraph:
    """The transition graph with everything a search step needs (built once per corpus).

    visemes: (N,) int16; parent: (N,) int64 (-1 = first phone); sentence_end: (N,) int64 one past
    the sentence's last state; by_diviseme: {(viseme of parent, viseme): (M,) states};
    by_viseme: {viseme: (M,) states with a parent}; first_by_viseme: {viseme: all states};
    u, v: (N, (L-2) * K) float32 halves of C's quadratic form; a, b: (N,) their squared norms;
    c_ref: median natural C (normalisation); log_duration: (N,) ln of each phone's recorded
    duration (s); config: the search configuration."""

    visemes: np.ndarray
    parent: np.ndarray
    sentence_end: np.ndarray
    by_diviseme: dict[tuple[int, int], np.ndarray]
    by_viseme: dict[int, np.ndarray]
    first_by_viseme: dict[int, np.ndarray]
    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c_ref: float
    log_duration: np.ndarray
    config: SearchConfig

    @property
    def n_states(self) -> int:
        return len(self.visemes)


def state_motion(corpus: MotionCorpus, points: int, dims: int | None = None) -> np.ndarray:
    """(N, L, K) the motion vectors (first K = min(dims, n_coefficients) dims) of every phone,
    sampled at L evenly spaced instants from its start to its end."""
    k = corpus.n_coefficients if dims is None else min(dims, corpus.n_coefficients)
    tau = np.linspace(0.0, 1.0, points)
    sent = corpus.phone_sentence()
    t = corpus.phone_start_s[:, None] + tau[None, :] * (corpus.phone_end_s - corpus.phone_start_s)[:, None]
    x = sample_motion(corpus, np.repeat(sent, points), t.ravel())[:, :k]
    return x.reshape(corpus.n_phones, points, k)


def build_graph(corpus: MotionCorpus, config: SearchConfig = SearchConfig()) -> UnitGraph:
    """The phonetic transition graph of ``corpus`` (all sentences) for searches with ``config``."""
    n = corpus.n_phones
    vis = np.asarray(corpus.phone_visemes, dtype=np.int16)
    po = corpus.phone_offsets
    sent = corpus.phone_sentence()
    idx = np.arange(n)
    parent = np.where(idx > po[sent], idx - 1, -1).astype(np.int64)
    sentence_end = po[sent + 1].astype(np.int64)
    has_parent = parent >= 0
    pv = np.where(has_parent, vis[np.maximum(parent, 0)], -1)
    by_diviseme: dict[tuple[int, int], np.ndarray] = {}
    keys = pv.astype(np.int64) * 1000 + vis
    order = np.argsort(keys[has_parent], kind="stable")
    hp = idx[has_parent][order]
    k_sorted = keys[has_parent][order]
    bounds = np.flatnonzero(np.diff(k_sorted)) + 1
    for chunk in np.split(hp, bounds):
        if len(chunk):
            by_diviseme[(int(pv[chunk[0]]), int(vis[chunk[0]]))] = chunk
    by_viseme = {int(c): idx[has_parent & (vis == c)] for c in np.unique(vis)}
    first_by_viseme = {int(c): idx[vis == c] for c in np.unique(vis)}

    x = state_motion(corpus, config.points, config.cost_components)
    w = crossfade(np.linspace(0.0, 1.0, config.points))
    d = second_difference(config.points)
    du, dv = d * (1.0 - w)[None, :], d * w[None, :]
    u = np.einsum("rl,nlk->nrk", du, x).reshape(n, -1)
    v = np.einsum("rl,nlk->nrk", dv, x).reshape(n, -1)
    # natural motion: C(i, i) over the phone's own recorded duration
    dur = np.maximum(corpus.phone_end_s - corpus.phone_start_s, config.min_blend_s)
    natural = np.einsum("ij,ij->i", u + v, u + v) / dur**4
    c_ref = float(np.median(natural)) if n else 1.0
    return UnitGraph(
        visemes=vis,
        parent=parent,
        sentence_end=sentence_end,
        by_diviseme=by_diviseme,
        by_viseme=by_viseme,
        first_by_viseme=first_by_viseme,
        u=u.astype(np.float32),
        v=v.astype(np.float32),
        a=np.einsum("ij,ij->i", u, u),
        b=np.einsum("ij,ij->i", v, v),
        c_ref=max(c_ref, 1e-12),
        log_duration=np.log(corpus.phone_end_s - corpus.phone_start_s),
        config=config,
    )


def smoothness(graph: UnitGraph, i: np.ndarray, p: np.ndarray, duration_s: float) -> np.ndarray:
    """C(i, p) (normalised) for pairs i (K,) x p (M,) -> (K, M), blended over ``duration_s``."""
    dur = max(duration_s, graph.config.min_blend_s)
    cross = (graph.u[i] @ graph.v[p].T).astype(np.float64)
    # clamp: the expansion can round slightly below 0 where the blend is nearly still
    return np.maximum(graph.a[i][:, None] + graph.b[p][None, :] + 2.0 * cross, 0.0) / (dur**4 * graph.c_ref)


def _jump_costs(graph: UnitGraph, i: np.ndarray, p: np.ndarray, phi: np.ndarray, duration_s: float) -> np.ndarray:
    """(K, M) ``phi_i + 1 + beta C(i, p)``: the cost of reaching parent ``p`` by a jump from active
    state ``i`` (the same values as ``phi[:, None] + 1 + beta * smoothness(...)``, computed in place)."""
    dur = max(duration_s, graph.config.min_blend_s)
    out = (graph.u[i] @ graph.v[p].T).astype(np.float64)
    out *= 2.0
    out += graph.a[i][:, None]
    out += graph.b[p][None, :]
    np.maximum(out, 0.0, out=out)
    out *= graph.config.beta / (dur**4 * graph.c_ref)
    out += (phi + 1.0)[:, None]
    return out


@dataclass(frozen=True, kw_only=True)
class Selection:
    """states: (T,) int64 the chosen corpus phone per target phone; cost: the path cost;
    n_units: recorded stretches used (1 + jumps); n_mismatched: junctions between different
    visemes (0 unless the fallback search ran)."""

    states: np.ndarray
    cost: float
    n_units: int
    n_mismatched: int


def observation_cost(graph: UnitGraph, cand: np.ndarray, viseme: int, duration_s: float) -> np.ndarray:
    """d_j(o_t) for candidates that show the target viseme: 0 (the paper), plus the duration term."""
    w = graph.config.pause_duration_weight if viseme == SIL else graph.config.duration_weight
    if w == 0:
        return np.zeros(len(cand))
    return w * np.abs(graph.log_duration[cand] - np.log(max(duration_s, 1e-3)))


def _runs(graph: UnitGraph, cand: np.ndarray, target: np.ndarray, t: int, cap: int) -> np.ndarray:
    """For each candidate state at step t: how many following target phones its sentence matches."""
    run = np.zeros(len(cand), dtype=np.int64)
    alive = np.ones(len(cand), dtype=bool)
    for m in range(1, min(cap, len(target) - 1 - t) + 1):
        s = cand + m
        ok = alive & (s < graph.sentence_end[cand])
        ok[ok] = graph.visemes[s[ok]] == target[t + m]
        alive = ok
        run += alive
        if not alive.any():
            break
    return run


def _prune(graph: UnitGraph, cand: np.ndarray, phi: np.ndarray, target: np.ndarray, t: int) -> np.ndarray:
    """Indices into cand of the states kept active (finite cost, at most max_active)."""
    finite = np.flatnonzero(np.isfinite(phi))
    cap = graph.config.max_active
    if cap is None or len(finite) <= cap:
        return finite
    key = phi[finite]
    if graph.config.lookahead > 0 and graph.config.lookahead_phones > 0:
        key = key - graph.config.lookahead * _runs(graph, cand[finite], target, t, graph.config.lookahead_phones)
    return finite[np.argpartition(key, cap - 1)[:cap]]


def viterbi(
    graph: UnitGraph,
    target: np.ndarray,
    durations_s: np.ndarray,
    *,
    mismatch_cost: float = np.inf,
    banned: np.ndarray | None = None,
) -> Selection:
    """The least-cost state sequence for target visemes ``target`` (T,) int with target phone
    durations ``durations_s`` (T,) s. ``mismatch_cost`` is G for junctions whose visemes differ
    (inf = the paper); ``banned``: (N,) bool states not to use. Raises NoPathError if every path
    costs infinity."""
    target = np.asarray(target, dtype=np.int64)
    durations_s = np.asarray(durations_s, dtype=np.float64)
    if target.ndim != 1 or len(target) == 0 or durations_s.shape != target.shape:
        raise ConfigError(
            f"target (T,) and durations (T,) must match and be non-empty: {target.shape}, {durations_s.shape}"
        )

    def allowed(c: np.ndarray) -> np.ndarray:
        return c if banned is None else c[~banned[c]]

    cand = allowed(graph.first_by_viseme.get(int(target[0]), np.zeros(0, np.int64)))
    if len(cand) == 0:
        raise NoPathError(f"no corpus phone shows viseme id {int(target[0])}")
    phi = observation_cost(graph, cand, int(target[0]), float(durations_s[0]))
    keep = _prune(graph, cand, phi, target, 0)
    active, phi = cand[keep], phi[keep]
    history: list[tuple[np.ndarray, np.ndarray]] = [(active, np.full(len(active), -1))]
    pos = np.full(graph.n_states, -1, dtype=np.int64)
    for t in range(1, len(target)):
        # the paper's G where the corpus recorded this diviseme; the finite stand-in only where it did not
        # (the recorded divisemes are those of the states not banned)
        cand = allowed(graph.by_diviseme.get((int(target[t - 1]), int(target[t])), np.zeros(0, np.int64)))
        relaxed = len(cand) == 0 and np.isfinite(mismatch_cost)
        if relaxed:
            cand = allowed(graph.by_viseme.get(int(target[t]), np.zeros(0, np.int64)))
        if len(cand) == 0 or len(active) == 0:
            raise NoPathError(
                f"no admissible unit for target phone {t} (viseme pair {int(target[t - 1])} -> "
                f"{int(target[t])} was never recorded)"
            )
        par = graph.parent[cand]
        # jumps: i (active) -> j (cand) through the junction i | parent(j); the (active x cand)
        # matrix is the search's bulk, so it is built in place (one allocation, no temporaries)
        jump = _jump_costs(graph, active, par, phi, float(durations_s[t - 1]))
        if relaxed:
            mism = graph.visemes[active][:, None] != graph.visemes[par][None, :]
            # G's finite stand-in is added outside beta so it outweighs any smoothness difference
            jump += np.where(mism, mismatch_cost, 0.0)
        # recorded transitions (parent(j) active) are not jumps: they are priced below at no cost
        pos[active] = np.arange(len(active))
        k = pos[par]
        stay = k >= 0
        jump[k[stay], np.flatnonzero(stay)] = np.inf
        best_i = np.argmin(jump, axis=0)
        new_phi = jump[best_i, np.arange(len(cand))]
        back = best_i.copy()
        stay_cost = np.where(stay, phi[np.maximum(k, 0)], np.inf)
        better = stay_cost <= new_phi
        new_phi = np.where(better, stay_cost, new_phi)
        back = np.where(better, k, back)
        pos[active] = -1
        new_phi = new_phi + observation_cost(graph, cand, int(target[t]), float(durations_s[t]))
        keep = _prune(graph, cand, new_phi, target, t)
        if len(keep) == 0:
            raise NoPathError(f"no admissible unit sequence reaches target phone {t}")
        history.append((cand[keep], back[keep]))
        active, phi = cand[keep], new_phi[keep]
    # backtrack
    best = int(np.argmin(phi))
    cost = float(phi[best])
    states = np.empty(len(target), dtype=np.int64)
    for t in range(len(target) - 1, -1, -1):
        st, bk = history[t]
        states[t] = st[best]
        best = int(bk[best])
    jumps = graph.parent[states[1:]] != states[:-1]
    par = graph.parent[states[1:]]
    mism = int(np.sum(jumps & ((par < 0) | (graph.visemes[np.maximum(par, 0)] != graph.visemes[states[:-1]]))))
    return Selection(states=states, cost=cost, n_units=int(1 + jumps.sum()), n_mismatched=mism)


def select_units(
    graph: UnitGraph, target: np.ndarray, durations_s: np.ndarray, *, banned: np.ndarray | None = None
) -> Selection:
    """:func:`viterbi` with the paper's costs, and the configuration's finite ``mismatch_cost`` at the
    junctions whose diviseme the corpus never recorded (see the module doc)."""
    return viterbi(graph, target, durations_s, mismatch_cost=graph.config.mismatch_cost, banned=banned)
