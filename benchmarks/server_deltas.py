"""What a vertex viewer's frame costs the server, one at a time or several back to back (prints JSON).

A delta frame (``server.session.Frame.payload(KIND_DELTAS, ...)``: the head's keyframe solve, the
(P, n_moving*3) product over the targets, the int16 encoding) is computed either in each
connection's callback, between other sessions' work, or for all the frames of a loop turn together
(:class:`server.live.TurnDeltas`). Here the other work is stood in for by a sweep over ``--evict-mb``
of memory between groups (0: everything stays in cache; 32: the L3 of this machine), and B frames
are computed back to back per group: CPU time per frame for B = 1..8, one ``Frame.payload`` at a time
and (a morph head) all B in one ``server.session.morph_delta_payloads`` call, as ``TurnDeltas`` does,
against the numpy reference frame by frame (the server's path before the compiled one), alternating.
Also numpy's one-pass product ``(B, P) @ (P, n)`` and the compiled one (``MorphRig.displacements_rows``)
against B row products (BLAS pinned to one thread as in the server): time per frame and whether each
gives the same bytes as the rows one by one. On a head with face shapes, what an expression adds to a frame: the
delta payloads and the morph weights with none and with a surprise, interleaved (``expression_per_frame_us``).

``python -m benchmarks.server_deltas [--evict-mb 0,2,32] [--repeats 200]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evict-mb", default="0,2,32", help="memory swept between groups (MB, comma-separated)")
    ap.add_argument("--repeats", type=int, default=200)
    ap.add_argument("--batch", default="1,2,4,8", help="frames per group (comma-separated)")
    args = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits

    from assets.heads.head import resolve_head
    from realtime_core.face.keyframes import MorphRig
    from server.session import Frame, morph_delta_payloads
    from wire import protocol as P

    rig = resolve_head("builtin").rig
    rng = np.random.default_rng(0)
    params = rng.normal(0.0, 0.05, (256, 4))
    params[:, 1] = np.abs(params[:, 1])
    sizes = [int(b) for b in args.batch.split(",")]
    report: dict = {"rig": type(rig).__name__, "moving": len(rig.moving), "per_frame_us": {}}
    with threadpool_limits(1):
        for mb in (int(x) for x in args.evict_mb.split(",")):
            junk = np.ones(max(mb, 1) << 20, dtype=np.uint8)
            row: dict = {}
            for b in sizes:
                cpu = []
                for r in range(args.repeats):
                    if mb:
                        junk[::64] += 1  # one write per cache line: the rest of the turn's work
                    frames = [
                        Frame(i, 0.0, params[(r * b + i) % len(params)], params[0], 0.0, 0.0, rig) for i in range(b)
                    ]
                    t0 = time.thread_time_ns()
                    for f in frames:
                        f.payload(P.KIND_DELTAS, P.ENC_INT16)
                    cpu.append((time.thread_time_ns() - t0) / b / 1e3)
                row[f"B={b}"] = round(float(np.median(cpu)), 1)
                if isinstance(rig, MorphRig):
                    # All B in one call, as TurnDeltas does, interleaved (alternating order) with the
                    # numpy reference frame by frame, as the server computed them before (rig.displacements,
                    # wire.protocol.encode_payload): the same memory sweeps before each.
                    together, reference = [], []
                    for r in range(args.repeats):
                        ps = [params[(r * b + i) % len(params)] for i in range(b)]
                        for which in (0, 1) if r % 2 else (1, 0):
                            if mb:
                                junk[::64] += 1
                            if which == 0:
                                t0 = time.thread_time_ns()
                                for p in ps:
                                    P.encode_payload(rig.displacements(p), P.ENC_INT16)
                                reference.append((time.thread_time_ns() - t0) / b / 1e3)
                            else:
                                frames = [Frame(i, 0.0, p, p, 0.0, 0.0, rig) for i, p in enumerate(ps)]
                                t0 = time.thread_time_ns()
                                morph_delta_payloads(frames, P.ENC_INT16)
                                together.append((time.thread_time_ns() - t0) / b / 1e3)
                    row[f"B={b} together"] = round(float(np.median(together)), 1)
                    row[f"B={b} numpy frame by frame"] = round(float(np.median(reference)), 1)
            report["per_frame_us"][f"evict {mb} MB"] = row
        if isinstance(rig, MorphRig) and rig.n_face:
            report["expression_per_frame_us"] = expression_costs(rig, params, args, sizes)
        if isinstance(rig, MorphRig):  # a morph head: the one-pass product against the row products
            rows = rig._rows
            w = rig.weights(params[:8])
            gemm: dict = {}
            for b in sizes:
                wb = np.ascontiguousarray(w[:b])
                by_row = np.stack([np.dot(x, rows) for x in wb])
                same = bool(np.array_equal(wb @ rows, by_row))
                compiled_same = bool(np.array_equal(rig.displacements_rows(wb), by_row))
                t = []
                for _ in range(args.repeats):
                    t0 = time.thread_time_ns()
                    wb @ rows
                    t1 = time.thread_time_ns()
                    for x in wb:
                        np.dot(x, rows)
                    t2 = time.thread_time_ns()
                    rig.displacements_rows(wb)
                    t.append(((t1 - t0) / b / 1e3, (t2 - t1) / b / 1e3, (time.thread_time_ns() - t2) / b / 1e3))
                med = np.median(np.array(t), axis=0)
                one_pass, by_rows, compiled = (round(float(x), 1) for x in med)
                gemm[f"B={b}"] = {
                    "one_pass_us": one_pass,
                    "rows_us": by_rows,
                    "same_bytes": same,
                    # MorphRig.displacements_rows: the server's fixed-order kernel (equal to BLAS only to
                    # rounding in general; whether its bytes happen to equal this BLAS's rows)
                    "compiled_us": compiled,
                    "compiled_same_bytes_as_rows": compiled_same,
                }
            report["product_per_frame_warm"] = gemm
    print(json.dumps(report, indent=1))
    return report


def expression_costs(rig, params: np.ndarray, args: argparse.Namespace, sizes: list[int]) -> dict:
    """CPU time per frame of the int16 delta payloads (``morph_delta_payloads``, B frames together) and of the morph
    weights (``Frame.payload(KIND_MORPH)``) with no expression and with a surprise at full intensity, interleaved
    (alternating order) after the same memory sweeps: what the head's face shapes (MorphRig.n_face targets, the
    vertices only they move) add to a frame that shows an expression; a frame without one skips them
    (MorphRig.active)."""
    from realtime_core.expressions import EXPRESSIONS
    from server.session import Frame, morph_delta_payloads
    from wire import protocol as P

    surprise = np.zeros(len(EXPRESSIONS))
    surprise[EXPRESSIONS.index("surprise")] = 1.0
    out: dict = {}
    for mb in (int(x) for x in args.evict_mb.split(",")):
        junk = np.ones(max(mb, 1) << 20, dtype=np.uint8)
        for b in sizes:
            cost: dict[str, list[float]] = {
                k: [] for k in ("deltas none", "deltas surprise", "morph none", "morph surprise")
            }
            for r in range(args.repeats):
                ps = [params[(r * b + i) % len(params)] for i in range(b)]
                for which in ("none", "surprise") if r % 2 else ("surprise", "none"):
                    e = None if which == "none" else surprise
                    frames = [
                        Frame(i, 0.0, p, p, 0.0, 0.0, rig, expression=e, speech_params=p) for i, p in enumerate(ps)
                    ]
                    if mb:
                        junk[::64] += 1
                    t0 = time.thread_time_ns()
                    morph_delta_payloads(frames, P.ENC_INT16)
                    cost[f"deltas {which}"].append((time.thread_time_ns() - t0) / b / 1e3)
                    if mb:
                        junk[::64] += 1
                    t0 = time.thread_time_ns()
                    for f in frames:
                        f.payload(P.KIND_MORPH, P.ENC_FLOAT32)
                    cost[f"morph {which}"].append((time.thread_time_ns() - t0) / b / 1e3)
            med = {k: float(np.median(v)) for k, v in cost.items()}
            out[f"evict {mb} MB, B={b}"] = {k: round(v, 1) for k, v in med.items()} | {
                "deltas ratio": round(med["deltas surprise"] / med["deltas none"], 2),
                "morph ratio": round(med["morph surprise"] / med["morph none"], 2),
            }
    return out


if __name__ == "__main__":
    main()
