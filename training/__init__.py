"""training: the data facecast learns from.

Stages (see ``docs/architecture.md``, "Training data"):
    espeak         speech + phoneme timings from espeak-ng's C library (ctypes)
    alignments     readers for real phone alignments (ARCTIC .lab, TextGrid, LibriVox JSON)
    articulatory   phoneme timeline -> the four mouth parameters at 30 fps (Cohen-Massaro)
    augment        microphone-like degradations (level, noise, reverberation, resampling)
    build_corpus   synthesise, label, augment and write a corpus folder
    video          mouth parameters measured on talking-face video (MediaPipe face mesh)
    corpus         the on-disk corpus layout: atomic writers and ``load_corpus``
    params         the definition of the four mouth parameters

Nothing here runs at import time; heavy or optional libraries are imported where used.
"""
