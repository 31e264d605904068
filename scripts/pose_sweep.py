"""Sweep: the rig checks' per-pose figures on every head of the test set and the held-out heads at many poses.

    python scripts/pose_sweep.py --out /tmp/sweep [--data ../shared/data] [--only TEXT] [--sets grid,extreme,say,test]

Issue 12's goals hold "at any pose"; :func:`realtime_core.face.checks.check_rig` measures them at
EXTREME_POSES only. This deforms each head (made as ``scripts/head_testset.py`` and
``scripts/heldout_heads.py`` make them) at four pose sets and reports, per head and set, the worst of
:func:`realtime_core.face.checks.pose_figures` (flipped triangles, max edge stretch, lip interpenetration,
teeth ahead of the lips) and the pose where each is worst:

- test: every frame (or every --test-stride-th) the shipped default model produces on the audio of the GRID s1
  test split (reporting only: nothing is tuned on it), as ``scripts/measure_param_box.py`` runs the live path;
- say: ``facecast say`` on --say-texts sentences with each expression (smile, sad, surprise, anger) at
  intensity 1;
- grid: 5 levels of each parameter over training.params.TYPICAL_RANGES (625 poses);
- hull: 600 random poses inside the hull of every checked pose (:func:`hull_poses`);
- extreme: the checks' EXTREME_POSES.

Prints a Markdown table (docs/animation.md, "Sweep: the goals at any pose") and writes OUT/sweep.json (per
head and set: the figures, their worst poses, the faces flipped at the worst flip pose).
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))
from assets.shared import shared_data_root  # noqa: E402 (after the path: a worktree's own package)

EXPRESSIONS = ("smile", "sad", "surprise", "anger")
LEVELS = 5


def grid_poses() -> np.ndarray:
    """(LEVELS**4, 4) every combination of LEVELS evenly spaced values of each parameter's typical range."""
    from training.params import TYPICAL_RANGES, VISUAL_PARAMS

    axes = [np.linspace(*TYPICAL_RANGES[name], LEVELS) for name in VISUAL_PARAMS]
    return np.array(list(itertools.product(*axes)), dtype=np.float64)


def hull_poses(n: int = 600, seed: int = 12) -> np.ndarray:
    """(n, 4) poses inside the hull of every checked pose (``checked_bound()``), at random: half on segments between
    two of its vertices, half convex combinations of four (Dirichlet 0.5). A head drives them through its own bound:
    a rig flip-free at the poses of its hull can still fold between them (the field is linear in the parameters, a
    triangle's orientation is not)."""
    from realtime_core.face.checks import checked_bound

    v = np.asarray(checked_bound().poses, dtype=np.float64)
    rng = np.random.default_rng(seed)
    half = n // 2
    pairs = rng.integers(0, len(v), size=(half, 2))
    t = rng.random((half, 1))
    quads = rng.integers(0, len(v), size=(n - half, 4))
    w = rng.dirichlet(np.full(4, 0.5), size=n - half)
    return np.vstack([(1 - t) * v[pairs[:, 0]] + t * v[pairs[:, 1]], np.einsum("ij,ijk->ik", w, v[quads])])


def pose_sets(data: Path, sets: list[str], say_texts: int, test_stride: int = 1) -> dict[str, np.ndarray]:
    """name -> (P, 4) poses; ``test_stride``: every so many frames of the test set."""
    from measure_param_box import SAY_TEXTS, model_frames, say_frames

    from assets.grid import split_of
    from realtime_core.face.checks import EXTREME_POSES

    out: dict[str, np.ndarray] = {}
    for s in sets:
        if s == "test":
            videos = (data / "video" / "grid_s1" / "video").glob("*.mp4")
            clips = sorted(p for p in videos if split_of(p.stem) == "test")
            if not clips:
                raise SystemExit(f"{data}: no GRID s1 test sentences (give --data)")
            out[s] = model_frames("default", clips)[::test_stride]
        elif s == "say":
            out[s] = np.concatenate([say_frames(SAY_TEXTS[:say_texts], extra=("--expression", e)) for e in EXPRESSIONS])
        elif s == "grid":
            out[s] = grid_poses()
        elif s == "hull":
            out[s] = hull_poses()
        elif s == "extreme":
            out[s] = np.asarray(EXTREME_POSES, dtype=np.float64)
        else:
            raise SystemExit(f"unknown pose set {s!r} (test, say, grid, hull, extreme)")
    return out


def sweep(head, poses: np.ndarray, finder) -> dict:
    """The worst of each per-pose figure over ``poses`` and where it is worst (as lists, for JSON)."""
    from assets.heads.head import head_check_inputs
    from realtime_core.face import face_frame
    from realtime_core.face.checks import flipped_faces, pose_figures

    landmarks, inputs = head_check_inputs(head, landmark_finder=finder)
    per = pose_figures(
        head.rig, landmarks, poses, lip_pairs=inputs["lip_pairs"], teeth=inputs["teeth"], reference=inputs["reference"]
    )
    res: dict = {"poses": len(poses)}
    for key, arr in (
        ("flipped", per.flipped),
        ("stretch", per.stretch),
        ("interpenetration", per.interpenetration),
        ("teeth_ahead", per.teeth_ahead),
    ):
        if arr is None:
            res[key] = None
            continue
        k = int(np.argmax(arr))
        res[key] = float(arr[k]) if key != "flipped" else int(arr[k])
        res[key + "_pose"] = [round(float(x), 4) for x in per.poses[k]]
    res["poses_flipping"] = int((per.flipped > 0).sum())
    res["poses_interpenetrating"] = int((per.interpenetration > 0.005).sum())
    if res["flipped"]:
        v0 = np.asarray(head.rig.neutral, dtype=np.float64)
        ref = v0 if inputs["reference"] is None else np.asarray(inputs["reference"], dtype=np.float64)
        v = np.asarray(head.rig.deformed(np.asarray(res["flipped_pose"])), dtype=np.float64)
        res["flipped_faces"] = [
            int(f) for f in flipped_faces(v, ref, head.rig.triangles, face_frame(v0, landmarks).iod)
        ]
    return res


def smile_reach(head) -> dict:
    """How far a full smile on speech goes through the head's bound, against the bound of every checked pose: the
    smile (intensity 1, ``add_expression``) on each of EXTREME_POSES, bounded both ways. Returns how many
    expression poses the rig holds (of how many), the mean lip_stretch either way (IOD), the largest distance
    between the two (IOD) and the smallest fraction of the smile's change from speech the head keeps."""
    from realtime_core.expressions import EXPRESSIONS, add_expression
    from realtime_core.face.checks import EXPRESSION_POSES, EXTREME_POSES, checked_bound
    from realtime_core.fitted_maps import EXPRESSION_PARAMS

    speech = np.asarray(EXTREME_POSES, dtype=np.float64)
    smile = add_expression(speech, np.tile(EXPRESSION_PARAMS[EXPRESSIONS.index("smile")], (len(speech), 1)))
    full, own = checked_bound()(smile), head.rig.bound(smile)
    change = np.linalg.norm(full - speech, axis=1)
    moved = change > 1e-9
    kept = np.linalg.norm(own - speech, axis=1)[moved] / change[moved]
    checks = head.rig.meta.get("checks")
    held = checks.get("expressions_held") if isinstance(checks, dict) else None
    return {
        "expressions_held": None if held is None else len(held),
        "expression_poses": len(EXPRESSION_POSES),
        "smile_lip_stretch": round(float(own[:, 1].mean()), 4),
        "smile_lip_stretch_full": round(float(full[:, 1].mean()), 4),
        "smile_cut_iod": round(float(np.linalg.norm(own - full, axis=1).max()), 4),
        "smile_kept": round(float(kept.min()), 3),
    }


def cell(r: dict | None) -> str:
    """flipped / stretch / interpenetration / teeth ahead, as one table cell."""
    if r is None:
        return "-"
    teeth = "n/a" if r["teeth_ahead"] is None else f"{r['teeth_ahead']:.3f}"
    return f"{r['flipped']} / {r['stretch']:.2f} / {r['interpenetration']:.4f} / {teeth}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="derived head files and sweep.json")
    ap.add_argument("--data", type=Path, default=shared_data_root())
    ap.add_argument("--only", default=None, help="only the heads whose name contains this text")
    ap.add_argument("--sets", default="grid,extreme,say,test", help="comma-separated pose sets")
    ap.add_argument("--say-texts", type=int, default=3, help="`facecast say` sentences per expression")
    ap.add_argument("--test-stride", type=int, default=1, help="every so many frames of the test set (30 fps)")
    args = ap.parse_args()
    import head_testset
    import heldout_heads
    from head_testset import _resolve

    from assets.progress import Progress
    from clients.render.landmarks import find_landmarks
    from realtime_core.errors import FacecastError

    heads = head_testset.derive(args.out / "heads", args.data)
    heads.update(heldout_heads.derive(args.out / "heldout", args.data))
    if args.only:
        heads = {k: v for k, v in heads.items() if args.only.lower() in k.lower()}
    sets = pose_sets(args.data, args.sets.split(","), args.say_texts, args.test_stride)
    results: dict[str, dict[str, dict | None]] = {}
    reach: dict[str, dict] = {}
    for name, (spec, opts) in Progress(heads.items(), desc="heads"):
        try:
            head = _resolve(spec, opts, find_landmarks)
        except FacecastError as exc:
            print(f"{name}: cannot rig ({exc})", file=sys.stderr)
            results[name] = {s: None for s in sets}
            continue
        results[name] = {}
        reach[name] = smile_reach(head)
        print(f"{name} [bound]: {reach[name]}", file=sys.stderr)
        for s, poses in sets.items():
            try:
                results[name][s] = sweep(head, poses, find_landmarks)
            except FacecastError as exc:  # no landmarks: not measurable, as the test set's table says
                print(f"{name}: not checked ({exc})", file=sys.stderr)
                results[name][s] = None
            print(f"{name} [{s}]: {results[name][s]}", file=sys.stderr)
    args.out.mkdir(parents=True, exist_ok=True)
    doc = {"poses": {s: len(p) for s, p in sets.items()}, "heads": results, "bound": reach}
    (args.out / "sweep.json").write_text(json.dumps(doc))
    print("| head | " + " | ".join(f"{s} ({len(p)} poses)" for s, p in sets.items()) + " |")
    print("|---|" + "---|" * len(sets))
    for name, per_set in results.items():
        print(f"| {name} | " + " | ".join(cell(per_set[s]) for s in sets) + " |")
    # The head's bound (smile_reach): expression poses held; a full smile on speech, mean lip_stretch (IOD) through
    # the head's bound (every checked pose's); largest cut (IOD); smallest fraction of the smile's change kept.
    print("\n| head | expression poses held | smile mean lip_stretch (all poses) | largest cut (IOD) | least kept |")
    print("|---|---|---|---|---|")
    for name, r in reach.items():
        n = r["expressions_held"]
        held = "not measured" if n is None else f"{n} of {r['expression_poses']}"
        print(
            f"| {name} | {held} | {r['smile_lip_stretch']:.3f} ({r['smile_lip_stretch_full']:.3f}) | "
            f"{r['smile_cut_iod']:.3f} | {r['smile_kept']:.2f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
