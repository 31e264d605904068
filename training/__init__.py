"""training: the data facecast learns from, training and evaluation (layer 3, beside ``server``
and ``clients``).

Stages (see ``docs/training.md``):
    festival       a second speech engine (Festival voices) with phone timings
    alignments     readers for real phone alignments (ARCTIC .lab, TextGrid, LibriVox JSON)
    force_align    phone alignments of transcribed speech with pocketsphinx
    articulatory   phoneme timeline -> the four mouth parameters at 30 fps (Cohen-Massaro)
    augment        microphone-like degradations (level, noise, reverberation, resampling)
    build_corpus   synthesise, label, augment and write a corpus folder
    video          mouth parameters measured on talking-face video (MediaPipe face mesh), cached, in parallel
    facetrack      FaceTrack: pose-free 3D landmark tracks of a talking face and their cache file
    grid_phones    ARPAbet phone labels inside GRID s1's word spans
    reallips       GRID s1 utterances for training and the real-lips scores
    unit_corpus    the unit-selection motion corpus of GRID s1 (built once, cached)
    unitsel_eval   objective evaluation of unit selection on real lips
    corpus         the on-disk corpus layout: atomic writers and ``load_corpus`` (tracks via assets.tracks)
    params         the definition of the four mouth parameters and the 30 fps frame grid
    trainer        corpus -> trained AvModel (with checkpoints)
    evaluation     accuracy against truth tracks beside a loudness baseline (``facecast eval``)
    report         training report plots (paper Figs. 7 and 8)
    errors         TrainingError (root of this package) and its file problems
    motion_units   paper 002 on GRID s1: Motion Units, audio-to-MUP mappers, the numbers
    mapper         training the GMM-selected MLP bank and the single-MLP baseline (scikit-learn)
    mu_train       ``facecast mu``: train and score paper 002's system
    mu_expressions expression deformations at the MU landmarks and Expression MUs
    mu_keyframes   keyframe sets in the MU landmark space (round-trip check)
    mu_report      Markdown of paper 002's numbers
    fit_maps       fits the blendshape maps and the expression table (``facecast fit-maps``)
    latency        the latency dial: accuracy against algorithmic delay

espeak-ng and the GRID corpus reader live in ``assets`` (espeak, grid). Nothing here runs at import
time; heavy or optional libraries are imported where used.
"""
