"""A head and its mirror image (or its mouth jittered), rigged fresh and checked as the head test set checks them.

    python scripts/mirror_probe.py --out /tmp/P [--only SUBSTR] [--which none,mirror,jitter0] [--three-quarter]
    python scripts/mirror_probe.py --out /tmp/P --only 3810 --same-landmarks

Heads (issue 12, docs/animation.md, "A head and its mirror image"): Lee Perry-Smith untextured (the test set's
``someone.glb`` without its colour map), its 1,428- and 3,810-triangle textured copies
(:func:`heldout_heads.lowpoly_heads`), its lips parted at rest (:func:`heldout_heads.parted_lps`) and the built-in
head without its targets. Each is read as facecast reads it and written as one glb: as it is (``none``), mirrored in x
with its winding reversed so that its normals stay outward (``mirror``), or every vertex within JITTER_REACH of the
mouth's centre moved uniformly by +-JITTER per axis (``jitterN``, seed N; copies at one place moved alike). The glbs
are rigged with automatic landmarks by the test set's :func:`head_testset.check_and_draw` (pictures in OUT/img).

``--same-landmarks``: the head and its mirror image rigged from the landmarks found on the head (``none``), mirrored
with left and right swapped, so that any difference is the rig's own, not MediaPipe's (no rig cache, no pictures).
"""

from __future__ import annotations

import argparse
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))
from assets.shared import shared_data_root  # noqa: E402 (after the path: a worktree's own package)

JITTER = 0.002  # IOD, the largest move per axis
JITTER_REACH = 0.35  # IOD from the mouth's centre (Lee Perry-Smith's hand landmarks)


def heads(out: Path, data: Path) -> dict:
    """name -> HeadMesh as facecast reads it."""
    from heldout_heads import lowpoly_heads, parted_lps

    from assets.heads.head import builtin_morph_head
    from assets.heads.mesh import load_mesh

    out.mkdir(parents=True, exist_ok=True)
    lps = data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    (out / "bare").mkdir(exist_ok=True)
    shutil.copy(lps, out / "bare" / "someone.glb")  # as the test set's row: the glb without its colour map
    found = {"untextured": load_mesh(out / "bare" / "someone.glb")}
    for name, (f, _) in lowpoly_heads(out / "lowpoly", data).items():
        found[name.split(",")[1].strip()] = load_mesh(f)
    found["parted"] = load_mesh(parted_lps(out, data))
    found["builtin"] = replace(builtin_morph_head().mesh, targets=None)
    return found


def mirrored(mesh):
    """``mesh`` mirrored in x, its winding reversed (normals outward)."""
    v = mesh.vertices.copy()
    v[:, 0] *= -1
    return replace(mesh, vertices=v, triangles=np.ascontiguousarray(mesh.triangles[:, ::-1]))


def jittered(mesh, seed: int, data: Path):
    """``mesh`` with its mouth jittered (JITTER, JITTER_REACH; Lee Perry-Smith's hand landmarks place the mouth)."""
    from assets.heads.landmarks import read_landmarks, shipped_landmarks
    from assets.heads.mesh import load_mesh
    from assets.heads.rigging import resolve_landmarks

    lps = data / "heads" / "lee-perry-smith" / "LeePerrySmith.glb"
    hand = shipped_landmarks(lps)
    assert hand is not None
    p = resolve_landmarks(read_landmarks(hand), load_mesh(lps).vertices, str(hand))
    eyes = [0.5 * (p[f"eye_outer_{s}"] + p[f"eye_inner_{s}"]) for s in ("left", "right")]
    iod = float(np.linalg.norm(eyes[0] - eyes[1]))
    mouth = 0.5 * (p["corner_left"] + p["corner_right"])
    pos, inv = np.unique(np.round(mesh.vertices, 9), axis=0, return_inverse=True)
    d = np.random.default_rng(seed).uniform(-JITTER, JITTER, pos.shape) * iod
    d[np.linalg.norm(pos - mouth, axis=1) > JITTER_REACH * iod] = 0.0
    return replace(mesh, vertices=mesh.vertices + d[inv.reshape(-1)])


def same_landmarks(name: str, mesh) -> None:
    """Rig ``mesh`` and its mirror image from the landmarks found on ``mesh``, mirrored; print both checks."""
    from assets.heads.head import rig_checked
    from clients.render.landmarks import find_landmarks

    def other_side(k: str) -> str:
        return k.replace("left", "#").replace("right", "left").replace("#", "right")

    found = {k: [float(x) for x in p] for k, p in dict(find_landmarks(mesh)).items()}
    flipped = {other_side(k): [-p[0], p[1], p[2]] for k, p in found.items()}
    for label, m, spec in (("as it is", mesh, found), ("mirrored", mirrored(mesh), flipped)):
        rig, _, report = rig_checked(replace(m, name="someone.glb"), spec)
        print(f"{name}, {label}: attempt {len(rig.meta.get('rig_attempts', [])) + 1}: {report.summary()}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--data", type=Path, default=shared_data_root())
    ap.add_argument("--only", default=None, help="only the heads whose name contains this text")
    ap.add_argument("--which", default="none,mirror", help="none, mirror, jitterN (comma-separated)")
    ap.add_argument("--three-quarter", action="store_true", help="also the mouth close-ups in three-quarter view")
    ap.add_argument("--same-landmarks", action="store_true", help="head and mirror from the head's landmarks")
    args = ap.parse_args()
    from head_testset import check_and_draw

    from assets.heads.glb import mesh_glb

    todo = {}
    for name, mesh in heads(args.out / "src", args.data).items():
        if args.only and args.only.lower() not in name.lower():
            continue
        if args.same_landmarks:
            same_landmarks(name, mesh)
            continue
        for way in args.which.split(","):
            if way.startswith("jitter") and name == "builtin":
                continue  # the jitter's mouth is Lee Perry-Smith's
            if way == "none":
                m = mesh
            else:
                m = mirrored(mesh) if way == "mirror" else jittered(mesh, int(way[6:]), args.data)
            d = args.out / f"{''.join(c if c.isalnum() else '_' for c in name.lower())}_{way}"
            d.mkdir(parents=True, exist_ok=True)
            (d / "someone.glb").write_bytes(mesh_glb(m))  # not a shipped name: automatic landmarks
            todo[f"{name} {way}"] = (d / "someone.glb", {"mode": "retarget"})

    def describe(head, report) -> tuple[str, str]:
        if head is None:
            return "opening; attempt; landmark set", ""
        meta = head.rig.meta
        opening = "n/a" if report is None or report.open_response is None else f"{report.open_response:.2f}"
        return "", f"{opening}; attempt {len(meta.get('rig_attempts', [])) + 1}; set {meta.get('landmark_set', 0)}"

    if todo:
        print("\n".join(check_and_draw(todo, args.out / "img", describe=describe, three_quarter=args.three_quarter)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
