"""Fits the blendshape maps and the expression table (``facecast fit-maps``), by eq. 4's least squares.

ARKit-52. The built-in head's own ARKit morph targets are keyframes ``K`` (columns: each target's
displacement of the rig's moving vertices, head units); for each signed unit of each mouth parameter
(+-0.05 IOD) the rig's displacement ``d`` is the shape to reproduce, and ``b = argmin |K b - d|^2 +
lambda |b|^2, b >= 0`` (:class:`realtime_core.motion_units.KeyframeSet`, non-negative) gives that
direction's weights (for a lowered upper lip and rounded lips also reproducing the rig's lip gaps and
mouth corners, :data:`LIP_GAP_DIRECTIONS`: else a lowered upper lip opened the lips). Weights are then
linear in the positive and negative parts of each parameter:
``w = clip(A+ max(p, 0) + A- max(-p, 0) + c, 0, 1)``. Side-shift targets (``jawLeft/Right,
mouthLeft/Right``, and ``jawForward``) are left out: the four parameters are symmetric and say
nothing of jaw protrusion.

OVR-15. No shipped head has viseme targets, so the keyframes are the visemes' articulatory targets in
the four parameters (:mod:`training.articulatory`, one phoneme class per viseme). A signed-unit fit
recruits unrelated visemes to cancel small side effects (a bilabial to trim an /a/'s spread), so
OVR weights are solved per frame instead: eq. 4 with ``b >= 0`` and ridge :data:`OVR_RIDGE` (at most
four visemes active), ``sil = 1 - sum(others)``.

Expressions. Each recipe of :data:`realtime_core.expressions.EXPRESSION_RECIPES` is applied to the
built-in head's targets and measured with :func:`realtime_core.face.model.measure_mouth`: its change
of the four mouth parameters (IOD).

The result is written as a Python module of constants (``realtime_core/fitted_maps.py``) so the sans-I/O
core reads no file; a test re-fits and compares, so the module cannot drift from its recipe.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import nnls

from realtime_core import VISUAL_PARAMS
from realtime_core.blendshapes import ARKIT_NAMES, ARKIT_RESOLVED, ARKIT_SIDE_SHIFTS, ARKIT_SPEECH, OVR_NAMES
from realtime_core.expressions import EXPRESSION_RECIPES, EXPRESSIONS
from realtime_core.motion_units import KeyframeSet

UNIT_IOD = 0.05
RIDGE = 1e-3
OVR_RIDGE = 0.05
LIP_GAP_DIRECTIONS = ((0, -1.0), (1, -1.0))
"""(parameter index, sign) of the signed units whose fit also reproduces the rig's lip gaps and mouth corners:
the lowered upper lip and the rounded lips, the two of the pressed bilabial pose (/m b p/). Fitted to the
whole-region motion alone, the lowered upper lip took jawOpen 2.20 and mouthFunnel 2.52 per IOD and opened the
inner lips by 1.38 IOD per IOD (a line of teeth at every /m/) where the rig closes them by 0.04; rounding opened
them by 0.10. The corners-up direction (lip_corner_depress < 0) stays as it was: reproduced, the rig's gaps
cross the lips by 0.006 IOD at the checks' corners-up poses (the rig's lip-contact push, which no linear map
has, keeps its own lips apart there); the others are within 0.008 IOD per 0.05 IOD unit of the rig's."""
LIP_GAP_WEIGHT = 1e3
"""Weight of a gap or corner row relative to one displacement coordinate's (head units, squared). 1e2 left the
lips 0.0127 IOD apart at upper_lip_raise -0.084, 1e3 0.0024, 1e4 0.0032; the lip_corner_depress correlation
of test_fitted_maps (0.888 unweighted) 0.83 with the corner rows at 1e3 and 1e4, 0.78 without them."""
SIDE_SHIFTS = ARKIT_SIDE_SHIFTS
RESOLVE_GAP_WEIGHT = 1e4
"""Weight of a lip gap or mouth corner row in the re-solve after antagonists are netted (ARKIT_RESOLVE_GRAM /
_CROSS; :mod:`realtime_core.blendshapes`), against one displacement coordinate's. Over 900 GRID s1 frames, the
4 parameters measured back from the built-in head's targets: RMS 0.0115 IOD at 1e3 (mouth_open 0.0010, corners
0.0178), 0.0097 at 1e4 (0.0008, 0.0128); the linear map before the netting 0.0159 (0.0009, 0.0189). At the checks'
closed poses with the upper lip lowered the lips stay within 0.0118 IOD (1e3: 0.0106; netted without the re-solve,
0.021: the smile the netting took away had been closing them)."""
OVR_CLASSES = {
    "PP": "bilabial",
    "FF": "labiodental",
    "TH": "dental",
    "DD": "alveolar",
    "kk": "velar",
    "CH": "postalveolar",
    "SS": "sibilant",
    "nn": "alveolar",
    "RR": "rhotic",
    "aa": "open_central",
    "E": "mid_front",
    "I": "close_front",
    "O": "mid_back_round",
    "U": "close_back_round",
}
"""OVR viseme -> the articulatory class whose target is its keyframe."""


def _signed_fit(keys: KeyframeSet, shape_of, gaps: np.ndarray, gap_of) -> tuple[np.ndarray, np.ndarray]:
    """``(P, 4)`` weights per IOD of each parameter's positive part and of its negative part.

    gaps: ``(m, P)`` each keyframe's change of the reference lip pairs' vertical gaps and of the mouth
    corners' height (head units); gap_of: a rig displacement ``(D,)`` -> its change of those ``(m,)``. For
    :data:`LIP_GAP_DIRECTIONS` they enter as extra least-squares rows weighted :data:`LIP_GAP_WEIGHT`: the fit
    reproduces the rig's lips first and its whole-region motion second."""
    p = len(keys.names)
    w = np.sqrt(LIP_GAP_WEIGHT)
    a = np.vstack([keys.ridge_rows(), w * gaps])  # the set's own ridge, as its non-negative fit has it
    pos, neg = np.zeros((p, 4)), np.zeros((p, 4))
    for i in range(4):
        for sign, out in ((1.0, pos), (-1.0, neg)):
            e = np.zeros(4)
            e[i] = sign * UNIT_IOD
            d = shape_of(e)
            if (i, sign) in LIP_GAP_DIRECTIONS:
                out[:, i] = nnls(a, np.concatenate([d, np.zeros(p), w * gap_of(d)]))[0] / UNIT_IOD
            else:
                out[:, i] = keys.weights(d, nonnegative=True) / UNIT_IOD
    return pos, neg


def fit_maps(head, rig) -> dict:
    """head: :class:`assets.heads.builtin.BuiltinHead`; rig: its :class:`realtime_core.face.rig.Rig`."""
    from assets.heads.targets import reference_lips
    from realtime_core.face import MouthLandmarks
    from realtime_core.face.checks import EXTREME_POSES, expression_poses
    from realtime_core.face.model import measure_mouth
    from training.articulatory import CLASSES

    # The maps reproduce the rig's field, not its lip-contact push: the push acts only on frames whose
    # lips would cross (the pressed-lip probe, mouth_open -0.05, crosses the built-in head's 0.007 IOD
    # rest gap), and fitted into a map it would move the lips apart at poses where they do not cross.
    rig = replace(rig, contact=np.zeros((0, 2), dtype=np.int64), contact_spread=None)
    mv = rig.moving

    def shape_of(p: np.ndarray) -> np.ndarray:
        return np.asarray(rig.displacements(p), dtype=np.float64).reshape(-1)

    mouth = ARKIT_SPEECH
    keys = KeyframeSet(
        names=mouth, shapes=np.column_stack([head.targets[n][mv].reshape(-1) for n in mouth]), ridge=RIDGE
    )
    lips = reference_lips(head.mesh.vertices, head.mesh.triangles, head.targets["jawOpen"], head.landmarks)
    up, lo = lips.pairs[:, 0], lips.pairs[:, 1]
    axis = lips.axis / float(np.linalg.norm(lips.axis))  # the face's up axis: gaps in head units
    corners = np.array([head.landmarks["corner_left"], head.landmarks["corner_right"]])
    gaps = np.array(
        [np.r_[(head.targets[n][up] - head.targets[n][lo]) @ axis, head.targets[n][corners] @ axis] for n in mouth]
    ).T

    def gap_of(d: np.ndarray) -> np.ndarray:
        dv = np.zeros_like(head.mesh.vertices)
        dv[mv] = d.reshape(-1, 3)
        return np.r_[(dv[up] - dv[lo]) @ axis, dv[corners] @ axis]

    pos_m, neg_m = _signed_fit(keys, shape_of, gaps, gap_of)
    a_pos, a_neg = np.zeros((len(ARKIT_NAMES), 4)), np.zeros((len(ARKIT_NAMES), 4))
    for j, n in enumerate(mouth):
        a_pos[ARKIT_NAMES.index(n)], a_neg[ARKIT_NAMES.index(n)] = pos_m[j], neg_m[j]
    # (4, 14): the visemes after "sil", in OVR order.
    ovr = np.column_stack([np.array(CLASSES[OVR_CLASSES[v]].target, dtype=np.float64) for v in OVR_NAMES[1:]])
    lm = MouthLandmarks(**{k: head.landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    v0 = head.mesh.vertices
    expr = np.array(
        [
            measure_mouth(v0, v0 + sum(w * head.targets[n] for n, w in EXPRESSION_RECIPES[e].items()), lm)
            for e in EXPRESSIONS
        ]
    )
    # As the module writes them (6 significant digits): the poses below are computed from what the core reads.
    expr = np.vectorize(lambda v: float(f"{v:.6g}"))(expr)
    # Each ARKit target's size (the norm of its displacement of the whole head, head units): antagonists cancel in
    # these units (realtime_core.blendshapes.ARKIT_ANTAGONISTS).
    size = np.array([float(np.linalg.norm(head.targets[n])) for n in ARKIT_NAMES])
    # The re-solve after the netting: eq. 4 over the other speech targets in the metric of the region's displacement
    # plus the lip gaps and corners (RESOLVE_GAP_WEIGHT), its ridge relative to the speech targets' mean diagonal.
    feats = np.vstack([keys.shapes, np.sqrt(RESOLVE_GAP_WEIGHT) * gaps])  # (D + m, len(mouth))
    own = feats[:, [mouth.index(n) for n in ARKIT_RESOLVED]]
    lam = RIDGE * float((feats**2).sum(axis=0).mean())
    resolve_gram = own.T @ own + lam * np.eye(own.shape[1])
    resolve_cross = own.T @ feats
    return {
        "ARKIT_POS": a_pos,
        "ARKIT_NEG": a_neg,
        "ARKIT_SIZE": size,
        "ARKIT_RESOLVE_GRAM": resolve_gram,
        "ARKIT_RESOLVE_CROSS": resolve_cross,
        "OVR_KEYFRAMES": ovr,
        "OVR_RIDGE": np.array([OVR_RIDGE]),
        "EXPRESSION_PARAMS": expr,
        "EXPRESSION_POSES": expression_poses(EXTREME_POSES, expr),
    }


def _row(a: np.ndarray, indent: str) -> str:
    """One 1-D array as a tuple literal, on one line when it fits in 120 columns, else one value a line."""
    line = "(" + ", ".join(f"{v:.6g}" for v in a) + ("," if a.size == 1 else "") + ")"
    if len(indent) + len(line) + 1 <= 120:
        return line
    return "(\n" + "".join(f"{indent}    {v:.6g},\n" for v in a) + f"{indent})"


def _assignment(name: str, a: np.ndarray) -> str:
    """``name = np.array(...)`` laid out as ``ruff format`` lays it out, so the generated module passes
    CI's ``ruff format --check`` as written (it did not: every run of fit-maps had to be reformatted)."""
    if a.ndim == 1:
        one = f"{name} = np.array({_row(a, '')})"
        if "\n" not in one and len(one) <= 120:
            return one
        return f"{name} = np.array(\n    {_row(a, '    ')}\n)"
    rows = "".join(f"        {_row(row, '        ')},\n" for row in a)
    return f"{name} = np.array(\n    (\n{rows}    )\n)"


ARRAY_NAMES: tuple[str, ...] = (
    "ARKIT_POS",
    "ARKIT_NEG",
    "ARKIT_SIZE",
    "ARKIT_RESOLVE_GRAM",
    "ARKIT_RESOLVE_CROSS",
    "OVR_KEYFRAMES",
    "OVR_RIDGE",
    "EXPRESSION_PARAMS",
)
"""The arrays of the generated module (:mod:`realtime_core.fitted_maps`), in their order there; EXPRESSION_POSES
follows them as a tuple."""


def module_text(maps: dict) -> str:
    """The generated ``realtime_core/fitted_maps.py``."""
    head = f'''"""Fitted blendshape maps and expression table: GENERATED by ``facecast fit-maps`` - do not edit.

ARKit-52 weights: ``w = clip(cancel(ARKIT_POS @ max(p, 0) + ARKIT_NEG @ max(-p, 0)), 0, 1)`` with
``p = {VISUAL_PARAMS}`` (IOD), ``cancel`` netting each
antagonist pair in ARKIT_SIZE units (:data:`realtime_core.blendshapes.ARKIT_ANTAGONISTS`);
rows follow :data:`realtime_core.blendshapes.ARKIT_NAMES`, columns the four parameters (weight per
IOD). Fitted by non-negative least squares (paper 002 eq. 4, ridge {RIDGE:g}) of the built-in head's own
ARKit targets to the head rig's motion for each signed parameter unit (+-{UNIT_IOD} IOD); a lowered upper lip
and rounded lips also reproduce its lip gaps and mouth corners (weight {LIP_GAP_WEIGHT:g}). ARKIT_SIZE ``(52,)``:
each target's displacement norm on the built-in head (head units). ARKIT_RESOLVE_GRAM ``(R, R)`` and
ARKIT_RESOLVE_CROSS ``(R, S)``: the re-solve of the ARKIT_RESOLVED targets after the netting (``K^T K + lambda I``,
``K^T K'``; K' the ARKIT_SPEECH targets, gap and corner rows weighted {RESOLVE_GAP_WEIGHT:g}). OVR_KEYFRAMES
``(4, 14)``: the 14 non-silence OVR visemes in the four parameters, solved per frame (ridge OVR_RIDGE).
See :mod:`training.fit_maps`. EXPRESSION_PARAMS ``(len(EXPRESSIONS), 4)``: each expression recipe's
change of the four mouth parameters (IOD), measured on the built-in head. EXPRESSION_POSES: speech under
those expressions, the poses the rig checks' hull needs,
``realtime_core.face.checks.expression_poses(EXTREME_POSES, EXPRESSION_PARAMS)`` (IOD; Qhull, a tenth of a
second or more: kept here rather than computed on every import of the checks).
"""

import numpy as np

'''
    body = []
    for name in ARRAY_NAMES:
        body.append(f"{_assignment(name, np.asarray(maps[name]))}\n{name}.setflags(write=False)\n")
    rows = "".join(f"    ({', '.join(repr(float(v)) for v in row)}),\n" for row in maps["EXPRESSION_POSES"])
    body.append(f"EXPRESSION_POSES: tuple[tuple[float, float, float, float], ...] = (\n{rows})\n")
    return head + "\n".join(body)
