"""Text for speech synthesis: cleaning, checks and sentence chunks (sans-I/O).

A chatbot streams text in pieces; speech is synthesised a sentence at a time, so the first
sentence can be spoken while the rest is still being written. :class:`SentenceChunker` takes
pushes of any size and returns the sentences now complete (a sentence ends at ``.``, ``!``, ``?``,
``;``, ``:`` or a newline followed by white space, or when it grows past ``max_chars``); the same
sentences come out whatever the chunking (tested).

:func:`clean_text` keeps what a synthesiser can pronounce: letters of any alphabet, digits, white
space, ordinary punctuation and the symbols espeak-ng reads as words (currency signs, ``% & + = / @ °``:
espeak-ng reads "$20 or 50%" as "dollar twenty or fifty percent"; without the signs it was "twenty or
fifty"); anything else (control characters, emoji, other symbols) becomes a space. ``#``
and ``*`` go too: in a chatbot's markdown they are headings and emphasis, not words. Text with nothing
pronounceable left raises :class:`TextError` naming the problem.
"""

from __future__ import annotations

import re
import unicodedata

from realtime_core.errors import ConfigError

MAX_TEXT_CHARS = 5000
"""Longest text accepted in one request (about five minutes of speech)."""

_KEEP_PUNCT = set(".,;:!?'\"-()¿¡’")
_SPOKEN_SYMBOLS = set("%&+=/@°")
"""Symbols the synthesiser reads as words ("percent", "and", "plus" ...); currency signs (category Sc) too."""
_SENTENCE_END = re.compile(r"[.!?;:]+[\"')\]]*\s+|\n\s*")


class TextError(ConfigError):
    """Text that cannot be spoken: empty, too long, or nothing pronounceable in it."""


def clean_text(text: object, *, max_chars: int = MAX_TEXT_CHARS) -> str:
    """``text`` with unpronounceable characters replaced by spaces and white space collapsed.

    Raises TextError for a non-string, an empty text, one longer than ``max_chars`` or one without
    a letter or digit."""
    if not isinstance(text, str):
        raise TextError(f"text must be a string, got {type(text).__name__}")
    if len(text) > max_chars:
        raise TextError(f"text is {len(text)} characters long; the limit is {max_chars}")
    out = []
    for ch in unicodedata.normalize("NFC", text):
        cat = unicodedata.category(ch)
        keep = cat[0] in "LN" or cat == "Sc" or ch in _KEEP_PUNCT or ch in _SPOKEN_SYMBOLS or ch.isspace()
        out.append(ch if keep else " ")
    cleaned = re.sub(r"\s+", " ", "".join(out)).strip()
    if not cleaned:
        raise TextError("empty text" if not text.strip() else f"no pronounceable characters in {text[:40]!r}")
    if not any(unicodedata.category(c)[0] in "LN" for c in cleaned):
        raise TextError(f"no pronounceable word in {text[:40]!r}")
    return cleaned


class SentenceChunker:
    """Streamed text -> complete sentences (see the module doc). ``max_chars``: a sentence longer
    than this is cut at its last space before the limit (a chatbot that never ends a sentence
    still gets spoken)."""

    def __init__(self, *, max_chars: int = 300) -> None:
        if max_chars < 20:
            raise ConfigError(f"max_chars must be >= 20, got {max_chars}")
        self.max_chars = max_chars
        self._buf = ""

    @property
    def pending(self) -> str:
        """Text received but not yet part of a complete sentence."""
        return self._buf

    def push(self, text: str) -> list[str]:
        """Add a piece of text; returns the sentences it completed (stripped, non-empty)."""
        if not isinstance(text, str):
            raise TextError(f"text must be a string, got {type(text).__name__}")
        self._buf += text
        out: list[str] = []
        while True:
            m = _SENTENCE_END.search(self._buf)
            if m is not None and m.end() <= self.max_chars:
                out.append(self._buf[: m.end()])
                self._buf = self._buf[m.end() :]
                continue
            if len(self._buf) > self.max_chars:
                cut = self._buf.rfind(" ", 0, self.max_chars)
                cut = cut if cut > 0 else self.max_chars
                out.append(self._buf[:cut])
                self._buf = self._buf[cut:]
                continue
            break
        return [s.strip() for s in out if s.strip()]

    def flush(self) -> list[str]:
        """The remaining text as a last sentence (end of the stream)."""
        rest, self._buf = self._buf.strip(), ""
        return [rest] if rest else []
