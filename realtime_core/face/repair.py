"""Fold repair: smooth a rig's deformation field where it folds, until no test pose folds it.

The harmonic field (:mod:`realtime_core.face.harmonic`) pins every control point to its simple
vertex's motion. On a dense scan, control points a few vertices apart can carry motions that differ
by a large fraction of the jaw opening (inner and outer lip surface, the chin crease, the edge of the
moving region): the field is exact at the pins but the triangles between them fold. The cause is the
pin, so the repair releases it locally: at each of the given poses (the rig checks' extreme poses)
the flipped and over-stretched triangles are found, and the weight rows of their vertices and one
ring around them are replaced by the mean of their mesh neighbours' rows (a Jacobi step of the
uniform Laplacian, which evens out triangle shapes), round after round until no pose folds or the
round limit is reached. The weights stay a sparse linear map (frames cost the same), and since they
follow mesh edges a cut lip seam keeps the lips apart.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from realtime_core.face.compiled import flipped_at_poses, stretched_at_poses
from realtime_core.face.projection import vertex_adjacency
from realtime_core.normals import triangle_normals


@dataclass(frozen=True)
class RepairResult:
    """weights (n_w, n_s) CSR after repair; rounds run; flips left at the worst pose; rows smoothed; settled:
    no pose folds within ``max_rounds`` (False also when the repair gave up, see ``patience``); bad: per round, the
    count of vertices on a fold or an over-stretched edge before that round's smoothing."""

    weights: sp.csr_matrix
    rounds: int
    flips_left: int
    smoothed_rows: int
    settled: bool
    bad: tuple[int, ...]


MAX_ROUNDS = 200
"""Smoothing rounds :func:`repair_folds` runs at most before its tie rounds (a repair that ends sooner settled)."""

PATIENCE = 40
"""Rounds without a new low of the bad-vertex count after which a repair asked to (``patience``) gives up. The test
set's heads that settle do so within 8 rounds, each round a new low or one back of it; the ones that do not settle
are flat from round 3-4 on (docs/animation.md, "The fold repair's rounds"). A growing patch can raise the count
for a while before it falls: 40 rounds leave room for two ``grow_every`` widenings (a 31 x 31 grid's disc
needs 30, tests/realtime_core/face/test_contact_repair.py)."""


def repair_folds(
    vertices: np.ndarray,
    triangles: np.ndarray,
    weights: sp.csr_matrix,
    motions: np.ndarray,
    *,
    max_stretch: float = 3.0,
    max_rounds: int = MAX_ROUNDS,
    steps: int = 2,
    fixed: np.ndarray | None = None,
    grow_every: int = 15,
    tiny: float = 0.0,
    measured: np.ndarray | None = None,
    tie_rounds: int = 60,
    own_side: np.ndarray | None = None,
    ties: Mapping[int, int | tuple[Sequence[int], Sequence[float]]] | None = None,
    stretch_poses: int | None = None,
    patience: int | None = None,
    widen: bool = False,
) -> RepairResult:
    """Smooth ``weights`` (n, n_s) (head vertex <- simple vertex) where the poses fold the mesh.

    vertices (n, 3), triangles (m, 3) of a welded mesh (texture-seam twins merged, cut lip seams not);
    motions (n_poses, n_s, 3) the simple-model displacement at each pose; max_stretch: edges stretched
    beyond this ratio count as folds too, at the first ``stretch_poses`` poses (None: all); fixed (n,) bool rows
    never changed (rigid parts).
    tiny: vertices joined by edges shorter than this fraction of the median edge move as one (their
    rows are averaged before and after every round): a scan's clusters of sliver triangles
    (0.001 IOD edges behind Lee Perry-Smith's mouth corners) flip at any motion difference the
    field leaves between their vertices, however smooth. 0 (the default) ties nothing.
    measured: (m,) bool the triangles whose flips and edges count (None: all); the smoothing still runs
    over every triangle's edges (faces that will be removed, e.g. hidden inner lip walls, join the surface
    but their folds are never seen).
    tie_rounds: when flips are left after ``max_rounds``, up to this many more rounds in which each
    triangle still flipped at some pose has its apex (the vertex with the largest rest angle, the one
    nearest the opposite edge) tied for good to that edge: the apex's row becomes the interpolation of
    the edge's two rows at the apex's projection on it, so the apex moves as the edge's point beside it
    does and the triangle keeps its rest height over the edge (it can flip only if the edge itself turns
    over). Uniform-Laplacian smoothing alone cannot unflip such a thin triangle: its fixed point puts a
    vertex at its neighbours' mean, which on an irregular coarse mesh is not the field's linear value
    at the vertex (Lee Perry-Smith decimated to 3,810 triangles kept one flip at a mouth corner through
    200 rounds). Rigs whose folds the smoothing removes never reach this phase and come out unchanged.
    own_side: (n,) bool vertices whose rows are smoothed over each other's only (a vertex with no such
    neighbour over all of them), so no motion enters them from the others through the smoothing: a coarse
    upper lip above a cut lip seam, whose neighbours round the mouth corners carry the jaw's motion (Lee
    Perry-Smith decimated to 1,428 triangles: smoothed over all of them, its upper lip dropped 0.42 IOD per unit
    of mouth_open; docs/animation.md, "The 1,428 copy's flap"). None (the default): every neighbour counts.
    ties: vertex -> the vertex whose row it takes, from the first round on (a coarse upper lip's back split
    behind the lip cut moves as the cut, :func:`assets.heads.knife.split_lip_back`), or -> (vertices, weights):
    the weighted sum of their rows, a point of a face it moves with (a knife-cut lower lip's edge glued to the
    lip under it, :func:`assets.heads.rigging.lip_edge_glue`); the smoothing then evens out the folds round them
    with the ties in place, and the tie rounds' apexes never replace them.
    patience: give up when the count of bad vertices (on a fold or an over-stretched edge, at any pose) has not
    reached a new low for this many rounds: the result is then not settled and runs no tie rounds (for a caller
    that falls back to fewer poses when this repair does not settle; docs/animation.md, "The fold repair's
    rounds"). None (the default): never give up.
    widen: a stubborn fold's patch grows one ring for every ``grow_every`` rounds its vertex has been on a fold,
    ring after ring outwards (a vertex folded 200 rounds smooths 14 rings round it). False (the default, the rows of
    every head rigged before): each further ring grows only from vertices that were themselves on a fold that long,
    so a fold whose neighbours never fold keeps its one ring however long it stays: the once-subdivided Lee
    Perry-Smith's copy (its mouth at the scan's own edges, half the shipped head's) kept 2-3 flips through its 200
    rounds, and the tie rounds (tied apexes flipping their neighbours, round after round) cleared them on its first
    cut and left 2 on its levelled one; widened, it settles in 50-52 rounds (docs/animation.md, "The dense head's
    wedge levelled"). Not for a coarse mesh, whose rings are wide: forced on Lee Perry-Smith's 3,810-triangle copy,
    the patch grew over the whole mouth, which then no longer opened.
    """
    v0 = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    n = len(v0)
    g = sp.csr_matrix(weights, dtype=np.float64)
    adj = vertex_adjacency(n, t).tocsr()
    adj.data[:] = 1.0
    mix = adj
    if own_side is not None:
        own = np.asarray(own_side, dtype=bool)
        # An own-side vertex's mean over its own-side neighbours (where it has any): drop its other entries.
        coo = adj.tocoo()
        has_own = np.bincount(coo.row[own[coo.col]], minlength=n) > 0
        keep_entry = ~(own[coo.row] & has_own[coo.row] & ~own[coo.col])
        mix = sp.csr_matrix((coo.data[keep_entry], (coo.row[keep_entry], coo.col[keep_entry])), shape=(n, n))
    deg = np.asarray(mix.sum(axis=1)).ravel()
    mean_op = (sp.diags(1.0 / np.maximum(deg, 1)) @ mix).tocsr()
    n0 = triangle_normals(v0, t)
    a0 = np.linalg.norm(n0, axis=1)
    ok_tri = a0 > 1e-12 * max(float(a0.max()), 1e-300)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    l0 = np.linalg.norm(v0[e[:, 0]] - v0[e[:, 1]], axis=1)
    ok_edge = l0 > 1e-9 * max(float(l0.max()), 1e-300)
    seen = np.ones(len(t), dtype=bool) if measured is None else np.asarray(measured, dtype=bool)
    ok_tri = ok_tri & seen
    ok_edge_measured = ok_edge & np.tile(seen, 3)
    frozen = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool)
    tie = _tie_tiny_edges(n, e, l0, tiny * float(np.median(l0[ok_edge])) if ok_edge.any() else 0.0, frozen)
    g = (tie @ g).tocsr()
    touched = np.zeros(n, dtype=bool)
    stuck = np.zeros(n, dtype=np.int64)
    worst = 0
    rounds = 0
    given = dict(ties or {})
    # tied vertex -> (vertices, weights): its row the weighted sum of theirs (an apex: its edge's two ends)
    on_edge: dict[int, tuple[tuple[int, ...], tuple[float, ...]]] = {
        i: ((j,), (1.0,)) if isinstance(j, int | np.integer) else (tuple(j[0]), tuple(j[1])) for i, j in given.items()
    }
    tie_edges = _on_edge_operator(n, on_edge) if on_edge else sp.identity(n, format="csr")
    for _ in range(3 if on_edge else 0):
        g = (tie_edges @ g).tocsr()
    flat = np.ascontiguousarray(np.asarray(motions, dtype=np.float64).transpose(1, 0, 2)).reshape(g.shape[1], -1)
    n_poses = len(motions)
    watch = _FoldWatch(
        v0,
        t,
        e,
        n0,
        ok_tri,
        ok_edge_measured,
        max_stretch * l0,
        flat,
        n_poses if stretch_poses is None else stretch_poses,
    )
    # The rounds work on a dense copy of the field and rewrite only the rows they change: a round smooths a few
    # hundred rows, and products of the whole sparse matrix (as before) cost the rig most of its time on a coarse
    # head whose repairs run their 260 rounds (2.4 min for a 4,500-triangle head). Each row's sums are the sparse
    # products' own, term by term in the same order, so the field is the same.
    gd = g.toarray()
    # Rows the tiny-edge operator averages (it keeps every other row exactly).
    in_cluster = np.flatnonzero(np.diff(tie.indptr) > 1)
    tie_rows = tie[in_cluster]
    changed = np.flatnonzero(gd.any(axis=1))
    smoothed = False
    history: list[int] = []
    best = (n + 1, 0)  # (fewest bad vertices so far, the round that reached it)
    gave_up = False
    for rounds in range(1, max_rounds + tie_rounds + 1):
        flipped, stretched = watch.update(gd, changed)
        worst = int(flipped.sum(axis=0).max()) if flipped.size else 0
        flipped_any = flipped.any(axis=1)
        bad = np.zeros(n, dtype=bool)
        bad[t[flipped_any].ravel()] = True
        bad[e[stretched].ravel()] = True
        history.append(int(bad.sum()))
        # After max_rounds only flips keep the repair going (stretch alone ends it, as before).
        if not bad.any() or (rounds > max_rounds and worst == 0):
            worst = 0
            rounds -= 1
            break
        if history[-1] < best[0]:
            best = (history[-1], rounds)
        if patience is not None and rounds <= max_rounds and rounds - best[1] >= patience:
            gave_up = True
            break
        if rounds > max_rounds:
            apexes = _apexes(v0, t[flipped_any], frozen).items()
            on_edge.update({k: ((a, b), (1.0 - s_, s_)) for k, (a, b, s_) in apexes if k not in given})
            tie_edges = _on_edge_operator(n, on_edge)
        # One ring around the folded vertices, so the smoothed patch blends into its surroundings.
        # A fold that survives local smoothing needs a wider patch: around each vertex, one more
        # ring for every ``grow_every`` rounds it has been part of a fold (stubborn spots only, so
        # the rest of the mouth keeps its motion).
        stuck[bad] += 1
        sel = bad.copy()
        front = bad.copy()
        level = 0
        if widen:
            sel, front = _widened(bad, stuck, e, grow_every), np.zeros(n, dtype=bool)
        while front.any():
            sel |= adj @ front.astype(np.float64) > 0
            level += 1
            front = sel & (stuck >= level * grow_every) if grow_every else np.zeros(n, dtype=bool)
        sel &= ~frozen
        if not sel.any():
            break
        touched |= sel
        rows = np.flatnonzero(sel)
        tied = np.fromiter(on_edge, dtype=np.int64, count=len(on_edge))
        # Every row this round may change (the first round's threshold may change any row).
        cand = np.arange(n) if not smoothed else np.unique(np.concatenate([rows, tied, in_cluster]))
        before = gd[cand]
        neighbours_mean = mean_op[rows]
        for _ in range(steps):  # Jacobi steps: every smoothed row from the field before the step
            gd[rows] = neighbours_mean @ gd
        if len(tied):
            tied_rows = tie_edges[tied]
            for _ in range(3):  # an apex on an edge whose end is an apex too: a few passes
                gd[tied] = tied_rows @ gd
        if len(in_cluster):
            gd[in_cluster] = tie_rows @ gd
        block = gd[cand]
        block[np.abs(block) < 1e-6] = 0.0
        gd[cand] = block
        changed = cand[(block != before).any(axis=1)]
        smoothed = True
    else:
        # The rounds ran out after a smoothing: count the weights returned, not the ones before that round.
        flipped, _ = watch.update(gd, changed)
        worst = int(flipped.sum(axis=0).max()) if flipped.size else 0
    if smoothed:
        g = sp.csr_matrix(gd)
    return RepairResult(
        weights=g.tocsr(),
        rounds=rounds,
        flips_left=worst,
        smoothed_rows=int(touched.sum()),
        settled=not gave_up and rounds < max_rounds,
        bad=tuple(history),
    )


class _FoldWatch:
    """The flipped triangles and over-stretched edges of a mesh at every pose as the repair changes its field.

    Each round the repair smooths a few hundred rows (of 7,788 moving on Lee Perry-Smith); the other vertices keep
    their motion exactly, so the triangles and edges none of whose vertices changed keep their state. Only the
    changed rows' displacements are recomputed (all poses in one sparse-dense product) and only the triangles and
    edges on them re-measured; triangles and edges whose vertices never move keep their rest shape and are never
    flipped or stretched (the repair measured the moving ones alone before, pose by pose: the same answers)."""

    def __init__(
        self,
        v0: np.ndarray,
        triangles: np.ndarray,
        edges: np.ndarray,
        n0: np.ndarray,
        tri_ok: np.ndarray,
        edge_ok: np.ndarray,
        longest: np.ndarray,
        flat: np.ndarray,
        n_stretch: int,
    ) -> None:
        """v0 (n, 3) rest; triangles (m, 3) with rest normals n0 (m, 3) and edges (3m, 2) with limits longest (3m,),
        measured where tri_ok (m,) / edge_ok (3m,); flat (n_s, 3 * n_poses) the motions pose-major; edges count
        as stretched at the first n_stretch poses."""
        self.v0, self.t, self.e, self.n0, self.longest, self.flat = v0, triangles, edges, n0, longest, flat
        self.tri_ok, self.edge_ok = tri_ok, edge_ok
        self.n_poses = flat.shape[1] // 3
        self.n_stretch = min(n_stretch, self.n_poses)
        self.disp = np.zeros((len(v0), flat.shape[1]))  # (n, 3 * n_poses) each vertex's displacement at every pose
        self.flipped = np.zeros((len(triangles), self.n_poses), dtype=bool)
        self.stretched = np.zeros(len(edges), dtype=bool)
        # vertex -> the triangles and edges on it, so a round re-measures only the ones its changed rows touch
        n, m, k = len(v0), len(triangles), len(edges)
        self.vertex_tri = sp.csr_matrix((np.ones(3 * m), (triangles.ravel(), np.repeat(np.arange(m), 3))), shape=(n, m))
        self.vertex_edge = sp.csr_matrix((np.ones(2 * k), (edges.ravel(), np.repeat(np.arange(k), 2))), shape=(n, k))

    def update(self, g: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(m, n_poses) bool flipped and (3m,) bool stretched under the field ``g`` (n, n_s) dense, whose rows
        ``rows`` (k,) int changed since the last call (the first call: every row with a weight) (views: read only)."""
        if rows.size == 0:
            return self.flipped, self.stretched
        # The rows are sparse (a few dozen simple vertices each): a sparse product is several times cheaper.
        self.disp[rows] = sp.csr_matrix(g[rows]) @ self.flat
        tri = np.unique(self.vertex_tri[rows].indices)
        tri = tri[self.tri_ok[tri]]
        edge = np.unique(self.vertex_edge[rows].indices)
        edge = edge[self.edge_ok[edge]]
        # Compiled (realtime_core.face.compiled): numpy's (triangles, poses, 3) temporaries were most of the repair's
        # time; the kernels make the same float64 operations in the same order, so the same decisions.
        flipped_at_poses(self.v0, self.disp, self.t, self.n0, tri, self.flipped)
        stretched_at_poses(self.v0, self.disp, self.e, self.longest, edge, self.n_stretch, self.stretched)
        return self.flipped, self.stretched


def _widened(bad: np.ndarray, stuck: np.ndarray, edges: np.ndarray, grow_every: int) -> np.ndarray:
    """(n,) bool the ``bad`` (n,) vertices and, round each, ``1 + stuck // grow_every`` rings of neighbours along
    ``edges`` (k, 2) (one ring when ``grow_every`` is 0): the patch :func:`repair_folds` smooths with ``widen``."""
    reach = np.full(len(bad), -1, dtype=np.int64)
    reach[bad] = 1 + (stuck[bad] // grow_every if grow_every else 0)
    for _ in range(int(reach.max(initial=0))):
        # Each vertex the largest reach of a neighbour, one ring less: a multi-source breadth-first search.
        grown = reach.copy()
        np.maximum.at(grown, edges[:, 0], reach[edges[:, 1]] - 1)
        np.maximum.at(grown, edges[:, 1], reach[edges[:, 0]] - 1)
        reach = grown
    return reach >= 0


def _apexes(v: np.ndarray, flipped: np.ndarray, frozen: np.ndarray) -> dict[int, tuple[int, int, float]]:
    """For each ``flipped`` (k, 3) triangle of rest positions ``v`` (n, 3): its apex (largest rest angle;
    not ``frozen``) -> (a, b, s), the opposite edge's ends and the apex's projection on it (0..1 from a)."""
    out: dict[int, tuple[int, int, float]] = {}
    for tri in flipped:
        p = v[tri]
        cos = []
        for k in range(3):
            u, w = p[(k + 1) % 3] - p[k], p[(k + 2) % 3] - p[k]
            cos.append(float(u @ w) / max(float(np.linalg.norm(u) * np.linalg.norm(w)), 1e-300))
        k = int(np.argmin(cos))
        apex, a, b = int(tri[k]), int(tri[(k + 1) % 3]), int(tri[(k + 2) % 3])
        if frozen[apex] or apex in out:
            continue
        ab = p[(k + 2) % 3] - p[(k + 1) % 3]
        s = float(np.clip((p[k] - p[(k + 1) % 3]) @ ab / max(float(ab @ ab), 1e-300), 0.0, 1.0))
        out[apex] = (a, b, s)
    return out


def _on_edge_operator(n: int, on_edge: dict[int, tuple[tuple[int, ...], tuple[float, ...]]]) -> sp.csr_matrix:
    """(n, n) CSR: identity, but each tied vertex's row the weighted sum of its anchors' rows."""
    keep = np.ones(n)
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    for apex, (anchors, weights) in on_edge.items():
        keep[apex] = 0.0
        rows += [apex] * len(anchors)
        cols += list(anchors)
        vals += list(weights)
    return (sp.diags(keep) + sp.csr_matrix((vals, (rows, cols)), shape=(n, n))).tocsr()


def _tie_tiny_edges(n: int, edges: np.ndarray, length: np.ndarray, limit: float, frozen: np.ndarray) -> sp.csr_matrix:
    """(n, n) CSR averaging operator: each cluster of vertices joined by edges shorter than ``limit``
    (rows not ``frozen``) gets its mean row; every other row is kept."""
    from scipy.sparse.csgraph import connected_components

    short = (length < limit) & ~frozen[edges[:, 0]] & ~frozen[edges[:, 1]]
    a = sp.csr_matrix((np.ones(int(short.sum())), (edges[short, 0], edges[short, 1])), shape=(n, n))
    _, comp = connected_components(a, directed=False)
    size = np.bincount(comp, minlength=comp.max() + 1).astype(np.float64)
    member = sp.csr_matrix((np.ones(n), (np.arange(n), comp)), shape=(n, len(size)))
    return (member @ sp.diags(1.0 / size) @ member.T).tocsr()
