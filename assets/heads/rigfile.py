"""Rig files: a :class:`Rig` plus the mesh it animates, as one ``.npz`` of plain arrays.

No pickle anywhere: arrays are numeric, the sparse matrix is stored as CSR parts, the simple
model's units as one stacked array with their names in the JSON metadata string, the texture as
its encoded bytes (uint8). Written atomically (temp file + ``os.replace``) and read with
``allow_pickle=False``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from assets.errors import RigFileError
from assets.files import not_a_file
from assets.heads.cache import atomic_savez
from assets.heads.mesh import HeadMesh
from realtime_core.archive import NOT_NPZ
from realtime_core.errors import RealtimeCoreError
from realtime_core.face import FaceModel, MouthCalibration, Rig

FORMAT = "facecast-rig"
VERSION = 1
# The built-in head's rig cache files (``builtin_rig_v<VERSION>_a<RIG_ALGORITHM>_c<COLORS_VERSION>.npz``):
# the one of this checkout's versions is current.
BUILTIN_RIG_FAMILY = re.compile(r"builtin_rig_v\d+_a\d+_c\d+\.npz")
# Rigs of meshes given by the user, cached as ``<cache>/rigs/<key>.npz`` (assets.heads.head._rig_key): the
# key hashes the rig algorithm in, so only the file's metadata tells an older algorithm's file.
RIG_CACHE_FAMILY = re.compile(r"[0-9a-f]{32}\.npz")


def rig_algorithm(path: str | Path) -> int | None:
    """The rig algorithm (``realtime_core.face.rig.RIG_ALGORITHM``) a rig file was built by, reading only
    its metadata; None if the file is not a readable rig file."""
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
        algorithm = meta["rig"]["algorithm"]
    except (OSError, ValueError, KeyError, TypeError, json.JSONDecodeError):
        return None
    return algorithm if isinstance(algorithm, int) else None


def save_rig(rig: Rig, mesh: HeadMesh, path: str | Path) -> Path:
    """Write ``rig`` and its ``mesh`` (same vertex count) to ``path`` (.npz) atomically."""
    if len(mesh.vertices) != len(rig.neutral):
        raise RigFileError(f"{path}: mesh has {len(mesh.vertices)} vertices, rig {len(rig.neutral)}")
    if mesh.part is not None and len(mesh.part) != len(mesh.vertices):
        raise RigFileError(f"{path}: mesh has {len(mesh.vertices)} vertices, its part labels {len(mesh.part)}")
    names = list(rig.simple.animation_units)
    meta = {
        "format": FORMAT,
        "version": VERSION,
        "unit_names": names,
        "groups": [list(g) for g in rig.calibration.groups],
        "mesh_name": mesh.name,
        "part_names": list(mesh.part_names),
        "rig": rig.meta,
    }
    m = rig.matrix.tocsr()
    arrays = {
        "meta": np.array(json.dumps(meta)),
        "neutral": np.asarray(rig.neutral, dtype=np.float32),
        "triangles": np.asarray(rig.triangles, dtype=np.int32),
        "moving": rig.moving.astype(np.int64),
        "matrix_data": m.data.astype(np.float32),
        "matrix_indices": m.indices.astype(np.int32),
        "matrix_indptr": m.indptr.astype(np.int64),
        "matrix_shape": np.array(m.shape, dtype=np.int64),
        "basis": rig.basis.astype(np.float32),
        "control": rig.control.astype(np.int64),
        "simple_vertices": rig.simple.vertices,
        "simple_triangles": rig.simple.triangles,
        "simple_units": np.stack([rig.simple.animation_units[n] for n in names])
        if names
        else np.zeros((0, rig.simple.n_vertices, 3)),
        "cal_response": rig.calibration.response,
        "cal_matrix": rig.calibration.matrix,
        "contact": np.asarray(rig.contact, dtype=np.int64),
        "contact_up": np.asarray(rig.contact_up, dtype=np.float64),
    }
    if rig.contact_spread is not None:
        # The push's spread over the lips: without it a loaded rig pushes the two contact vertices of a
        # crossing column alone, a different (folding) deformation from the rig that was saved.
        cs = rig.contact_spread.tocsr()
        arrays.update(
            spread_data=cs.data.astype(np.float32),
            spread_indices=cs.indices.astype(np.int32),
            spread_indptr=cs.indptr.astype(np.int64),
            spread_shape=np.array(cs.shape, dtype=np.int64),
        )
    if mesh.uvs is not None:
        arrays["uvs"] = np.asarray(mesh.uvs, dtype=np.float32)
    if mesh.colors is not None:
        arrays["colors"] = np.asarray(mesh.colors, dtype=np.float32)
    if mesh.texture is not None:
        arrays["texture"] = np.frombuffer(mesh.texture, dtype=np.uint8)
    if mesh.part is not None:  # which file object each vertex came from: teeth and eyes are found by name
        arrays["part"] = np.asarray(mesh.part, dtype=np.int16)
    return atomic_savez(path, **arrays)


def load_rig(path: str | Path) -> tuple[Rig, HeadMesh]:
    """Read a rig file; RigFileError naming the file if it is missing, of another format or inconsistent."""
    p = Path(path)
    if not p.is_file():
        raise RigFileError(f"{p}: rig file {not_a_file(p)}")
    try:
        with p.open("rb") as fh:
            zipped = fh.read(2) == b"PK"
    except OSError as exc:
        raise RigFileError(f"{p}: cannot be read: {exc.strerror or exc}") from None
    if not zipped:
        raise RigFileError(f"{p}: not a readable rig file: {NOT_NPZ}")
    try:
        with np.load(p, allow_pickle=False) as z:
            a = {k: z[k] for k in z.files}
        meta = json.loads(str(a["meta"]))
    except (OSError, ValueError, KeyError, json.JSONDecodeError) as exc:
        raise RigFileError(f"{p}: not a readable rig file: {exc}") from exc
    if meta.get("format") != FORMAT or meta.get("version") != VERSION:
        raise RigFileError(f"{p}: expected {FORMAT} version {VERSION}, got {meta.get('format')} {meta.get('version')}")
    try:
        names = meta["unit_names"]
        simple = FaceModel(
            vertices=a["simple_vertices"],
            triangles=a["simple_triangles"],
            animation_units={n: a["simple_units"][i] for i, n in enumerate(names)},
            name="simple",
        )
        cal = MouthCalibration(
            groups=tuple(tuple(g) for g in meta["groups"]), response=a["cal_response"], matrix=a["cal_matrix"]
        )
        shape = tuple(int(x) for x in a["matrix_shape"])
        matrix = sp.csr_matrix((a["matrix_data"], a["matrix_indices"], a["matrix_indptr"]), shape=shape)
        spread = None
        if "spread_data" in a:  # (files written before the spread was stored push the contact vertices alone)
            spread = sp.csr_matrix(
                (a["spread_data"], a["spread_indices"], a["spread_indptr"]),
                shape=tuple(int(x) for x in a["spread_shape"]),
            )
        rig = Rig(
            neutral=a["neutral"],
            triangles=a["triangles"],
            moving=a["moving"],
            matrix=matrix,
            basis=a["basis"],
            control=a["control"],
            simple=simple,
            calibration=cal,
            meta=meta.get("rig", {}),
            contact=a.get("contact", np.zeros((0, 2), dtype=np.int64)),
            contact_up=a.get("contact_up", np.array([0.0, 1.0, 0.0])),
            contact_spread=spread,
        )
    except (KeyError, ValueError, IndexError, RealtimeCoreError) as exc:
        raise RigFileError(f"{p}: inconsistent rig file: {exc}") from exc
    mesh = HeadMesh(
        vertices=a["neutral"].astype(np.float64),
        triangles=a["triangles"].astype(np.int64),
        uvs=a.get("uvs"),
        texture=a["texture"].tobytes() if "texture" in a else None,
        colors=a.get("colors"),
        name=meta.get("mesh_name", str(p)),
        part=a.get("part"),
        part_names=tuple(meta.get("part_names", ())),
    )
    return rig, mesh


def builtin_rig(cache: Path | None = None) -> tuple[Rig, HeadMesh]:
    """The built-in head's rig, from the cache or built (and cached) on first use."""
    from assets.heads.builtin import COLORS_VERSION, load_builtin_head
    from assets.heads.cache import cache_dir, remove_stale_siblings
    from assets.heads.rigging import rig_head
    from realtime_core.face.rig import RIG_ALGORITHM

    root = cache or cache_dir()
    # The algorithm in the name: checkouts at different rig algorithms share one cache without
    # rebuilding each other's file over and over. The head's colours too: the file stores them.
    path = root / f"builtin_rig_v{VERSION}_a{RIG_ALGORITHM}_c{COLORS_VERSION}.npz"

    if path.is_file():
        try:
            rig, mesh = load_rig(path)
            if rig.meta.get("algorithm") == RIG_ALGORITHM:
                return rig, mesh
        except RigFileError:
            pass
        path.unlink(missing_ok=True)  # unreadable or built by an older algorithm (or removed meanwhile): rebuilt below
    from assets.heads.head import with_checks

    head = load_builtin_head(root)
    rig, mesh = rig_head(head.mesh, None, head=head)
    rig = with_checks(rig, mesh)  # its checks (and the poses it holds) kept in the file: measured once
    save_rig(rig, mesh, path)
    remove_stale_siblings(path, BUILTIN_RIG_FAMILY)
    return rig, mesh
