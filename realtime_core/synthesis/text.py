"""Text for speech synthesis: cleaning, checks and sentence chunks (sans-I/O).

A chatbot streams text in pieces; speech is synthesised a sentence at a time, so the first
sentence can be spoken while the rest is still being written. :class:`SentenceChunker` takes
pushes of any size and returns the sentences now complete (a sentence ends at ``.``, ``!``, ``?``,
``;``, ``:`` or ``…``, with any closing quotes or brackets after it, followed by white space; or at a
newline; or when it grows past ``max_chars``); the same sentences come out whatever the chunking
(tested). Each cut costs ~0.45 s of silence (a spoken sentence starts and ends at rest), so a ``.``
that does not end a sentence is no cut: after a title or other abbreviation (:data:`TITLES`,
:data:`ABBREVIATIONS`, English and Spanish), a single letter (an initial: "J. R. Tolkien") or a list
number at a line's start ("1. Eggs"). An abbreviation that often ends a sentence too ("etc.",
"p.m.") ends one when the next word starts with a capital letter, so the chunker waits for that
word's first letter. A stalled stream is spoken through its last word boundary
(:meth:`SentenceChunker.flush_words`), and a long first sentence can be started at a clause
boundary (:meth:`SentenceChunker.take_clause`).

:func:`clean_text` keeps what a synthesiser can pronounce: letters of any alphabet, digits, white
space, ordinary punctuation and the symbols espeak-ng reads as words (currency signs, ``% & + = / @ °``, the maths
signs ``× ÷ − ± ≤ ≥ ≠ ≈``, which its Spanish voice mostly skips:
espeak-ng reads "$20 or 50%" as "dollar twenty or fifty percent"; without the signs it was "twenty or
fifty"); anything else (control characters, emoji, other symbols) becomes a space. ``#``
and ``*`` go too: in a chatbot's markdown they are headings and emphasis, not words; a markdown link
``[the docs](https://...)`` is spoken as its text ("the docs"), and a fenced code block (a line starting
with ```` ``` ```` or ``~~~`` to the next such line) is not spoken at all: read out, a chatbot's answer
said "python", "print hello", "x equals one, two, three" and its URLs letter by letter. Text with nothing
pronounceable left raises :class:`TextError` naming the problem.
"""

from __future__ import annotations

import re
import unicodedata

from realtime_core.errors import ConfigError

MAX_TEXT_CHARS = 5000
"""Longest text accepted in one request (about five minutes of speech)."""

_KEEP_PUNCT = set(".,;:!?'\"-()¿¡’")
_SPOKEN_SYMBOLS = set("%&+=/@°×÷−±≤≥≠≈")  # the maths signs: "3 × 4" was "3 4" (English espeak-ng reads them)
_SCRIPTS = ("LATIN", "GREEK")
"""Scripts whose letters are spoken (the voices are English and Spanish; a Greek letter is read by its name, "pi").
espeak-ng reads a letter of any other script as its description: "你好世界" as "Chinese letter" four times, Arabic
as "Arabic meem Arabic ra ...", with exit 0; such letters are left out like emoji, and text of only them refused."""
_SPOKEN_SIGNS = set("µªº")  # micro, the Spanish ordinal indicators: letters named without a script


def _spoken_letter_or_digit(ch: str, cat: str) -> bool:
    """A letter of a spoken script (:data:`_SCRIPTS`) or a digit espeak-ng reads as a number (ASCII, or a
    fraction or superscript such as ½ ²; another script's digits are read by their description)."""
    if cat[0] == "L":
        return ch in _SPOKEN_SIGNS or unicodedata.name(ch, "").split(" ")[0] in _SCRIPTS
    return ch.isascii() or cat == "No"


"""Symbols the synthesiser reads as words ("percent", "and", "plus" ...); currency signs (category Sc) too."""
_SENTENCE_END = re.compile(r"([.!?;:…]+)[\"'”’»)\]]*\s+|\n\s*")
"""A candidate sentence end: end marks, closing quotes or brackets, white space (group 1: the marks); or a newline."""
_CLAUSE_END = re.compile(r"(?:[,;:]|\s[-–—]|[–—])[\"'”’»)\]]*\s+")
"""A clause boundary: a comma (or ``;`` ``:``), or a dash, followed by white space."""
TITLES = frozenset("dr dra mr mrs ms prof profa st sr sra srta sres mt gen col lt sgt capt rev vs".split())  # noqa: SIM905 (a word list)
"""Words before a name: a ``.`` after them never ends a sentence (compared lower-case, without the dot)."""
ABBREVIATIONS = frozenset("etc e.g i.e a.m p.m jr approx dept fig inc ltd no núm pág tel ud uds vol aprox".split())  # noqa: SIM905 (a word list)
"""Abbreviations that also end sentences ("... apples, pears, etc. Then"): a ``.`` after one ends a
sentence only when the next word starts with a capital letter. ``no`` (number, "No. 5") is both a
word and an abbreviation: it is one only before a digit. Dotted initialisms ("U.S.") count as these."""
_WORD_BEFORE = re.compile(r"(\S*)$")
_LIST_NUMBER = re.compile(r"(?:^|\n)[ \t]*\d{1,3}$")
_INITIALISM = re.compile(r"(?:\w\.)+\w")
_FENCE = re.compile(r"[ \t]{0,3}(?:`{3,}[^`\n]*|~{3,}.*)$")
"""A markdown code fence line (CommonMark: up to 3 spaces of indent, 3+ backticks or tildes, an info string
such as ``python``; a backtick fence's info string holds no backtick, so ```` ```x``` ```` is inline code)."""
_CODE_BLOCK = re.compile(r"^[ \t]{0,3}(`{3,}|~{3,})[^\n]*\n.*?(?:^[ \t]{0,3}\1[ \t]*$|\Z)", re.M | re.S)
"""A whole fenced code block in a text (:func:`clean_text`): from its opening fence to a closing one, or the end."""
_MARKUP_LINE = re.compile(r"[ \t]{0,3}(?:(?:[-*_][ \t]*){3,}|\|?(?:[ \t]*:?-+:?[ \t]*\|)+(?:[ \t]*:?-+:?[ \t]*)?)$")
"""A markdown line that is layout, not words: a thematic break (``---``, ``***``, ``___``) or a table's delimiter
row (``|---|:--:|``). Sent alone it has nothing to speak, and each got a `rejected` reply a chatbot's client had
to tell from a real refusal; it is skipped as a fence is (:meth:`SentenceChunker._take`)."""
_LINK = re.compile(r"!?\[([^\]\n]*)\]\([^)\s]*\)")
"""A markdown link or image ``[text](url)``: spoken as its text."""
_OPENERS = "\"'“‘«([¿¡"
_WORD_END = tuple(".,;:!?…\"'”’»)]")


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
    prose = _LINK.sub(r"\1", _CODE_BLOCK.sub("\n", text))
    out = []
    other_script = False  # a letter or digit of a script the voices do not speak was left out
    for ch in unicodedata.normalize("NFC", prose):
        cat = unicodedata.category(ch)
        if cat[0] in "LN":
            keep = _spoken_letter_or_digit(ch, cat)
            other_script = other_script or not keep
        else:
            keep = cat == "Sc" or ch in _KEEP_PUNCT or ch in _SPOKEN_SYMBOLS or ch.isspace()
        out.append(ch if keep else " ")
    cleaned = re.sub(r"\s+", " ", "".join(out)).strip()
    # Why nothing is left, when it is the script: the voices speak Latin-script (and Greek) letters only.
    script = " (the voices speak English and Spanish: Latin-script letters)" if other_script else ""
    if not cleaned and text.strip() and not prose.strip():  # it was "empty text": a code block is text, not spoken
        raise TextError(f"nothing to speak in {text[:40]!r}: a fenced code block is not spoken")
    if not cleaned:
        raise TextError("empty text" if not text.strip() else f"no pronounceable characters in {text[:40]!r}{script}")
    if not any(unicodedata.category(c)[0] in "LN" for c in cleaned):
        raise TextError(f"no pronounceable word in {text[:40]!r}{script}")
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
        self._line_start = True  # the pending text starts a line (a list number there is no sentence end)
        self._in_code = False  # inside a fenced code block: its lines are not spoken

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
            end = self._sentence_end()
            if end is not None and end <= self.max_chars:
                out.append(self._take(end))
                continue
            if len(self._buf) > self.max_chars:
                cut = self._buf.rfind(" ", 0, self.max_chars)
                out.append(self._take(cut if cut > 0 else self.max_chars))
                continue
            break
        return [s for s in out if s]

    def flush(self) -> list[str]:
        """The remaining text as a last sentence (end of the stream)."""
        rest = self._take(len(self._buf))
        return [rest] if rest else []

    def reset(self) -> None:
        """Drop the pending text and start afresh (a new answer after a cancel: not inside a code block)."""
        self._buf, self._line_start, self._in_code = "", True, False

    def flush_words(self) -> list[str]:
        """The pending text through its last word boundary as a sentence (a stalled stream); a trailing
        word fragment ("Then he went ho") stays pending: the next piece may complete it ("me")."""
        if self._buf.endswith(_WORD_END) or self._buf[-1:].isspace():
            return self.flush()
        cut = max(self._buf.rfind(" "), self._buf.rfind("\n"), self._buf.rfind("\t"))
        head = self._take(cut) if cut > 0 else ""
        return [head] if head else []

    def take_clause(self, min_words: int) -> list[str]:
        """The pending text up to its first clause boundary (comma, ``;``, ``:`` or dash followed by
        white space) with at least ``min_words`` words before it, as a sentence; [] when there is none.
        For a first sentence: speech can start before the whole sentence has been written."""
        for m in _CLAUSE_END.finditer(self._buf):
            if len(self._buf[: m.start()].split()) >= min_words:
                head = self._take(m.end())
                return [head] if head else []
        return []

    def take_words(self, min_words: int) -> list[str]:
        """The pending text through its last whole word as a sentence once at least ``min_words`` whole words
        are pending; [] before. For a run-on first sentence without a clause boundary (600 characters without
        punctuation waited for the 300-character cut: the first frame 5.3 s after the first piece)."""
        cut = max(self._buf.rfind(" "), self._buf.rfind("\n"), self._buf.rfind("\t"))
        if cut <= 0 or len(self._buf[:cut].split()) < min_words:
            return []
        head = self._take(cut)
        return [head] if head else []

    def _take(self, end: int) -> str:
        """Remove the first ``end`` characters of the pending text -> them stripped, as a sentence to speak, or
        "" when they are white space or code: a fence line (toggling the code block) or a line inside one; or a
        markdown layout line (:data:`_MARKUP_LINE`)."""
        at_line_start = self._line_start
        head, self._buf = self._buf[:end], self._buf[end:]
        if head:
            self._line_start = "\n" in head[len(head.rstrip()) :]
        text = head.strip()
        if at_line_start and _FENCE.fullmatch(text):
            self._in_code = not self._in_code
            return ""
        if self._in_code or (at_line_start and _MARKUP_LINE.fullmatch(text)):
            return ""
        return text

    def _sentence_end(self) -> int | None:
        """Where the first complete sentence of the pending text ends, None when there is none yet
        (or when deciding needs a character not yet received)."""
        pos = 0
        while (m := _SENTENCE_END.search(self._buf, pos)) is not None:
            ends = self._ends_sentence(m)
            if ends is None:
                return None
            if ends:
                return m.end()
            pos = m.end()
        return None

    def _ends_sentence(self, m: re.Match[str]) -> bool | None:
        """Whether candidate ``m`` ends a sentence (see the module doc); None: it depends on the next
        word's first character, not received yet."""
        if m.group(1) != ".":  # !, ?, ;, :, …, "..." or a newline
            return True
        before = self._buf[: m.start()]
        word = _WORD_BEFORE.search(before).group(1).lstrip(_OPENERS).lower()  # type: ignore[union-attr]
        if word in TITLES or (len(word) == 1 and word.isalpha()):
            return False
        if _LIST_NUMBER.search(("\n" if self._line_start else " ") + before):
            return False
        if word in ABBREVIATIONS or _INITIALISM.fullmatch(word):
            nxt = self._buf[m.end() : m.end() + 1].lstrip(_OPENERS) or None
            if nxt is None:
                return None
            return not nxt.isdigit() if word == "no" else nxt.isupper()
        return True
