"""perceptual: the perceptual test kit (intelligibility in noise, emotion perception and opinion scores,
with people). A measurement of the whole product like ``benchmarks``, so it sits in that layer: it
builds stimuli with ``training`` (espeak-ng speech, GRID alignments) and ``clients`` (rendering).

    errors     BuildError and the package's other errors
    design     conditions, response sets, blocks and the per-participant balanced trial plan
    stimuli    ``facecast perceptual build``: noisy speech, the real talker, the rendered head; cache + manifest
    store      the SQLite response database (one committed row per answer, schema/test version checks)
    server     ``facecast perceptual serve``: the aiohttp experiment server (pages, media, answers, results)
    analysis   scores C_A, C_N, C_S, C_V (seed 000 eq. 13), confusions, paired tests, MOS intervals
    report     ``facecast perceptual report``: plots (matplotlib PNG) and a Markdown report
    web/       the participant page (consent, practice, trials, response grids, pause/resume)

See ``docs/perceptual.md``.
"""
