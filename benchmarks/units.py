"""Unit-selection benchmarks (prints figures, asserts nothing): search speed, `facecast say` to MP4,
first frame of a server text session.

    python -m benchmarks.units [--corpus C.npz] [--sentences 40] [--skip-say] [--skip-server]

1. **Search**: the Viterbi unit search (:func:`realtime_core.synthesis.search.select_units`) for
   20-phone targets over the whole corpus graph: espeak-ng phones of varied English sentences cut
   to their first 20 phones. Median / p95 / max in ms, the active-state cap's cost against an exact
   search (max_active=None), and the graph build time. Then every 8th corpus sentence from its own
   phones (it must select itself as one zero-cost unit and reproduce its motion), and how much
   recorded context everyday English and Spanish text gets (units, junctions outside the corpus),
   and what averaging ``n_best`` unit sequences costs on the say sentence.
2. **say**: command to MP4 for a 10-word sentence, in-process after start-up (imports, corpus and
   graph are loaded once first): speech synthesis + unit selection + the built-in head resolved as
   the command resolves it (its morph rig from the cache) + rendering and encoding, median of 3,
   with `facecast say`'s defaults (no MSAA, x264 veryfast) and the former ones (MSAA 4, medium);
   also the CPU time (this process and ffmpeg), which is what an otherwise idle machine would take.
3. **server**: a real server over loopback with a text session on this corpus; a viewer watches;
   the time from sending the first text piece (a complete sentence) to the viewer receiving frame 0,
   median of 5 sessions.
BLAS is pinned to one thread (threadpoolctl) as in the server.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import time

import numpy as np

SENTENCES = (
    "Please put the blue box on the table by nine tonight.",
    "The weather today is much better than it was last week.",
    "Could you tell me the way to the nearest train station?",
    "I would like a cup of coffee with milk and no sugar.",
    "We have been working on this project for several months now.",
    "She sells sea shells by the sea shore every summer morning.",
    "My brother bought a new red car for his long drive home.",
    "All of the students passed the final exam with good marks.",
)
SPANISH = (
    "Hola, me llamo Pedro y vivo en Madrid.",
    "El tiempo hoy es mucho mejor que la semana pasada.",
    "¿Puede decirme dónde está la estación de tren?",
    "Quiero un café con leche y sin azúcar, por favor.",
    "Los estudiantes aprobaron el examen final con buenas notas.",
    "Mañana vamos a la playa con mis amigos.",
)
GRID_VOCABULARY = (
    "bin blue at f two now",
    "place red by z nine again",
    "set white with p four please",
    "lay green in a six soon",
)
SAY_TEXT = "Please put the blue box on the table by nine tonight."  # ten words


def bench_search(stored, n: int) -> None:
    from assets.tts import speak
    from realtime_core.synthesis.search import SearchConfig, build_graph, select_units
    from realtime_core.synthesis.synthesizer import make_target

    t0 = time.perf_counter()
    graph = build_graph(stored.corpus, SearchConfig())
    exact = build_graph(stored.corpus, SearchConfig(max_active=None))
    print(
        f"graph build: {1000 * (time.perf_counter() - t0) / 2:.0f} ms for {stored.corpus.n_phones} states "
        f"({stored.corpus.n_sentences} sentences)"
    )
    targets = []
    for text in (SENTENCES * ((n // len(SENTENCES)) + 1))[:n]:
        s = speak(text)
        tg = make_target(s.phones, s.inventory, stored.corpus.visemes_present())
        targets.append((tg.visemes[:20], tg.durations_s[:20]))
    for tv, td in targets[:3]:
        select_units(graph, tv, td)  # warm-up
    times, gaps = [], []
    for tv, td in targets:
        t = time.perf_counter()
        sel = select_units(graph, tv, td)
        times.append(1000 * (time.perf_counter() - t))
        gaps.append(sel.cost - select_units(exact, tv, td).cost)
    a = np.asarray(times)
    print(
        f"unit search, 20-phone targets x {n} (goal < 50 ms): median {np.median(a):.1f} ms, "
        f"p95 {np.percentile(a, 95):.1f} ms, max {a.max():.1f} ms"
    )
    g = np.asarray(gaps)
    print(
        f"active-state cap {graph.config.max_active} vs exact search: path cost equal in {np.mean(g < 1e-9):.0%} "
        f"of targets, mean excess {g.mean():.3f}, max {g.max():.3f}"
    )


def check_self_selection(stored, step: int = 8) -> None:
    """Every ``step``-th corpus sentence from its own phones: one unit, zero cost, its motion exactly."""
    from realtime_core.synthesis.synthesizer import UnitSynthesizer

    c = stored.corpus
    synth = UnitSynthesizer(c)
    picked = range(0, c.n_sentences, step)
    one = exact = 0
    for s in picked:
        a, b = c.phone_offsets[s], c.phone_offsets[s + 1]
        phones = [(c.phone_labels[q], c.phone_start_s[q], c.phone_end_s[q]) for q in range(a, b)]
        n = int(c.frame_offsets[s + 1] - c.frame_offsets[s])
        res = synth.synthesize(phones, "arpabet", n_frames=n)
        one += res.selection.n_units == 1 and res.selection.cost == 0.0
        t = np.arange(n) / 30.0
        covered = (t >= c.phone_start_s[a]) & (t <= c.phone_end_s[b - 1])
        exact += float(np.abs(res.frames[covered] - c.sentence_frames(s)[covered]).max()) < 1e-5
    print(
        f"corpus sentences from their own phones: {one}/{len(picked)} select themselves as one zero-cost unit, "
        f"{exact}/{len(picked)} reproduce their recorded motion exactly"
    )


def bench_languages(stored) -> None:
    """How much recorded context text outside the corpus's vocabulary or language gets."""
    from assets.tts import speak
    from realtime_core.synthesis.synthesizer import UnitSynthesizer

    synth = UnitSynthesizer(stored.corpus, rest=stored.rest_frame())
    print("| text | phones | phones per unit | junctions outside the recorded divisemes (per phone) |")
    print("|---|---|---|---|")
    for name, texts, lang in (
        ("GRID vocabulary (English)", GRID_VOCABULARY, "en"),
        ("everyday English", SENTENCES[:6], "en"),
        ("everyday Spanish", SPANISH, "es"),
    ):
        phones = units = junctions = 0
        for text in texts:
            s = speak(text, language=lang)
            res = synth.synthesize(list(s.phones), s.inventory)
            phones += len(res.target.labels)
            units += res.selection.n_units
            junctions += res.selection.n_mismatched
        print(f"| {len(texts)} sentences, {name} | {phones} | {phones / units:.1f} | {junctions / phones:.2f} |")


def bench_n_best(stored, repeats: int = 3) -> None:
    """What averaging ``n_best`` unit sequences costs: synthesis of the say sentence (search(es),
    warping, the ensemble), median of ``repeats``."""
    from assets.tts import speak
    from realtime_core.synthesis.synthesizer import UnitSynthesizer

    synth = UnitSynthesizer(stored.corpus, rest=stored.rest_frame())
    s = speak(SAY_TEXT)
    phones = list(s.phones)
    synth.synthesize(phones, s.inventory)  # warm-up
    cells = []
    for n in (1, 3, 5, 10):
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            synth.synthesize(phones, s.inventory, n_best=n)
            ts.append(1000 * (time.perf_counter() - t))
        cells.append(f"n_best={n} {np.median(ts):.0f} ms")
    print(f"unit synthesis of the say sentence ({len(phones)} phones): " + ", ".join(cells))


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (ffmpeg)."""
    import resource

    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def bench_say(stored, repeats: int = 3, samples: int = 0, preset: str = "veryfast") -> None:
    """``facecast say``'s work for the 10-word sentence, in-process: speech, units, the head as the
    command resolves it (``resolve_head("builtin")``: the built-in head through its own targets, its
    morph rig read from the cache) and render + encode, all inside the clock. The corpus and graph are
    loaded once first (the command's "corpus + graph" lap), and the imports and numba's per-process
    set-up are paid once per process, not per repeat."""
    import tempfile
    from pathlib import Path

    from assets.audio import write_wav
    from assets.heads.head import resolve_head
    from assets.heads.landmarks import credit_for
    from assets.tts import speak
    from clients.render.renderer import RenderConfig, renderer_for_rig
    from clients.render.video import VideoConfig, with_caption, write_video
    from realtime_core.synthesis.synthesizer import UnitSynthesizer

    synth = UnitSynthesizer(stored.corpus, rest=stored.rest_frame())
    # Once before the clock so the timed runs read the morph rig cache, as every `facecast say` after
    # the first does (a cold cache builds it: a one-off ~0.8 s, docs/unit_selection.md).
    kind = resolve_head("builtin").kind
    k = stored.corpus.n_coefficients
    cfg = RenderConfig(width=640, height=480, samples=samples)
    totals, parts, cpus = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeats):
            t0 = time.perf_counter()
            c0 = _cpu_s()
            s = speak(SAY_TEXT)
            t1 = time.perf_counter()
            res = synth.synthesize(list(s.phones), s.inventory, n_frames=int(np.ceil(s.duration_s * 30)))
            t2 = time.perf_counter()
            rig, mesh = resolve_head("builtin")
            credit = credit_for(mesh.name)
            t3 = time.perf_counter()
            wav = write_wav(Path(tmp) / "s.wav", s.samples, s.sample_rate_hz)
            with renderer_for_rig(rig, mesh, cfg) as r:
                write_video(
                    res.frames[:, k:],
                    lambda p, r=r, rig=rig, c=credit: with_caption(r.render(rig.deformed(p)), c),  # as `say` draws
                    Path(tmp) / f"say{i}.mp4",
                    size=(cfg.width, cfg.height),
                    audio=wav,
                    config=VideoConfig(fps=30.0, preset=preset),
                )
            t4 = time.perf_counter()
            cpus.append(_cpu_s() - c0)
            totals.append(t4 - t0)
            parts.append((t1 - t0, t2 - t1, t3 - t2, t4 - t3, len(res.frames)))
    i = int(np.argsort(totals)[len(totals) // 2])
    sp, us, hd, rv, nf = parts[i]
    print(
        f"say, 10 words ({nf} frames, 640x480, MSAA {samples}, x264 {preset}) command to MP4 after start-up, "
        f"head resolve_head('builtin') = {kind} rig from the cache, inside the clock (goal < 2 s): median "
        f"{np.median(totals):.2f} s = speech {1000 * sp:.0f} ms + units {1000 * us:.0f} ms + head {1000 * hd:.0f} ms "
        f"+ render/encode {1000 * rv:.0f} ms ({1000 * rv / nf:.1f} ms/frame); CPU time (this process + ffmpeg, "
        f"what an idle machine would take) {np.median(cpus):.2f} s; load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} cores"
    )


def bench_server(corpus_path, repeats: int = 5) -> None:
    from websockets.asyncio.client import connect

    from assets.modelfile import load_model
    from clients.client import ViewerClient
    from server.app import FacecastServer
    from server.config import ServerConfig
    from server.text_session import espeak_backend

    async def one(srv, name: str) -> float:
        url = srv.url.replace("http", "ws")
        async with connect(url + "/text") as ws:
            await ws.send(json.dumps({"type": "start", "session": name, "language": "en"}))
            await ws.recv()
            async with ViewerClient(srv.url, session=name, kind="params", audio=True) as viewer:
                it = viewer.__aiter__()
                t0 = time.perf_counter()
                await ws.send(json.dumps({"type": "text", "text": "Hello there, how are you today? "}))
                while True:
                    m = await it.__anext__()
                    if m.kind != 5:
                        dt = time.perf_counter() - t0
                        break
                await ws.send(json.dumps({"type": "end"}))
                async for _ in it:
                    pass
        return dt

    async def main() -> list[float]:
        srv = FacecastServer(load_model(), config=ServerConfig(port=0))
        srv.text_backend = espeak_backend(corpus_path)
        await srv.start()
        try:
            return [await one(srv, f"t{i}") for i in range(repeats)]
        finally:
            await srv.stop()

    dts = asyncio.run(main())
    print(
        f"server text session, first text piece -> viewer has frame 0 (goal < 300 ms): median "
        f"{1000 * np.median(dts):.0f} ms, max {1000 * max(dts):.0f} ms over {repeats} sessions"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--corpus", default=None, help="unit corpus (.npz); default: shipped or newest built")
    ap.add_argument("--sentences", type=int, default=40, help="search targets")
    ap.add_argument("--skip-say", action="store_true", help="skip the say-to-MP4 timing")
    ap.add_argument("--skip-server", action="store_true", help="skip the server first-frame timing")
    args = ap.parse_args(argv)
    from threadpoolctl import threadpool_limits

    from assets.unitcorpus import find_unit_corpus, load_unit_corpus

    path = find_unit_corpus(args.corpus)
    stored = load_unit_corpus(path)
    print(f"corpus {path}")
    with threadpool_limits(limits=1):
        bench_search(stored, args.sentences)
        check_self_selection(stored)
        bench_languages(stored)
        bench_n_best(stored)
        if not args.skip_say:
            bench_say(stored, samples=0, preset="veryfast")  # `facecast say`'s defaults
            bench_say(stored, samples=4, preset="medium")  # the defaults before: MSAA 4, ffmpeg's medium
        if not args.skip_server:
            bench_server(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
