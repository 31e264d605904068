"""The one head resolver: whatever the user names as a head becomes one :class:`Head`.

``resolve_head(spec)`` accepts

- ``"builtin"``: the built-in head, driven through its own 52 ARKit targets (``mode="retarget"``:
  its Sec. 5 rig instead);
- a rig file (``.npz``, written by ``facecast rig``);
- a Candide-3 model (``.wfm``): driven through its own animation units (:mod:`assets.heads.wfm`);
- a head mesh (``.glb/.gltf/.vrm/.obj/.ply``): driven through its own morph targets when it has enough
  mouth targets (:mod:`assets.heads.targets`; no rig step), otherwise rigged now from landmarks
  (``landmarks`` JSON, else the file shipped for known heads, else ``landmark_finder(mesh)``, e.g.
  :func:`clients.render.landmarks.find_landmarks`, which finds them on a render of the face; the
  finder is passed in because rendering lives in a layer above this one).

A :class:`Head` holds the mesh and what animates it: a :class:`realtime_core.face.Rig` (retarget,
paper 000 Sec. 5) or a :class:`realtime_core.face.keyframes.MorphRig` (own targets, paper 002
eq. 4). Both have ``neutral``, ``triangles``, ``moving``, ``displacements(params)``,
``deformed(params)`` and ``meta``, which is all the renderer, the exporters and the server use.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from assets.errors import CannotWriteError, LandmarkError, MeshError, RigFileError
from assets.files import not_a_file
from assets.heads.landmarks import FoundLandmarks
from assets.heads.mesh import MESH_SUFFIXES, HeadMesh
from realtime_core import VISUAL_PARAMS
from realtime_core.face import Rig, RigConfig
from realtime_core.face.keyframes import MorphRig

if TYPE_CHECKING:
    from realtime_core.face.checks import RigCheckLimits, RigReport

AnyRig = Rig | MorphRig
LandmarkFinder = Callable[[HeadMesh], Mapping[str, object]]
HeadMode = Literal["auto", "morph", "retarget"]
HEAD_MODES: tuple[str, ...] = ("auto", "morph", "retarget")
# The built-in morph rig's cache files (``builtin_morph_<key>.npz``): one per key, the newest current.
MORPH_CACHE_FAMILY = re.compile(r"builtin_morph_[0-9a-f]+\.npz")
# The automatic landmarks found for own-target heads (``landmarks/a<RIG_ALGORITHM>_<key>.json``, cached_finder).
LANDMARK_CACHE_FAMILY = re.compile(r"a[0-9]+_[0-9a-f]{32}\.json")
# Mesh heads driven by their own targets (``morph_heads/<key>.npz``, morph_head): the key hashes the generation in, so
# only the file's "head_meta" tells an older generation's file (morph_head_generation).
MORPH_HEAD_CACHE_FAMILY = re.compile(r"[0-9a-f]{32}\.npz")
MORPH_HEAD_FORMAT = "facecast-morph-head"
MORPH_HEAD_VERSION = 3
"""Bump when :func:`morph_head` makes something else from the same inputs while neither
:data:`assets.heads.targets.MORPH_RIG_VERSION` (the fit) nor ``RIG_ALGORITHM`` (the mouth cavity, its shading, the
checks, the automatic landmarks) changes, or when its cache file's layout does: a head driven by its own targets is
read from the cache under a key holding it (:func:`morph_head_generation`)."""
LANDMARK_CACHE_VERSION = 2
"""Of what cached_finder keeps: 2, with the finder's alternative sets (older files hold none, so are found again)."""


@dataclass(frozen=True)
class Head:
    """A head ready to animate: ``rig`` (Rig or MorphRig) and the ``mesh`` it deforms (same vertex order).
    The rig drives within :func:`realtime_core.face.checks.checked_bound` (set here when it has no bound): every
    head the commands and the server animate is made here, and parameters outside the poses its rig was
    repaired and checked at give the nearest checked pose instead of a fold (docs/animation.md, "Which poses,
    and why"). The hull is speech and the expression poses its rig holds, as its checks measured them (meta
    "checks", ``expressions_held``: :func:`rig_checked`, :func:`with_checks`); all of them when not measured. Its
    closure reach is the head's own (``closure_reach_iod``: mouth_open goes below 0 only until its lips meet),
    :data:`realtime_core.face.checks.CLOSURE_REACH` when not measured."""

    rig: AnyRig
    mesh: HeadMesh

    def __post_init__(self) -> None:
        if len(self.mesh.vertices) != len(self.rig.neutral):
            raise MeshError(
                f"{self.mesh.name}: mesh has {len(self.mesh.vertices)} vertices, its rig {len(self.rig.neutral)}"
            )
        if self.rig.bound is None:
            from realtime_core.face.checks import CLOSURE_REACH, checked_bound

            kept = self.rig.meta.get("checks")
            kept = kept if isinstance(kept, dict) else {}
            held = kept.get("expressions_held")
            poses = None if held is None else tuple(tuple(float(x) for x in p) for p in held)
            reach = kept.get("closure_reach_iod")
            reach = CLOSURE_REACH if reach is None else float(reach)
            object.__setattr__(self, "rig", replace(self.rig, bound=checked_bound(poses, reach)))

    @property
    def kind(self) -> str:
        """ "morph" (own targets) or "retarget" (Sec. 5 rig)."""
        return "morph" if isinstance(self.rig, MorphRig) else "retarget"

    def __iter__(self):
        return iter((self.rig, self.mesh))


def builtin_morph_head(cache: Path | None = None) -> Head:
    """The built-in head animated through its own 52 ARKit targets: its morph rig is read from the cache
    (``<cache>/builtin_morph_<key>.npz``, :func:`assets.heads.targets.morph_rig_key`), built and written there
    when missing."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.cache import atomic_savez, cache_dir, remove_stale_siblings
    from assets.heads.targets import (
        morph_rig,
        morph_rig_arrays,
        morph_rig_from_arrays,
        morph_rig_key,
        reference_lips,
    )
    from realtime_core.archive import npz_arrays

    b = load_builtin_head(cache)
    mesh = HeadMesh(
        vertices=b.mesh.vertices,
        triangles=b.mesh.triangles,
        uvs=b.mesh.uvs,
        texture=b.mesh.texture,
        colors=b.mesh.colors,
        name="builtin",
        targets=dict(b.targets),
        part=b.part.astype("int16"),
        part_names=("skin", "eyes", "upper teeth", "lower teeth", "tongue"),
    )
    key = morph_rig_key(mesh.vertices, mesh.triangles, b.targets, b.landmarks)
    path = (cache or cache_dir()) / f"builtin_morph_{key}.npz"
    rig = None
    if path.is_file():
        try:
            arrays = npz_arrays(path.read_bytes(), "built-in morph rig")
            rig = morph_rig_from_arrays(arrays, mesh.vertices, mesh.triangles)
        except (OSError, KeyError, ValueError):  # unreadable (ModelFormatError), another writer's: built again
            path.unlink(missing_ok=True)
    if rig is None:
        # The build solves the keyframe map's QP at the probe and checked poses (0.8 s of a `facecast say`
        # on 2 cores); its result depends only on what the key holds.
        lips = reference_lips(b.mesh.vertices, b.mesh.triangles, b.targets["jawOpen"], b.landmarks)
        rig = morph_rig("builtin", mesh.vertices, mesh.triangles, b.targets, b.targets, lips=lips)
        assert rig is not None  # the reference reproduces itself
        rig.meta["landmarks"] = {k: b.mesh.vertices[i].tolist() for k, i in b.landmarks.items()}
        rig = with_checks(rig, mesh)  # kept in the file's meta: measured once
        with contextlib.suppress(CannotWriteError):  # a read-only cache costs time, not the rig
            atomic_savez(path, **morph_rig_arrays(rig))
            remove_stale_siblings(path, MORPH_CACHE_FAMILY)
    return Head(rig, mesh)


def resolve_head(
    spec: str | Path = "builtin",
    *,
    landmarks: str | Path | Mapping[str, object] | None = None,
    mode: HeadMode = "auto",
    target_map: str | Path | None = None,
    config: RigConfig | None = None,
    cache: Path | None = None,
    landmark_finder: LandmarkFinder | None = None,
    parts: tuple[str | Path, ...] = (),
    progress: Callable[[str], None] | None = None,
) -> Head:
    """The head named by ``spec`` ('builtin', a rig .npz or a mesh file), see the module docstring.
    parts: further mesh files of the same head (separate eyes, teeth), appended to a mesh file's head.
    progress: told a line before each rig made for a mesh not in the rig cache (:func:`rig_checked`).

    mode: "auto" (own targets when enough, else retarget), "morph" (own targets or an error),
    "retarget" (always a Sec. 5 rig). target_map: a user mapping JSON for morph-target names.
    Raises MeshError / LandmarkError / RigFileError naming the file and what to do."""
    config = config or RigConfig()
    if mode not in HEAD_MODES:
        raise ValueError(f"mode must be one of {HEAD_MODES}, got {mode!r}")
    if parts and (str(spec) == "builtin" or Path(spec).suffix.lower() not in MESH_SUFFIXES):
        raise MeshError(
            f"{spec}: --head-part adds meshes to a head mesh file ({', '.join(MESH_SUFFIXES)}), not to this head"
        )
    if target_map is not None and (
        mode == "retarget" or str(spec) == "builtin" or Path(spec).suffix.lower() not in MESH_SUFFIXES
    ):
        # It was read only on the way to a mesh file's own targets: anywhere else a typo in it went unnoticed.
        raise MeshError(
            f"{target_map}: --target-map names a mesh file's own morph targets; {spec} "
            + ("is retargeted" if mode == "retarget" else "is not a mesh file")
            + " (give it with --head MESH.glb/.vrm and --head-mode auto or morph)"
        )
    if str(spec) == "builtin":
        if mode == "retarget" or landmarks is not None:
            from assets.heads.rigfile import builtin_rig

            if landmarks is None:
                return Head(*builtin_rig(cache))
            return _rig_mesh(builtin_morph_head(cache).mesh, landmarks, config, None, cache=cache, progress=progress)
        return builtin_morph_head(cache)
    p = Path(spec)
    if p.suffix.lower() == ".wfm":  # Candide-3: a face model with its own animation units
        from assets.heads.cavity import with_mouth_cavity
        from assets.heads.wfm import candide_head

        if mode == "retarget":
            raise MeshError(f"{p}: a Candide-3 model is driven by its own animation units; use --head-mode auto")
        if not p.is_file():
            raise MeshError(f"{p}: Candide-3 file {not_a_file(p)}")
        # A face mask: its open mouth shows a dark cavity. Checked (34 ms) so that it drives within the poses it
        # holds and its own closure reach: its lips touch at rest, and the shared reach crossed them.
        masked = with_mouth_cavity(candide_head(p))
        return Head(with_checks(masked.rig, masked.mesh), masked.mesh)
    if p.suffix.lower() == ".npz":
        from assets.heads.rigfile import load_rig

        return Head(*load_rig(p))
    if p.suffix.lower() not in MESH_SUFFIXES:
        if not p.exists():
            raise MeshError(
                f"{p}: head not found (give 'builtin', a rig .npz, a Candide-3 .wfm or a mesh "
                f"{', '.join(MESH_SUFFIXES)})"
            )
        raise MeshError(
            f"{p}: unsupported head file {p.suffix!r}; give 'builtin', a rig .npz, a Candide-3 .wfm or a mesh "
            f"({', '.join(MESH_SUFFIXES)})"
        )
    from assets.heads.mesh import load_mesh

    mesh = load_mesh(p, cache=cache, parts=parts)
    if mode == "auto" and set(VISUAL_PARAMS) <= set(mesh.targets or {}):
        # facecast's own glb of a retargeted head (assets.heads.glb.head_glb): its lips cut open and a cavity added in
        # the mesh, which a rig made again reads as a new head's: Lee Perry-Smith's tore (a jagged dark slit at rest,
        # 110 s of rigging), the built-in head's crumpled its lower lip. Its own targets are not ARKit's, so "auto"
        # rigged it without a word.
        raise MeshError(
            f"{p}: a glb facecast exported from a retargeted head (its morph targets are the mouth parameters "
            f"{', '.join(VISUAL_PARAMS)}), its lips already cut open and a mouth cavity added: rigged again they "
            "tear; give the head it was exported from, or --head-mode retarget to rig this file all the same"
        )
    if mode != "retarget":
        head = morph_head(
            mesh, target_map=target_map, cache=cache, require_enough=mode == "auto", landmark_finder=landmark_finder
        )
        if head is not None:
            return head
        if mode == "morph":
            n = len(mesh.targets or {})
            raise MeshError(
                f"{p}: {n} morph targets, none recognised as mouth shapes (ARKit, OVR visemes, VRM); "
                "give a mapping with --target-map or use --head-mode retarget"
            )
    return _rig_mesh(mesh, landmarks, config, landmark_finder, cache=cache, progress=progress)


def morph_head(
    mesh: HeadMesh,
    *,
    target_map: str | Path | None = None,
    cache: Path | None = None,
    require_enough: bool = True,
    landmark_finder: LandmarkFinder | None = None,
) -> Head | None:
    """The mesh driven by its own targets, or None (no targets / not enough mouth targets).
    landmark_finder: where the mouth is when the file does not say and its dark inside needs it
    (:func:`assets.heads.cavity.with_mouth_cavity`).

    What is made here (the fit, the mouth cavity and shading, the checks: 2-3 s on 2 cores for the built-in head's
    size) is kept in ``<cache>/morph_heads/<key>.npz`` (:func:`morph_head_path`) and read from there by the next
    load; a file that cannot be read back is made again and rewritten. The head made now is the one read back from
    the arrays written, so a cold and a warm load give the same head to the bit."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.cache import atomic_savez, remove_stale_siblings
    from assets.heads.targets import read_target_map

    if not mesh.targets:
        return None
    user = read_target_map(target_map) if target_map is not None else None
    b = load_builtin_head(cache)
    generation = morph_head_generation(b)
    path = morph_head_path(mesh, user, landmark_finder, generation, cache=cache)
    head = _cached_morph_head(path, mesh, generation)
    if head is None:
        made = _made_morph_head(mesh, b, user, require_enough, landmark_finder, cache)
        if made is None:
            return None
        arrays = morph_head_arrays(made, mesh, generation)
        head = morph_head_from_arrays(arrays, mesh, generation)
        with contextlib.suppress(CannotWriteError):  # a read-only cache costs time, not the head
            atomic_savez(path, **arrays)
            remove_stale_siblings(
                path, MORPH_HEAD_CACHE_FAMILY, stale=lambda p: _morph_head_file_generation(p) != generation
            )
    if require_enough and not head.rig.meta.get("enough_mouth_targets"):
        return None  # kept by a load that did not require them (--head-mode morph): not enough for "auto"
    return head


def _made_morph_head(
    mesh: HeadMesh,
    b,
    user: Mapping[str, Mapping[str, float]] | None,
    require_enough: bool,
    landmark_finder: LandmarkFinder | None,
    cache: Path | None,
) -> Head | None:
    """:func:`morph_head` computed: the fit against the built-in head ``b`` (a BuiltinHead), the mouth cavity and
    shading, the checks; None when the mesh has too few mouth targets."""
    from assets.heads.targets import morph_rig, reference_lips

    rig = morph_rig(
        mesh.name,
        mesh.vertices,
        mesh.triangles,
        mesh.targets or {},
        b.targets,
        user_map=user,
        require_enough=require_enough,
        lips=reference_lips(b.mesh.vertices, b.mesh.triangles, b.targets["jawOpen"], b.landmarks),
    )
    if rig is None:
        return None
    from assets.heads.cavity import with_mouth_cavity

    finder = None if landmark_finder is None else cached_finder(landmark_finder, cache)
    # The checks (and the bound they decide) once the cavity has placed its landmarks and lips modelled apart rest
    # where they meet; unchanged without landmarks.
    shaded = with_mouth_cavity(Head(rig, mesh), landmark_finder=finder)
    rested = closing_rest(shaded.rig, shaded.mesh, gap=reference_rest_gap(b), landmark_finder=finder)
    return Head(with_checks(rested, shaded.mesh, landmark_finder=finder), shaded.mesh)


REST_JAW_MIN = -0.5
"""The lowest jaw-target weight :func:`closing_rest` rests a head at: half a stroke of the jaw closing past the head as
modelled. Its target is extrapolated there, linearly; a mouth modelled further open than that is left as modelled (the
rig checks then warn that its lips stay apart at closure)."""
REST_UP_TILT_DEG = 10.3
"""Degrees the face frame's up axis is known to: the built-in head's automatic landmarks (MediaPipe's eye corners on
the skin) tilt it 10.3 degrees from its shipped ones (eye points deeper in the head). Its lower inner lip lies 0.022 IOD
behind the upper, so the one mesh read 0.0070 IOD apart in one frame and 0.0111 in the other, over
:data:`assets.heads.rigging.REST_GAP_MAX`: its own targets in a glb rested at jawOpen -0.007. :func:`closing_rest` takes
lips within the limit along any up axis this close to the frame's as not modelled apart."""
REST_JAW_OPENS = 0.1
"""IOD of inner-lip opening per unit weight below which a head's jaw target is not taken to close its lips (a jaw
target that hardly parts them would need a weight far past the modelled head's to close them)."""


def reference_rest_gap(b) -> float:
    """IOD: how far apart the built-in head ``b`` (a BuiltinHead, the reference face whose motion own-target heads
    are fitted to) models its inner lips, along its face's up axis (0.007: within the closure limit)."""
    import numpy as np

    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face import face_frame, inner_lip_gap

    v = np.asarray(b.mesh.vertices, dtype=np.float64)
    lm = mouth_landmarks(dict(b.landmarks))
    return inner_lip_gap(v, lm.upper_inner, lm.lower_inner, face_frame(v, lm))


def closing_rest(
    rig: MorphRig, mesh: HeadMesh, *, gap: float, landmark_finder: LandmarkFinder | None = None
) -> MorphRig:
    """``rig`` (a head's own targets, on ``mesh``), resting with its lips together when they are modelled apart.

    The mouth parameters' zero is lips touching, and the model's closures (/m b p/, silence) give mouth_open 0; a head
    whose own targets are fitted from its neutral keeps its lips as far apart as modelled there (a head modelled
    with the jaw 0.05 of jawOpen open: 0.033 IOD apart at every /m/, 0.0135 even at its closure pose, which its other
    targets cannot close). When its inner-lip landmarks lie more than :data:`assets.heads.rigging.REST_GAP_MAX` apart
    along the face's up axis, and along every axis within :data:`REST_UP_TILT_DEG` of it (the frame's uncertainty), and
    it has a jaw target (the one mapped to ARKit ``jawOpen`` and nothing else) that opens them at least
    :data:`REST_JAW_OPENS` IOD per unit, the rig rests at that target's weight that brings them ``gap`` IOD apart
    (:attr:`realtime_core.face.keyframes.MorphRig.rest`, below 0; the targets are linear, so exact at the landmarks),
    down to :data:`REST_JAW_MIN`. ``gap``: the reference face's own
    (:func:`reference_rest_gap`), where the motions the fit reproduces start: closed to 0, a head modelled 0.05 of
    jawOpen apart crossed its lips by 0.0103 IOD at an upper-lip raise of 0.054 (limit 0.005), the reference's lips
    rising into each other from 0.007 apart; at 0.007, 0.0033 (docs/heads.md, "Lips modelled apart"). Retargeted
    heads rest at their closure through their field (:func:`realtime_core.face.rig.with_rest_pose`). Recorded as meta
    "rest_weights" (target -> weight). Else (no landmarks, lips within the limit, no such jaw target, a gap past its
    reach) ``rig`` unchanged."""
    import numpy as np

    from assets.heads.rigging import REST_GAP_MAX
    from realtime_core.errors import FacecastError
    from realtime_core.face import face_frame, inner_lip_gap

    if rig.rest is not None:
        return rig
    try:
        landmarks, _ = head_check_inputs(Head(rig, mesh), landmark_finder=landmark_finder)
    except FacecastError:
        return rig
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    fr = face_frame(v0, landmarks)
    ui, li = landmarks.upper_inner, landmarks.lower_inner
    apart = inner_lip_gap(v0, ui, li, fr)
    # The smallest gap along an up axis tilted back or forward by the frame's uncertainty (about the eye line): lips
    # within the limit there are the reference's own, read in another frame (a copy of the built-in head: 0.0111 IOD).
    tilt = np.radians(REST_UP_TILT_DEG)
    lips = (v0[ui] - v0[li]) / fr.iod
    least = min(apart, *(float(lips @ (np.cos(tilt) * fr.axes[1] + s * np.sin(tilt) * fr.axes[2])) for s in (-1, 1)))
    # The jaw: a target that is ARKit's jawOpen alone (not a viseme or vowel holding some of it: run backwards, an
    # "aa" would not close a jaw but unround and unspread the lips too).
    mapped = rig.meta.get("targets") or {}
    jaw = [k for k, name in enumerate(rig.names) if set(mapped.get(name) or {}) == {"jawOpen"}]
    if least <= max(REST_GAP_MAX, gap) or not jaw:
        return rig
    k = jaw[0]
    d = np.zeros((len(v0), 3))
    d[rig.moving] = rig.targets[k]
    opens = inner_lip_gap(d, ui, li, fr)  # per unit of the jaw's weight
    if opens < REST_JAW_OPENS or -(apart - gap) / opens < REST_JAW_MIN:
        return rig
    rest = np.zeros(len(rig.names), dtype=np.float32)
    rest[k] = -(apart - gap) / opens
    meta = {**rig.meta, "rest_weights": {rig.names[k]: float(rest[k])}}
    return replace(rig, rest=rest, meta=meta)


def morph_head_generation(b) -> str:
    """Hex digest of what every cached own-target head depends on besides its own mesh: the built-in head ``b`` (a
    BuiltinHead) as the fit's reference, with the fit's constants and versions
    (:func:`assets.heads.targets.morph_rig_key`), the checks' poses and limits, :data:`MORPH_HEAD_VERSION`."""
    import hashlib

    import numpy as np

    from assets.heads.targets import morph_rig_key
    from realtime_core.face.checks import CHECK_POSES, CLOSURE_REACH, RigCheckLimits

    h = hashlib.sha256(f"{MORPH_HEAD_FORMAT} {MORPH_HEAD_VERSION} {RigCheckLimits()!r} {CLOSURE_REACH!r}".encode())
    h.update(morph_rig_key(b.mesh.vertices, b.mesh.triangles, b.targets, b.landmarks).encode())
    h.update(np.asarray(CHECK_POSES, dtype=np.float64).tobytes())
    return h.hexdigest()[:32]


def morph_head_path(
    mesh: HeadMesh,
    user: Mapping[str, Mapping[str, float]] | None,
    finder: LandmarkFinder | None,
    generation: str,
    *,
    cache: Path | None = None,
) -> Path:
    """Where :func:`morph_head` keeps ``mesh`` driven by its own targets: ``<cache>/morph_heads/<key>.npz``, the key
    a digest of the ``generation`` (:func:`morph_head_generation`), the mesh as loaded (its content, not its path:
    :func:`_hash_mesh`), its targets in file order (the first of two spellings of one target drives it), the user's
    target map as read (its order decides the driven targets' order) and which landmark finder would place the
    mouth."""
    import hashlib
    import json

    import numpy as np

    from assets.heads.cache import cache_dir

    h = hashlib.sha256(f"morph head {generation}".encode())
    _hash_mesh(h, mesh, name=False)
    for name, d in (mesh.targets or {}).items():
        a = np.ascontiguousarray(d)
        h.update(f" {name!r} {a.dtype} {a.shape}".encode())
        h.update(a.tobytes())
    h.update(b"-" if user is None else json.dumps(user).encode())
    h.update(f" finder {'-' if finder is None else getattr(finder, '__qualname__', type(finder).__name__)}".encode())
    return (cache or cache_dir()) / "morph_heads" / f"{h.hexdigest()[:32]}.npz"


def morph_head_arrays(head: Head, loaded: HeadMesh, generation: str) -> dict[str, Any]:
    """A head :func:`morph_head` made from ``loaded`` as plain arrays for an ``.npz`` (no pickle): its rig
    (:func:`assets.heads.targets.morph_rig_arrays`, the checks in its meta) and its mesh as the mouth cavity and
    shading left it, but for what :func:`morph_head_from_arrays` takes from ``loaded`` (the targets, a texture the
    cavity did not change); "head_meta" (JSON) names the format, the ``generation`` and the part names."""
    import json

    import numpy as np

    from assets.heads.targets import morph_rig_arrays

    m, rig = head.mesh, head.rig
    if not isinstance(rig, MorphRig):
        raise TypeError(f"{m.name}: a head driven by its own targets has a MorphRig, not {type(rig).__name__}")
    texture = "none" if m.texture is None else "loaded" if m.texture == loaded.texture else "stored"
    info = {
        "format": MORPH_HEAD_FORMAT,
        "version": MORPH_HEAD_VERSION,
        "generation": generation,
        "part_names": list(m.part_names),
        "texture": texture,
    }
    arrays: dict[str, Any] = {
        **morph_rig_arrays(rig),
        "head_meta": np.array(json.dumps(info)),
        "mesh_vertices": np.asarray(m.vertices),
        "mesh_triangles": np.asarray(m.triangles),
    }
    for key, a in (("mesh_uvs", m.uvs), ("mesh_colors", m.colors), ("mesh_part", m.part)):
        if a is not None:
            arrays[key] = np.asarray(a)
    if texture == "stored":  # the cavity's dark strip added to a texture without a dark block
        arrays["mesh_texture"] = np.frombuffer(m.texture or b"", dtype=np.uint8)
    return arrays


def morph_head_from_arrays(arrays: Mapping[str, Any], loaded: HeadMesh, generation: str) -> Head:
    """The head :func:`morph_head_arrays` stored for ``loaded`` (named as ``loaded`` is now: the cache is keyed by
    content). Raises KeyError / ValueError / TypeError / FacecastError when the arrays are not such a head's, of
    another ``generation`` or for another mesh."""
    import json

    import numpy as np

    from assets.heads.cavity import target_with_cavity
    from assets.heads.targets import morph_rig_from_arrays

    info = json.loads(str(arrays["head_meta"]))
    if (info.get("format"), info.get("version"), info.get("generation")) != (
        MORPH_HEAD_FORMAT,
        MORPH_HEAD_VERSION,
        generation,
    ):
        raise ValueError(f"another kind or generation of file: {info.get('format')} {info.get('version')}")
    v = np.asarray(arrays["mesh_vertices"])
    t = np.asarray(arrays["mesh_triangles"])
    n0, n = len(loaded.vertices), len(v)
    if v.ndim != 2 or v.shape[1] != 3 or n < n0 or not np.array_equal(v[:n0], loaded.vertices):
        raise ValueError(f"vertices {v.shape} are not the mesh's {len(loaded.vertices)}")
    if t.ndim != 2 or t.shape[1] != 3 or (t.size and not 0 <= int(t.min()) <= int(t.max()) < n):
        raise ValueError(f"triangles {t.shape} do not index {n} vertices")
    rig = morph_rig_from_arrays(arrays, v, t)
    if len(rig.moving) and not 0 <= int(rig.moving.min()) <= int(rig.moving.max()) < n:
        raise ValueError(f"moving vertices do not index {n} vertices")
    targets = loaded.targets
    if targets and n > n0:  # the mouth cavity's vertices (with_mouth_cavity): as the rig moves them (its floor)
        targets = {k: target_with_cavity(np.asarray(d), rig, k, n0) for k, d in targets.items()}
    kind = info["texture"]
    if kind not in ("none", "loaded", "stored"):
        raise ValueError(f"texture {kind!r}")
    texture = loaded.texture if kind == "loaded" else None
    if kind == "stored":
        texture = np.asarray(arrays["mesh_texture"], dtype=np.uint8).tobytes()
    mesh = HeadMesh(
        vertices=v,
        triangles=t,
        uvs=arrays.get("mesh_uvs"),
        texture=texture,
        colors=arrays.get("mesh_colors"),
        name=loaded.name,
        targets=targets,
        part=arrays.get("mesh_part"),
        part_names=tuple(str(x) for x in info["part_names"]),
    )
    return Head(replace(rig, meta={**rig.meta, "head": loaded.name}), mesh)


def _cached_morph_head(path: Path, loaded: HeadMesh, generation: str) -> Head | None:
    """The head :func:`morph_head` kept at ``path`` for ``loaded``, or None: none there, or unreadable (removed, to be
    made again and rewritten: a corrupt file, another writer's, a generation the key did not tell apart)."""
    from realtime_core.archive import npz_arrays
    from realtime_core.errors import FacecastError

    if not path.is_file():
        return None
    try:
        return morph_head_from_arrays(npz_arrays(path.read_bytes(), "morph head"), loaded, generation)
    except (OSError, KeyError, ValueError, TypeError, IndexError, FacecastError):
        path.unlink(missing_ok=True)
        return None


def _morph_head_file_generation(path: Path) -> str | None:
    """The generation (:func:`morph_head_generation`) a morph-head cache file was written at, reading only its
    "head_meta"; None if it is not a readable one."""
    import json

    import numpy as np

    try:
        with np.load(path, allow_pickle=False) as z:
            generation = json.loads(str(z["head_meta"]))["generation"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return generation if isinstance(generation, str) else None


R = TypeVar("R", Rig, MorphRig)


def with_checks(rig: R, mesh: HeadMesh, *, landmark_finder: LandmarkFinder | None = None) -> R:
    """``rig`` (of ``mesh``) with its checks (:func:`head_checks`) kept in its meta "checks" and no bound, so that a
    :class:`Head` drives it within the poses it holds, when its landmarks are known (its meta, else
    ``landmark_finder(mesh)``, e.g. :func:`cached_finder`'s) and it records no checks yet; else ``rig`` as it is.
    For rigs :func:`rig_checked` does not make (own targets, the built-in head's): the full-body avatar's targets
    fold at some expression poses, and the built-in head's exported with other target names at a closed-lip smile
    (issue 12)."""
    from realtime_core.errors import FacecastError

    if isinstance(rig.meta.get("checks"), dict) or not (rig.meta.get("landmarks") or landmark_finder):
        return rig
    try:
        report = head_checks(Head(rig, mesh), landmark_finder=landmark_finder)
    except FacecastError:  # no landmarks found, or none the checks can use: bound by every checked pose, as before
        return rig
    return replace(rig, meta={**rig.meta, "checks": report.as_dict()}, bound=None)


def _rig_mesh(
    mesh: HeadMesh,
    landmarks: str | Path | Mapping[str, object] | None,
    config: RigConfig,
    finder: LandmarkFinder | None,
    *,
    cache: Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> Head:
    """Rig ``mesh``, or read the rig cached for the same mesh content, landmarks, configuration and rig
    algorithm (``<cache>/rigs/``): rigging a scanned head takes minutes, and every command taking
    ``--head MESH`` would otherwise pay it again."""
    from assets.heads.rigfile import load_rig

    path = rig_cache_path(mesh, landmarks, config, finder, cache=cache)
    if path.is_file():
        try:
            rig, kept = load_rig(path)
            return Head(rig, _named(kept, mesh.name))
        except RigFileError:
            path.unlink(missing_ok=True)  # unreadable (an older writer): rig again below
    spec, source = head_landmarks(mesh, landmarks, finder)
    rig, rigged, _ = rig_checked(mesh, spec, landmark_source=source, config=config, progress=progress)
    keep_rig(rig, rigged, path)
    return Head(rig, rigged)


def rig_cache_path(
    mesh: HeadMesh,
    landmarks: str | Path | Mapping[str, object] | None,
    config: RigConfig,
    finder: LandmarkFinder | None,
    *,
    cache: Path | None = None,
) -> Path:
    """Where the rig of ``mesh`` made from ``landmarks`` (as given: a file, a mapping, or None for the shipped
    file or ``finder``) and ``config`` is cached: ``<cache>/rigs/<key>.npz`` (:func:`_rig_key`). ``facecast rig``
    writes there too, so that ``--head MESH`` finds the rig it made."""
    from assets.heads.cache import cache_dir

    return (cache or cache_dir()) / "rigs" / f"{_rig_key(mesh, landmarks, config, finder)}.npz"


def _named(mesh: HeadMesh, name: str) -> HeadMesh:
    """A cached rig's mesh under the name (path) the mesh was given as now: the cache is keyed by content, and
    errors and pictures should name the file the user typed, not the one an earlier command was given."""
    from dataclasses import replace

    return mesh if mesh.name == name else replace(mesh, name=name)


def cached_rig(path: Path, name: str | None = None) -> tuple[Rig, HeadMesh, RigReport] | None:
    """The rig kept at ``path`` (:func:`rig_cache_path`) with the checks measured when it was made (its meta
    "checks", :func:`rig_checked`), its mesh named ``name`` when given (:func:`_named`), or None: none there,
    unreadable, or without its checks (an older writer)."""
    from assets.heads.rigfile import load_rig
    from realtime_core.face.checks import RigReport

    if not path.is_file():
        return None
    try:
        rig, mesh = load_rig(path)
        kept = rig.meta.get("checks")
        fields: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in dict(kept or {}).items()}
        report = RigReport(**fields)
    except (RigFileError, TypeError, ValueError):  # unreadable, or checks missing or of another version
        return None
    return rig, mesh if name is None else _named(mesh, name), report


def keep_rig(rig: Rig, mesh: HeadMesh, path: Path) -> None:
    """Write a rig into the rig cache (``path`` from :func:`rig_cache_path`), atomically, and remove the stale
    rigs there; a read-only cache costs the next command time, not the rig, so it is skipped silently."""
    from assets.heads.rigfile import save_rig

    with contextlib.suppress(CannotWriteError):
        save_rig(rig, mesh, path)
        remove_stale_rigs(path)


def remove_stale_rigs(written: Path) -> list[Path]:
    """After ``written`` (a rig in ``<cache>/rigs/``) was saved: remove the rigs there that an older (or
    another) rig algorithm built and that were written over a day ago (each algorithm change leaves one
    file per head, 7 MB or more). A current algorithm's rig (another head's) is kept whatever its age;
    so is everything not named like a rig key (assets.heads.cache.remove_stale_siblings)."""
    from assets.heads.cache import remove_stale_siblings
    from assets.heads.rigfile import RIG_CACHE_FAMILY, rig_algorithm
    from realtime_core.face.rig import RIG_ALGORITHM

    return remove_stale_siblings(written, RIG_CACHE_FAMILY, stale=lambda p: rig_algorithm(p) != RIG_ALGORITHM)


def _rig_key(
    mesh: HeadMesh,
    landmarks: str | Path | Mapping[str, object] | None,
    config: RigConfig,
    finder: LandmarkFinder | None,
) -> str:
    """Hex digest of everything a rig is made from: the mesh as loaded (its content, not the path it was given as:
    ``rig head.glb`` and ``--head /abs/head.glb`` share one rig; a cached rig is handed out under the name given
    now, :func:`_named`), the landmarks as given (a file's bytes, a mapping's JSON; without them the
    shipped file's bytes, or which finder would place them), the rig configuration and the rig
    algorithm."""
    import hashlib
    import json

    from assets.heads.rigfile import VERSION
    from realtime_core.face.rig import RIG_ALGORITHM

    h = hashlib.sha256(f"rig {VERSION} {RIG_ALGORITHM} {config!r}".encode())
    _hash_mesh(h, mesh, name=False)
    if isinstance(landmarks, Mapping):
        h.update(json.dumps(landmarks, sort_keys=True, default=str).encode())
    else:
        from assets.heads.landmarks import shipped_landmarks

        given = Path(landmarks) if landmarks is not None else shipped_landmarks(mesh.name)
        if given is not None:
            try:
                h.update(given.read_bytes())
            except OSError:  # unreadable: head_landmarks names the file when it reads it
                h.update(str(given).encode())
        else:
            h.update(f"finder {getattr(finder, '__qualname__', type(finder).__name__)}".encode())
    return h.hexdigest()[:32]


def _hash_mesh(h, mesh: HeadMesh, *, name: bool = True) -> None:
    """Feed ``h`` (a hashlib object) the mesh as loaded: its name (unless ``name`` is False), geometry, colours,
    texture and parts (what a rig or a render of it is made from; its morph targets are not drawn at rest)."""
    import json

    import numpy as np

    if name:
        h.update(f" {mesh.name}".encode())
    for a in (mesh.vertices, mesh.triangles, mesh.uvs, mesh.colors, mesh.part):
        h.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
    h.update(mesh.texture or b"-")
    h.update(json.dumps(list(mesh.part_names)).encode())


def cached_finder(finder: LandmarkFinder, cache: Path | None = None) -> LandmarkFinder:
    """``finder`` whose answer for a mesh is kept in ``<cache>/landmarks/`` (JSON, written atomically; with its
    ``alternatives``, :class:`assets.heads.landmarks.FoundLandmarks`) under a digest of the mesh as loaded, the
    finder's name, LANDMARK_CACHE_VERSION and ``RIG_ALGORITHM`` (the automatic landmarks change with
    it, as the rigs they make do): an untextured head driven by its own targets with no landmarks in its file
    (a full-body avatar) is located on every load to shade its mouth's inside
    (:func:`assets.heads.cavity.with_mouth_cavity`), and the finder (an offscreen render and MediaPipe) took
    most of that load. A finder that found no face (LandmarkError) is kept too, and raises again."""
    import hashlib
    import json

    import numpy as np

    from assets.files import atomic_write_bytes
    from assets.heads.cache import cache_dir, remove_stale_siblings
    from realtime_core.face.rig import RIG_ALGORITHM

    name = getattr(finder, "__qualname__", type(finder).__name__)

    def listed(points: Mapping[str, object]) -> dict[str, object]:
        return {k: np.asarray(p).tolist() for k, p in points.items()}

    def find(mesh: HeadMesh) -> Mapping[str, object]:
        h = hashlib.sha256(f"landmarks {LANDMARK_CACHE_VERSION} {name}".encode())
        _hash_mesh(h, mesh)
        path = (cache or cache_dir()) / "landmarks" / f"a{RIG_ALGORITHM}_{h.hexdigest()[:32]}.json"
        try:
            kept = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):  # none yet, or unreadable: found again below
            kept = None
        if isinstance(kept, dict) and "landmarks" in kept:
            if kept["landmarks"] is None:
                raise LandmarkError(str(kept.get("error", f"{mesh.name}: no face found")))
            return FoundLandmarks(dict(kept["landmarks"]), tuple(dict(a) for a in kept.get("alternatives", [])))
        try:
            found = finder(mesh)
            points: dict[str, object] | None = listed(found)
            others = [listed(a) for a in getattr(found, "alternatives", ())]
            doc: dict[str, object] = {"landmarks": points, "alternatives": others}
        except LandmarkError as exc:
            points, others, doc = None, [], {"landmarks": None, "error": str(exc)}
        with contextlib.suppress(CannotWriteError):  # a read-only cache costs time, not the landmarks
            atomic_write_bytes(path, json.dumps(doc).encode())
            remove_stale_siblings(
                path, LANDMARK_CACHE_FAMILY, stale=lambda p: not p.name.startswith(f"a{RIG_ALGORITHM}_")
            )
        if points is None:
            raise LandmarkError(str(doc["error"]))
        return FoundLandmarks(points, tuple(others))

    return find


def head_landmarks(
    mesh: HeadMesh, landmarks: str | Path | Mapping[str, object] | None, finder: LandmarkFinder | None = None
) -> tuple[Mapping[str, object] | None, str]:
    """The landmark spec for a mesh and where it came from: given (file or mapping), shipped for a
    known head, the built-in head's own, or found automatically (LandmarkError when that fails; a finder's
    :class:`FoundLandmarks` kept as it is, with its alternatives for :func:`rig_checked`)."""
    from assets.heads.landmarks import read_landmarks, shipped_landmarks

    if isinstance(landmarks, Mapping):
        return dict(landmarks), "landmarks"
    if landmarks is not None:
        return read_landmarks(landmarks), str(landmarks)
    if mesh.name == "builtin":
        return None, "builtin landmarks"
    shipped = shipped_landmarks(mesh.name)
    if shipped is not None:
        return read_landmarks(shipped), str(shipped)
    if finder is None:
        raise LandmarkError(f"{mesh.name}: no landmarks file given (--landmarks L.json) and none shipped for this head")
    found = finder(mesh)
    return (found if isinstance(found, FoundLandmarks) else dict(found)), "automatic landmarks"


TEETH_WORDS = ("teeth", "tooth", "gum", "dent")


def rig_checked(
    mesh: HeadMesh,
    spec: Mapping[str, object] | None,
    *,
    dense_proxy: bool = True,
    progress: Callable[[str], None] | None = None,
    limits: RigCheckLimits | None = None,
    **rig_options: Any,
) -> tuple[Rig, HeadMesh, RigReport]:
    """:func:`_rig_checked_once` (the tries, below) from ``spec``; when it was found automatically with alternatives
    (:class:`assets.heads.landmarks.FoundLandmarks`) and every try fails, the same tries from each alternative set in
    turn, the first rig that passes kept (meta "landmark_set": its number, 1 for the first alternative; meta
    "landmark_sets_failed": the failures of the sets tried before it), else the rig from ``spec`` as before. MediaPipe's
    points move by up to ~0.02 IOD between renders of one head (docs/animation.md, "Steadier automatic landmarks"), and
    whether a rig passes can hang on where they fall. A rig that passes from ``spec`` is made exactly as before."""
    alternatives = spec.alternatives if isinstance(spec, FoundLandmarks) else ()
    points = None if spec is None else dict(spec)
    options: dict[str, Any] = {"dense_proxy": dense_proxy, "progress": progress, "limits": limits, **rig_options}
    rig, rigged, report = _rig_checked_once(mesh, points, **options)
    if report.passed or not alternatives:
        return rig, rigged, report
    last = list(report.failures)
    failed: list[dict[str, object]] = [{"set": 0, "failures": last}]
    for n, other in enumerate(alternatives, start=1):
        if progress is not None:
            # The first alternative is the steady views' median, the others single views' (find_landmarks).
            before = "the automatic landmarks" if n == 1 else f"landmark set {n - 1}"
            progress(
                f"every rig from {before} fails its checks ({'; '.join(last)}); "
                f"rigging from another set of them ({n} of {len(alternatives)}, found on other views of the head)"
            )
        a_rig, a_rigged, a_report = _rig_checked_once(mesh, dict(other), **options)
        if a_report.passed:
            meta = {**a_rig.meta, "landmark_set": n, "landmark_sets_failed": failed}
            return replace(a_rig, meta=meta), a_rigged, a_report
        last = list(a_report.failures)
        failed.append({"set": n, "failures": last})
    return replace(rig, meta={**rig.meta, "landmark_sets_failed": failed}), rigged, report


def _rig_checked_once(
    mesh: HeadMesh,
    spec: Mapping[str, object] | None,
    *,
    dense_proxy: bool = True,
    progress: Callable[[str], None] | None = None,
    limits: RigCheckLimits | None = None,
    **rig_options: Any,
) -> tuple[Rig, HeadMesh, RigReport]:
    """:func:`assets.heads.rigging.rig_head` with ``rig_options``, checked (:func:`head_checks`): returns
    ``(rig, the mesh it animates, RigReport)``. Tried in this order, the first rig that passes kept (else
    the first one without clean lips): a closed-lip cut (1) with clean lips (``clean_lips=True``: fewer
    islands, no slit into the upper lip, smoothed seam rows; docs/animation.md, "Clean lips"), on a hollow
    head (2) also with the fold repair on the final mesh (``walls_in_repair=False``), then (3) without clean
    lips, as before, and on a hollow head (4) with the repair on the final mesh: the repair smoothing across
    the crease's hidden walls passes some rigs of Lee Perry-Smith, the repair on the final mesh others
    ("Any head, cleanly"). A knife-cut (coarse) mouth whose four rigs fail is then rigged the same four ways with
    the simple face's mouth corners at the given corner points (``corners_at_points=True``; docs/animation.md, "A
    coarse mouth's corners at their points"), the first that passes kept (else the plain one, as before). A knife-cut
    mouth whose cut was raised to the lips' meeting (meta "knife_raised") is first rigged the first four ways so, and
    when they fail all of the above with the cut through the inner-lip point (``knife_meeting=False``, every later rig
    too). A head with no cut is rigged once; a cut head up to four times (a knife-cut one eight, twelve when raised),
    only while its rigs fail. A head
    whose rigs all fail is rigged once more with the simple face's local gains capped (``gain_capped=True``;
    :data:`assets.heads.rigging.ADAPT_MAX_GAIN`), kept if it passes (each capped rig here is first made with its upper
    lip eased, ``ease_upper_lip=True``, and made as before only if that one fails: docs/animation.md, "The upper lip
    drawn to a peak"); if that fails too and its lower inner-lip
    point lies on the upper lip (:func:`assets.heads.rigging.lower_inner_on_lower_lip`), once more as the first try
    with that point on the lower lip's front (meta "lower_inner_moved"), kept if it passes; if that fails too (or was
    not tried) and its lips were cut though they only touch, apart in the mesh
    (:func:`assets.heads.rigging.lips_touch_apart`), once more not cut, rigged as apart with capped gains
    (``touching_apart=True``, meta "lips_touching_apart"), kept if it passes. Any of these rigs that fails only by
    the inside shown through the skin is first tried with that inside moved with the skin in front of it
    (:func:`_lined`; the anny thin old woman's mouth bag behind her cheeks), kept if that passes. When every rig
    fails and the lips read as joined only through the lower inner-lip point on the upper lip
    (:func:`assets.heads.rigging.lips_joined_by_misplaced_point`: a decimated head's few lip vertices), the rig
    returned is the one with that point on the lower lip's front, not the first one, cut along the upper lip.
    ``dense_proxy``: a head above :data:`assets.heads.dense.DENSE_TRIANGLES` is rigged through a decimated copy that
    keeps the mouth's own faces (:mod:`assets.heads.dense`; the once-subdivided Lee Perry-Smith: PASS in 160-212 s, was
    FAIL in 11-18 minutes; docs/animation.md, "A dense scan through a decimated proxy"). False: rigged directly.
    ``limits``: the checks' limits every try is judged by (None: :class:`realtime_core.face.checks.RigCheckLimits`'
    defaults); a dense scan's decimated copy is not judged on the inside it shows (its coarser skin), the dense rig is.
    ``progress``: called with a line before each rig it makes (and why, when an earlier one failed): rigging a scan
    takes from seconds to minutes, and a user waiting should see which way it is trying.
    Meta "rig_attempts": the failures of the rigs tried before the one returned; meta "checks": the returned
    rig's RigReport (:meth:`RigReport.as_dict`), kept with it (its file, the rig cache) so that loading it does
    not measure it again (:func:`facecast.commands.headopts.warn_failing_checks` reads it)."""
    import math
    from dataclasses import replace

    import numpy as np

    from assets.heads.dense import CUT_DIP_WINDOW, DENSE_TRIANGLES, MOUTH_KEEP, proxy_mesh
    from assets.heads.mesh import check_mesh
    from assets.heads.rigging import (
        lips_joined_by_misplaced_point,
        lips_touch_apart,
        lower_inner_on_lower_lip,
        resolve_landmarks,
        rig_head,
    )
    from realtime_core.face.checks import RigCheckLimits

    def say(line: str) -> None:
        if progress is not None:
            progress(line)

    def checked(r: Rig, m: HeadMesh) -> tuple[Rig, HeadMesh, RigReport]:
        # A rig judged by ``limits``, lined where the inside only shows through the skin (_lined).
        return _lined(r, m, head_checks(Head(r, m), limits=limits), limits)

    def eased_first(options: dict[str, Any], why: list[str]) -> tuple[Rig, HeadMesh, RigReport]:
        # A capped rig with its upper lip eased (rig_head, ease_upper_lip: the correction drew it to a peak), else as
        # before: the eased anny old heavy man passes (peak at /a/ 0.042 -> 0.007 IOD), the eased child does not
        # (stretch 4.3 at its corners' short edges) and keeps its rig as it was.
        say(_trying({**options, "ease_upper_lip": True}, why))
        e_rig, e_rigged = rig_head(mesh, spec, **rig_options, **options, ease_upper_lip=True)
        e_rig, e_rigged, e_report = checked(e_rig, e_rigged)
        if e_report.passed:
            return e_rig, e_rigged, e_report
        attempts.append({**options, "ease_upper_lip": True, "failures": list(e_report.failures)})
        say(_trying(options, list(e_report.failures)))
        r, m = rig_head(mesh, spec, **rig_options, **options)
        return checked(r, m)

    # Bad input names itself before any progress line (one line on stderr for the user, then nothing).
    check_mesh(mesh)
    if spec is not None:
        resolve_landmarks(spec, mesh.vertices, str(rig_options.get("landmark_source", "landmarks")), mesh.triangles)
    harmonic = (rig_options.get("config") or RigConfig()).method == "harmonic"
    if dense_proxy and len(mesh.triangles) > DENSE_TRIANGLES and harmonic:
        # A dense scan: its decimated copy rigged and checked as any head, its field carried onto the dense mesh
        # (cut along its own lips), which is then checked itself (assets/heads/dense.py).
        source = str(rig_options.get("landmark_source", "landmarks"))
        points = resolve_landmarks(spec, mesh.vertices, source, mesh.triangles) if spec is not None else None
        mouth, keep = None, 0.0
        if points is not None:
            mouth = np.mean([points[k] for k in ("corner_left", "corner_right", "upper_lip", "lower_lip")], axis=0)
            keep = MOUTH_KEEP * float(np.linalg.norm(points["eye_outer_left"] - points["eye_outer_right"]))
        base = mesh
        if points is not None and mesh.part is not None:
            # Its layers (a beard shell) left out of the copy: the dense rig moves them with its skin (layers.py).
            from assets.heads.layers import without_layers
            from assets.heads.rigging import mouth_landmarks
            from realtime_core.face import face_frame

            near = {k: int(np.argmin(np.linalg.norm(mesh.vertices - p, axis=1))) for k, p in points.items()}
            base = without_layers(mesh, near["nose_tip"], face_frame(mesh.vertices, mouth_landmarks(near)).iod)
        proxy = proxy_mesh(base, mouth=mouth, keep=keep)
        say(
            f"{len(mesh.triangles):,} triangles (over {DENSE_TRIANGLES:,}): rigging a "
            f"{len(proxy.triangles):,}-triangle copy that keeps the mouth's own faces, then carrying its rig over"
        )
        # The copy's own skin is not judged on the inside it shows: decimated outside the mouth, its cheeks lie
        # nearer the mouth's inside than the scan's (the once-subdivided Lee Perry-Smith's copy: the cheek lining
        # behind the right corner 0.062 IOD through the skin at (0, 0, 0.465, 0), so every try failed and all five
        # ran, 271 s for 150; the carried dense rig 0.0000). The dense rig is checked in full below.
        # Its cut is levelled over CUT_DIP_WINDOW (the scan's short lip edges spread the cut's V over several: a pink
        # wedge of lower lip hung from the upper lip's middle at small openings), and its fold repair widens a stubborn
        # fold's patch ring after ring (widen_repair): levelled, the plain repair kept 2 chin flips through all its
        # rounds; widened it settles in 52 (docs/animation.md, "The dense head's wedge levelled").
        p_rig, p_rigged, _ = rig_checked(
            proxy,
            None if points is None else {k: p.tolist() for k, p in points.items()},
            # The copy itself may hold more than DENSE_TRIANGLES when the scan's mouth alone is that dense (Lee
            # Perry-Smith subdivided twice: 58,116 kept of 64,112): it is rigged directly, never through a copy of
            # its own (whose decimated rest would be smaller than its target).
            dense_proxy=False,
            progress=progress,
            limits=replace(limits or RigCheckLimits(), max_inside_shown=math.inf),
            **rig_options,
            record_hidden=True,
            dip_window=CUT_DIP_WINDOW,
            widen_repair=True,
        )
        chosen: dict[str, Any] = {
            "clean_lips": bool(p_rig.meta.get("clean_lips")),
            "walls_in_repair": p_rig.meta.get("fold_repair_mesh") != "final",
            "corners_at_points": bool(p_rig.meta.get("simple_corners_at_points")),
            "gain_capped": bool(p_rig.meta.get("simple_gain_capped")),
            "touching_apart": bool(p_rig.meta.get("lips_touching_apart")),
            "ease_upper_lip": bool(p_rig.meta.get("upper_lip_eased")),
        }
        used = spec
        if p_rig.meta.get("lower_inner_moved") and spec is not None:
            # The proxy passed with its lower inner-lip point moved onto the lower lip (rig_checked's last try): the
            # dense head takes the same point (the proxy keeps the mouth's faces, so it lies on both surfaces).
            used = {**spec, "lower_inner": p_rig.meta["landmarks"]["lower_inner"]}
        say(f"carrying the copy's rig onto the {len(mesh.triangles):,}-triangle mesh and checking it")
        rig, rigged = rig_head(mesh, used, **rig_options, **chosen, proxy=(p_rig, p_rigged))
        rig, rigged, report = checked(rig, rigged)
        return replace(rig, meta={**rig.meta, "checks": report.as_dict()}), rigged, report

    tries: list[dict[str, Any]] = [
        {"clean_lips": True},
        {"clean_lips": True, "walls_in_repair": False},
        {},
        {"walls_in_repair": False},
    ]
    # A knife-cut (coarse) mouth whose rigs all fail: the same four with the simple face's mouth corners at the
    # given corner points, not their vertices (rig_head, corners_at_points; rigs that pass are left as they were).
    tries += [{**o, "corners_at_points": True} for o in tries]
    attempts: list[dict[str, object]] = []
    hollow = False  # known from the first rig: a cut whose crease's hidden walls were removed
    coarse = False  # known from the first rig: a knife-cut mouth
    plain: tuple[Rig, HeadMesh, RigReport] | None = None
    failed: list[str] = []  # the last rig's failures (progress lines say why another is made)
    # A knife cut raised to the lips' meeting (rig_head, knife_meeting; assets/heads/knife.py, lips_meeting): its first
    # four tries, and when they all fail every try as before, the knife through the inner-lip point as given (None in
    # the queue: from there on knife_meeting=False, the capped and later rigs too). A held-back decimation of Lee
    # Perry-Smith (the lead's check): its raised cut's lips parted by 0.26-0.41 of mouth_open at each of the four tries,
    # its upper side's cut vertices dropping with the jaw; through the point its first try passes, as on main.
    queue: list[dict[str, Any] | None] = list(tries)
    at = 0
    done = False
    while at < len(queue):
        options = queue[at]
        at += 1
        if options is None:
            rig_options = {**rig_options, "knife_meeting": False}
            say("the knife's cut raised to the lips' meeting fails its checks; cutting through the inner-lip point")
            continue
        if options.get("walls_in_repair") is False and not hollow:
            continue
        if options.get("corners_at_points") and not coarse:
            continue
        say(_trying(options, failed))
        rig, rigged = rig_head(mesh, spec, **rig_options, **options)
        rig, rigged, report = checked(rig, rigged)
        failed = list(report.failures)
        if not rig.meta.get("lip_seam_cut"):
            done = True
            break  # no cut: the other rigs would be this one
        hollow = bool(rig.meta.get("inner_lip_removed"))
        coarse = bool(rig.meta.get("contact_knife"))
        if report.passed:
            done = True
            break
        attempts.append({**options, "failures": list(report.failures)})
        if not options:
            plain = (rig, rigged, report)
        if at == 1 and rig.meta.get("knife_raised") and rig_options.get("knife_meeting", True):
            queue = [*tries[:4], None, *tries]
    crumple_limit = (limits or RigCheckLimits()).max_lip_crumple
    if done and report.passed and options is not None and (report.lip_crumple_deg or 0.0) > crumple_limit:
        # A rig that passes with a crumpled lip (the checks' lip crumple over its limit: the anny head as one mesh, a
        # zig-zag crease along its lower lip at the widest opening, its corners pulled down by the head-response
        # correction): the tries once more, in order, then the capped last try (eased, then not), with the
        # lip_corner_depress that mouth_open shows left uncorrected (rig_head, open_depress_left), the first that passes
        # and crumples less kept (docs/animation.md, "A crumpled lower lip"); else the rig is returned as it was, its
        # meta too. The anny head as one mesh (no cut) passes at the capped, eased try. Kept only if no figure of what a
        # close-up shows gets worse (_no_worse_seen): on james's scan the retry crumpled less but drew a longer V to
        # the chin (skin seen dark 5.8e-3 -> 10.5e-3), on the 3,810-triangle Lee Perry-Smith a slit at /m/.
        crumpled = f"lip crumple {report.lip_crumple_deg:.0f} degrees > {crumple_limit:.0f} (a warning)"
        ways = [
            o
            for o in tries
            if not ((o.get("walls_in_repair") is False and not hollow) or (o.get("corners_at_points") and not coarse))
        ]
        if not rig.meta.get("lip_seam_cut"):
            ways = ways[:1]  # no cut: the other tries would make this rig
        capped: dict[str, Any] = {"clean_lips": True, "gain_capped": True}
        ways += [{**capped, "ease_upper_lip": True}, capped]
        for o in ways:
            retry = {**o, "open_depress_left": True}
            say(f"the rig passes, but its {crumpled}; " + _trying(retry, []))
            u_rig, u_rigged = rig_head(mesh, spec, **rig_options, **retry)
            u_rig, u_rigged, u_report = checked(u_rig, u_rigged)
            if (
                u_report.passed
                and (u_report.lip_crumple_deg or 0.0) < (report.lip_crumple_deg or 0.0)
                and _no_worse_seen(u_report, report)
            ):
                attempts.append({**options, "failures": [crumpled]})
                rig, rigged, report = u_rig, u_rigged, u_report
                break
    # The rig from the lower inner-lip point moved onto the lower lip when the lips read as joined only through it, and
    # its attempt (kept by the last tries below).
    misread: tuple[Rig, HeadMesh, RigReport] | None = None
    misread_attempt: dict[str, object] = {}
    plain_failures: tuple[str, ...] | list[str] = []
    if not done:
        assert plain is not None  # the third try always runs
        rig, rigged, report = plain
    if not report.passed:
        # Last, for a head whose rigs all fail: the simple face's units carried with capped local gains (rig_head,
        # gain_capped): a chin placed far behind the mouth (a heavy double chin) read as a 4.4x stretch of the jaw
        # drop, which dragged the upper lip down into a V. Not the first try: on the MediaPipe face it folds.
        last: dict[str, Any] = {"clean_lips": True, "gain_capped": True}
        c_rig, c_rigged, c_report = eased_first(last, failed)
        moved = None if c_report.passed or spec is None else lower_inner_on_lower_lip(mesh, spec)
        if moved is not None:
            # Its lower inner-lip point on the upper lip (an upper lip dropped over the lower one): the lips read as
            # joined and were cut along a mouth the mesh has open. Once more, the point on the lower lip's front.
            # Its gains as the first try's (on the thin old woman, capped: stretch 3.24; not: 3.58).
            attempts.append({**last, "failures": list(c_report.failures)})
            last = {"clean_lips": True}
            say(_trying({**last, "lower_inner_moved": True}, list(c_report.failures)))
            c_rig, c_rigged = rig_head(mesh, moved, **rig_options, **last)
            c_rig, c_rigged, c_report = checked(c_rig, c_rigged)
            last["lower_inner_moved"] = True
            c_rig = replace(c_rig, meta={**c_rig.meta, "lower_inner_moved": True})
        if c_report.passed:
            attempts.append({"failures": list(report.failures)})
            rig, rigged, report = c_rig, c_rigged, c_report
        else:
            attempts.append({**last, "failures": list(c_report.failures)})
            # The lips read as joined only through the lower inner-lip point (moved: already found above).
            if moved is not None and spec is not None and lips_joined_by_misplaced_point(mesh, spec, moved=moved):
                misread, misread_attempt, plain_failures = (c_rig, c_rigged, c_report), attempts[-1], report.failures
            if rig.meta.get("lip_seam_cut") and spec is not None and lips_touch_apart(mesh, spec):
                # Lips that touch but are apart in the mesh (anny's child: an open-mouthed base mesh whose lips a
                # macro target brings together): cut as closed lips, the lower lip tore from its own inner wall. Once
                # more, not cut, rigged as apart (rig_head, touching_apart), with capped gains (the child's field read
                # -1.06 of lip_corner_depress per unit mouth_open, the old heavy man's fault: uncapped, stretch 4.09).
                apart: dict[str, Any] = {"gain_capped": True, "touching_apart": True}
                a_rig, a_rigged, a_report = eased_first(apart, list(c_report.failures))
                if a_report.passed:
                    rig, rigged, report = a_rig, a_rigged, a_report
                else:
                    attempts.append({**apart, "failures": list(a_report.failures)})
    if not report.passed and misread is not None:
        # Every rig failed and the lips read as joined only through the lower inner-lip point on the upper lip
        # (lips_joined_by_misplaced_point): the rigs from the point as given were cut along the upper lip (anny's old
        # heavy man at 3,000 triangles: its lower face torn at /a/, opening 0.16), so the failing rig returned is the
        # one from the point on the lower lip's front (there: whole lips, opening 0.56, 3 flips at the corners).
        rig, rigged, report = misread
        attempts = [a for a in attempts if a is not misread_attempt] + [{"failures": list(plain_failures)}]
    meta = {**rig.meta, "checks": report.as_dict()}
    if attempts:
        meta["rig_attempts"] = attempts
    return replace(rig, meta=meta), rigged, report


# The advisory figures of a RigReport that a close-up shows, and flips under expressions (lower is better; None:
# nothing measured, as 0).
_SEEN_FIGURES = (
    "lip_edge_notch_iod",
    "lip_backs_iod2",
    "skin_dark_iod2",
    "lip_tops_iod2",
    "bilabial_gap_iod",
    "inside_shown_iod",
    "lips_dark_iod2",
    "expression_flips",
)


def _no_worse_seen(new: RigReport, old: RigReport) -> bool:
    """Whether none of the figures of what a close-up shows (:data:`_SEEN_FIGURES`) is larger in ``new`` than in
    ``old``."""
    return all((getattr(new, k) or 0.0) <= (getattr(old, k) or 0.0) for k in _SEEN_FIGURES)


_WAYS = {
    "clean_lips": "clean lips",
    "walls_in_repair": "the fold repair on the final mesh",
    "corners_at_points": "the mouth corners at their points",
    "gain_capped": "capped gains",
    "lower_inner_moved": "the lower inner-lip point moved onto the lower lip",
    "touching_apart": "lips that only touch rigged as apart, not cut",
    "ease_upper_lip": "the upper lip eased",
    "open_depress_left": "the corners' depress read off mouth_open left uncorrected",
}


def _trying(options: Mapping[str, Any], failed: list[str]) -> str:
    """The progress line before a rig ``rig_checked`` makes: its way (``options``) and why (``failed``: the
    failures of the rig made before it; empty for the first)."""
    # walls_in_repair=False is the way named (the repair on the final mesh); the other options name theirs when set.
    on = {k: (v is False) if k == "walls_in_repair" else bool(v) for k, v in options.items()}
    ways = [w for k, w in _WAYS.items() if on.get(k)]
    line = "rigging" + (f" ({', '.join(ways)})" if ways else "")
    if failed:
        line = f"the last rig fails its checks ({'; '.join(failed)}); " + line
    return line


def _lined(
    rig: Rig, rigged: HeadMesh, report: RigReport, limits: RigCheckLimits | None = None
) -> tuple[Rig, HeadMesh, RigReport]:
    """A rig whose only failure is the inside shown through the skin (a mouth bag's wall through a thin cheek,
    :func:`realtime_core.face.checks.inside_shown`) with that inside moved with the skin in front of it
    (:func:`assets.heads.lining.with_lining_behind_skin`), if that passes; else the rig as it was (every other rig,
    to the bit). The lining's rows are a blend of rows the rig has, so no rig is made again (a few seconds); meta
    "inside_lined" says how many vertices were moved."""
    from assets.heads.lining import with_lining_behind_skin
    from realtime_core.face.checks import RigCheckLimits

    limit = (limits or RigCheckLimits()).max_inside_shown
    if report.passed or len(report.failures) != 1 or not (report.inside_shown_iod or 0.0) > limit:
        return rig, rigged, report
    landmarks, _ = head_check_inputs(Head(rig, rigged))
    lined = with_lining_behind_skin(rig, landmarks)
    if lined is None:
        return rig, rigged, report
    lined_report = head_checks(Head(lined, rigged), limits=limits)
    return (lined, rigged, lined_report) if lined_report.passed else (rig, rigged, report)


def head_checks(head: Head, *, limits=None, landmark_finder: LandmarkFinder | None = None, poses=None):
    """:func:`realtime_core.face.checks.check_rig` for a head, with :func:`head_check_inputs`; ``poses`` (None:
    the checks' :data:`EXTREME_POSES`; flips under expressions are reported at check_rig's default poses).
    Returns a RigReport."""
    import numpy as np

    from realtime_core.face.checks import EXTREME_POSES, RigCheckLimits, check_rig

    landmarks, inputs = head_check_inputs(head, landmark_finder=landmark_finder)
    layer = head.rig.meta.get("layer_vertices")  # a layer on the skin (assets/heads/layers.py): skin, not a cover
    return check_rig(
        head.rig,
        landmarks,
        **inputs,
        layer=None if not isinstance(layer, list) else np.asarray(layer, dtype=np.int64),
        limits=limits or RigCheckLimits(),
        poses=EXTREME_POSES if poses is None else poses,
        cavity_vertices=int(head.rig.meta.get("mouth_cavity", 0) or 0),
    )


def head_check_inputs(head: Head, *, landmark_finder: LandmarkFinder | None = None):
    """What the rig checks measure a head with: its mouth landmarks (from the rig's meta, nearest vertices; a
    morph head from a file without them: ``landmark_finder(mesh)``) and the keyword arguments ``lip_pairs``
    (the two sides of a cut lip seam, or the rig's contact columns), ``teeth`` (from the mesh's part names; a one-mesh
    head's teeth rows and tongue from the rig's meta ``inner_rigid_pieces``)
    and ``reference`` (the head as modelled) of :func:`realtime_core.face.checks.check_rig` and
    :func:`realtime_core.face.checks.pose_figures`, and ``joined_pairs`` (the seams between the head's meshes,
    :func:`assets.heads.parts.part_seam_pairs`; None: none) of check_rig."""
    import numpy as np
    from scipy.spatial import cKDTree

    from assets.heads.rigging import mouth_landmarks

    rig, mesh = head.rig, head.mesh
    v0 = np.asarray(rig.neutral, dtype=np.float64)
    pts = rig.meta.get("landmarks")
    if not pts and landmark_finder is not None:
        pts = dict(landmark_finder(mesh))
    if not pts:
        raise MeshError(f"{mesh.name}: the rig records no landmarks; the checks need them (give --landmarks)")
    idx = {k: int(np.argmin(np.linalg.norm(v0 - np.asarray(p), axis=1))) for k, p in pts.items()}
    pairs = None
    contact = getattr(rig, "contact", None)
    if contact is not None and len(contact):
        # The rig's own lip columns (a cut seam's two sides, else the inner contours): the pairs its
        # non-interpenetration constraint holds apart.
        pairs = np.asarray(contact, dtype=np.int64)
    cut = int(rig.meta.get("lip_seam_cut", 0) or 0)
    if cut:
        if pairs is None:
            n0 = len(v0) - cut - int(rig.meta.get("mouth_cavity", 0) or 0)
            d, j = cKDTree(v0[:n0]).query(v0[n0 : n0 + cut])
            ok = d <= 1e-9 * float(np.ptp(v0, axis=0).max())
            pairs = np.column_stack([j[ok], np.arange(n0, n0 + cut)[ok]])  # (upper original, lower copy)
        # The copy at the lower-inner landmark is the lower lip's.
        same = np.linalg.norm(v0[pairs[:, 1]] - v0[idx["lower_inner"]], axis=1) <= 1e-9 * float(
            np.ptp(v0, axis=0).max()
        )
        lower = pairs[(pairs[:, 0] == idx["lower_inner"]) & same & (pairs[:, 1] != idx["lower_inner"]), 1]
        if len(lower):
            idx["lower_inner"] = int(lower[0])
    if idx["upper_inner"] == idx["lower_inner"]:
        # Closed lips given as one point where the upper and lower inner lips are two coincident vertices (a
        # wireframe like Candide-3's): the one the mouth-open parameter lifts most is the upper lip's, the one
        # it drops most the lower's. Measured at one vertex, the lips' gap is 0 at every pose.
        tol = 1e-9 * float(np.ptp(v0, axis=0).max())
        twins = np.flatnonzero(np.linalg.norm(v0 - v0[idx["upper_inner"]], axis=1) <= tol)
        if len(twins) > 1:
            lm0 = mouth_landmarks(idx)
            from realtime_core.face import face_frame

            up = face_frame(v0, lm0).axes[1]
            rise = (np.asarray(rig.deformed(np.array([0.0, 0.0, 0.3, 0.0])))[twins] - v0[twins]) @ up
            idx["upper_inner"], idx["lower_inner"] = int(twins[np.argmax(rise)]), int(twins[np.argmin(rise)])
    teeth = None
    if mesh.part is not None and mesh.part_names:
        ids = [i for i, n in enumerate(mesh.part_names) if any(w in n.lower() for w in TEETH_WORDS)]
        if ids:
            teeth = np.flatnonzero(np.isin(mesh.part, ids))
    if teeth is None and rig.meta.get("inner_rigid_pieces"):
        # A one-mesh head's unnamed teeth rows and tongue, found and moved rigidly by the rig (rigid_inner_pieces).
        teeth = np.asarray(rig.meta["inner_rigid_pieces"], dtype=np.int64)
    joined = None
    if mesh.part is not None and len(mesh.part_names) > 1 and len(mesh.part) == len(v0):
        # The seams between the head's meshes (a separate jaw mesh): the cut's copies and the cavity part on purpose.
        from assets.heads.parts import part_seam_pairs

        cavity = int(rig.meta.get("mouth_cavity", 0) or 0)
        n0 = len(v0) - cut - cavity
        skip = np.r_[np.arange(n0, n0 + cut), np.arange(len(v0) - cavity, len(v0))]
        joined = part_seam_pairs(v0, mesh.part, int(mesh.part[idx["nose_tip"]]), mesh.part_names, skip=skip)
        joined = joined if len(joined) else None
    reference = None
    if rig.meta.get("rest_pose") is not None and isinstance(rig, Rig):
        from realtime_core.face.rig import modelled_rest

        reference = modelled_rest(rig)  # folds are measured from the head as modelled
    inputs = {"lip_pairs": pairs, "teeth": teeth, "reference": reference, "joined_pairs": joined}
    return mouth_landmarks(idx), inputs
