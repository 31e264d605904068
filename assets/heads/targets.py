"""A head's own morph targets: recognise them by name and drive them (paper 002 eq. 4).

Name matching (:func:`match_targets`) knows

- ARKit's 52 blendshapes in Apple's spelling (``jawOpen``, ``mouthSmileLeft``) and the common
  variants: any case, ``_L/_R``, ``.L/.R``, ``Left/Right``, ``_l/_r``, snake case
  (``mouth_smile_left``), exporter prefixes up to the last ``.`` or ``:`` (``blendShape1.jawOpen``) and prefixes
  joined by underscores (``AK_09_JawOpen``);
- Character Creator 4's facial profile, whose names are mostly ARKit's in snake case (``Mouth_Smile_L``,
  ``Jaw_Open``) with its own words for some (``Mouth_Up_Upper_L`` = ``mouthUpperUpLeft``, :data:`CC_SIDED`)
  and with ARKit's unsided targets split into sides or quarters (``Mouth_Roll_In_Upper_L`` is the left half of
  ``mouthRollUpper``, ``Mouth_Funnel_Up_L`` a quarter of ``mouthFunnel``: :data:`CC_PARTS`, :func:`target_part`);
- the 15 Oculus/OVR visemes (``viseme_aa``, ``viseme_PP``, ``v_aa``, ...);
- VRM expressions (VRM 1.0 ``aa ih ou ee oh``, VRM 0.x ``A I U E O``, with or without a ``Fcl_MTH_`` prefix);
- a user mapping file for anything else (:func:`read_target_map`).

Each recognised target gets a *semantic correspondent* on the reference face (the built-in head,
which carries the 52 ARKit targets): an ARKit target itself, or for a viseme a fixed ARKit mixture
(:data:`VISEME_ARKIT`). The mouth parameters become a reference motion through the ARKit-52
weights facecast streams (``realtime_core.blendshapes``), and :class:`realtime_core.face.keyframes.KeyframeMap`
solves for the head's own weights by bounded least squares. A head whose targets reproduce the
jaw opening and most of the other parameters ("enough mouth targets", :func:`morph_rig`), or whose
mouth targets are the five vowels of a VRM avatar and open the jaw (:data:`VOWELS`), is
animated this way by default, with no rig step.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets.errors import MeshError
from realtime_core.blendshapes import ARKIT_NAMES, blendshape_weights
from realtime_core.face.keyframes import KeyframeMap, MorphRig

VISEME_ARKIT: dict[str, dict[str, float]] = {
    # OVR visemes (and VRM vowels, which are the same five vowels) as ARKit mixtures on the
    # reference face: what each mouth shape looks like in ARKit terms (hand-set, documented).
    "sil": {},
    "PP": {"mouthPressLeft": 0.6, "mouthPressRight": 0.6, "mouthRollLower": 0.3, "mouthRollUpper": 0.3},
    "FF": {"mouthRollLower": 0.6, "mouthUpperUpLeft": 0.3, "mouthUpperUpRight": 0.3, "jawOpen": 0.05},
    "TH": {"jawOpen": 0.15, "tongueOut": 0.4},
    "DD": {"jawOpen": 0.2, "mouthLowerDownLeft": 0.2, "mouthLowerDownRight": 0.2},
    "kk": {"jawOpen": 0.25, "mouthStretchLeft": 0.2, "mouthStretchRight": 0.2},
    "CH": {"mouthFunnel": 0.5, "jawOpen": 0.15, "mouthShrugUpper": 0.2},
    "SS": {
        "mouthStretchLeft": 0.3,
        "mouthStretchRight": 0.3,
        "jawOpen": 0.05,
        "mouthSmileLeft": 0.2,
        "mouthSmileRight": 0.2,
    },
    "nn": {"jawOpen": 0.15, "mouthStretchLeft": 0.1, "mouthStretchRight": 0.1},
    "RR": {"mouthFunnel": 0.3, "mouthPucker": 0.3, "jawOpen": 0.1},
    "aa": {"jawOpen": 0.6, "mouthLowerDownLeft": 0.3, "mouthLowerDownRight": 0.3},
    "E": {"jawOpen": 0.3, "mouthStretchLeft": 0.4, "mouthStretchRight": 0.4},
    "I": {
        "jawOpen": 0.2,
        "mouthSmileLeft": 0.4,
        "mouthSmileRight": 0.4,
        "mouthStretchLeft": 0.2,
        "mouthStretchRight": 0.2,
    },
    "O": {"jawOpen": 0.4, "mouthFunnel": 0.6},
    "U": {"jawOpen": 0.15, "mouthPucker": 0.8, "mouthFunnel": 0.2},
}
_VRM = {"aa": "aa", "a": "aa", "ih": "I", "i": "I", "ou": "U", "u": "U", "ee": "E", "e": "E", "oh": "O", "o": "O"}

# Reference motions that "enough mouth targets" must reproduce: (params (4,), max relative residual).
# The parameter order is realtime_core.VISUAL_PARAMS (upper_lip_raise, lip_stretch, mouth_open,
# lip_corner_depress), at about two thirds of each one's typical range.
ENOUGH_PROBES: tuple[tuple[tuple[float, float, float, float], float], ...] = (
    ((0.0, 0.0, 0.25, 0.0), 0.5),  # the jaw must open
    ((0.04, 0.0, 0.0, 0.0), 0.9),
    ((0.0, 0.07, 0.0, 0.0), 0.9),
    ((0.0, -0.08, 0.0, 0.0), 0.9),
)

VOWELS = frozenset({"aa", "I", "U", "E", "O"})
"""The five vowels (:data:`VISEME_ARKIT` keys) a VRM avatar's lip sync drives (its ``aa ih ou ee oh`` expressions,
VRoid's ``Fcl_MTH_A`` ...). A head whose mouth targets are these five and no others is driven through them when they
open the jaw (the first of :data:`ENOUGH_PROBES`), although they fail the others (no upper-lip raise; the built-in
head's vowels reproduce 6 % of the lips' narrowing): they are the mouth its author made for speech, and a retarget
needs a face the landmark finder recognises, which an anime avatar's often is not (docs/heads.md)."""


DRIVEN_MIN = 0.01
"""A head target is driven when its weight reaches this at some speech pose (the built-in head's
22 mouth targets reach 0.09 or more at the checked poses; the other 30 stay below 0.001)."""


def _norm(s: str) -> str:
    return re.sub(r"[^a-z0-9]", "", s.lower())


_ARKIT_BY_KEY = {_norm(n): n for n in ARKIT_NAMES}
_OVR_BY_KEY = {_norm(v): v for v in VISEME_ARKIT}


CC_SIDED = {"mouthupupper": "mouthUpperUp", "mouthdownlower": "mouthLowerDown", "browdrop": "browDown"}
"""Character Creator 4's words for sided ARKit targets (the stem, normalised, -> ARKit's stem; the side kept)."""

CC_PARTS = {
    "mouthrollinupper": ("mouthRollUpper", 2),
    "mouthrollinlower": ("mouthRollLower", 2),
    "mouthfunnelup": ("mouthFunnel", 4),
    "mouthfunneldown": ("mouthFunnel", 4),
    "mouthpuckerup": ("mouthPucker", 4),
    "mouthpuckerdown": ("mouthPucker", 4),
    "cheekpuff": ("cheekPuff", 2),
    "browraiseinner": ("browInnerUp", 2),
}
"""Character Creator 4's sided parts of ARKit's unsided targets: the stem, normalised, -> (ARKit name, how many parts
make it). Each part's correspondent is the whole target over the count: speech is symmetric, so the solve gives every
part the whole target's weight and the parts together move the head as the whole target would."""


def _base_and_side(name: str) -> tuple[str, str | None, str]:
    """(the name without exporter prefixes, its side "left" / "right" or None, the stem before the side)."""
    segs = re.split(r"[.:|]", name.strip())
    base = segs[-1].strip()
    if len(segs) > 1 and base in ("L", "R", "l", "r"):  # Blender's "mouthSmile.L": the side, not a prefix
        base = segs[-2].strip() + "_" + base
    # Side suffixes: _L/_R, .L/.R, -L, " L", _l, Left/Right in any case.
    m = re.match(r"^(.*?)[_\-. ]?([LlRr])$", base)
    if m and m.group(1) and not m.group(1).endswith(("Left", "Right", "left", "right")):
        return base, "left" if m.group(2) in "Ll" else "right", m.group(1)
    return base, None, base


def target_part(name: str) -> tuple[str, float] | None:
    """(ARKit name, share) for a target that is one side or quarter of an unsided ARKit target (Character Creator 4's
    ``Mouth_Roll_In_Upper_L``: ``("mouthRollUpper", 0.5)``), or None."""
    _, side, stem = _base_and_side(name)
    part = CC_PARTS.get(_norm(stem)) if side is not None else None
    return None if part is None else (part[0], 1.0 / part[1])


def canonical_name(name: str) -> str | None:
    """The ARKit name (``"jawOpen"``) or viseme (``"viseme:aa"``) a morph-target name stands for, or None."""
    base, side, stem = _base_and_side(name)
    if side is not None:
        key = _norm(stem)
        key = (_norm(CC_SIDED[key]) if key in CC_SIDED else key) + side
        if key in _ARKIT_BY_KEY:
            return _ARKIT_BY_KEY[key]
    key = _norm(base)
    if key in _ARKIT_BY_KEY:
        return _ARKIT_BY_KEY[key]
    for prefix in ("viseme", "vrc.v", "v", "fclmth", "mth"):
        if key.startswith(prefix) and len(key) > len(prefix):
            rest = key[len(prefix) :]
            if rest in _OVR_BY_KEY:
                return "viseme:" + _OVR_BY_KEY[rest]
            if rest in _VRM:
                return "viseme:" + _VRM[rest]
    if key in _VRM and len(base) <= 2:  # a bare VRM vowel: "aa", "A", "ih", ...
        return "viseme:" + _VRM[key]
    # Prefixes joined by underscores (Rocketbox's "AK_09_JawOpen", a Daz export's "Genesis8Female__jawOpen",
    # "CTRL_expressions_jawOpen"): the rest after each, ARKit names only (a short rest such as "aa" after any prefix
    # would read too many names as visemes).
    tokens = [x for x in base.split("_") if x]
    for i in range(1, len(tokens) - (side is not None)):
        c = canonical_name("_".join(tokens[i:]))
        if c is not None and not c.startswith("viseme:"):
            return c
    return None


def read_target_map(path: str | Path) -> dict[str, dict[str, float]]:
    """A user mapping file: ``{"targets": {head_target: "jawOpen" | "viseme:aa" | {"jawOpen": 0.5, ...}}}``.

    Each value names the ARKit target (or viseme) the head's target looks like, or an ARKit
    mixture. Raises MeshError naming the file on any problem."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MeshError(f"{p}: cannot read the morph-target mapping: {exc}") from exc
    table = doc.get("targets") if isinstance(doc, dict) else None
    if not isinstance(table, dict):
        raise MeshError(f'{p}: expected {{"targets": {{head_target: ARKit name | "viseme:aa" | {{ARKit: weight}}}}}}')
    out: dict[str, dict[str, float]] = {}
    for k, v in table.items():
        try:
            out[str(k)] = correspondent(v)
        except ValueError as exc:
            raise MeshError(f"{p}: target {k!r}: {exc}") from exc
    return out


def correspondent(value: object) -> dict[str, float]:
    """An ARKit mixture for a mapping value (ARKit name, ``viseme:X`` or {ARKit name: weight})."""
    if isinstance(value, str):
        c = canonical_name(value) if not value.startswith("viseme:") else value
        if c is None and (part := target_part(value)) is not None:
            return {part[0]: part[1]}
        if c is None:
            raise ValueError(f"{value!r} is neither an ARKit name nor a viseme")
        return dict(VISEME_ARKIT[c[7:]]) if c.startswith("viseme:") else {c: 1.0}
    if isinstance(value, Mapping):
        mix: dict[str, float] = {}
        for k, w in value.items():
            c = canonical_name(str(k))
            if c is None or c.startswith("viseme:") or isinstance(w, bool) or not isinstance(w, (int, float)):
                raise ValueError(f"{k!r}: {w!r} is not an ARKit name with a number")
            mix[c] = mix.get(c, 0.0) + float(w)
        return mix
    raise ValueError(f"{value!r} must be an ARKit name, 'viseme:X' or an object of ARKit weights")


def match_targets(
    names: list[str] | tuple[str, ...], user_map: Mapping[str, Mapping[str, float]] | None = None
) -> dict[str, dict[str, float]]:
    """Head target name -> ARKit mixture of its correspondent, for every recognised target.

    ARKit targets are preferred: when the head has at least as many ARKit mouth targets as
    visemes, visemes are left out (avatars often carry both sets; one set drives the mouth).
    The user map adds to (and overrides) the recognised names."""
    arkit: dict[str, dict[str, float]] = {}
    vis: dict[str, dict[str, float]] = {}
    parts: dict[str, dict[str, float]] = {}
    seen: set[str] = set()  # one head target per ARKit target or part of one (the first of its spellings)
    for n in names:
        c = canonical_name(n)
        if c is None:
            part = target_part(n)
            if part is not None and (key := "part:" + _norm(_base_and_side(n)[0])) not in seen:
                seen.add(key)
                parts[n] = {part[0]: part[1]}
        elif c.startswith("viseme:"):
            if VISEME_ARKIT[c[7:]] and c not in {canonical_name(x) for x in vis}:
                vis[n] = dict(VISEME_ARKIT[c[7:]])
        elif c not in seen:
            seen.add(c)
            arkit[n] = {c: 1.0}
    # A head with a whole target and its parts too: the whole one drives it (both would move the lips twice).
    arkit.update({k: m for k, m in parts.items() if next(iter(m)) not in seen})
    n_mouth = sum(1 for m in arkit.values() if next(iter(m)).startswith(("jaw", "mouth")))
    out = dict(arkit) if n_mouth >= len(vis) else dict(vis)
    for k, v in (user_map or {}).items():
        if k in names:
            out[k] = dict(v)
    return out


@dataclass(frozen=True)
class ReferenceLips:
    """The reference face's lip columns, whose gaps the keyframe solve keeps from crossing
    (:class:`realtime_core.face.keyframes.KeyframeMap`): pairs (m, 2) reference vertex indices
    (upper, lower); rest (m,) their gap along the face's up axis at rest (IOD); axis (3,) up / IOD."""

    pairs: np.ndarray
    rest: np.ndarray
    axis: np.ndarray


LIP_COLUMN_WIDTH = 0.04
"""IOD: the width of a reference lip column (the built-in head's mouth is 0.8 IOD wide: 20 columns, 4 of
which hold a lip-skin pair besides the inner-lip landmarks)."""


def reference_lips(
    vertices: np.ndarray, triangles: np.ndarray, jaw: np.ndarray, landmarks: Mapping[str, int]
) -> ReferenceLips:
    """The reference face's lip columns: vertices (n, 3); triangles (m, 3); jaw (n, 3) its jaw-opening
    target (moves the lower lip, not the upper); landmarks: name -> vertex index (the mouth landmarks).

    The inner contours' pairs by :func:`realtime_core.face.rig.lip_pairs_by_drop` (the rule a rig's lip
    columns follow), in columns LIP_COLUMN_WIDTH IOD wide, with the jaw target's drop relative to its
    largest within the mouth (the chin drops further than the lower lip), among the lips' own pieces only
    (:func:`realtime_core.face.rig.lip_pieces`); the inner-lip landmarks always."""
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face.model import face_frame
    from realtime_core.face.rig import lip_pairs_by_drop, lip_pieces

    v = np.asarray(vertices, dtype=np.float64)
    lm = mouth_landmarks(dict(landmarks))
    fr = face_frame(v, lm)
    drop = -(np.asarray(jaw, dtype=np.float64) @ fr.axes[1]) / fr.iod
    # Without the pieces the built-in head's teeth stood for a lip: its 2 columns were the inner-lip
    # landmarks and an upper tooth over a lower tooth (x = 0.22 IOD), so the solve kept teeth apart.
    on_lips = lip_pieces(v, triangles, lm)
    pr = lip_pairs_by_drop(v, drop, lm, fr, column_width=LIP_COLUMN_WIDTH, top_in_box=True, candidates=on_lips)
    axis = fr.axes[1] / fr.iod
    return ReferenceLips(pairs=pr, rest=(v[pr[:, 0]] - v[pr[:, 1]]) @ axis, axis=axis)


MORPH_RIG_VERSION = 2
"""Bump when :func:`morph_rig` or :func:`reference_lips` builds something else from the same inputs: the built-in
head's morph rig is cached under a key holding it (:func:`morph_rig_key`). (2: the expressions' face shapes.)"""


def arkit_source(params: np.ndarray) -> np.ndarray:
    """Mouth parameters (..., 4) -> the ARKit-52 weights facecast streams (..., 52)."""
    return blendshape_weights(params, "arkit52").astype(np.float64)


def morph_rig(
    name: str,
    vertices: np.ndarray,
    triangles: np.ndarray,
    targets: Mapping[str, np.ndarray],
    reference: Mapping[str, np.ndarray],
    *,
    user_map: Mapping[str, Mapping[str, float]] | None = None,
    require_enough: bool = True,
    lips: ReferenceLips | None = None,
) -> MorphRig | None:
    """A :class:`MorphRig` driving the head's own ``targets`` (name -> (n, 3) displacement at weight 1),
    or None when too few mouth targets are recognised (``require_enough``) to reproduce the
    :data:`ENOUGH_PROBES` (the five :data:`VOWELS` alone: the jaw's). ``reference``: the built-in head's 52 ARKit
    targets (name -> (n_ref, 3)).
    ``lips``: the reference's lip columns (:func:`reference_lips`): the weights never cross them further
    than the reference motion does (None: not constrained)."""
    matched = match_targets(list(targets), user_map)
    if not any(k.startswith(("jaw", "mouth", "tongue")) for mix in matched.values() for k in mix):
        return None  # no mouth shape among the recognised targets (eyes, brows only)
    head_names = tuple(matched)
    ref = np.stack([reference[n] for n in ARKIT_NAMES])  # (52, n_ref, 3)
    rows = np.flatnonzero(np.abs(ref).max(axis=(0, 2)) > 0)  # reference vertices any target moves
    a = ref[:, rows].reshape(len(ARKIT_NAMES), -1)  # (52, d): reference displacement per ARKit weight
    index = {n: i for i, n in enumerate(ARKIT_NAMES)}
    mix = np.zeros((len(head_names), len(ARKIT_NAMES)))
    for i, n in enumerate(head_names):
        for arkit, w in matched[n].items():
            mix[i, index[arkit]] = w
    kprime = mix @ a  # (P, d) correspondents kappa'_i
    keep = np.abs(kprime).max(axis=1) > 0
    head_names = tuple(n for n, k in zip(head_names, keep) if k)
    if not head_names:
        return None
    kprime = kprime[keep]
    contact = None
    if lips is not None:
        # The lip gaps as linear functions of the flat reference displacement over ``rows``.
        where = -np.ones(ref.shape[1], dtype=np.int64)
        where[rows] = np.arange(len(rows))
        gap = np.zeros((len(lips.pairs), len(rows), 3))
        for i, (u, lo) in enumerate(lips.pairs):
            if where[u] >= 0:
                gap[i, where[u]] += lips.axis
            if where[lo] >= 0:
                gap[i, where[lo]] -= lips.axis
        contact = (lips.rest, gap.reshape(len(lips.pairs), -1))
    keymap = KeyframeMap.from_reference(kprime, a, contact=contact)
    residuals = [keymap.residual(kprime, a, arkit_source(np.array(p))) for p, _ in ENOUGH_PROBES]
    enough = all(r <= lim for r, (_, lim) in zip(residuals, ENOUGH_PROBES))
    mouth = {canonical_name(n) for n in head_names if any(k.startswith(("jaw", "mouth")) for k in matched[n])}
    vowels = mouth == {f"viseme:{v}" for v in VOWELS}
    enough = enough or (vowels and residuals[0] <= ENOUGH_PROBES[0][1])
    if require_enough and not enough:
        return None
    # Targets speech never drives (eyes, brows, cheeks of an ARKit head: their weights stay below
    # DRIVEN_MIN at every speech pose, carrying only the ridge's noise) are left out: each driven
    # target costs the per-frame solve, the wire and a renderer (a GPU loops over them per vertex).
    from realtime_core.face.checks import CHECK_POSES

    driven = keymap.weights(arkit_source(np.asarray(CHECK_POSES, dtype=np.float64))).max(axis=0) >= DRIVEN_MIN
    if driven.any() and not driven.all():
        head_names = tuple(n for n, k in zip(head_names, driven) if k)
        kprime = kprime[driven]
        keymap = KeyframeMap.from_reference(kprime, a, contact=contact)
    face_names, recipe = face_targets(targets, exclude=head_names)
    d = np.stack([np.asarray(targets[n], dtype=np.float64) for n in head_names + face_names])  # (P + F, n, 3)
    if d.shape[1:] != np.asarray(vertices).shape:
        raise MeshError(f"{name}: morph targets do not match the mesh's {len(vertices)} vertices")
    moving = np.flatnonzero(np.abs(d).max(axis=(0, 2)) > 0)
    meta = {
        "head": name,
        "kind": "morph",
        "targets": {n: matched[n] for n in head_names},
        "face_shapes": {n: canonical_name(n) for n in face_names},
        "probe_residuals": [round(r, 4) for r in residuals],
        "undriven_targets": len(matched) - len(head_names),
        "enough_mouth_targets": bool(enough),
        "vowels_only": vowels,
    }
    return MorphRig(
        neutral=vertices,
        triangles=triangles,
        names=head_names + face_names,
        targets=d[:, moving],
        moving=moving,
        keymap=keymap,
        source=arkit_source,
        meta=meta,
        face_recipe=recipe,
    )


def face_targets(
    targets: Mapping[str, np.ndarray], *, exclude: tuple[str, ...] = ()
) -> tuple[tuple[str, ...], np.ndarray | None]:
    """The head's own targets that are the face shapes of the expressions' recipes (cheeks, eyes, brows, nose:
    :func:`realtime_core.expressions.face_shapes`) by their ARKit name in any spelling :func:`canonical_name`
    knows, the first spelling of each, none of ``exclude`` (the targets speech drives) and none that moves nothing ->
    (their names (F,), the (E, F) recipe weights per expression of :data:`realtime_core.expressions.EXPRESSIONS`),
    or ``((), None)`` when the head has none."""
    from realtime_core.expressions import EXPRESSIONS, face_shapes

    wanted = {k for e in EXPRESSIONS for k in face_shapes(e)}
    chosen: dict[str, str] = {}  # ARKit name -> the head's target
    for n, t in targets.items():
        c = canonical_name(n)
        if c in wanted and c not in chosen and n not in exclude and np.abs(np.asarray(t)).max(initial=0.0) > 0:
            chosen[c] = n
    if not chosen:
        return (), None
    recipe = np.array([[face_shapes(e).get(c, 0.0) for c in chosen] for e in EXPRESSIONS], dtype=np.float32)
    return tuple(chosen.values()), recipe


def morph_rig_key(
    vertices: np.ndarray,
    triangles: np.ndarray,
    targets: Mapping[str, np.ndarray],
    landmarks: Mapping[str, int],
) -> str:
    """Hex digest of what the built-in head's morph rig is made from (:func:`morph_rig` of its own targets with
    :func:`reference_lips`): vertices (n, 3), triangles (m, 3), the 52 ARKit targets (n, 3) each, the landmark
    vertex indices, the ARKit weights at the probe and checked poses (so a changed ARKit mapping or pose set
    rebuilds it), the constants the build reads and the algorithm versions (this module's and the rig's, whose
    lip-column rule :func:`reference_lips` follows)."""
    import hashlib

    from realtime_core.face import keyframes
    from realtime_core.face.checks import CHECK_POSES
    from realtime_core.face.rig import RIG_ALGORITHM

    consts = (
        ENOUGH_PROBES,
        DRIVEN_MIN,
        LIP_COLUMN_WIDTH,
        keyframes.CONTACT_TOL,
        keyframes.LIP_OPEN_TOL,
        keyframes.LIP_CLOSED_GAP,
        keyframes.LIP_OPEN_RAMP,
        keyframes.CONTACT_SWEEPS,
        keyframes.CONTACT_SEARCH,
    )
    h = hashlib.sha256(f"morph {MORPH_RIG_VERSION} {RIG_ALGORITHM} {consts!r}".encode())
    for a in (vertices, triangles, *(targets[n] for n in ARKIT_NAMES)):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    h.update(json.dumps(dict(landmarks), sort_keys=True).encode())
    poses = np.array([p for p, _ in ENOUGH_PROBES] + list(CHECK_POSES), dtype=np.float64)
    h.update(arkit_source(poses).tobytes())
    return h.hexdigest()[:32]


def morph_rig_arrays(rig: MorphRig) -> dict[str, np.ndarray]:
    """What :func:`morph_rig` computed, as plain arrays for an ``.npz`` (no pickle): the driven targets, the
    vertices they move, the keyframe map's matrices, the rest weights (when set) and the meta as JSON. The neutral
    mesh, its triangles and the source function are the caller's (:func:`morph_rig_from_arrays`)."""
    km = rig.keymap
    arrays = {
        "names": np.array(rig.names, dtype=str),
        "targets": rig.targets,
        "moving": rig.moving,
        "gram": km.gram,
        "cross": km.cross,
        "bounds": np.array([km.lo, km.hi]),
        "meta": np.array(json.dumps(rig.meta)),
    }
    if rig.rest is not None:  # a head modelled with its lips apart rests where they meet
        arrays["rest"] = rig.rest
    if rig.face_recipe is not None:  # the last F targets: face shapes driven by expressions
        arrays["face_recipe"] = rig.face_recipe
    if km.contact_rest is not None and km.contact_rows is not None and km.contact_source is not None:
        arrays |= {
            "contact_rest": km.contact_rest,
            "contact_rows": km.contact_rows,
            "contact_source": km.contact_source,
        }
    return arrays


def morph_rig_from_arrays(arrays: Mapping[str, np.ndarray], vertices: np.ndarray, triangles: np.ndarray) -> MorphRig:
    """The :class:`MorphRig` :func:`morph_rig_arrays` stored, on ``vertices`` (n, 3) and ``triangles`` (m, 3),
    driven by :func:`arkit_source`. Raises KeyError / ValueError on a file that is not such arrays."""
    lo, hi = (float(v) for v in arrays["bounds"])
    keymap = KeyframeMap(
        gram=arrays["gram"],
        cross=arrays["cross"],
        lo=lo,
        hi=hi,
        contact_rest=arrays.get("contact_rest"),
        contact_rows=arrays.get("contact_rows"),
        contact_source=arrays.get("contact_source"),
    )
    return MorphRig(
        neutral=vertices,
        triangles=triangles,
        names=tuple(str(n) for n in arrays["names"]),
        targets=arrays["targets"],
        moving=arrays["moving"],
        keymap=keymap,
        source=arkit_source,
        meta=json.loads(str(arrays["meta"])),
        rest=arrays.get("rest"),
        face_recipe=arrays.get("face_recipe"),
    )
