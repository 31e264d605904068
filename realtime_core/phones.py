"""The phone timeline type shared by speech synthesis, forced alignment, corpora, the articulatory
rules and unit selection (a domain type, so it lives in the lowest layer)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PhonemeSegment:
    """One phoneme of a timeline: a label (espeak mnemonic, ARPAbet or IPA) over
    ``[start_s, end_s)`` seconds from the audio's first sample. The one timeline type of
    synthesis, alignments, corpora and the articulatory rules."""

    phoneme: str
    start_s: float
    end_s: float
