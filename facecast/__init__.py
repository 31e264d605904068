"""facecast: real-time speech-driven facial animation; this package is the command line (top layer).

cli        ``facecast`` argument parsing and dispatch (argparse lives only here and in commands/)
__main__   ``python -m facecast``
commands   one module per subcommand: animate, bench, corpus, demo, eval, extract, record, render,
           rig, serve, train, view
demo       the ``facecast demo`` runner: espeak-ng speech through a live session, MP4 out
"""

__version__ = "0.1.0"
PACKAGES = ("realtime_core", "wire", "assets", "server", "clients", "training", "benchmarks", "perceptual", "facecast")
"""The top-level packages facecast installs (the layer contract's root packages; tests/facecast/test_layers.py
holds it to pyproject and to the tree)."""
