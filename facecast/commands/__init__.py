"""One module per ``facecast`` subcommand (see facecast/cli.py for the contract: ``add_parser`` and ``run``).

animate  speech file -> parameter CSV / glTF / JSON / TSV    bench    benchmarks (core, render, latency, capacity)
corpus   build a training corpus                            demo     the whole product on defaults
eval     accuracy against truth tracks                      extract  parameters measured on video
record   save a live session                                render   offline MP4 of a head
rig      rig a head mesh                                    serve    the streaming server
train    train a model                                      view     watch a live session
adapt    speaker adaptation from enrolment speech           say      text -> speech + lips (unit selection)
units    build the unit-selection corpus                    phones   GRID s1 phone labels
perceptual  perceptual tests with people                    headopts the shared --head options
mu       paper 002 on GRID s1 (Motion Units, MLP mapper)     fit-maps re-fit the blendshape maps
readout  fit a model's learned readout (GRID s1, or your own corpus: --corpus DIR)
speech_options  the shared --model/--mapper options
"""
