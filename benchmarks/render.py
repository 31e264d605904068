"""Animation benchmarks (prints figures, asserts nothing): rig application and offline rendering.

    python -m benchmarks.render [--frames 200] [--quick]

1. Per-frame cost of applying a rig, ``rig.displacements(params)`` (one (n_s*3, 4) product and one
   CSR product), for the built-in head and for a synthetic 10,000-vertex rig with the same
   structure (3 control points per vertex); median and 99th percentile in microseconds.
2. Frames per second of the moderngl renderer at 640x480 for the built-in head (deform + upload +
   draw + MSAA resolve + read-back), for 0, 2 and 4 MSAA samples.
BLAS is pinned to one thread (threadpoolctl) as in the server.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp


def _percentiles(samples_s: list[float]) -> tuple[float, float]:
    a = np.asarray(samples_s) * 1e6
    return float(np.median(a)), float(np.percentile(a, 99))


def time_rig(rig, n: int) -> tuple[float, float]:
    """Median and p99 (us) of rig.displacements over n random parameter vectors."""
    rng = np.random.default_rng(0)
    ps = rng.normal(scale=0.05, size=(n, 4)).astype(np.float32)
    for p in ps[:20]:
        rig.displacements(p)
    out = []
    for p in ps:
        t = time.perf_counter()
        rig.displacements(p)
        out.append(time.perf_counter() - t)
    return _percentiles(out)


def synthetic_rig(n_head: int = 10_000, n_simple: int = 220):
    """A Rig with n_head moving vertices, each following 3 random control points (Sec. 5 structure)."""
    from realtime_core.face import FaceModel, MouthCalibration, Rig

    rng = np.random.default_rng(1)
    cols = np.stack([rng.choice(n_simple, 3, replace=False) for _ in range(n_head)])
    w = rng.dirichlet(np.ones(3), size=n_head)
    g = sp.csr_matrix((w.ravel(), (np.repeat(np.arange(n_head), 3), cols.ravel())), shape=(n_head, n_simple))
    simple = FaceModel(vertices=rng.normal(size=(n_simple, 3)), triangles=np.zeros((0, 3), int), name="synthetic")
    cal = MouthCalibration(groups=(("a",), ("b",), ("c",), ("d",)), response=np.eye(4), matrix=np.eye(4))
    return Rig(
        neutral=rng.normal(size=(n_head, 3)).astype(np.float32),
        triangles=np.zeros((0, 3), np.int32),
        moving=np.arange(n_head),
        matrix=sp.kron(g, sp.identity(3), format="csr"),
        basis=rng.normal(size=(n_simple * 3, 4)),
        control=np.arange(n_simple),
        simple=simple,
        calibration=cal,
    )


def time_render(rig, mesh, samples: int, frames: int) -> float:
    from clients.render.renderer import RenderConfig, renderer_for_rig

    with renderer_for_rig(rig, mesh, RenderConfig(width=640, height=480, samples=samples)) as r:
        ps = np.zeros((frames, 4))
        ps[:, 2] = 0.1 * (1 + np.sin(np.arange(frames) / 3)) / 2
        r.render(rig.deformed(ps[0]))
        t = time.perf_counter()
        for p in ps:
            r.render(rig.deformed(p))
        return frames / (time.perf_counter() - t)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=200, help="frames per render measurement")
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits

    from clients.heads.rigfile import builtin_rig

    n_rig = 2000 if args.quick else 20000
    frames = 50 if args.quick else args.frames
    with threadpool_limits(limits=1):
        rig, mesh = builtin_rig()
        print("rig application (rig.displacements, float32), goal < 100 us for 10k vertices")
        for name, r in (("built-in head", rig), ("synthetic 10k", synthetic_rig())):
            med, p99 = time_rig(r, n_rig)
            print(f"  {name:15s} {len(r.moving):6d} moving, nnz {r.matrix.nnz:6d}: median {med:6.1f} us, p99 {p99:6.1f} us")
        print(f"rendering 640x480, built-in head ({len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles), goal >= 200 fps")
        for s in (0, 2, 4):
            print(f"  MSAA {s}: {time_render(rig, mesh, s, frames):6.1f} fps (deform + upload + draw + resolve + read-back)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
