"""One module per ``facecast`` subcommand (see facecast/cli.py for the contract: ``add_parser`` and ``run``).

    animate  speech file -> parameter CSV / glTF / JSON / TSV    bench    benchmarks (core, render, latency, capacity)
    corpus   build a training corpus                            demo     the whole product on defaults
    eval     accuracy against truth tracks                      extract  parameters measured on video
    record   save a live session                                render   offline MP4 of a head
    rig      rig a head mesh                                    serve    the streaming server
    train    train a model                                      view     watch a live session
"""
