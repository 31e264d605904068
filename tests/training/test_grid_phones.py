"""GRID s1 phone labels (training.grid_phones, `facecast phones`): the shipped file, its reader,
the per-word pocketsphinx alignment and its fallback."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from realtime_core.phones import PhonemeSegment
from tests.prerequisites import missing, require_module
from training.alignments import Alignment
from training.articulatory import classes_for
from training.errors import AlignmentFormatError
from training.grid_phones import (
    BILABIALS,
    DEFAULT_PATH,
    PRONUNCIATIONS,
    SILENCE,
    SentencePhones,
    check_sentence,
    label_sentence,
    read_grid_phones,
    read_grid_phones_file,
    spread,
    write_grid_phones,
)

pytestmark = pytest.mark.slow  # pocketsphinx alignment and the 900-sentence label file


@pytest.fixture
def needs_pocketsphinx() -> None:
    require_module("pocketsphinx", "optional extra: pip install 'facecast[align]'")


@pytest.fixture(scope="module")
def grid_root(shared_data):
    root = shared_data / "video" / "grid_s1"
    if not (root / "align").is_dir():
        missing(f"GRID s1 corpus not found at {root}")
    return root


def test_reader_round_trip(tmp_path) -> None:
    a = SentencePhones(
        sentence_id="bbaf2n",
        method="pocketsphinx+spread",
        spread_words=("at",),
        edge_silences=1,
        phones=(
            PhonemeSegment("SIL", 0.0, 0.95),
            PhonemeSegment("B", 0.95, 1.0123456),
            PhonemeSegment("IH", 1.0123456, 1.18),
        ),
    )
    b = SentencePhones(sentence_id="aaaa0a", method="spread", phones=(PhonemeSegment("EY", 0.5, 0.7),))
    path = write_grid_phones(tmp_path / "p.json", [a, b])
    back = read_grid_phones_file(path)
    assert list(back) == ["aaaa0a", "bbaf2n"]  # sorted by id
    assert back["bbaf2n"].method == a.method and back["bbaf2n"].spread_words == ("at",)
    assert back["bbaf2n"].edge_silences == 1 and back["aaaa0a"] == b
    got = back["bbaf2n"].phones
    assert [p.phoneme for p in got] == ["SIL", "B", "IH"]
    np.testing.assert_allclose([p.end_s for p in got], [0.95, 1.0123, 1.18], atol=1e-9)  # 0.1 ms rounding
    header = json.loads(path.read_text())["header"]
    assert "Cooke" in header["credit"] and "CC BY 4.0" in header["credit"] and "ARPAbet" in header["phone_set"]
    al = read_grid_phones(path)["bbaf2n"]
    assert isinstance(al, Alignment) and al.inventory == "arpabet" and isinstance(al.phones[0], PhonemeSegment)


def test_reader_names_the_file_for_bad_input(tmp_path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(AlignmentFormatError, match=r"bad.json"):
        read_grid_phones_file(bad)
    bad.write_text(json.dumps({"header": {"format": "something else"}}))
    with pytest.raises(AlignmentFormatError, match="not a GRID phones file"):
        read_grid_phones_file(bad)
    with pytest.raises(AlignmentFormatError, match=r"missing.json"):
        read_grid_phones_file(tmp_path / "missing.json")


def test_every_label_is_known_to_the_articulatory_rules() -> None:
    labels = {p for pron in PRONUNCIATIONS.values() for p in pron} | {SILENCE}
    assert all(classes_for(lab, "arpabet") is not None for lab in labels), labels


def test_spread_tiles_the_span_and_weights_vowels() -> None:
    ph = spread(PRONUNCIATIONS["at"], 1.0, 1.3)
    assert [p.phoneme for p in ph] == ["AE", "T"]
    assert ph[0].start_s == 1.0 and ph[-1].end_s == 1.3 and ph[0].end_s == ph[1].start_s
    assert ph[0].end_s - ph[0].start_s == pytest.approx(2 * (ph[1].end_s - ph[1].start_s))


def test_label_sentence_rejects_bad_word_alignments() -> None:
    with pytest.raises(AlignmentFormatError, match="gap or overlap"):
        label_sentence("x", [(0.0, 0.5, "sil"), (0.6, 0.9, "bin")], None, None, source="x.align")
    with pytest.raises(AlignmentFormatError, match="not in the GRID vocabulary"):
        label_sentence("x", [(0.0, 0.5, "sil"), (0.5, 0.9, "banana")], None, None, source="x.align")
    with pytest.raises(AlignmentFormatError, match="end"):
        label_sentence("x", [(0.5, 0.5, "bin")], None, None, source="x.align")


def test_shipped_file_covers_the_corpus_inside_the_word_spans(grid_root) -> None:
    """Every sentence: phones tile its GRID word spans exactly, in pronunciation order (so every
    word with /p b m/ has them), with plausible durations."""
    from assets.grid import SILENCE_WORDS, read_words, sentences

    shipped = read_grid_phones_file(DEFAULT_PATH)
    sents = sentences(grid_root)
    assert len(sents) == 900 and {s.sentence_id for s in sents} == set(shipped)
    durations = []
    n_bilabial_words = 0
    for s in sents:
        words = read_words(s.align)
        phones = shipped[s.sentence_id].phones
        chk = check_sentence(phones, words)
        assert not chk.problems, (s.sentence_id, chk.problems)
        assert phones[0].start_s == pytest.approx(words[0][0]) and phones[-1].end_s == pytest.approx(words[-1][1])
        for a0, a1, w in words:
            if w not in SILENCE_WORDS and BILABIALS & set(PRONUNCIATIONS[w]):
                n_bilabial_words += 1
                assert any(p.phoneme in BILABIALS and a0 - 1e-6 <= p.start_s and p.end_s <= a1 + 1e-6 for p in phones)
        durations += [d for _, d in chk.durations]
        assert shipped[s.sentence_id].method in ("pocketsphinx", "pocketsphinx+spread", "spread")
    d = np.array(durations)
    assert n_bilabial_words > 900  # every sentence-initial "bin"/"place"/"blue"/... at least
    assert d.min() >= 0.01 and np.median(d) == pytest.approx(0.075, abs=0.03) and np.percentile(d, 99) < 0.3
    methods = [shipped[s.sentence_id].method for s in sents]
    assert methods.count("spread") <= 5 and methods.count("pocketsphinx") > 800  # 1 (bwwb1a) and 878 in the file


def _high_band_fraction(x: np.ndarray, rate_hz: int = 16000) -> float:
    """Share of a segment's energy above 3 kHz (of that above 100 Hz): high for frication."""
    spec = np.abs(np.fft.rfft(x * np.hanning(len(x)))) ** 2
    f = np.fft.rfftfreq(len(x), 1.0 / rate_hz)
    return float(spec[f > 3000].sum() / spec[f > 100].sum())


def test_hand_checked_sentence_bbaf2n(grid_root, ffmpeg) -> None:
    """'bin blue at f two now', checked by ear and on the plot: both bilabials open their words;
    the frication of /F/ and the aspiration of the /T/ of "two" and the quiet /B/ closures are
    where the labels say (spectra and levels computed here, independently of the aligner)."""
    from training.video import decode_audio

    ph = read_grid_phones(DEFAULT_PATH)["bbaf2n"].phones
    labels = [p.phoneme for p in ph]
    assert labels == ["SIL", "B", "IH", "N", "B", "L", "UW", "AE", "T", "EH", "F", "T", "UW", "N", "AW", "SIL"]
    assert ph[1].start_s == pytest.approx(0.95) and ph[4].start_s == pytest.approx(1.18)  # GRID's "bin", "blue"
    assert 0.03 <= ph[1].end_s - ph[1].start_s <= 0.12 and 0.03 <= ph[4].end_s - ph[4].start_s <= 0.12
    x = decode_audio(grid_root / "video" / "bbaf2n.mp4", 16000)

    def seg(p: PhonemeSegment) -> np.ndarray:
        return x[int(p.start_s * 16000) : int(p.end_s * 16000)]

    eh, f, t, uw = ph[9], ph[10], ph[11], ph[12]
    assert _high_band_fraction(seg(f)) > 0.2 and _high_band_fraction(seg(t)) > 0.2  # measured 0.46, 0.50
    assert _high_band_fraction(seg(eh)) < 0.05 and _high_band_fraction(seg(uw)) < 0.05  # voiced vowels: 0.002
    # the /B/ of "bin" is quieter than the vowel after it (closure, then the burst)
    assert np.sqrt(np.mean(seg(ph[1]) ** 2)) < 0.5 * np.sqrt(np.mean(seg(ph[2]) ** 2))


@pytest.mark.usefixtures("needs_pocketsphinx")
def test_pronunciations_are_cmudict_but_for_the_british_letters() -> None:
    from pocketsphinx import Decoder

    d = Decoder(samprate=16000, bestpath=False, loglevel="FATAL")
    differ = {w for w, p in PRONUNCIATIONS.items() if d.lookup_word(w) != " ".join(p)}
    assert differ == {"a", "z"}  # CMUdict's first entries: A = AH (the article), Z = Z IY (American)


@pytest.mark.usefixtures("needs_pocketsphinx")
def test_aligning_again_reproduces_the_shipped_labels(grid_root, ffmpeg) -> None:
    from assets.grid import read_words
    from training.grid_phones import SentenceAligner
    from training.video import decode_audio

    shipped = read_grid_phones_file(DEFAULT_PATH)
    aligner = SentenceAligner()
    for sid in ("bbaf2n", "bbwt1a", "lbad9a"):
        words = read_words(grid_root / "align" / f"{sid}.align")
        got = label_sentence(sid, words, decode_audio(grid_root / "video" / f"{sid}.mp4", 16000), aligner)
        assert got.method == shipped[sid].method and got.spread_words == shipped[sid].spread_words
        assert [p.phoneme for p in got.phones] == [p.phoneme for p in shipped[sid].phones]
        np.testing.assert_allclose([p.end_s for p in got.phones], [p.end_s for p in shipped[sid].phones], atol=2e-4)
    # without audio every word is spread, inside the same spans
    spread_only = label_sentence("bbaf2n", read_words(grid_root / "align" / "bbaf2n.align"), None, None)
    assert (
        spread_only.method == "spread"
        and not check_sentence(spread_only.phones, read_words(grid_root / "align" / "bbaf2n.align")).problems
    )


@pytest.mark.usefixtures("needs_pocketsphinx")
def test_cli_labels_a_folder_and_names_a_broken_alignment(grid_root, ffmpeg, tmp_path, capsys) -> None:
    from facecast.cli import main

    root = tmp_path / "grid"
    (root / "video").mkdir(parents=True)
    (root / "align").mkdir()
    for sid in ("bbaf2n", "bbaf3s"):
        (root / "video" / f"{sid}.mp4").symlink_to(grid_root / "video" / f"{sid}.mp4")
        shutil.copy(grid_root / "align" / f"{sid}.align", root / "align")
    (root / "video" / "bbaf4p.mp4").symlink_to(grid_root / "video" / "bbaf4p.mp4")
    (root / "align" / "bbaf4p.align").write_text("0 100 sil\n200 5000 bin\n")  # gap: malformed
    out = tmp_path / "phones.json"
    png = tmp_path / "plot.png"
    assert main(["phones", "--root", str(root), "-o", str(out), "--plot", str(png), "--workers", "2"]) == 0
    text = capsys.readouterr().out
    assert "wrote 2 sentences" in text and "tiling/pronunciation problems: 0" in text
    assert "skipped" in text and "bbaf4p.align" in text and "gap or overlap" in text
    assert set(read_grid_phones_file(out)) == {"bbaf2n", "bbaf3s"} and png.stat().st_size > 10_000


def test_shipped_hmm_file_covers_the_corpus_near_the_word_spans(grid_root) -> None:
    """The talker-specific labels (unit selection's default): every sentence has the words'
    pronunciations in order, contiguous from 0 s to about the recording's end, each word within
    0.1 s of its GRID span (plus the 10 ms frame the window is rounded to and the 7.5 ms from a
    frame edge to its boundary), phones at least 30 ms (3 states of 10 ms)."""
    from assets.grid import read_words, sentences
    from training.grid_phones import HMM_PATH, check_free_sentence

    shipped = read_grid_phones_file(HMM_PATH)
    sents = sentences(grid_root)
    assert {s.sentence_id for s in sents} == set(shipped)
    durations = []
    for s in sents:
        words = read_words(s.align)
        entry = shipped[s.sentence_id]
        chk = check_free_sentence(entry.phones, words, slack_s=0.1 + 0.0175 + 1e-6)
        assert not chk.problems, (s.sentence_id, chk.problems)
        assert entry.method == "hmm" and entry.phones[-1].end_s == pytest.approx(words[-1][1], abs=0.05)
        durations += [d for _, d in chk.durations]
    d = np.array(durations)
    assert d.min() >= 0.03 - 1e-6 and np.median(d) == pytest.approx(0.075, abs=0.03)


@pytest.mark.parametrize("method", ["pocketsphinx", "hmm"])
def test_each_method_relabels_its_own_shipped_file(method) -> None:
    """`facecast phones --method M` without -o writes the file whose labels are M's (the shipped files as
    evidence), so relabelling with the HMM never replaces the pocketsphinx labels every reader but unit
    selection uses (it did: both methods wrote grid_s1_phones.json)."""
    from training.grid_phones import default_path

    methods = {s.method for s in read_grid_phones_file(default_path(method)).values()}
    assert (methods == {"hmm"}) == (method == "hmm")
