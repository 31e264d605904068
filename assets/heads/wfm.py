"""Candide-3 wireframe files (``.wfm``): the one reader, and Candide-3 as a head of its own.

Candide-3 (Ahlberg 2001) is itself a parameterised face: 113 vertices with animation units (AUs)
such as "jaw drop" or "lip stretcher". It is too coarse to be rigged by facecast's simple face
model (which has more vertices than it), and it needs no retarget: the four mouth parameters are
mapped onto its own AUs, the way the paper drives its face model. :func:`candide_head` calibrates
one AU per parameter on the model itself (:func:`realtime_core.face.calibrate_mouth`: each AU's
measured mouth response, inverted) and animates the wireframe through those AUs as morph targets,
so it plays, renders, streams (morph weights) and exports like any head with its own targets.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from assets.errors import MeshError
from assets.heads.mesh import HeadMesh
from realtime_core.errors import RealtimeCoreError
from realtime_core.face import FaceModel, calibrate_mouth, parse_wfm

AU_RANGE = (-1.0, 1.0)
"""Weight bounds of Candide-3's animation units (the report defines them on [-1, 1])."""


def read_wfm(path: str | Path) -> FaceModel:
    """A Candide-3 ``.wfm`` file (3.1.6 or the UV variant); MeshError naming the file on any problem."""
    p = Path(path)
    try:
        text = p.read_text(encoding="latin-1")
    except OSError as exc:
        raise MeshError(f"{p}: cannot read the Candide-3 file: {exc}") from exc
    try:
        return parse_wfm(text, name=p.stem)
    except RealtimeCoreError as exc:
        raise MeshError(f"{p}: not a usable Candide-3 model: {exc}") from exc


def candide_head(path: str | Path):
    """:class:`assets.heads.head.Head` of a Candide-3 file driven through its own animation units."""
    from assets.heads.head import Head
    from realtime_core.face.candide import CANDIDE3_LANDMARKS, candide3_mouth_groups, candide3_mouth_landmarks
    from realtime_core.face.keyframes import KeyframeMap, MorphRig

    p = Path(path)
    model = read_wfm(p)
    try:
        groups = candide3_mouth_groups(model)
        cal = calibrate_mouth(model, candide3_mouth_landmarks(), groups=groups)
    except RealtimeCoreError as exc:
        raise MeshError(f"{p}: cannot calibrate the mouth on this Candide-3 model: {exc}") from exc
    names = tuple(g[0] for g in cal.groups)
    d = np.stack([np.sum([model.animation_units[n] for n in g], axis=0) for g in cal.groups])  # (4, n, 3)
    moving = np.flatnonzero(np.abs(d).max(axis=(0, 2)) > 0)
    # Weights = the calibration's (4, 4) inverse response @ params, within the AUs' range: the bounded
    # eq. 4 of KeyframeMap with an identity Gram matrix is exactly that, clipped.
    keymap = KeyframeMap(gram=np.eye(len(names)), cross=np.asarray(cal.matrix), lo=AU_RANGE[0], hi=AU_RANGE[1])
    v = np.asarray(model.vertices, dtype=np.float64)
    triangles = _outward(v, np.asarray(model.triangles, dtype=np.int64))
    meta = {
        "head": str(p),
        "kind": "morph",
        "targets": {n: {"candide3": 1.0} for n in names},
        "calibration": {"units": list(names), "response": np.asarray(cal.response).round(6).tolist()},
        "landmarks": {k: v[i].tolist() for k, i in CANDIDE3_LANDMARKS.items()},
    }
    rig = MorphRig(
        neutral=v,
        triangles=triangles,
        names=names,
        targets=d[:, moving],
        moving=moving,
        keymap=keymap,
        source=_params,
        meta=meta,
    )
    uvs = getattr(model, "uvs", None)
    mesh = HeadMesh(
        vertices=v,
        triangles=triangles,
        uvs=None if uvs is None else np.asarray(uvs, dtype=np.float64),
        name=str(p),
        targets={n: d[j] for j, n in enumerate(names)},
    )
    return Head(rig, mesh)


def _outward(v: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The wireframe's triangles facing the viewer (the file mixes both windings): Candide-3 is a
    face mask looking along +z, so each triangle is wound so that its normal points away from a
    point well behind the mask (renderers shade back faces dark)."""
    t = np.asarray(triangles, dtype=np.int64).copy()
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    normal = np.cross(b - a, c - a)
    behind = v.mean(0) - np.array([0.0, 0.0, 2.0 * float(np.ptp(v, axis=0).max())])
    flip = np.einsum("ij,ij->i", normal, (a + b + c) / 3 - behind) < 0
    t[flip] = t[flip][:, ::-1]
    return np.ascontiguousarray(t)


def _params(params: np.ndarray) -> np.ndarray:
    """The keymap's source coordinates are the mouth parameters themselves (..., 4)."""
    return np.asarray(params, dtype=np.float64)
