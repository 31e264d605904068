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

:func:`normalise_for_speech` writes out what espeak-ng reads badly as a person reads it, per language (a URL as
its host, dates, times, amounts, units, ranges; :func:`clean_text` calls it first when given the language).
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

import functools
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
TITLES = frozenset("dr dra mr mrs ms prof profa st sr sra srta sres mt gen col lt sgt capt rev vs ee".split())  # noqa: SIM905 (a word list)
"""Words before a name: a ``.`` after them never ends a sentence (compared lower-case, without the dot)."""
ABBREVIATIONS = frozenset(
    "etc e.g i.e a.m p.m jr approx dept fig inc ltd no núm pág tel ud uds vol aprox ej uu".split()  # noqa: SIM905
    + "jan feb mar apr jun jul aug sep sept oct nov dec ene abr ago dic".split()  # noqa: SIM905 (month short forms)
)
"""Abbreviations that also end sentences ("... apples, pears, etc. Then"): a ``.`` after one ends a
sentence only when the next word starts with a capital letter ("Dec. 7" is one sentence, as "p. ej. manzanas"
and "EE. UU. es"). ``no`` (number, "No. 5") is both a word and an abbreviation: it is one only before a
digit. Dotted initialisms ("U.S.") count as these."""
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


def clean_text(
    text: object, *, language: str | None = None, day_first: bool | None = None, max_chars: int = MAX_TEXT_CHARS
) -> str:
    """``text`` with unpronounceable characters replaced by spaces and white space collapsed; with a ``language``
    ("en", "es") also what espeak-ng reads badly written out as said (:func:`normalise_for_speech`, ``day_first``
    there): URLs, dates, times, amounts, units (before the characters are filtered: a URL's ``#`` and ``_`` too).

    Raises TextError for a non-string, an empty text, one longer than ``max_chars`` or one without
    a letter or digit."""
    if not isinstance(text, str):
        raise TextError(f"text must be a string, got {type(text).__name__}")
    if len(text) > max_chars:
        raise TextError(f"text is {len(text)} characters long; the limit is {max_chars}")
    prose = _LINK.sub(r"\1", _CODE_BLOCK.sub("\n", text))
    if language is not None:
        prose = normalise_for_speech(prose, language=language, day_first=day_first)
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


# --- What a chatbot writes that espeak-ng reads badly (:func:`normalise_for_speech`) -----------------------------
# Survey (session text50, espeak-ng 1.51, en-us and es): "https://docs.python.org/3/" was read "h t t p s colon
# slash slash docs dot python dot org slash three slash", "2026-12-07" "two thousand twenty six dash twelve dash
# zero seven", "9:00" "nine zero zero", "$5" "dollar five", "5 km" "five k m", "Dec 7" "deck seven",
# "(555) 123-4567" "five hundred fifty five one hundred twenty three dash four thousand ...", Spanish "1.º" "uno
# punto o", "p. ej." "pe ex". Only these are rewritten; what espeak-ng reads well is left to it: e-mail addresses
# ("support at example dot com", "soporte arroba ejemplo punto com"), "14:30" ("fourteen thirty"), "2:30 pm",
# "12.5%", ordinals ("3rd"), "e.g.", "Dr.", "@mentions", Spanish phone numbers read in groups.
# Survey (session text52, issue 13): "Python 3.12" "three point one two", "v2.0.1" "two point zero point one", "3/4"
# "three slash four", "100-2000" "one zero zero, two zero zero zero" (as a phone number), "17:00" "seventeen hundred",
# "24/7" "twenty four slash seven", "x2" "eks two", "#1" "one", "i.e." "I E", "1st-3rd" "first third", "5'10"" "five
# ten", "9am–5pm" "nine a m five p m"; a word in capitals of up to three letters espeak-ng does not know is spelled in a
# sentence ("RAM" "R A M", "TOO" "T O O", "NO" "ene o"). Left alone: "/usr/bin" ("slash usser slash bin"), "e.g."
# ("for example"), "etc.", "21st", "&" ("and"), "10-20%", emoji and markdown (clean_text drops them), "CPU", "API",
# "USA", "NASA", "OK" and the Spanish acronyms in a sentence ("la IA", "el USB": spelled).

_MONTHS = {
    "en": "January February March April May June July August September October November December".split(),  # noqa: SIM905
    "es": "enero febrero marzo abril mayo junio julio agosto septiembre octubre noviembre diciembre".split(),  # noqa: SIM905
}
_MONTH_ABBR = {  # a month's short form, only next to a day number ("Mar" and "may" are words on their own)
    "en": {**{m[:3]: i for i, m in enumerate(_MONTHS["en"])}, "Sept": 8},
    "es": {**{m[:3]: i for i, m in enumerate(_MONTHS["es"])}, "sept": 8},
}
_WEEKDAYS = {  # short form -> name, only in a range ("Mon-Fri": "mon fry"); "Sun", "Sat" and "mar" are words
    language: {name[:3].lower(): name for name in names.split()} | other_forms
    for language, names, other_forms in (
        (
            "en",
            "Monday Tuesday Wednesday Thursday Friday Saturday Sunday",
            {"tues": "Tuesday", "thur": "Thursday", "thurs": "Thursday"},
        ),
        ("es", "lunes martes miércoles jueves viernes sábado domingo", {"mie": "miércoles", "sab": "sábado"}),
    )
}
_WORDS = {  # per language: the words the rewrites put in
    "en": {"dot": "dot", "port": "port", "to": "to", "version": "version", "between": "between", "and": "and"},
    "es": {"dot": "punto", "port": "puerto", "to": "a", "version": "versión", "between": "entre", "and": "y"},
}
_CURRENCY = {  # sign or ISO code -> (one, many, one hundredth, many hundredths)
    "en": {
        "$": ("dollar", "dollars", "cent", "cents"),
        "€": ("euro", "euros", "cent", "cents"),
        "£": ("pound", "pounds", "penny", "pence"),
        "¥": ("yen", "yen", "sen", "sen"),
    },
    "es": {
        "$": ("dólar", "dólares", "centavo", "centavos"),
        "€": ("euro", "euros", "céntimo", "céntimos"),
        "£": ("libra", "libras", "penique", "peniques"),
        "¥": ("yen", "yenes", "sen", "sen"),
    },
}
_CODES = {"USD": "$", "EUR": "€", "GBP": "£", "JPY": "¥"}
_UNITS = {  # symbol after a number -> (one, many); "m", "s", "l" are left alone ("$5m", "the 90s")
    "en": {
        "km/h": ("kilometer per hour", "kilometers per hour"),
        "km": ("kilometer", "kilometers"),
        "cm": ("centimeter", "centimeters"),
        "mm": ("millimeter", "millimeters"),
        "kg": ("kilogram", "kilograms"),
        "mg": ("milligram", "milligrams"),
        "g": ("gram", "grams"),
        "ml": ("milliliter", "milliliters"),
        "TB": ("terabyte", "terabytes"),
        "GB": ("gigabyte", "gigabytes"),
        "MB": ("megabyte", "megabytes"),
        "KB": ("kilobyte", "kilobytes"),
        "kB": ("kilobyte", "kilobytes"),
        "GHz": ("gigahertz", "gigahertz"),
        "MHz": ("megahertz", "megahertz"),
        "kHz": ("kilohertz", "kilohertz"),
        "Hz": ("hertz", "hertz"),
        "ms": ("millisecond", "milliseconds"),
        "min": ("minute", "minutes"),
        "h": ("hour", "hours"),
        "°C": ("degree Celsius", "degrees Celsius"),
        "ºC": ("degree Celsius", "degrees Celsius"),
        "°F": ("degree Fahrenheit", "degrees Fahrenheit"),
    },
    # espeak-ng's Spanish reads "gigabytes" as written ("jigabites"): spelt as said ("gigabáits")
    "es": {
        "km/h": ("kilómetro por hora", "kilómetros por hora"),
        "km": ("kilómetro", "kilómetros"),
        "cm": ("centímetro", "centímetros"),
        "mm": ("milímetro", "milímetros"),
        "kg": ("kilo", "kilos"),
        "mg": ("miligramo", "miligramos"),
        "g": ("gramo", "gramos"),
        "ml": ("mililitro", "mililitros"),
        "TB": ("terabáit", "terabáits"),
        "GB": ("gigabáit", "gigabáits"),
        "MB": ("megabáit", "megabáits"),
        "KB": ("kilobáit", "kilobáits"),
        "kB": ("kilobáit", "kilobáits"),
        "GHz": ("gigahercio", "gigahercios"),
        "MHz": ("megahercio", "megahercios"),
        "kHz": ("kilohercio", "kilohercios"),
        "Hz": ("hercio", "hercios"),
        "ms": ("milisegundo", "milisegundos"),
        "min": ("minuto", "minutos"),
        "h": ("hora", "horas"),
        "°C": ("grado Celsius", "grados Celsius"),
        "ºC": ("grado Celsius", "grados Celsius"),
        "°F": ("grado Fahrenheit", "grados Fahrenheit"),
    },
}
_ORDINALS_ES = ["primer", "segund", "tercer", "cuart", "quint", "sext", "séptim", "octav", "noven", "décim"]
_ABBREVIATIONS_SPOKEN = {  # abbreviations espeak-ng spells or clips ("p. ej." "pe ex", "etc." "etk")
    "en": {r"vs\.": "versus", r"approx\.": "approximately", r"and/or": "and or", r"i\.\s?e\.": "that is"},
    "es": {
        r"p\.\s?ej\.": "por ejemplo",
        r"etc\.": "etcétera",
        r"aprox\.": "aproximadamente",
        r"EE\.\s?UU\.": "Estados Unidos",
        r"vs\.": "contra",
        r"y/o": "y o",
        r"i\.\s?e\.": "es decir",
    },
}
_TLDS = (
    "com org net edu gov int mil io dev ai app co info biz uk us ca au nz ie de fr it es pt nl be ch eu mx ar cl "
    "pe br jp cn ru"
)
_URL_END = r"(?=[.,;:!?)\]}>'\"»”’*_`]*(?:\s|$))"
"""Where a URL ends: before white space, or the punctuation or markdown marks that close the sentence or wrap it."""
_URL = re.compile(
    r"(?<![\w@/.-])(?:(?:https?|ftp)://(?:[^\s/@]+@)?|www\.)"  # a scheme (and user info) or "www."
    r"(?P<host>[\w-]+(?:\.[\w-]+)*)(?::(?P<port>\d{1,5}))?"
    rf"(?P<rest>[/?#]\S*?)?{_URL_END}",  # path, query, fragment; not the sentence's end
    re.I,
)
"""A URL with a scheme, or one starting "www.": spoken as its host (and port)."""
_DOMAIN = re.compile(
    rf"(?<![\w@/.:-])(?P<host>(?:[\w-]+\.)+(?:{'|'.join(_TLDS.split())}))(?![\w-]|\.\w)"
    rf"(?::(?P<port>\d{{1,5}}))?(?P<rest>/\S*?)?{_URL_END}",
    re.I,
)
"""A bare domain ("example.com/docs", "docs.python.org"): a known top-level domain, so "Node.js" and "file.py" stay."""
_NOT_AFTER = r"(?![\w/-]|[.,:]\d)"
_DOT = r"(?:\.(?!\s*$))?"
"""An abbreviation's full stop, unless it ends the text (then it is the sentence's, and stays)."""
_ISO_DATE = re.compile(rf"(?<![\w.,:/-])(\d{{4}})-(\d{{2}})-(\d{{2}}){_NOT_AFTER}")
_NUMERIC_DATE = re.compile(rf"(?<![\w.,:/-])(\d{{1,2}})([/.-])(\d{{1,2}})\2(\d{{4}}){_NOT_AFTER}")
_PHONE_EN = re.compile(
    r"(?<![\w.+/-])(?:\+\d{1,3}(?:[ .-]?\(?\d{1,4}\)?){2,5}|(?:1[ .-])?(?:\(\d{3}\)\s?|\d{3}[.-])?\d{3}[.-]\d{4})"
    r"(?![\w-]|[.,]\d)"
)
"""A phone number as written in English: international ("+44 20 7946 0958") or North American ("(555) 123-4567",
"555-123-4567", "555-0199", "1-800-555-0199"): read digit by digit in its groups, a toll-free "800" as "8 hundred"."""
_RANGE = re.compile(r"(?<![\w.,:/-])(\d+(?:[.,:]\d+)*)(?:-|\s?–\s?)([$€£¥]?\d+(?:[.,:]\d+)*)(?![\w-]|[.,:]\d)")
"""A range "10-20", "5–10", "9:00-17:00" ("ten dash twenty", "five ten"): "10 to 20" / "10 a 20". A hyphen
between spaces is a minus ("5 - 3") and stays, as a chain ("912-345-678", a Spanish phone number)."""
_TIME = re.compile(r"(?<![\w.,:])(\d{1,2}):(\d{2})(?![\d:])(?P<h>\s?h\b)?")
_AMPM = re.compile(r"\s?(?:[ap]\.?m\.?)(?!\w)", re.I)
_VERSION = re.compile(r"(?<![\w.])v(\d+(?:\.\d+)*)\b")
_DOTTED = re.compile(r"(?<![\w.,])(\d+)((?:\.\d+)+)(?![\w]|[.,]\d)")
"""A number with dotted parts: a decimal ("3.12"), a version ("Python 3.12", "2.0.1") or an IP address."""
_VERSION_WORDS = "version|versión|release|update|patch|build|v"
_VERSIONED = (
    "python java node ruby php perl rust go swift kotlin scala ubuntu debian fedora windows macos ios android linux "
    "chrome firefox safari edge django flask react angular vue rails postgres postgresql mysql redis docker "
    "kubernetes typescript javascript gpt claude gemini llama bluetooth usb http html tls ssl wi-fi openssl unity "
    "blender numpy pandas pytorch tensorflow cuda xcode gradle spring laravel wordpress drupal excel office"
)
_NAMES_WITH_VERSIONS = frozenset(_VERSIONED.split())
"""Names a version number follows even at a sentence's start ("Python 3.12 is out"); elsewhere any capitalised name
does ("use Ubuntu 22.04", "on iOS 17.2")."""
_SCALE_AFTER = re.compile(r"\s?(?:%|percent|por ciento|thousand|million|billion|trillion|mil|millones?)\b", re.I)
_FRACTIONS = {  # denominator -> (one, many); "3/4" "three slash four"
    "en": {
        2: ("half", "halves"),
        3: ("third", "thirds"),
        4: ("quarter", "quarters"),
        5: ("fifth", "fifths"),
        6: ("sixth", "sixths"),
        8: ("eighth", "eighths"),
        10: ("tenth", "tenths"),
        16: ("sixteenth", "sixteenths"),
        32: ("thirty-second", "thirty-seconds"),
        64: ("sixty-fourth", "sixty-fourths"),
        100: ("hundredth", "hundredths"),
    },
    "es": {
        2: ("medio", "medios"),
        3: ("tercio", "tercios"),
        4: ("cuarto", "cuartos"),
        5: ("quinto", "quintos"),
        6: ("sexto", "sextos"),
        8: ("octavo", "octavos"),
        10: ("décimo", "décimos"),
        16: ("dieciseisavo", "dieciseisavos"),
        100: ("centésimo", "centésimos"),
    },
}
_FRACTION = re.compile(r"(?<![\w.,/:-])(?:(\d+)\s)?(\d+(?:[.,]\d+)?)/(\d{1,3})(?![\w/]|[.,]\d)")
"""A fraction or a score without a year after it ("3/4 cup", "1 1/2", "4.5/5"; "3/4/2025" is a date)."""
_OUT_OF = {5, 10, 100}
"""Denominators of a score: "4.5/5", "10/10" are "4.5 out of 5" (a numerator not below the denominator)."""
_FEET_INCHES = re.compile(r"(?<![\w.,])(\d)['’′]\s?(\d{1,2})(?:\"|”|″|'')?(?![\w'’\"”])")
_TIMES = re.compile(
    r"(?<![\w.])(?:(?P<n>\d+(?:\.\d+)?)x|x(?P<m>10|\d(?:\.\d+)?)|(?P<a>[1-9]\d*)(?P<s>\s?)x(?P=s)(?P<b>\d+))(?![\w-]|[.,]\d)"
)
"""A multiplier, a size or a product: "2x faster", "speed x2", "1920x1080", "3 x 4" ("two eks", "eks two"; "1x1" "one
eks one")."""
_AMPM_RANGE = re.compile(
    r"(?<![\w.,:])(\d{1,2}(?::\d{2})?(?:\s?[ap]\.?m\.?)?)\s?[-–]\s?(\d{1,2}(?::\d{2})?\s?[ap]\.?m\.?)(?!\w)", re.I
)
"""A range of 12-hour times ("9am–5pm", "9-5 pm"): the en dash was dropped, "nine a m five p m"."""
_ORDINAL_RANGE = re.compile(r"(?<![\w.,])(\d+(?:st|nd|rd|th|\.?[ºª]))\s?[-–]\s?(\d+(?:st|nd|rd|th|\.?[ºª]))(?!\w)")
_SPOKEN_CAPS = {
    # espeak-ng spells a word in capitals of up to three letters it does not know ("RAM" "R A M", "TOO" "T O O",
    # Spanish "NO" "ene o", "MUY" "eme u i griega"): these are said as words. Others it reads as a word though they
    # are spelled ("ETA" "eeta"). An acronym it spells, "CPU", "API", "USA", and one it says, "NASA", is left to it.
    "en": {
        **{w: w.lower() for w in "RAM ROM SIM PIN LAN WAN ZIP".split()},  # noqa: SIM905
        **{
            w: w.lower()  # emphasis ("It is TOO big", "a BIG deal")
            for w in "ALL ANY ASK BAD BIG BUT CAN DAY END FEW GET HOT HOW NEW NOT NOW OFF OLD ONE OUR OUT "  # noqa: SIM905
            "PUT RUN SAY SEE SET TOO TOP TRY TWO USE WAY WHY YES YET YOU".split()
        },
        "ETA": "E.T.A.",
        "IMHO": "I.M.H.O.",
        "SaaS": "sass",
    },
    "es": {
        w: w.lower()
        for w in "NO SÍ YA HOY MÁS MUY SIN CON POR QUÉ TÚ YO ES TAN MAL FIN".split()  # noqa: SIM905
    },
}


def _month_en(name: str) -> int:
    """An English month's index 0-11 from its name or short form ("Dec", "Sept")."""
    return _MONTH_ABBR["en"][name] if name in _MONTH_ABBR["en"] else _MONTHS["en"].index(name)


def _money(text: str, language: str) -> str:
    """Amounts as said: "$5" -> "5 dollars" (espeak-ng: "dollar five"), "$19.99" -> "19 dollars and 99 cents",
    "3,50 €" -> "3 euros con 50 céntimos", "20 EUR" -> "20 euros" ("twenty your"), "$5 million" -> "5 million
    dollars"; Spanish "1" as "un" ("un euro", espeak-ng: "uno euro")."""
    names = _CURRENCY[language]
    sign = r"[$€£¥]|(?:USD|EUR|GBP|JPY)"
    # English writes 1,000.50; Spanish 1.000,50 (and, from a chatbot, often 19.99)
    integer, decimal = (r"\d{1,3}(?:,\d{3})+|\d+", r"\.") if language == "en" else (r"\d{1,3}(?:\.\d{3})+|\d+", r"[.,]")
    scales = r"thousand|million|billion|trillion|k|M|bn" if language == "en" else r"mil millones|millones|millón|mil"
    amount = rf"(?P<int>{integer})(?:{decimal}(?P<dec>\d+))?(?!\d)"

    def said(m: re.Match[str]) -> str:
        one, many, cent, cents = names[_CODES.get(m.group("sign"), m.group("sign"))]
        whole, dec, scale = m.group("int"), m.group("dec"), m.groupdict().get("scale")
        if scale:  # "$1.5 million": the number as written, then the scale
            scale = {"k": "thousand", "M": "million", "bn": "billion"}.get(scale, scale)
            number = m.group(0)[m.start("int") - m.start() : m.end("dec" if dec else "int") - m.start()]
            return (
                f"{number} {scale} {many}" if language == "en" else f"{number} {scale}{' de' * (scale != 'mil')} {many}"
            )
        if dec is not None and len(dec) != 2:  # "$1.5": a number, not cents
            return f"{whole}{m.group(0)[m.end('int') - m.start()]}{dec} {many}"
        c = int(dec or 0)
        if language == "es":
            un = "una" if one == "libra" else "un"
            main = f"{un if whole == '1' else whole} {one if whole == '1' else many}"
            return main + (f" con {'un' if c == 1 else c} {cent if c == 1 else cents}" if c else "")
        main = f"{whole} {one if whole == '1' else many}"
        if c and whole == "0":
            return f"{c} {cent if c == 1 else cents}"
        return main + (f" and {c} {cent if c == 1 else cents}" if c else "")

    text = re.sub(rf"(?<![\w.,])(?P<sign>{sign})\s?{amount}(?:\s?(?P<scale>{scales})\b)?", said, text)
    return re.sub(rf"(?<![\w.,]){amount}\s?(?P<sign>[$€£¥]|(?:USD|EUR|GBP|JPY)\b)", said, text)


def _ordinal_en(day: int) -> str:
    suffix = "th" if 10 <= day % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(day % 10, "th")
    return f"{day}{suffix}"


def _date(language: str, year: str | None, month: int, day: int) -> str:
    """A date as said: "December 7th, 2026", "7 de diciembre de 2026" (month 0-11)."""
    name = _MONTHS[language][month]
    if language == "es":
        return f"{day} de {name}" + (f" de {year}" if year else "")
    return f"{name} {_ordinal_en(day)}" + (f", {year}" if year else "")


def _host(m: re.Match[str], language: str) -> str:
    """A URL's host as said: as written ("docs.python.org": espeak-ng says "docs dot python dot org", "docs punto
    python punto org"), without "www." and the scheme, path, query and fragment; a port as "port 8080" (it was
    "colon eight thousand eighty"); an IP address's numbers joined by "dot" ("192.168.1.10" was "one hundred
    ninety two point one six eight point ...")."""
    host = m.group("host")
    if host.lower().startswith("www."):
        host = host[4:]
    if re.fullmatch(r"\d+(?:\.\d+){3}", host):
        host = f" {_WORDS[language]['dot']} ".join(host.split("."))
    return host + (f" {_WORDS[language]['port']} {m.group('port')}" if m.group("port") else "")


def _dotted(m: re.Match[str], language: str) -> str:
    """A number with dotted parts as said: an IP address's parts joined by "dot" ("192.168.1.10" was "one hundred
    ninety two point one six eight point ..."); in English a version as "3 point 12" ("Python 3.12" was "three
    point one two", a decimal's reading) and "2 point oh point 1" ("two point zero point one"), when it follows a
    version word or a name (:data:`_NAMES_WITH_VERSIONS`, a capitalised word not starting the sentence) or has
    three parts; a decimal is left to espeak-ng. espeak-ng's Spanish reads "3.12" "tres punto doce" already."""
    parts = [m.group(1), *m.group(2)[1:].split(".")]
    if len(parts) == 4 and all(len(p) <= 3 and int(p) <= 255 for p in parts):
        return f" {_WORDS[language]['dot']} ".join(parts)
    if language != "en" or _SCALE_AFTER.match(m.string, m.end()):
        return m.group(0)
    before = m.string[: m.start()]
    word = re.search(r"([\w.+#-]+)\s$", before)
    name = word.group(1).rstrip(".") if word else ""
    starts_sentence = word is not None and re.search(r"(?:^|[.!?:]\s+|\n\s*)$", before[: word.start()]) is not None
    named = name.lower() in _NAMES_WITH_VERSIONS or (
        any(c.isupper() for c in name) and name[:1].isalpha() and not starts_sentence
    )
    after_version = re.search(rf"\b(?:{_VERSION_WORDS})\s?$", before, re.I) is not None
    if len(parts) == 2 and not (named or after_version):
        return m.group(0)
    # a part's leading zeros are said "oh" ("2.05": "two point oh five"); the first part is a number ("0.9")
    said = [parts[0]] + [" ".join(["oh"] * (len(p) - len(p.lstrip("0"))) + [p.lstrip("0")]).strip() for p in parts[1:]]
    return " point ".join(said)


def _fraction(m: re.Match[str], language: str) -> str:
    """A fraction as said ("3/4" "3 quarters", "1/2" "a half", "1 1/2" "1 and a half"; Spanish "3 cuartos", "media
    taza") or a score ("4.5/5" "4.5 out of 5", "4,5 de 5"); anything else ("10/20", a path) as written."""
    whole, num, den = m.group(1), m.group(2), int(m.group(3))
    names = _FRACTIONS[language]
    decimal = not num.isdigit()
    if den in _OUT_OF and (decimal or int(num) >= den) and not whole:
        return f"{num} {'out of' if language == 'en' else 'de'} {den}"
    if decimal or den not in names or not 0 < int(num) < den:
        return m.group(0)
    one, many = names[den]
    n = int(num)
    if language == "es":
        # "1/2 taza" "media taza": medio agrees with the noun after it (a feminine one mostly ends in -a)
        feminine = den == 2 and re.match(r"\s+(?:de\s+)?\w*as?\b", m.string[m.end() :]) is not None
        one = "media" if feminine else one
        said = (one if den == 2 else f"un {one}") if n == 1 else f"{n} {many}"
        return f"{whole} y {said}" if whole else said
    said = f"a {one}" if n == 1 else f"{n} {many}"
    return f"{whole} and {said}" if whole else said


def _times(m: re.Match[str], language: str) -> str:
    """A multiplier or size as said: "2x" "2 times", "x2" "times 2", "1920x1080" "1920 by 1080" ("2 veces", "por 2",
    "1920 por 1080"); "3 x 4" "3 times 4"; "0x1F" (hexadecimal) is no match."""
    times, by = ("times", "by") if language == "en" else ("veces", "por")
    if m.group("n"):
        return f"{m.group('n')} {times}"
    if m.group("m"):
        return f"{'times' if language == 'en' else 'por'} {m.group('m')}"
    return f"{m.group('a')} {by if not m.group('s') else times if language == 'en' else 'por'} {m.group('b')}"


def normalise_for_speech(text: str, *, language: str, day_first: bool | None = None) -> str:
    """``text`` with what espeak-ng reads badly written out as a person reads it, in ``language`` ("en", "es"):
    a URL as its host ("https://example.com/docs?q=1" -> "example.com": "example dot com"), dates ("2026-12-07"
    -> "December 7th, 2026" / "7 de diciembre de 2026"; "Dec 7" -> "December 7th"), whole hours and minutes under
    ten ("9:00" -> "9 o'clock", "9:05" -> "9 oh 5"; "a las 9:00" -> "a las 9"), amounts ("$5" -> "5 dollars",
    "3,50 €" -> "3 euros con 50 céntimos"), units after a number ("5 km" -> "5 kilometers"), ranges ("10-20" ->
    "10 to 20"), versions ("v2.1.3" -> "version 2 point 1 point 3"; "Python 3.12" -> "Python 3 point 12"), English
    phone numbers digit by digit, Spanish ordinals ("1.º" -> "primero") and abbreviations ("p. ej." -> "por
    ejemplo"), fractions ("3/4" -> "3 quarters"), scores ("4.5/5" -> "4.5 out of 5"), "24/7", "x2", "#1", "5'10"",
    English 24-hour afternoon times ("17:00" -> "5 pm") and capitals espeak-ng spells (:data:`_SPOKEN_CAPS`).
    ``day_first``: how "07/12/2026" is read when both fields could be the month; None = the language's custom
    (Spanish day first; English month first, as the default en-us voice). Everything else is left as written:
    espeak-ng reads it well (the surveys above)."""
    if language not in _WORDS:
        raise ConfigError(f"unsupported language {language!r}; supported: {sorted(_WORDS)}")
    words = _WORDS[language]
    day_first = language != "en" if day_first is None else day_first
    text = _URL.sub(lambda m: _host(m, language), text)
    text = _DOMAIN.sub(lambda m: _host(m, language), text)

    def iso(m: re.Match[str]) -> str:
        y, mo, d = m.group(1), int(m.group(2)), int(m.group(3))
        return _date(language, y, mo - 1, d) if 1 <= mo <= 12 and 1 <= d <= 31 else m.group(0)

    def numeric(m: re.Match[str]) -> str:
        a, b, y = int(m.group(1)), int(m.group(3)), m.group(4)
        # a field over 12 is the day whatever the custom ("15/01/2025" in English too)
        d, mo = (a, b) if a > 12 or (day_first and b <= 12) else (b, a)
        return _date(language, y, mo - 1, d) if 1 <= mo <= 12 and 1 <= d <= 31 else m.group(0)

    text = _NUMERIC_DATE.sub(numeric, _ISO_DATE.sub(iso, text))
    # after the dates ("3/4/2025" is one): "24/7" "twenty four slash seven", "5'10"" "five ... ten"
    text = re.sub(r"(?<![\w/])(?:24/7(?:/365)?|50/50)(?![\w/])", lambda m: m.group(0).replace("/", " "), text)
    text = _FEET_INCHES.sub(lambda m: f"{m.group(1)} {'foot' if language == 'en' else 'pies'} {m.group(2)}", text)
    text = _FRACTION.sub(lambda m: _fraction(m, language), text)
    abbr = _MONTH_ABBR[language]
    if language == "en":
        month = "|".join(_MONTHS["en"] + sorted(abbr, key=len, reverse=True))
        text = re.sub(  # "Dec 7", "December 7, 2026" -> "December 7th, 2026" (espeak-ng: "deck seven")
            rf"\b({month})\.?\s(\d{{1,2}})(?:st|nd|rd|th)?\b(?!:|[.,]\d)(?:,?\s(\d{{4}})\b)?",
            lambda m: (
                _date("en", m.group(3), _month_en(m.group(1)), int(m.group(2))) if int(m.group(2)) <= 31 else m.group(0)
            ),
            text,
        )
        text = re.sub(  # "7 Dec 2026" -> "the 7th of December 2026"
            rf"(?<![\w.,:])(\d{{1,2}})(?:st|nd|rd|th)?\s({month})\b{_DOT}(?:,?\s(\d{{4}})\b)?",
            lambda m: (
                f"the {_ordinal_en(int(m.group(1)))} of {_MONTHS['en'][_month_en(m.group(2))]}"
                + (f" {m.group(3)}" if m.group(3) else "")
                if int(m.group(1)) <= 31
                else m.group(0)
            ),
            text,
        )

        def phone(m: re.Match[str]) -> str:
            groups = re.findall(r"\d+", m.group(0))
            if sum(map(len, groups)) < 7:
                return m.group(0)
            # "100-2000" is a range: a local number's exchange starts 2-9, and one of round hundreds is no number
            if len(groups) == 2 and (groups[0][0] in "01" or (groups[0].endswith("00") and groups[1].endswith("00"))):
                return m.group(0)
            said = [
                g[0] + " hundred" if len(groups) == 4 and re.fullmatch(r"[89]00", g) else " ".join(g) for g in groups
            ]
            return "plus " * m.group(0).startswith("+") + ", ".join(said)

        text = _PHONE_EN.sub(phone, text)
    else:
        short = "|".join(sorted(abbr, key=len, reverse=True))
        text = re.sub(  # "7 dic. 2026" -> "7 de diciembre de 2026"
            rf"(?<![\w.,:])(\d{{1,2}})\s(?:de\s)?({short})\b{_DOT}(?:\s(?:de\s)?(\d{{4}})\b)?",
            lambda m: _date("es", m.group(3), abbr[m.group(2).lower()], int(m.group(1))),
            text,
            flags=re.I,
        )
    days = _WEEKDAYS[language]
    day = "|".join(sorted(days, key=len, reverse=True))
    text = re.sub(  # "Mon-Fri" -> "Monday to Friday"
        rf"\b({day})\.?\s?[-–]\s?({day})\b{_DOT}",
        lambda m: f"{days[m.group(1).lower()]} {words['to']} {days[m.group(2).lower()]}",
        text,
        flags=re.I,
    )

    def span(m: re.Match[str]) -> str:
        # "between 10-20" is "between 10 and 20" ("between 10 to 20" was said), as "entre 10 y 20"
        after_between = re.search(rf"\b{words['between']}\s[$€£¥]?$", m.string[: m.start()], re.I)
        between = words["and"] if after_between else words["to"]
        return f"{m.group(1)} {between} {m.group(2)}"

    to = words["to"]
    text = _ORDINAL_RANGE.sub(rf"\1 {to} \2", text)  # "1st-3rd" "first third", with a pause between
    text = _AMPM_RANGE.sub(rf"\1 {to} \2", text)  # "9am–5pm": the en dash was dropped, "nine a m five p m"
    text = _RANGE.sub(span, text)

    def clock(m: re.Match[str]) -> str:
        h, mi, hours = int(m.group(1)), int(m.group(2)), m.group("h")
        if h > 24 or mi > 59:
            return m.group(0)
        ampm = _AMPM.match(m.string, m.end()) is not None
        if language == "es":
            if hours:
                return f"{h} horas" if mi == 0 else f"{m.group(1)}:{m.group(2)} horas"
            # "9:05" "nueve y cinco"; "14:05" stays "catorce cero cinco", as a 24-hour time is read
            return (f"{h}" if h else "0 horas") if mi == 0 else f"{h} y {mi}" if mi < 10 and h <= 12 else m.group(0)
        if 12 < h < 24 and not hours:  # "17:00" "seventeen hundred", "14:30" "fourteen thirty": 5 pm, 2:30 pm
            return (f"{h - 12}" if mi == 0 else f"{h - 12} oh {mi}" if mi < 10 else f"{h - 12}:{mi}") + " pm"
        if mi == 0:
            said = f"{h}" if ampm else "midnight" if h in (0, 24) else f"{h} o'clock" if h <= 12 else f"{h} hundred"
        elif mi < 10:
            said = f"{h} oh {mi}"
        else:
            return m.group(0)
        return said + (" hours" if hours else "")

    text = _TIME.sub(clock, text)
    text = _money(text, language)
    units = _UNITS[language]
    symbol = "|".join(re.escape(u) for u in sorted(units, key=len, reverse=True))

    def unit(m: re.Match[str]) -> str:
        number, (one, many) = m.group(1), units[m.group(2)]
        if language == "es" and number == "1":  # espeak-ng: "uno kilómetro"
            return f"{'una' if one == 'hora' else 'un'} {one}"
        # "a 5 km run": "a 5 kilometer run", as an adjective the unit is singular
        single = number == "1" or (language == "en" and re.search(r"\ban?\s$", m.string[: m.start()], re.I))
        return f"{number} {one if single else many}"

    text = re.sub(rf"(?<![\w.,])(\d+(?:[.,]\d+)?)\s?({symbol})(?![\w/°º])", unit, text)
    # "v2.1.3" "vee two point one point three"; "version v2" is not said twice
    text = _VERSION.sub(
        lambda m: (
            m.group(1)
            if re.search(r"versi[oó]n\s$", m.string[: m.start()], re.I)
            else f"{words['version']} {m.group(1)}"
        ),
        text,
    )
    text = _DOTTED.sub(lambda m: _dotted(m, language), text)
    text = _TIMES.sub(lambda m: _times(m, language), text)
    number = "number" if language == "en" else "número"
    text = re.sub(r"(?<![\w#&])#(?=\d)", f"{number} ", text)  # "#1": clean_text drops "#" as markdown ("we're 1")
    text = re.sub(r"\b([A-G])#(?!\w)", r"\1 sharp", text)  # "C#", "F#": "C"
    # "~5", ">50", "<10": clean_text drops the sign ("5 minutes" for about 5)
    signs = (
        {"~": "about", ">": "more than", "<": "less than"}
        if language == "en"
        else {"~": "unos", ">": "más de", "<": "menos de"}
    )
    text = re.sub(r"(?<![\w~<>=])([~<>])\s?(?=\d)", lambda m: f"{signs[m.group(1)]} ", text)
    caps = _SPOKEN_CAPS[language]
    text = re.sub(
        rf"(?<![\w.])({'|'.join(sorted(caps, key=len, reverse=True))})(s?)(?![\w'’]|\.\w)",
        lambda m: caps[m.group(1)] + m.group(2),
        text,
    )
    if language == "es":  # "1.º" "uno punto o", "2.ª" "dos punto a": primero, segunda; "1.er" primer

        def ordinal(m: re.Match[str]) -> str:
            n, mark = int(m.group(1)), m.group(2)
            # "1.º lugar": "primer lugar" (before a masculine noun 1 and 3 lose their -o, as "1.er" writes it)
            noun = re.match(r"\s+(?!(?:de|del|y|e|o|u|en|a|al|con|por|para)\b)[a-záéíóúñ]", m.string[m.end() :])
            if mark == "er" or (mark == "º" and n in (1, 3) and noun):
                return _ORDINALS_ES[n - 1] if n in (1, 3) else m.group(0)
            return _ORDINALS_ES[n - 1] + ("o" if mark == "º" else "a")

        text = re.sub(r"(?<![\w.,])(10|[1-9])\.?(º|ª|er)(?!\w)", ordinal, text)

    def written_out(m: re.Match[str], said: str) -> str:
        # the full stop of an abbreviation that ends the sentence is the sentence's: kept ("..., etcétera.")
        return said + "." * (not m.string[m.end() :].strip())

    for pattern, said in _ABBREVIATIONS_SPOKEN[language].items():
        text = re.sub(rf"(?<!\w){pattern}(?!\w)", functools.partial(written_out, said=said), text)
    return text


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
