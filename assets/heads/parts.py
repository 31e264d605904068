"""Separate head parts (eyes, teeth, tongue) as rigid components of a retargeted head.

Heads often come with the eyes, teeth and tongue as separate meshes: objects of an OBJ, meshes of a
glTF scene, or files of their own (``--head head.obj --head-part eyes.obj --head-part teeth.obj``,
:func:`assets.heads.mesh.load_mesh`). Such a part has no control point of the simple face model, so
the rig would move it with whatever lies near its centroid (upper teeth pulled down by the lower
lip, eyeballs dragged by the cheeks). Here each part is classified by its name, and for teeth by
where it sits, and given a rigid motion:

- ``skull``: eyes (eyeball, iris, cornea, pupil, sclera, eyelashes...) and upper teeth/gums: still;
- ``jaw``: lower teeth/gums and the tongue: the displacement of the chin landmark (the jaw's
  motion; the lower outer-lip midpoint when the rig does not move the chin), the same for every vertex.

The part holding the face (the nose-tip landmark) is never reclassified, whatever its name. A teeth
part whose name says neither upper nor lower is split by connected pieces: above the mouth line
(the corners' midpoint, along the face's up direction) upper, below lower.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from assets.heads.mesh import HeadMesh

EYE_WORDS = ("eye", "iris", "cornea", "pupil", "sclera", "lash")
TEETH_WORDS = ("teeth", "tooth", "gum", "dent")
TONGUE_WORDS = ("tongue",)
UPPER_WORDS = ("upper", "top", "up", "maxill")
LOWER_WORDS = ("lower", "bottom", "low", "mandib", "jaw")


def _words(name: str) -> list[str]:
    # "Eye_L", "teethUpper", "eyes:default" -> lower-case words
    return [w.lower() for w in re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+", name)]


def _has(words: list[str], keys: tuple[str, ...]) -> bool:
    return any(w.startswith(k) for w in words for k in keys)


def part_kind(name: str) -> str | None:
    """ "eyes", "teeth", "upper teeth", "lower teeth", "tongue" or None (skin, unknown) for a part name."""
    w = _words(name)
    if _has(w, TONGUE_WORDS):
        return "tongue"
    if _has(w, TEETH_WORDS):
        if _has(w, LOWER_WORDS):
            return "lower teeth"
        if _has(w, UPPER_WORDS):
            return "upper teeth"
        return "teeth"
    if _has(w, EYE_WORDS) and not any("brow" in x or "lid" in x for x in w):  # brows and lids: skin
        return "eyes"
    return None


def rigid_labels(mesh: HeadMesh, landmarks: Mapping[str, int]) -> np.ndarray:
    """(n,) per-vertex label: "skull", "jaw" or "" (left to the rig) from the mesh's part names.
    landmarks: name -> vertex index (nose_tip, corner_left/right, eye corners)."""
    n = len(mesh.vertices)
    out = np.full(n, "", dtype=object)
    if mesh.part is None or not mesh.part_names:
        return out
    v = np.asarray(mesh.vertices, dtype=np.float64)
    face = int(mesh.part[landmarks["nose_tip"]])
    mouth = 0.5 * (v[landmarks["corner_left"]] + v[landmarks["corner_right"]])
    eyes = 0.25 * sum(
        v[landmarks[k]] for k in ("eye_outer_left", "eye_inner_left", "eye_outer_right", "eye_inner_right")
    )
    up = (eyes - mouth) / max(float(np.linalg.norm(eyes - mouth)), 1e-300)
    for i, name in enumerate(mesh.part_names):
        kind = part_kind(name)
        sel = np.flatnonzero(mesh.part == i)
        if kind is None or i == face or not len(sel):
            continue
        if kind == "teeth":  # both rows in one part: each connected piece by its side of the mouth line
            out[sel] = _split_rows(v, mesh.triangles, sel, mouth, up)
        else:
            out[sel] = "skull" if kind in ("eyes", "upper teeth") else "jaw"
    return out


def _split_rows(v: np.ndarray, triangles: np.ndarray, sel: np.ndarray, mouth: np.ndarray, up: np.ndarray) -> np.ndarray:
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    local = -np.ones(len(v), dtype=np.int64)
    local[sel] = np.arange(len(sel))
    t = np.asarray(triangles, dtype=np.int64)
    t = local[t[(local[t] >= 0).all(axis=1)]]
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    adj = sp.csr_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(sel), len(sel)))
    _, comp = connected_components(adj, directed=False)
    height = (v[sel] - mouth) @ up
    mean = np.bincount(comp, weights=height) / np.bincount(comp)
    return np.where(mean[comp] >= 0, "skull", "jaw")


def with_rigid_parts(rig, mesh: HeadMesh, landmarks: Mapping[str, int]):
    """The :class:`realtime_core.face.Rig` with the rows of its separate parts replaced by their rigid
    motion (see the module docstring); the rig unchanged when the mesh has no such parts. Records
    ``rigid_parts`` (label -> vertex count) in the rig's meta."""
    labels = rigid_labels(mesh, landmarks)
    if not (labels != "").any():
        return rig
    n = len(rig.neutral)
    row = -np.ones(n, dtype=np.int64)  # each vertex's row among the moving ones
    row[rig.moving] = np.arange(len(rig.moving))
    anchor = landmarks["chin"] if row[landmarks["chin"]] >= 0 else landmarks["lower_lip"]
    source = np.arange(n)
    source[labels == "jaw"] = anchor
    src_row = np.where(labels == "skull", -1, row[source])
    moving = np.flatnonzero(src_row >= 0)
    rows = (3 * src_row[moving][:, None] + np.arange(3)).reshape(-1)
    counts = {k: int((labels == k).sum()) for k in ("skull", "jaw") if (labels == k).any()}
    meta = {**rig.meta, "rigid_parts": counts, "jaw_anchor": int(anchor)}
    spread = rig.contact_spread
    if spread is not None:
        # The lip-contact push is a correction of the lips' own surface: a part that follows the
        # jaw rigidly takes none of it (it would bend the teeth with the lips).
        own = (labels[moving] == "").astype(np.float32)
        spread = sp.diags(own) @ spread[src_row[moving]]
    return replace(rig, moving=moving.astype(np.int64), matrix=rig.matrix[rows], meta=meta, contact_spread=spread)
