"""training: the data facecast learns from, training and evaluation (layer 3, beside ``server``
and ``clients``).

Stages (see ``docs/training.md``):
    espeak         speech + phoneme timings from espeak-ng's C library (ctypes)
    festival       a second speech engine (Festival voices) with phone timings
    alignments     readers for real phone alignments (ARCTIC .lab, TextGrid, LibriVox JSON)
    force_align    phone alignments of transcribed speech with pocketsphinx
    articulatory   phoneme timeline -> the four mouth parameters at 30 fps (Cohen-Massaro)
    augment        microphone-like degradations (level, noise, reverberation, resampling)
    build_corpus   synthesise, label, augment and write a corpus folder
    video          mouth parameters measured on talking-face video (MediaPipe face mesh)
    grid           the GRID s1 corpus: ids, the one train/val/test split, word alignments
    corpus         the on-disk corpus layout: atomic writers and ``load_corpus`` (tracks via assets.tracks)
    params         the definition of the four mouth parameters and the 30 fps frame grid
    trainer        corpus -> trained AvModel (with checkpoints)
    evaluation     accuracy against truth tracks beside a loudness baseline (``facecast eval``)
    report         training report plots (paper Figs. 7 and 8)
    errors         TrainingError (root of this package) and its file problems

Nothing here runs at import time; heavy or optional libraries are imported where used.
"""
