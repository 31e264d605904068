"""The head test set: derive the files that reproduce each failure class, check every head, draw it.

    python scripts/head_testset.py [--out build/heads] [--images docs/img/heads]

Heads: the built-in head (own ARKit targets, and retargeted), the built-in head as an ARKit glb
with exporter spellings and with its lips modelled apart (0.1 of its jawOpen baked in, its teeth showing),
Lee Perry-Smith (hollow, closed lips; shipped landmarks and automatic ones, with and without its colour map), the
MediaPipe canonical face, Candide-3 (both files, driven by their own animation units), plus
derived files: meshopt-compressed and quantized Lee Perry-Smith (glTF-Transform; vertex order changes,
so automatic landmarks), the built-in head as a multi-material OBJ with separate eyes and teeth
objects and as separate skin / eyes / teeth / tongue files (--head-part), a viseme-only glb, and
Lee Perry-Smith split at the face's midline into two texture charts as a textured OBJ (a texture seam through the
lips, ``seam_split_obj``), menpo3d's face scan ``james.obj`` (fetched from PyPI, :func:`menpo3d_file`), Lee
Perry-Smith decimated to ~4,000 and ~1,500 triangles as textured OBJs
(``heldout_heads.lowpoly_heads``; the other held-out heads, ``python scripts/heldout_heads.py``, stay out of this set).
Derived files go to --out (not committed); two pictures per head (closed, /a/, /u/, /m/) to --images:
the whole face (260x260 per pose) and the mouth close up (400x300 per pose, 1.1 IOD wide: a
fold, a tear, a sliver or a tooth past the lips shows at this size); the rig checks are printed
as a Markdown table (docs/animation.md shows it).
Third-party heads are read from ../shared/data (or $FACECAST_SHARED_DATA).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))
from assets.shared import shared_data_root  # noqa: E402 (after the path: a worktree's own package)

POSES = {
    "closed": (0.0, 0.0, 0.0, 0.0),
    "/a/": (0.0, 0.02, 0.35, 0.0),
    "/u/": (0.0, -0.10, 0.08, 0.0),
    "/m/": (-0.02, 0.0, 0.0, 0.0),
}


def derive(out: Path, data: Path) -> dict[str, tuple[Path | str, dict]]:
    """name -> (head spec, resolve options)."""
    from assets.heads.builtin import load_builtin_head
    from assets.heads.glb import mesh_glb
    from assets.heads.head import builtin_morph_head
    from assets.heads.mesh import HeadMesh
    from assets.heads.targets import VISEME_ARKIT

    out.mkdir(parents=True, exist_ok=True)
    heads: dict[str, tuple[Path | str, dict]] = {
        "builtin (own ARKit targets)": ("builtin", {}),
        "builtin (retarget)": ("builtin", {"mode": "retarget"}),
    }
    b = builtin_morph_head().mesh
    arkit = out / "builtin_arkit_spellings.glb"
    arkit.write_bytes(
        mesh_glb(
            HeadMesh(
                vertices=b.vertices,
                triangles=b.triangles,
                colors=b.colors,
                name="a",
                targets={
                    "blendShape1." + k.replace("Left", "_L").replace("Right", "_R"): d for k, d in b.targets.items()
                },
            )
        )
    )
    heads["ARKit glb, exporter spellings"] = (arkit, {})
    # Own targets on lips modelled apart, its teeth showing between them: 0.1 of its jawOpen baked into the mesh (the
    # fit never drives a target below 0, so these lips stayed apart at every closure; the teeth took the finder's
    # upper inner-lip point). docs/animation.md, "Own targets with the lips modelled apart".
    parted = out / "arkit_lips_apart.glb"
    parted.write_bytes(
        mesh_glb(
            HeadMesh(
                vertices=b.vertices + 0.1 * b.targets["jawOpen"],
                triangles=b.triangles,
                colors=b.colors,
                name="apart",
                targets=dict(b.targets),
            )
        )
    )
    heads["ARKit glb, lips modelled apart, teeth showing"] = (parted, {})
    bh = load_builtin_head()
    vis = {f"viseme_{k}": sum(w * bh.targets[a] for a, w in mix.items()) for k, mix in VISEME_ARKIT.items() if mix}
    vg = out / "visemes_only.glb"
    vg.write_bytes(
        mesh_glb(HeadMesh(vertices=b.vertices, triangles=b.triangles, colors=b.colors, name="v", targets=vis))
    )
    heads["OVR visemes only"] = (vg, {})
    # Multi-material OBJ with separate eye / teeth / tongue objects (one material each).
    obj = out / "builtin_parts.obj"
    cols = {
        0: (0.80, 0.60, 0.50),
        1: (0.92, 0.92, 0.90),
        2: (0.95, 0.93, 0.85),
        3: (0.95, 0.93, 0.85),
        4: (0.70, 0.30, 0.32),
    }
    names = {0: "skin", 1: "eyes", 2: "upper_teeth", 3: "lower_teeth", 4: "tongue"}
    (out / "builtin_parts.mtl").write_text(
        "".join(f"newmtl {names[i]}\nKd {c[0]} {c[1]} {c[2]}\n" for i, c in cols.items())
    )
    lines = ["mtllib builtin_parts.mtl"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in b.vertices]
    part = np.asarray(b.part)
    for i, pname in names.items():
        tris = b.triangles[part[b.triangles[:, 0]] == i]
        lines += [f"o {pname}", f"usemtl {pname}"] + [f"f {a + 1} {c + 1} {d + 1}" for a, c, d in tris]
    obj.write_text("\n".join(lines) + "\n")
    import json

    lm = {k: int(v) for k, v in bh.landmarks.items()}
    (out / "builtin_parts.json").write_text(json.dumps({"landmarks": lm}))
    heads["multi-material OBJ, separate eyes/teeth"] = (
        obj,
        {"landmarks": out / "builtin_parts.json", "mode": "retarget"},
    )
    lps = data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    if lps.is_file():
        heads["Lee Perry-Smith (hollow, closed lips)"] = (lps, {})
        auto = out / "someone.glb"  # not a shipped name: automatic landmarks
        shutil.copy(lps, auto)
        shutil.copy(lps.parent / "Map-COL.jpg", out / "Map-COL.jpg")
        heads["Lee Perry-Smith, automatic landmarks"] = (auto, {})
        # The .glb alone, as a user may copy it (or any scan without a texture): rendered untextured.
        (out / "untextured").mkdir(exist_ok=True)
        bare = out / "untextured" / "someone.glb"
        shutil.copy(lps, bare)
        heads["Lee Perry-Smith, automatic landmarks, no colour map"] = (bare, {})
        cli = REPO / "node_modules" / ".bin" / "gltf-transform"
        for kind in ("meshopt", "quantize"):
            dst = out / f"lps_{kind}.glb"
            subprocess.run([str(cli), kind, str(lps), str(dst)], check=True, capture_output=True)
            heads[f"Lee Perry-Smith, {kind} (glTF-Transform)"] = (dst, {})
        # As the user had it: the .glb alone (no colour map beside it; automatic landmarks on the untextured render).
        (out / "jaw_split").mkdir(exist_ok=True)
        heads["Lee Perry-Smith, jaw as a separate mesh (glb, Z-up cm under a metres node)"] = (
            jaw_split_glb(lps, out / "jaw_split" / "lps_jaw_split.glb"),
            {},
        )
        heads["Lee Perry-Smith, texture seam through the lips (OBJ, two charts)"] = (
            seam_split_obj(lps, out / "seam_split" / "head.obj"),
            {},
        )
        # A real face scan nobody here modelled, written as two unwelded texture charts by MeshLab (its "Tr 1" means
        # opaque; its texture seam runs through the lips): it could not be rigged until both were handled (stop 42).
        heads["james, a real face scan (menpo3d, MeshLab OBJ, two texture charts)"] = (
            menpo3d_file(out, "james.obj"),
            {},
        )
        # Low-poly textured OBJ copies (decimated by meshoptimizer): found in the held-out heads, kept here.
        from heldout_heads import lowpoly_heads

        heads.update(lowpoly_heads(out / "lowpoly", data))
    mp = data / "heads" / "mediapipe-canonical" / "canonical_face_model.obj"
    if mp.is_file():
        heads["MediaPipe canonical face"] = (mp, {})
    for wfm in sorted((data / "candide3").glob("*.wfm")):
        # Candide-3 is a face model of its own: driven through its own animation units, no retarget.
        heads[f"Candide-3 ({wfm.stem.removeprefix('candide3-')}, own animation units)"] = (wfm, {})
    # The built-in head as four files: skin, eyes, both teeth rows in one file, tongue (--head-part).
    keep = {}
    for pname, ids in (("skin", [0]), ("eyes", [1]), ("teeth", [2, 3]), ("tongue", [4])):
        sel = np.flatnonzero(np.isin(part, ids))
        new = -np.ones(len(b.vertices), dtype=np.int64)
        new[sel] = np.arange(len(sel))
        tris = new[b.triangles[(new[b.triangles] >= 0).all(axis=1)]]
        c = cols[ids[0]]
        (out / f"split_{pname}.mtl").write_text(f"newmtl {pname}\nKd {c[0]} {c[1]} {c[2]}\n")
        (out / f"split_{pname}.obj").write_text(
            "\n".join(
                [f"mtllib split_{pname}.mtl", f"o {pname}", f"usemtl {pname}"]
                + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in b.vertices[sel]]
                + [f"f {a + 1} {c_ + 1} {d + 1}" for a, c_, d in tris]
            )
            + "\n"
        )
        keep[pname] = sel
    skin_index = {int(o): i for i, o in enumerate(keep["skin"])}
    (out / "split_skin.json").write_text(json.dumps({"landmarks": {k: skin_index[v] for k, v in lm.items()}}))
    heads["separate eye, teeth and tongue files (--head-part)"] = (
        out / "split_skin.obj",
        {
            "landmarks": out / "split_skin.json",
            "mode": "retarget",
            "parts": tuple(str(out / f"split_{k}.obj") for k in ("eyes", "teeth", "tongue")),
        },
    )
    return heads


def jaw_split_glb(lps: Path, dst: Path) -> Path:
    """Lee Perry-Smith as a studio may export it (issue 12): two meshes, "Head" and "Jaw" (the lower face below the
    mouth line, in front, within the chin's width), their vertices in Z-up centimetres under an "Armature" node that
    turns them into Y-up metres; the meshes meet at coincident vertices, not shared ones. Written to ``dst``."""
    import trimesh

    from assets.heads.landmarks import read_landmarks, shipped_landmarks
    from assets.heads.rigging import resolve_landmarks

    src = trimesh.load(lps, force="scene")
    g = next(iter(src.geometry.values()))
    lm_path = shipped_landmarks(lps)
    assert lm_path is not None  # the shipped hand landmarks
    at = resolve_landmarks(read_landmarks(lm_path), np.asarray(g.vertices), str(lm_path))
    c = g.triangles_center
    mouth_y = at["upper_inner"][1]
    cx = 0.5 * (at["corner_left"][0] + at["corner_right"][0])
    jaw = (c[:, 1] < mouth_y) & (c[:, 2] > 0.3) & (np.abs(c[:, 0] - cx) < 2.2) & (c[:, 1] > mouth_y - 3.5)
    z_up = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
    scene = trimesh.Scene()
    to_metres_y_up = trimesh.transformations.scale_matrix(0.01) @ np.linalg.inv(z_up)
    scene.graph.update(frame_to="Armature", frame_from=scene.graph.base_frame, matrix=to_metres_y_up)
    for name, mask in (("Head", ~jaw), ("Jaw", jaw)):
        sub = g.submesh([np.flatnonzero(mask)], append=True)
        sub.apply_transform(z_up @ trimesh.transformations.scale_matrix(3.0))  # scan units -> cm (24 cm head), Z up
        scene.add_geometry(sub, node_name=name, geom_name=name + "Mesh", parent_node_name="Armature")
    scene.export(dst)
    return dst


MENPO3D = (
    "https://files.pythonhosted.org/packages/cf/3b/1490a36682e1a5da3703efc1c7af3f1d07c1247477b699b980a3b5eb9a20/"
    "menpo3d-0.8.6.tar.gz",
    "96ad2c8b55b74e026cdc190cf6b1564ad7c8e6c53976cf897d6a1bf4940f084a",
)
"""menpo3d 0.8.6's source package on PyPI (BSD-3, Imperial College London and others) and its SHA-256: it ships a
face scan (``menpo3d/data/james.obj``, a MeshLab export with its MTL and colour map) and a face template
(``template.ply``), real faces nobody here modelled."""


def menpo3d_file(out: Path, name: str) -> Path:
    """``out/menpo3d/NAME`` (and, for an OBJ, its MTL and colour map) from menpo3d's ``data`` folder: the package
    fetched once from PyPI into the facecast cache (SHA-256 checked), read from there, never into the repository."""
    import hashlib
    import tarfile
    import urllib.request

    from assets.files import atomic_write_bytes
    from assets.heads.cache import cache_dir

    url, sha = MENPO3D
    sdist = cache_dir() / "wheels" / url.rsplit("/", 1)[1]
    if not sdist.is_file() or hashlib.sha256(sdist.read_bytes()).hexdigest() != sha:
        sdist.parent.mkdir(parents=True, exist_ok=True)
        with urllib.request.urlopen(url, timeout=120) as r:
            body = r.read()
        if hashlib.sha256(body).hexdigest() != sha:
            raise SystemExit(f"{url}: SHA-256 differs from the one this script was written for")
        atomic_write_bytes(sdist, body)
    d = out / "menpo3d"
    d.mkdir(parents=True, exist_ok=True)
    stem = Path(name).stem
    with tarfile.open(sdist) as tar:
        for member in tar.getmembers():
            p = Path(member.name)
            ours = p.parent.as_posix() == "menpo3d-0.8.6/menpo3d/data" and p.name.startswith(stem + ".")
            if ours and member.isfile():
                got = tar.extractfile(member)
                if got is None:
                    raise SystemExit(f"{sdist}: {member.name} is not a file")
                (d / p.name).write_bytes(got.read())
    if not (d / name).is_file():
        raise SystemExit(f"{sdist}: no menpo3d/data/{name}")
    return d / name


def seam_split_obj(lps: Path, dst: Path) -> Path:
    """Lee Perry-Smith as a scanner may write it (issue 12: menpo3d's james.obj): its two halves, split at the face's
    vertical midline (between the shipped mouth corners), each its own texture chart (the colour map twice side by
    side, the right half's faces on the second copy), so the midline's vertices are true texture-seam copies (one
    position, two texture coordinates) and the seam runs down through the lips. A textured OBJ written to ``dst``
    (automatic landmarks: not a shipped name)."""
    import io

    from heldout_heads import write_obj
    from PIL import Image

    from assets.heads.landmarks import read_landmarks, shipped_landmarks
    from assets.heads.mesh import load_mesh
    from assets.heads.rigging import resolve_landmarks

    m = load_mesh(lps)
    assert m.uvs is not None and m.texture is not None  # its colour map lies beside it
    lm_path = shipped_landmarks(lps)
    assert lm_path is not None  # the shipped hand landmarks
    at = resolve_landmarks(read_landmarks(lm_path), m.vertices, str(lm_path))
    mid = 0.5 * (at["corner_left"][0] + at["corner_right"][0])
    tri = np.asarray(m.triangles, dtype=np.int64)
    right = m.vertices[tri].mean(axis=1)[:, 0] > mid
    # Every vertex of the right half's faces a copy of its own: the copies of the midline's vertices make the seam.
    n = len(m.vertices)
    tri = np.where(right[:, None], tri + n, tri)
    uv = np.asarray(m.uvs, dtype=np.float64)
    uvs = np.vstack([uv * [0.5, 1.0], uv * [0.5, 1.0] + [0.5, 0.0]])
    img = Image.open(io.BytesIO(m.texture)).convert("RGB")
    both = Image.new("RGB", (2 * img.width, img.height))
    both.paste(img, (0, 0))
    both.paste(img, (img.width, 0))
    buf = io.BytesIO()
    both.save(buf, format="JPEG", quality=92)
    dst.parent.mkdir(parents=True, exist_ok=True)
    return write_obj(dst, np.vstack([m.vertices, m.vertices]), tri, uvs, buf.getvalue())


CLOSE_UP_WIDTH = 1.1
"""IOD: the width the mouth close-up shows (a mouth is about 0.6 IOD wide; /a/ opens 0.45 IOD)."""


def mouth_renderer(head, finder, config):
    """A renderer framed on the mouth (front view, CLOSE_UP_WIDTH IOD wide), from the rig's landmarks or
    the finder's (as :func:`assets.heads.head.head_checks` takes them); None when there are none."""
    from assets.heads.rigging import mouth_landmarks
    from clients.render.renderer import HeadRenderer, parted_for
    from realtime_core.face import face_frame

    pts = head.rig.meta.get("landmarks") or dict(finder(head.mesh))
    if not pts:
        return None
    names = list(pts)
    pv = np.array([pts[k] for k in names], dtype=np.float64)
    fr = face_frame(pv, mouth_landmarks({k: i for i, k in enumerate(names)}))
    mouth = 0.5 * (np.asarray(pts["corner_left"]) + np.asarray(pts["corner_right"]))
    # Pivot behind the lips (as the face view's), a little below the corners (/a/ opens downwards).
    centre = mouth - 0.5 * fr.iod * fr.axes[2] - 0.08 * fr.iod * fr.axes[1]
    size = CLOSE_UP_WIDTH * fr.iod * config.height / config.width
    return HeadRenderer(head.mesh, centre=centre, axes=fr.axes, size=size, config=config, parted=parted_for(head.rig))


def _resolve(spec, opts: dict, finder):
    from assets.heads.head import resolve_head

    return resolve_head(spec, landmark_finder=finder, **opts)


def _warned(rep) -> str:
    """The advisory figures over their limits, as the table's checks column notes them."""
    from realtime_core.face.checks import SLIVER_REST, RigCheckLimits

    lim = RigCheckLimits()
    over = []
    sliver = ""
    if rep.sliver_stretch is not None and rep.max_edge_stretch > lim.max_stretch >= rep.sliver_stretch:
        # The largest stretch is a sliver's: the rig is judged on it from SLIVER_REST of the median edge.
        sliver = f" (a sliver's stretch: {rep.sliver_stretch:.2f} from {SLIVER_REST} of the median edge)"
    if rep.lip_edge_notch_iod is not None and rep.lip_edge_notch_iod > lim.max_lip_edge_notch:
        over.append("notch")
    if rep.lip_backs_iod2 is not None and rep.lip_backs_iod2 > lim.max_lip_backs:
        over.append("backs")
    if rep.lip_tops_iod2 is not None and rep.lip_tops_iod2 > lim.max_lip_tops:
        over.append("tops")
    if rep.skin_dark_iod2 is not None and rep.skin_dark_iod2 > lim.max_skin_dark:
        over.append("dark")
    if rep.bilabial_gap_iod is not None and rep.bilabial_gap_iod > lim.max_bilabial_gap:
        over.append("/m/")
    if rep.lip_crumple_deg is not None and rep.lip_crumple_deg > lim.max_lip_crumple:
        over.append("crumple")
    return sliver + (f" ({' + '.join(over)} warning)" if over else "")


def check_and_draw(
    heads: dict, images: Path, *, link: str = "img/heads", describe=None, three_quarter: bool = False
) -> list[str]:
    """Resolve, check and draw every head (name -> (spec, resolve options)); the pictures go to ``images``
    (linked in the table as ``link``/...), the checks come back as the rows of a Markdown table.
    ``describe(head, report or None) -> (header, cell)``: an extra column after the head's name
    (``describe(None, None)`` gives the header; None: no extra column). ``three_quarter``: the mouth close-ups
    also from the renderer's three-quarter view (``SLUG_mouth_34.jpg``: a lip face that shows its back, drawn
    dark, shows there first; docs/animation.md, "Three-quarter view")."""
    from PIL import Image, ImageDraw

    from assets.heads.head import head_checks
    from assets.progress import Progress
    from clients.render.landmarks import find_landmarks
    from clients.render.renderer import RenderConfig, renderer_for_rig
    from realtime_core.errors import FacecastError

    images.mkdir(parents=True, exist_ok=True)
    rows = [
        (
            "| head | driven by | flipped triangles | max edge stretch | lip interpenetration (IOD) | "
            "lip gap at closure (IOD) | teeth ahead (IOD) | lip edge notch (IOD) | lip backs seen (1e-3 IOD^2) | "
            "skin seen dark (1e-3 IOD^2) | inside through the skin (IOD) | closed lips seen dark (1e-3 IOD^2) | "
            "checks |"
        ),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    if describe is not None:
        rows = [rows[0].replace("| driven by |", f"| {describe(None, None)[0]} | driven by |"), rows[1] + "---|"]
    for name, (spec, opts) in Progress(heads.items(), desc="heads"):
        try:
            head = _resolve(spec, opts, find_landmarks)
        except FacecastError as exc:
            dashes = " - |" * 10
            rows.append(f"| {name} |{' - |' if describe else ''} cannot rig |{dashes} {exc} |")
            continue
        rep = None
        try:
            rep = head_checks(head, landmark_finder=find_landmarks)
            print(f"{name}: {rep.summary()}", file=sys.stderr)
            figs = (
                f"{rep.flipped_triangles} | {rep.max_edge_stretch:.2f} | {rep.lip_interpenetration_iod:.4f} | "
                f"{rep.closure_gap_iod:.4f} | "
                f"{'n/a' if rep.teeth_ahead_iod is None else f'{rep.teeth_ahead_iod:.3f}'} | "
                f"{'n/a' if rep.lip_edge_notch_iod is None else f'{rep.lip_edge_notch_iod:.4f}'} | "
                f"{'n/a' if rep.lip_backs_iod2 is None else f'{1000 * rep.lip_backs_iod2:.2f}'} | "
                f"{'n/a' if rep.skin_dark_iod2 is None else f'{1000 * rep.skin_dark_iod2:.2f}'} | "
                f"{'n/a' if rep.inside_shown_iod is None else f'{rep.inside_shown_iod:.4f}'} | "
                f"{'n/a' if rep.lips_dark_iod2 is None else f'{1000 * rep.lips_dark_iod2:.2f}'} | "
                f"{'pass' if rep.passed else 'FAIL'}{_warned(rep)}"
            )
        except FacecastError as exc:  # a head without landmarks cannot be checked; say so in the table
            figs = f"- | - | - | - | - | - | - | - | - | - | not checked ({exc})"
        kind = "own targets" if head.kind == "morph" else "retarget (harmonic)"
        tiles = []
        with renderer_for_rig(head.rig, head.mesh, RenderConfig(width=260, height=260)) as r:
            for label, p in POSES.items():
                img = Image.fromarray(r.render(head.rig.deformed(np.array(p))))
                ImageDraw.Draw(img).text((6, 6), label, fill=(255, 255, 255))
                tiles.append(np.asarray(img))
        slug = "".join(c if c.isalnum() else "_" for c in name.lower()).strip("_")
        Image.fromarray(np.hstack(tiles)).save(images / f"{slug}.png")
        close = []
        try:
            mr = mouth_renderer(head, find_landmarks, RenderConfig(width=400, height=300))
        except FacecastError:
            mr = None
        if mr is not None:
            with mr as r:
                for label, p in POSES.items():
                    img = Image.fromarray(r.render(head.rig.deformed(np.array(p))))
                    ImageDraw.Draw(img).text((6, 6), label, fill=(255, 255, 255))
                    close.append(np.asarray(img))
            # JPEG (quality 92): a textured close-up is 0.3-0.45 MB as PNG, ~0.1 MB so, defects as visible.
            Image.fromarray(np.hstack(close)).save(images / f"{slug}_mouth.jpg", quality=92)
            pics = f"![]({link}/{slug}.png) ![]({link}/{slug}_mouth.jpg)"
            if three_quarter:
                side = []
                turned = RenderConfig(width=400, height=300, view="three_quarter")
                with mouth_renderer(head, find_landmarks, turned) as r:
                    for label, p in POSES.items():
                        img = Image.fromarray(r.render(head.rig.deformed(np.array(p))))
                        ImageDraw.Draw(img).text((6, 6), label, fill=(255, 255, 255))
                        side.append(np.asarray(img))
                Image.fromarray(np.hstack(side)).save(images / f"{slug}_mouth_34.jpg", quality=92)
                pics += f" ![]({link}/{slug}_mouth_34.jpg)"
        else:
            pics = f"![]({link}/{slug}.png)"
        extra = f" {describe(head, rep)[1]} |" if describe else ""
        rows.append(f"| {name} {pics} |{extra} {kind} | {figs} |")
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "build" / "heads")
    ap.add_argument("--images", type=Path, default=REPO / "docs" / "img" / "heads")
    ap.add_argument("--data", type=Path, default=shared_data_root())
    ap.add_argument("--only", default=None, help="check only the heads whose name contains this text")
    ap.add_argument("--three-quarter", action="store_true", help="also the mouth close-ups in three-quarter view")
    args = ap.parse_args()
    heads = derive(args.out, args.data)
    if args.only:
        heads = {k: v for k, v in heads.items() if args.only.lower() in k.lower()}
    print("\n".join(check_and_draw(heads, args.images, three_quarter=args.three_quarter)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
