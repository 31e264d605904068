"""Projection (paper 000 Sec. 5.1): each simple-model vertex onto one head vertex, the control points.

Each placed simple-model vertex takes the closest head vertex (3D Euclidean) not already taken:
vertices are served in order of their nearest distance, so the best-placed ones win conflicts and
the map is never two-to-one. Then every simple-model triangle is checked: between the control
points of each of its edges a greedy walk over the head mesh (always step to the neighbour closest
to the goal) must see the Euclidean distance to the goal strictly decrease until it arrives. A walk
that gets stuck means the two control points lie on surfaces that are close in space but not
connected near there, e.g. the upper and lower lip. The strictly decreasing rule also stops in
harmless dents of real meshes (26 of 1041 edges of the MakeHuman face), so the walk may step to a
neighbour up to ``slack`` (0.3 of the edge's length by default) farther than the best distance so
far, never revisiting a vertex: then at most 2 of those 1041 edges and no triangle of the Lee
Perry-Smith scan fail, while the lips still do (crossing them means a detour round the corner).
``walk="shortest"`` instead follows the shortest edge path (Dijkstra) and requires the distance
to decrease along it with the same slack, and a path at most 3 times the straight line. The
vertex of a failing triangle that takes part in most failing edges (ties: the one farther from
its simple-model vertex) is then replaced by its next-closest free head vertex, and the check
repeats until every triangle passes or the candidates run out (the triangle is then reported and
left out of the interpolation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from realtime_core.errors import ConfigError


def vertex_adjacency(n_vertices: int, triangles: np.ndarray) -> sp.csr_matrix:
    """Symmetric (n, n) CSR adjacency (value 1) of the edges of ``triangles`` (m, 3)."""
    t = np.asarray(triangles, dtype=np.int64)
    i = np.concatenate([t[:, 0], t[:, 1], t[:, 2], t[:, 1], t[:, 2], t[:, 0]])
    j = np.concatenate([t[:, 1], t[:, 2], t[:, 0], t[:, 0], t[:, 1], t[:, 2]])
    a = sp.csr_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(n_vertices, n_vertices))
    a.data[:] = 1
    return a


def edge_length_graph(vertices: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Symmetric (n, n) CSR graph of the edges of ``triangles`` (m, 3) weighted by their lengths between
    ``vertices`` (n, 3) (plus 1e-300, so that an edge between coincident vertices stays an edge)."""
    h = np.asarray(vertices, dtype=np.float64)
    adj = vertex_adjacency(len(h), triangles).tocoo()
    w = np.linalg.norm(h[adj.row] - h[adj.col], axis=1) + 1e-300
    return sp.csr_matrix((w, (adj.row, adj.col)), shape=adj.shape)


def greedy_walk_reaches(
    vertices: np.ndarray,
    adjacency: sp.csr_matrix,
    start: int,
    goal: int,
    *,
    slack: float = 0.0,
    max_steps: int = 10_000,
) -> bool:
    """True if the greedy walk from ``start`` to ``goal`` over the mesh edges arrives while the
    Euclidean distance to ``goal`` keeps decreasing (vertices (n, 3)).

    Each step goes to the unvisited neighbour closest to the goal; the step is allowed if it does
    not end farther than the best distance so far plus ``slack`` times |start - goal| (0 = strictly
    decreasing, the literal rule; a small slack walks over the zig-zag of real mesh edges).
    """
    if start == goal:
        return True
    g = vertices[goal]
    tol = slack * float(np.linalg.norm(vertices[start] - g))
    cur = start
    best = float(np.linalg.norm(vertices[cur] - g))
    visited = {start}
    indptr, indices = adjacency.indptr, adjacency.indices
    for _ in range(max_steps):
        nb = indices[indptr[cur] : indptr[cur + 1]]
        if np.any(nb == goal):
            return True
        nb = np.array([x for x in nb if x not in visited], dtype=np.int64)
        if nb.size == 0:
            return False
        d = np.linalg.norm(vertices[nb] - g, axis=1)
        k = int(np.argmin(d))
        if slack == 0.0 and not d[k] < best:
            return False
        if not d[k] < best + tol:
            return False
        cur = int(nb[k])
        visited.add(cur)
        best = min(best, float(d[k]))
    return False


def shortest_path_monotone(
    vertices: np.ndarray, graph: sp.csr_matrix, start: int, goal: int, *, slack: float = 0.1, max_ratio: float = 3.0
) -> bool:
    """True if the shortest edge path from ``start`` to ``goal`` (``graph``: edge-length CSR) is at
    most ``max_ratio`` times their distance and the Euclidean distance to ``goal`` never rises
    by more than ``slack`` times that distance along it (vertices (n, 3))."""
    if start == goal:
        return True
    from scipy.sparse.csgraph import dijkstra

    e = float(np.linalg.norm(vertices[start] - vertices[goal]))
    dist, pred = dijkstra(graph, indices=start, limit=max_ratio * e * (1 + 1e-9), return_predecessors=True)
    if not np.isfinite(dist[goal]):
        return False
    path = [goal]
    while path[-1] != start:
        path.append(int(pred[path[-1]]))
    d = np.linalg.norm(vertices[path[::-1]] - vertices[goal], axis=1)
    return bool(np.all(np.diff(d) <= slack * e))


@dataclass(frozen=True)
class ProjectionResult:
    """control: (n_simple,) head vertex index per simple vertex; bad_triangles: (m_simple,) bool,
    triangles that still fail the geodesic check; replacements: how many times a control point
    moved to its next-closest candidate."""

    control: np.ndarray
    bad_triangles: np.ndarray
    replacements: int


def project(
    simple_vertices: np.ndarray,
    simple_triangles: np.ndarray,
    head_vertices: np.ndarray,
    head_triangles: np.ndarray,
    *,
    candidates: int = 24,
    geodesic_check: bool = True,
    allowed: np.ndarray | None = None,
    walk: str = "greedy",
    slack: float = 0.3,
) -> ProjectionResult:
    """Control points for a simple model already placed on the head (all coordinates head units).

    simple_vertices (n_s, 3), simple_triangles (m_s, 3), head_vertices (n_h, 3), head_triangles
    (m_h, 3); ``candidates``: how many nearest head vertices each simple vertex may fall back to;
    ``allowed``: optional (n_h,) bool mask of head vertices that may become control points;
    ``walk``: "greedy" (default) or "shortest" (see the module docstring); ``slack``: how much
    farther than the best distance so far a step may end, in units of the edge's length.
    """
    if walk not in ("shortest", "greedy"):
        raise ConfigError(f"walk must be 'shortest' or 'greedy', got {walk!r}")
    s = np.asarray(simple_vertices, dtype=np.float64)
    h = np.asarray(head_vertices, dtype=np.float64)
    pool = np.arange(len(h)) if allowed is None else np.flatnonzero(np.asarray(allowed, dtype=bool))
    if len(pool) < len(s):
        raise ConfigError(f"head has {len(pool)} usable vertices, fewer than the {len(s)} simple-model vertices")
    k = min(candidates, len(pool))
    tree = cKDTree(h[pool])
    dist, cand = tree.query(s, k=k)  # (n_s, k) candidates, nearest first
    dist = dist.reshape(len(s), k)
    cand = pool[cand.reshape(len(s), k)]
    # Symmetric faces give exact distance ties (mirror pairs) that floating-point noise would
    # break differently after a rotation: compare distances quantised to 1e-9 of the head's size
    # and break ties by index, so the result is invariant to a similarity transform.
    quantum = 1e-9 * max(float(np.ptp(h, axis=0).max()), 1e-300)
    qd = np.round(dist / quantum)
    order = np.array([np.lexsort((c, d)) for c, d in zip(cand, qd)]).reshape(cand.shape)
    dist = np.take_along_axis(dist, order, axis=1)
    cand = np.take_along_axis(cand, order, axis=1)
    qd = np.take_along_axis(qd, order, axis=1)
    rank: list[int] = [0] * len(s)
    control = np.full(len(s), -1, dtype=np.int64)
    used: dict[int, int] = {}

    extra: dict[int, np.ndarray] = {}

    def take(i: int, far: bool = False) -> bool:
        while rank[i] < k:
            c = int(cand[i, rank[i]])
            if c not in used:
                used[c] = i
                control[i] = c
                return True
            rank[i] += 1
        if not far:
            return False
        # A coarse head (fewer vertices than the simple model has nearby): look further out.
        if i not in extra:
            kk = min(len(pool), 8 * k)
            dd, ii = tree.query(s[i], k=kk)
            extra[i] = pool[ii][np.lexsort((pool[ii], np.round(dd / quantum)))]
        for c in extra[i]:
            if int(c) not in used:
                used[int(c)] = i
                control[i] = int(c)
                return True
        return False

    for i in np.lexsort((np.arange(len(s)), qd[:, 0])):
        if not take(int(i), far=True):
            raise ConfigError(f"simple vertex {i}: all {k} nearest head vertices are taken; raise `candidates`")

    tri = np.asarray(simple_triangles, dtype=np.int64)
    bad = np.zeros(len(tri), dtype=bool)
    replacements = 0
    if not geodesic_check or len(tri) == 0:
        return ProjectionResult(control=control, bad_triangles=bad, replacements=0)
    adj = vertex_adjacency(len(h), head_triangles)
    coo = adj.tocoo()
    graph = sp.csr_matrix(
        (np.linalg.norm(h[coo.row] - h[coo.col], axis=1) + 1e-300, (coo.row, coo.col)), shape=adj.shape
    )
    cache: dict[tuple[int, int], bool] = {}

    def edge_ok(a: int, b: int) -> bool:
        key = (min(a, b), max(a, b))
        if key not in cache:
            if walk == "greedy":
                cache[key] = greedy_walk_reaches(h, adj, a, b, slack=slack) or greedy_walk_reaches(
                    h, adj, b, a, slack=slack
                )
            else:
                cache[key] = shortest_path_monotone(h, graph, a, b, slack=slack)
        return cache[key]

    exhausted = np.zeros(len(s), dtype=bool)
    for _ in range(len(tri) * 4):
        changed = False
        for t_i, (a, b, c) in enumerate(tri):
            if bad[t_i]:
                continue
            fails = [(u, v) for u, v in ((a, b), (b, c), (c, a)) if not edge_ok(int(control[u]), int(control[v]))]
            if not fails:
                continue
            votes = {int(a): 0, int(b): 0, int(c): 0}
            for u, v in fails:
                votes[int(u)] += 1
                votes[int(v)] += 1
            worst_first = sorted(
                (x for x in votes if votes[x] > 0 and not exhausted[x]),
                key=lambda x: (-votes[x], -dist[x, min(rank[x], k - 1)]),
            )
            if not worst_first:
                bad[t_i] = True
                continue
            x = worst_first[0]
            del used[int(control[x])]
            rank[x] += 1
            if not take(x):
                exhausted[x] = True
                rank[x] = 0
                take(x, far=True)  # back to its best free candidate; the triangle may be marked bad later
            replacements += 1
            changed = True
        if not changed:
            break
    for t_i, (a, b, c) in enumerate(tri):
        if not bad[t_i]:
            bad[t_i] = not all(edge_ok(int(control[u]), int(control[v])) for u, v in ((a, b), (b, c), (c, a)))
    return ProjectionResult(control=control, bad_triangles=bad, replacements=replacements)
