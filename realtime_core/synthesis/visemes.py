"""The viseme category table of unit selection (seed 001 Sec. 3.7): phones -> visual classes.

A *viseme* is the visible production of one or more phones: phones that look alike on the
lips and jaw share a class. Unit selection only asks whether two phones are in the same class
(the observation cost ``d_j(o_t)`` and the junction condition ``G``), so the table decides how
freely recorded motion may be reused: finer classes give more faithful units, coarser classes
more choice. Classes are ARPAbet-named; the table maps three phone inventories onto them, so a
corpus labelled in ARPAbet serves targets from espeak-ng's English and Spanish phones.

=========  =========================================  ==================  =====================  ==============
class      looks like                                 ARPAbet             espeak-ng English      espeak-ng Spanish
=========  =========================================  ==================  =====================  ==============
sil        mouth at rest                              sil sp pau spn      _ _: _! _^_             _ _: _!
PBM        lips pressed together                      p b m em            p b m                   p b m B
FV         lower lip under the upper teeth            f v                 f v                     f
TH         tongue tip between the teeth               th dh               T D                     T D
TDNL       jaw high, tongue on the ridge, lips free   t d n l dx nx en el t d n l t# d# @L ...    t d n l ** r R R2 rr
SZ         teeth together, lips slightly spread       s z                 s z                     s z
SH         lips protruded and rounded                 sh zh ch jh         S Z tS dZ               tS dZ
KG         jaw mid, lips free (back of the mouth)     k g ng hh q         k g N x h ?             k g Q x N
R          lips rounded, protruded (English /r/)      r                   r r-                    -
W          lips tightly rounded                       w wh                w w#                    w
Y          spread lips, high jaw                      y                   j                       j jj y n^ J^ l^
IY         spread, nearly closed                      iy ih ix            i: i I I2 I# i@ IR      i
EH         spread, half open                          eh                  e E e@                  e E
AE         spread, open                               ae                  a aa a#                 -
AA         wide open, neutral width                   aa                  A: A@ 0 VR              a
AH         mid open, neutral (/ʌ/ and schwa)          ah ax               @ @2 @5 @- 3 V          -
ER         r-coloured, slightly rounded               er axr              3:                      -
AO         open, rounded                              ao                  O: O2 O@ o@             o O
UW         close, tightly rounded                     uw uh ux            u: U U@                 u
EY         half open gliding to spread                ey                  eI                      eI eU
AY         open gliding to spread                     ay                  aI aI2 aI@ aI3          aI
AW         open gliding to rounded                    aw                  aU                      aU
OW         rounded gliding to tight rounding          ow                  oU @U                   -
OY         rounded gliding to spread                  oy                  OI                      oI
=========  =========================================  ==================  =====================  ==============

Diphthongs are classes of their own: their lips move within the phone, and the recorded unit of
the same diphthong carries exactly that glide. espeak-ng's ``;`` (between two vowels, "my
umbrella" ``maI; Vmbr'El@``, "see it" ``s'i:; It``) is no phone of its own but a link, voiced and
with the lips moving on from the vowel before: :data:`LINKS` gives its time to that vowel.
Spanish has no /ʌ/, /æ/ or English /r/; its mid back /o/ is closest to English /ɔ/ (AO). When a
corpus lacks a class, :data:`FALLBACK` names the classes that look most alike, in order (e.g. OY
-> AO -> OW).
"""

from __future__ import annotations

import re

from realtime_core.errors import ConfigError

VISEMES: tuple[str, ...] = (
    "sil",
    "PBM",
    "FV",
    "TH",
    "TDNL",
    "SZ",
    "SH",
    "KG",
    "R",
    "W",
    "Y",
    "IY",
    "EH",
    "AE",
    "AA",
    "AH",
    "ER",
    "AO",
    "UW",
    "EY",
    "AY",
    "AW",
    "OW",
    "OY",
)
"""The viseme classes; a class's index in this tuple is its integer id."""

VISEME_ID: dict[str, int] = {v: i for i, v in enumerate(VISEMES)}

INVENTORIES: tuple[str, ...] = ("arpabet", "espeak-en", "espeak-es")


def _table(spec: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for group in spec.split(";"):
        viseme, _, labels = group.strip().partition(":")
        for label in labels.split():
            out[label] = viseme.strip()
    return out


PHONE_TO_VISEME: dict[str, dict[str, str]] = {
    "arpabet": _table(
        "sil: sil sp pau spn h# <sil> ; PBM: p b m em ; FV: f v ; TH: th dh ;"
        " TDNL: t d n l dx nx en el ; SZ: s z ; SH: sh zh ch jh ; KG: k g ng hh h q ; R: r ; W: w wh ;"
        " Y: y ; IY: iy ih ix ; EH: eh ; AE: ae ; AA: aa ; AH: ah ax ; ER: er axr ; AO: ao ;"
        " UW: uw uh ux ; EY: ey ; AY: ay ; AW: aw ; OW: ow ; OY: oy"
    ),
    "espeak-en": _table(
        "sil: _ _: _! _^_ ; PBM: p b m ; FV: f v ; TH: T D ;"
        " TDNL: t d n l t# d# t2 t[ d[ n- l/ @L ; SZ: s z ; SH: S Z tS dZ ; KG: k g N x h ? ;"
        " R: r r- ; W: w w# ; Y: j ; IY: i: i I I2 I# i@ i@3 IR ; EH: e E e@ ; AE: a aa a# ;"
        " AA: A: A@ 0 VR ; AH: @ @2 @5 @- 3 V ; ER: 3: ; AO: O: O2 O@ o@ ; UW: u: U U@ ;"
        " EY: eI ; AY: aI aI2 aI@ aI3 ; AW: aU ; OW: oU @U ; OY: OI"
    ),
    "espeak-es": _table(
        "sil: _ _: _! _^_ ; PBM: p b m B ; FV: f ; TH: T D ; TDNL: t d n l ** r R R2 rr ;"
        " SZ: s z ; SH: tS dZ ; KG: k g Q x N ; W: w ; Y: j jj y n^ J^ l^ ; IY: i ; EH: e E ;"
        " AA: a ; AO: o O ; UW: u ; EY: eI eU ; AY: aI ; AW: aU ; OY: oI"
    ),
}
"""inventory -> {phone label: viseme class} (the table in the module doc)."""

LINKS: dict[str, frozenset[str]] = {
    "arpabet": frozenset(),
    "espeak-en": frozenset({";"}),
    "espeak-es": frozenset({";"}),
}
"""inventory -> labels that mark a link between phones rather than a phone (espeak's ``;``, written
between two vowels): a target gives their time to the phone before them."""

FALLBACK: dict[str, tuple[str, ...]] = {
    "sil": ("PBM",),
    "PBM": ("FV", "sil"),
    "FV": ("PBM", "TH"),
    "TH": ("TDNL", "SZ"),
    "TDNL": ("SZ", "KG"),
    "SZ": ("TDNL", "TH"),
    "SH": ("R", "SZ"),
    "KG": ("TDNL", "AH"),
    "R": ("W", "SH"),
    "W": ("UW", "R"),
    "Y": ("IY", "TDNL"),
    "IY": ("EH", "Y"),
    "EH": ("AE", "IY"),
    "AE": ("EH", "AA"),
    "AA": ("AH", "AE"),
    "AH": ("AA", "EH"),
    "ER": ("R", "AH"),
    "AO": ("OW", "AA"),
    "UW": ("OW", "W"),
    "EY": ("EH", "IY"),
    "AY": ("AA", "AE"),
    "AW": ("AA", "AO"),
    "OW": ("AO", "UW"),
    "OY": ("AO", "OW"),
}
"""Per class, the classes that look most alike, in order (used when a corpus lacks a class)."""

for _inv, _tab in PHONE_TO_VISEME.items():  # a typo in the tables must fail at import, not at run
    for _label, _v in _tab.items():
        if _v not in VISEME_ID:
            raise ConfigError(f"{_inv} phone {_label!r} maps to unknown viseme {_v!r}")
if set(FALLBACK) != set(VISEMES) or any(f not in VISEME_ID for fs in FALLBACK.values() for f in fs):
    raise ConfigError("FALLBACK must list known classes for every viseme")


def normalise_phone(label: str, inventory: str) -> str:
    """ARPAbet: lower case without stress digits (``AH0`` -> ``ah``); espeak labels as they are
    (case matters there) without stress marks."""
    label = label.strip()
    if inventory == "arpabet":
        return re.sub(r"[0-9]", "", label).lower()
    return label.lstrip("',")


def viseme_of(label: str, inventory: str, *, default: str | None = None) -> str:
    """The viseme class of one phone label. Unknown labels raise ConfigError naming the label,
    unless ``default`` (a class) is given."""
    if inventory not in PHONE_TO_VISEME:
        raise ConfigError(f"unknown phone inventory {inventory!r}; known: {INVENTORIES}")
    v = PHONE_TO_VISEME[inventory].get(normalise_phone(label, inventory))
    if v is None:
        if default is None:
            raise ConfigError(f"phone {label!r} is not in the {inventory} viseme table")
        if default not in VISEME_ID:
            raise ConfigError(f"default viseme {default!r} is not a class")
        return default
    return v


def resolve(viseme: str, available: set[str] | frozenset[str]) -> str:
    """``viseme`` if the corpus has it, else the first available class in a breadth-first walk of
    :data:`FALLBACK`; raises ConfigError if the corpus has no class at all reachable."""
    seen, queue = {viseme}, [viseme]
    while queue:
        v = queue.pop(0)
        if v in available:
            return v
        for f in FALLBACK[v]:
            if f not in seen:
                seen.add(f)
                queue.append(f)
    raise ConfigError(f"no viseme class similar to {viseme!r} is in the corpus (it has {sorted(available)})")
