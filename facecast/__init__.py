"""facecast: real-time speech-driven facial animation. The command line lives here."""

__version__ = "0.1.0"
