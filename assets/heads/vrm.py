"""VRM avatars (``.vrm``: a binary glTF as VRoid Studio, VRoid Hub, UniVRM and Ready Player Me's VRM option write it):
their mouth and emotion expressions as morph targets.

A VRM file is read by the glTF reader (:mod:`assets.heads.gltf`); this module reads what only VRM has. Its
expressions are not morph targets of their own: each *binds* targets by index with a weight, and the targets
may have any names (VRoid's ``Fcl_MTH_A``, "vrc.v_aa", Japanese names, "Key 12"), so name matching alone misses
them. Read:

- VRM 1.0: ``extensions.VRMC_vrm.expressions.preset.{aa, ih, ou, ee, oh}`` and ``{happy, angry, sad, surprised}``,
  each with ``morphTargetBinds: [{node, index, weight}]`` (node: a glTF node whose mesh holds the target; weight 0-1);
- VRM 0.x: ``extensions.VRM.blendShapeMaster.blendShapeGroups[]`` with ``presetName`` ``a i u e o`` and
  ``joy angry sorrow surprised``, ``binds: [{mesh, index, weight}]`` (mesh: a glTF mesh index, every node drawing it;
  weight 0-100).

Each vowel becomes one morph target ``vrm.aa``, ``vrm.ih``, ``vrm.ou``, ``vrm.ee``, ``vrm.oh`` (VRM 1.0's names
for both versions): the weighted sum of the targets it binds, over every primitive of the bound node or mesh, as
a VRM runtime sets them at the expression's weight 1. :func:`assets.heads.targets.match_targets` reads those
names as the VRM vowels. The four emotions become ``vrm.happy``, ``vrm.angry``, ``vrm.sad``, ``vrm.surprised`` (VRM
1.0's names for both versions), which facecast's smile, anger, sad and surprise drive (:data:`EMOTIONS`,
:func:`assets.heads.targets.face_targets`): a VRM user who asks for a smile expects the avatar's own happy face, and
an avatar's targets are rarely named as ARKit's. Speech drives no expression but the vowels; blink, look-at,
``relaxed`` / ``fun`` and the ``neutral`` preset are not read, nor an expression's ``overrideMouth`` (speech keeps
driving the mouth under an emotion) or ``isBinary``, and material colour / texture binds change no geometry.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from assets.errors import MeshError
from assets.heads.gltf import Primitive

VOWELS_1 = ("aa", "ih", "ou", "ee", "oh")
"""VRM 1.0's preset vowel expressions; also the names used for VRM 0.x's (:data:`VOWELS_0`)."""

VOWELS_0 = {"a": "aa", "i": "ih", "u": "ou", "e": "ee", "o": "oh"}
"""VRM 0.x's ``presetName`` of each vowel -> VRM 1.0's."""

EMOTIONS = {"smile": "happy", "anger": "angry", "sad": "sad", "surprise": "surprised"}
"""facecast's expression (:data:`realtime_core.expressions.EXPRESSIONS`) -> the VRM 1.0 preset emotion expression an
avatar's artist made for it (``relaxed`` has none: facecast has no such expression). Its target ``vrm.happy`` ...
is the expression's face shape on that avatar (:func:`assets.heads.targets.face_targets`)."""

EMOTIONS_0 = {"joy": "happy", "angry": "angry", "sorrow": "sad", "surprised": "surprised"}
"""VRM 0.x's ``presetName`` of each emotion -> VRM 1.0's (``fun`` has no facecast expression)."""


def emotion_of(name: str) -> str | None:
    """The facecast expression a morph target named as an emotion expression is made into (``vrm.happy``,
    ``vrm.expression.happy``: :func:`expression_targets`) stands for (``"smile"``), or None."""
    for prefix in (PREFIX, PREFIX + "expression."):
        if name.startswith(prefix):
            rest = name[len(prefix) :]
            return next((e for e, v in EMOTIONS.items() if v == rest), None)
    return None


VRM0_TURN = np.array([-1.0, 1.0, -1.0])
"""Per-axis sign turning a VRM 0.x avatar half way round about +y: VRM 0.x files face -z (UniVRM's convention),
VRM 1.0 files and glTF's convention +z, which is where facecast looks for a face it has no landmarks of (a head
driven by its own targets is framed from +z, :func:`clients.render.renderer.renderer_for_rig`); three-vrm turns them
so too (``VRMUtils.rotateVRM0``)."""

PREFIX = "vrm."
"""Morph-target name prefix of an expression (``vrm.aa``): exporter prefixes up to a ``.`` are dropped when names are
matched, so the rest is the bare VRM vowel; a file whose own target is already named so gets ``vrm.expression.aa``."""


def is_vrm0(doc: Mapping) -> bool:
    """True for a VRM 0.x document (its extension ``VRM``, not VRM 1.0's ``VRMC_vrm``): it faces -z."""
    ext = doc.get("extensions") or {}
    return "VRM" in ext and "VRMC_vrm" not in ext


@dataclass(frozen=True)
class Bind:
    """One morph target an expression moves: by ``node`` (VRM 1.0, a glTF node index) or ``mesh`` (VRM 0.x, a glTF
    mesh index), the primitive's target ``index``, and ``weight`` (0-1) at the expression's weight 1."""

    index: int
    weight: float
    node: int | None = None
    mesh: int | None = None


def vrm_expressions(path: Path, doc: Mapping) -> dict[str, tuple[Bind, ...]]:
    """The vowel and emotion expressions of a VRM document (:data:`VOWELS_1` and :data:`EMOTIONS` VRM 1.0 name -> its
    binds; {} for a glTF without VRM's extension). Raises MeshError naming ``path`` when the extension is malformed."""
    ext = doc.get("extensions") or {}
    out: dict[str, tuple[Bind, ...]] = {}
    try:
        if "VRMC_vrm" in ext:
            preset = (ext["VRMC_vrm"].get("expressions") or {}).get("preset") or {}
            for name in (*VOWELS_1, *EMOTIONS.values()):
                binds = (preset.get(name) or {}).get("morphTargetBinds") or []
                out[name] = tuple(
                    Bind(index=int(b["index"]), weight=float(b.get("weight", 1.0)), node=int(b["node"])) for b in binds
                )
        elif "VRM" in ext:
            groups = (ext["VRM"].get("blendShapeMaster") or {}).get("blendShapeGroups") or []
            for g in groups:
                preset = str(g.get("presetName", "")).lower()
                which = VOWELS_0.get(preset) or EMOTIONS_0.get(preset)
                if which is None or which in out:  # another preset, or a second group of one (the first is used)
                    continue
                out[which] = tuple(
                    Bind(index=int(b["index"]), weight=float(b.get("weight", 100.0)) / 100.0, mesh=int(b["mesh"]))
                    for b in g.get("binds") or []
                )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise MeshError(f"{path}: malformed VRM expressions ({type(exc).__name__}: {exc})") from exc
    nodes, meshes = len(doc.get("nodes", [])), len(doc.get("meshes", []))
    for name, binds in out.items():
        for b in binds:
            if (b.node is not None and not 0 <= b.node < nodes) or (b.mesh is not None and not 0 <= b.mesh < meshes):
                what = f"node {b.node}" if b.node is not None else f"mesh {b.mesh}"
                raise MeshError(f"{path}: VRM expression {name!r} binds {what}, which the file does not have")
    return {k: v for k, v in out.items() if v}


def expression_targets(
    path: Path, prims: Sequence[Primitive], expressions: Mapping[str, tuple[Bind, ...]], taken: set[str]
) -> dict[str, np.ndarray]:
    """Each expression as a morph target on the merged vertices (primitives concatenated in order, as
    :func:`assets.heads.mesh.load_mesh` merges them): name (:data:`PREFIX` + vowel, avoiding the file's own
    target names ``taken``) -> (n, 3) world-unit displacement, the weighted sum of the bound targets of every
    primitive the bind names. An expression binding nothing drawn (another scene) is left out. Raises MeshError
    naming ``path`` when a bind names a target its primitive does not have."""
    offs = np.concatenate([[0], np.cumsum([len(p.vertices) for p in prims])]).astype(np.int64)
    out: dict[str, np.ndarray] = {}
    for which, binds in expressions.items():
        d = np.zeros((int(offs[-1]), 3))
        hit = False
        for b in binds:
            for i, p in enumerate(prims):
                if (p.node_index if b.node is not None else p.mesh_index) != (b.node if b.node is not None else b.mesh):
                    continue
                if not 0 <= b.index < len(p.by_index):
                    raise MeshError(
                        f"{path}: VRM expression {which!r} binds morph target {b.index} of node {p.node!r}, which has "
                        f"{len(p.by_index)} targets"
                    )
                t = p.by_index[b.index]
                if t is not None:  # a target without POSITION moves nothing here (normals only)
                    d[offs[i] : offs[i + 1]] += b.weight * t
                    hit = True
        name = next((n for n in (PREFIX + which, f"{PREFIX}expression.{which}") if n not in taken), None)
        if hit and name is not None:  # both names taken by the file's own targets: those stand for it
            out[name] = d
    return out
