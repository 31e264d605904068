"""The GRID s1 corpus (``../shared/data/video/grid_s1/``): sentence ids, the evaluation split,
word alignments and the sentence text the ids spell.

One split for every consumer (real-lips training, Motion Units, unit selection, perceptual
stimuli), by sentence: a sentence's split is fixed by a hash of its id, so adding or removing
clips never moves another sentence between splits. About 80 % train, 10 % val (model selection,
tuning), 10 % test (reported only; never tuned on).

The corpus is read from where the user says; :func:`default_root` is the development location
beside the repository (never copied into it).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from assets.errors import AlignmentFormatError, GridNotFoundError
from assets.shared import ENV, shared_data_root

Split = Literal["train", "val", "test"]

WORD_ALIGN_UNIT_S = 1.0 / 25000.0
"""GRID ``.align`` times are in 1/25000 s (1000 units per 25 fps video frame)."""

SILENCE_WORDS = frozenset({"sil", "sp"})

_COMMAND = {"b": "bin", "l": "lay", "p": "place", "s": "set"}
_COLOUR = {"b": "blue", "g": "green", "r": "red", "w": "white"}
_PREPOSITION = {"a": "at", "b": "by", "i": "in", "w": "with"}
_DIGIT = {
    "z": "zero",
    "1": "one",
    "2": "two",
    "3": "three",
    "4": "four",
    "5": "five",
    "6": "six",
    "7": "seven",
    "8": "eight",
    "9": "nine",
    "0": "zero",
}
_ADVERB = {"a": "again", "n": "now", "p": "please", "s": "soon"}


def default_root() -> Path:
    """``$FACECAST_SHARED_DATA/video/grid_s1`` when that variable is set, else
    ``../shared/data/video/grid_s1`` beside the repository checkout."""
    return shared_data_root() / "video" / "grid_s1"


def split_of(sentence_id: str) -> Split:
    """The split of one sentence id: sha1(id) mod 10 == 0 -> test, == 1 -> val, else train."""
    bucket = int(hashlib.sha1(sentence_id.encode("ascii")).hexdigest(), 16) % 10
    return "test" if bucket == 0 else "val" if bucket == 1 else "train"


@dataclass(frozen=True, kw_only=True)
class GridSentence:
    """One sentence: ``video`` (mp4 with audio) and ``align`` (word alignment) paths."""

    sentence_id: str
    video: Path
    align: Path

    @property
    def split(self) -> Split:
        return split_of(self.sentence_id)


def sentences(root: str | Path | None = None, *, split: Split | None = None) -> list[GridSentence]:
    """Every sentence under ``root`` with both a video and an alignment, sorted by id.

    Raises :class:`GridNotFoundError` naming ``root`` when it holds no sentence at all (of any split): a folder
    missing or mistyped, or the shared data elsewhere, was an empty list that each command reported as its own
    "no sentences to build a unit corpus from" or "no utterances left to train on (check the corpus folders and
    --exclude-source)"."""
    root = Path(root) if root is not None else default_root()
    every = []
    for video in sorted((root / "video").glob("*.mp4")):
        align = root / "align" / f"{video.stem}.align"
        if align.is_file():
            every.append(GridSentence(sentence_id=video.stem, video=video, align=align))
    if not every:
        where = "no such folder" if not root.is_dir() else "no video/*.mp4 with its align/*.align in it"
        raise GridNotFoundError(
            root,
            f"no GRID s1 sentences ({where}): give the GRID s1 folder (it holds video/ and align/), or set "
            f"{ENV} to the shared data folder that holds video/grid_s1",
        )
    return [s for s in every if split is None or s.split == split]


def read_words(path: str | Path) -> list[tuple[float, float, str]]:
    """A GRID ``.align`` file -> ``[(start_s, end_s, word)]`` including ``sil``/``sp``.

    Raises :class:`~training.errors.AlignmentFormatError` naming the file for a missing or
    unreadable file, a line that is not ``start end word`` with integer times, times that run
    backwards, or no words at all.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise AlignmentFormatError(path, f"cannot be read ({exc})") from exc
    out: list[tuple[float, float, str]] = []
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        parts = line.split()
        try:
            if len(parts) != 3:
                raise ValueError
            a, b = int(parts[0]), int(parts[1])
        except ValueError:
            raise AlignmentFormatError(path, f"line {n} is not 'start end word' with integer times: {line!r}") from None
        if b < a or (out and a * WORD_ALIGN_UNIT_S < out[-1][1] - 1e-9):
            raise AlignmentFormatError(path, f"line {n}: times run backwards ({line!r})")
        out.append((a * WORD_ALIGN_UNIT_S, b * WORD_ALIGN_UNIT_S, parts[2]))
    if not out:
        raise AlignmentFormatError(path, "no words")
    return out


def align_for_video(video: str | Path) -> Path | None:
    """The word alignment of a video, or None: ``<root>/align/<id>.align`` for
    ``<root>/video/<id>.mp4`` (this corpus's layout), else ``<id>.align`` beside the video, else
    one beside it whose stem ends the video's stem (GRID's ``id2_vcd_swwp2s.mpg`` <- ``swwp2s.align``)."""
    video = Path(video)
    for cand in (video.parent.parent / "align" / f"{video.stem}.align", video.with_suffix(".align")):
        if cand.is_file():
            return cand
    for cand in sorted(video.parent.glob("*.align")):
        if video.stem.endswith(cand.stem):
            return cand
    return None


def sentence_text(sentence_id: str) -> str:
    """The six-word sentence a GRID id spells, e.g. ``bbaf2n`` -> ``bin blue at f two now``.

    Letters are written as the letter itself (its pronunciation is the word alignment's business).
    """
    sid = sentence_id.lower()
    if len(sid) != 6:
        raise ValueError(f"not a GRID sentence id: {sentence_id!r}")
    try:
        return " ".join(
            (_COMMAND[sid[0]], _COLOUR[sid[1]], _PREPOSITION[sid[2]], sid[3], _DIGIT[sid[4]], _ADVERB[sid[5]])
        )
    except KeyError as exc:
        raise ValueError(f"not a GRID sentence id: {sentence_id!r}") from exc
