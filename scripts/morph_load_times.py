"""How long a head driven by its own morph targets takes to load, cold (nothing of it in the cache) and warm (issue 12).

    python scripts/morph_load_times.py [--out build/morph_load] [--runs 5] [--code DIR]

Four heads, made here from the built-in head and its source (nothing downloaded beyond them): the held-out Character
Creator 4 export with its targets (``heldout_heads.character_creator_glb``), the test set's ARKit glb (exporter
spellings, as ``head_testset.derive`` writes it), a VRM 1.0 avatar (``tests/assets/heads/test_vrm_heads._vrm``) and
the held-out full-body avatar with its targets, uncompressed (``heldout_heads.avatar_glb``). Each is loaded
as the commands load a head (``resolve_head`` with the automatic landmark finder), in a new process each time, the
time of that call alone (imports outside it): once in a fresh cache holding only the built-in head's file (cold),
then ``--runs`` times in that cache (warm). ``--code DIR``: the facecast checkout the loads run (another commit's
export, e.g. ``git archive <commit> | tar -x -C DIR``), for a before/after; the heads are made with this one.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

ONE_LOAD = r"""
import json, sys, time
from assets.heads.head import resolve_head
from clients.render.landmarks import find_landmarks
import assets.heads.cavity, assets.heads.targets, realtime_core.face.checks  # imported outside the timing
t = time.perf_counter()
head = resolve_head(sys.argv[1], landmark_finder=find_landmarks)
print(json.dumps({"s": time.perf_counter() - t, "kind": head.kind, "n": len(head.mesh.vertices)}))
"""


def make_heads(out: Path) -> list[Path]:
    """The four heads, written into ``out``."""
    from heldout_heads import avatar_glb, character_creator_glb

    from assets.heads.builtin import load_builtin_head
    from assets.heads.glb import mesh_glb
    from assets.heads.head import builtin_morph_head
    from assets.heads.mesh import HeadMesh
    from tests.assets.heads.test_vrm_heads import _vrm

    out.mkdir(parents=True, exist_ok=True)
    cc4 = character_creator_glb(out / "cc4_targets.glb", with_targets=True)
    b = builtin_morph_head().mesh
    arkit = out / "arkit.glb"
    targets = {"blendShape1." + k.replace("Left", "_L").replace("Right", "_R"): d for k, d in (b.targets or {}).items()}
    mesh = HeadMesh(vertices=b.vertices, triangles=b.triangles, colors=b.colors, name="a", targets=targets)
    arkit.write_bytes(mesh_glb(mesh))
    vrm = _vrm(out / "avatar.vrm", load_builtin_head(), "1.0")
    body = avatar_glb(out / "fullbody_targets.glb", with_targets=True)
    return [cc4, arkit, vrm, body]


def load_once(head: Path, cache: Path, code: Path) -> dict:
    env = {**os.environ, "FACECAST_CACHE": str(cache), "PYTHONPATH": str(code)}
    done = subprocess.run(
        [sys.executable, "-c", ONE_LOAD, str(head)], env=env, cwd=code, capture_output=True, text=True, check=False
    )
    if done.returncode:
        raise SystemExit(f"{head}: {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "build" / "morph_load")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--code", type=Path, default=REPO)
    args = ap.parse_args()
    from assets.heads.builtin import HEAD_FILE
    from assets.heads.cache import cache_dir

    heads = make_heads(args.out)
    print("| head | kind | vertices | cold (s) | warm (s), each run | warm, min (s) |")
    print("|---|---|---|---|---|---|")
    for head in heads:
        cache = Path(tempfile.mkdtemp(prefix="cache_", dir=args.out))
        shutil.copy(cache_dir() / HEAD_FILE, cache / HEAD_FILE)  # the built-in head only: cold for this head
        try:
            cold = load_once(head, cache, args.code.resolve())
            warm = [load_once(head, cache, args.code.resolve())["s"] for _ in range(args.runs)]
        finally:
            shutil.rmtree(cache)
        each = " ".join(f"{w:.2f}" for w in warm)
        row = f"| {head.name} | {cold['kind']} | {cold['n']} | {cold['s']:.2f} | {each} | {min(warm):.2f} |"
        print(row, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
