"""What a perceptual test is made of, and who sees what: conditions, response sets, blocks, trial plans.

Pure code (no files, no clocks): the stimulus builder writes the blocks into the manifest, the
server turns them into one plan per participant, the analysis scores responses with the same rules.

Conditions (seed 000 Sec. 6.2): ``A`` audio only, ``N`` audio with the real talker's video, ``S``
audio with the facecast head animated from the *clean* speech (as in the paper), ``Sn`` the head
animated from the *noisy* speech the participant hears. Emotion blocks show the head ``neutral``,
``smile`` or ``sad`` (seed 002 Sec. VII-C); opinion-score blocks rate any labelled clips (seed 001
Sec. 4.2).

Balanced presentation ("latin" design): a block's cells are its condition x SNR pairs (n_cells); its
first ``n_cells * per_cell`` items are split into n_cells groups of ``per_cell``; participant number
``r`` (0, 1, 2, ... in order of arrival) sees group g in cell ``(g + r) mod n_cells``. So every
participant gets every cell exactly ``per_cell`` times and never the same item twice, and every run
of n_cells consecutive participants sees every item in every cell exactly once (a cyclic Latin
square). The order inside a block is shuffled by a seeded generator per participant. "factorial"
blocks show every item in every cell (emotion, opinion scores: the comparison is within item).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from perceptual.errors import AnswerError, ManifestError

LETTERS: tuple[str, ...] = tuple("abcdefghijklmnopqrstuvxyz")
"""GRID's letter keywords: a-z without w (25)."""
DIGITS: tuple[str, ...] = tuple("0123456789")
"""GRID's digit keywords."""
CONSONANTS: tuple[str, ...] = ("p", "b", "m", "f", "t", "d", "s", "sh", "k")
"""Seed 000's consonants /p b m f t d s sh k/ in front-to-back place of articulation."""
VOWELS: tuple[str, ...] = ("a", "i", "u")
SYLLABLES: tuple[str, ...] = tuple(c + v for v in VOWELS for c in CONSONANTS)
"""The 27 consonant-vowel syllables, vowel-major (pa ba ... ka, pi ... ki, pu ... ku)."""
EXPRESSIONS: tuple[str, ...] = ("neutral", "smile", "sad")
"""Expressions shown in emotion blocks."""
EMOTIONS: tuple[str, ...] = ("neutral", "happy", "sad", "not sure")
"""Emotions a participant can report (seed 002 Tables III-VII)."""
EXPECTED_EMOTION = {"neutral": "neutral", "smile": "happy", "sad": "sad"}
MOS_LABELS: tuple[str, ...] = ("bad", "poor", "fair", "good", "excellent")
"""The five-point opinion scale 1..5 (seed 001 Sec. 4.2)."""
MOS_SCALES: tuple[str, ...] = ("accuracy", "naturalness")
INTELLIGIBILITY_CONDITIONS: tuple[str, ...] = ("A", "N", "S", "Sn")

Kind = Literal["keywords", "syllable", "emotion", "mos"]
KINDS: tuple[str, ...] = ("keywords", "syllable", "emotion", "mos")
DESIGNS: tuple[str, ...] = ("latin", "factorial")


def snr_label(snr_db: float | None) -> str:
    """``-5`` -> ``"-5"``, None (no noise) -> ``"clean"``."""
    return "clean" if snr_db is None else f"{snr_db:g}"


def stimulus_id(block: str, item: str, condition: str, snr_db: float | None) -> str:
    """The manifest key of one stimulus, e.g. ``grid|bbaf2n|S|-5``."""
    return f"{block}|{item}|{condition}|{snr_label(snr_db)}"


def grid_keywords(sentence_id: str) -> dict[str, str]:
    """The two GRID keywords an id spells: ``bbaf2n`` -> ``{"letter": "f", "digit": "2"}`` (z = zero)."""
    sid = sentence_id.lower()
    if len(sid) != 6 or sid[3] not in LETTERS or sid[4] not in "z0123456789":
        raise ManifestError(f"not a GRID sentence id with letter and digit keywords: {sentence_id!r}")
    return {"letter": sid[3], "digit": "0" if sid[4] == "z" else sid[4]}


def syllable_of(item: str) -> str:
    """A CV item ``"en:sha"`` -> ``"sha"``."""
    syl = item.split(":", 1)[-1]
    if syl not in SYLLABLES:
        raise ManifestError(f"not a CV syllable item: {item!r}")
    return syl


@dataclass(frozen=True, kw_only=True)
class Block:
    """One block of a test, as stored in the manifest.

    kind: what the participant reports (``keywords`` letter+digit, ``syllable``, ``emotion``, ``mos``);
    conditions x snrs_db are the cells (an SNR of None means no added noise); items are sentence ids,
    ``lang:syllable`` or clip labels; per_cell: items per cell per participant ("latin" design).
    """

    name: str
    kind: str
    design: str
    conditions: tuple[str, ...]
    snrs_db: tuple[float | None, ...]
    items: tuple[str, ...]
    per_cell: int = 1
    practice: bool = False
    title: str = ""
    instructions: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ManifestError(f"block {self.name!r}: unknown kind {self.kind!r}; known: {KINDS}")
        if self.design not in DESIGNS:
            raise ManifestError(f"block {self.name!r}: unknown design {self.design!r}; known: {DESIGNS}")
        if not self.conditions or not self.snrs_db or not self.items:
            raise ManifestError(f"block {self.name!r}: needs conditions, SNRs and items")
        if self.design == "latin" and (self.per_cell < 1 or len(self.items) < self.n_cells * self.per_cell):
            raise ManifestError(
                f"block {self.name!r}: {len(self.items)} items cannot fill {self.n_cells} cells x {self.per_cell}"
            )

    @property
    def cells(self) -> list[tuple[str, float | None]]:
        """(condition, snr_db) pairs, condition-major."""
        return [(c, s) for c in self.conditions for s in self.snrs_db]

    @property
    def n_cells(self) -> int:
        return len(self.conditions) * len(self.snrs_db)

    def stimulus_ids(self) -> list[str]:
        """Every stimulus any participant can see in this block (what the builder must make)."""
        items = self.items[: self.n_cells * self.per_cell] if self.design == "latin" else self.items
        return [stimulus_id(self.name, i, c, s) for i in items for c, s in self.cells]

    def to_json(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Block:
        try:
            return cls(
                **{
                    **d,
                    "conditions": tuple(d["conditions"]),
                    "snrs_db": tuple(d["snrs_db"]),
                    "items": tuple(d["items"]),
                }
            )
        except (TypeError, KeyError) as exc:
            raise ManifestError(f"malformed block in manifest: {exc}") from exc


@dataclass(frozen=True, kw_only=True)
class Trial:
    """One trial of a participant's plan: its position, block and stimulus."""

    index: int
    block: str
    stimulus: str


def _rng(seed_text: str) -> np.random.Generator:
    return np.random.default_rng(int.from_bytes(hashlib.sha256(seed_text.encode()).digest()[:8], "little"))


def block_trials(block: Block, ordinal: int, seed_text: str) -> list[str]:
    """The stimulus ids participant number ``ordinal`` sees in ``block``, in presentation order."""
    if ordinal < 0:
        raise ValueError(f"participant ordinal must be >= 0, got {ordinal}")
    cells = block.cells
    if block.design == "latin":
        k = block.per_cell
        out = []
        for g in range(block.n_cells):
            cond, snr = cells[(g + ordinal) % block.n_cells]
            out += [stimulus_id(block.name, item, cond, snr) for item in block.items[g * k : (g + 1) * k]]
    else:
        out = [stimulus_id(block.name, item, c, s) for item in block.items for c, s in cells]
    order = _rng(f"{seed_text}|{block.name}").permutation(len(out))
    return [out[i] for i in order]


def plan(blocks: list[Block], ordinal: int, seed_text: str) -> list[Trial]:
    """The whole plan of participant number ``ordinal``: blocks in manifest order, each shuffled by
    a generator seeded from ``seed_text`` (test id + participant id) and the block name."""
    trials: list[Trial] = []
    for b in blocks:
        for sid in block_trials(b, ordinal, seed_text):
            trials.append(Trial(index=len(trials), block=b.name, stimulus=sid))
    return trials


def validate_response(kind: str, response: Any) -> dict[str, Any]:
    """The response normalised (lower-case strings, int scores) or AnswerError naming what is wrong."""
    if not isinstance(response, dict):
        raise AnswerError(f"response must be an object, got {type(response).__name__}")

    def pick(key: str, allowed: tuple[str, ...]) -> str:
        v = response.get(key)
        v = v.lower() if isinstance(v, str) else v
        if v not in allowed:
            raise AnswerError(f"{kind} response {key}={response.get(key)!r} is not one of {list(allowed)}")
        return v

    if kind == "keywords":
        return {"letter": pick("letter", LETTERS), "digit": pick("digit", DIGITS)}
    if kind == "syllable":
        return {"syllable": pick("syllable", SYLLABLES)}
    if kind == "emotion":
        return {"emotion": pick("emotion", EMOTIONS)}
    if kind == "mos":
        out = {}
        for scale in MOS_SCALES:
            v = response.get(scale)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 5:
                raise AnswerError(f"mos response {scale}={v!r} must be an integer 1..5")
            out[scale] = v
        return out
    raise AnswerError(f"unknown response kind {kind!r}")


def truth_of(kind: str, item: str, condition: str) -> dict[str, str]:
    """The correct answer of a stimulus (empty for opinion scores)."""
    if kind == "keywords":
        return grid_keywords(item)
    if kind == "syllable":
        return {"syllable": syllable_of(item)}
    if kind == "emotion":
        return {"emotion": EXPECTED_EMOTION[condition]}
    return {}


def n_correct(kind: str, truth: dict[str, str], response: dict[str, Any]) -> tuple[int, int]:
    """(correct units, scored units): GRID scores its two keywords, a syllable or emotion is one unit."""
    if kind == "mos":
        return 0, 0
    keys = ("letter", "digit") if kind == "keywords" else tuple(truth)
    return sum(int(response.get(k) == truth[k]) for k in keys), len(keys)
