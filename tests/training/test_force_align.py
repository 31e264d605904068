"""pocketsphinx forced alignment of transcribed real speech (optional extra "align")."""

from __future__ import annotations

import numpy as np
import pytest

from assets.audio import read_wav
from tests.prerequisites import require_module
from training.build_corpus import BuildConfig, build_corpus
from training.corpus import load_corpus

# pocketsphinx forced alignment on real speech.
pytestmark = [pytest.mark.system, pytest.mark.slow]


@pytest.fixture(autouse=True)
def _pocketsphinx_installed() -> None:
    require_module("pocketsphinx", "optional extra: pip install 'facecast[align]'")


def test_reproduces_the_shipped_librivox_alignment(shared_data) -> None:
    """The LibriVox clips' *.phone.json came from pocketsphinx: aligning the .txt again gives
    the same phones within 20 ms on average."""
    from training.alignments import read_phone_json
    from training.force_align import force_align

    stem = shared_data / "speech" / "librivox" / "sense_and_sensibility_01_austen_64kb-0880"
    samples, rate = read_wav(stem.with_suffix(".wav"))
    got = force_align(samples, rate, stem.with_suffix(".txt").read_text(), source=stem.with_suffix(".wav"))
    ref = read_phone_json(stem.with_name(stem.name + ".phone.json"))
    assert [p.phoneme for p in got.phones] == [p.phoneme for p in ref.phones]
    assert np.mean([abs(a.start_s - b.start_s) for a, b in zip(got.phones, ref.phones)]) < 0.02


def test_builder_aligns_transcribed_speech_and_names_what_it_skips(shared_data, tmp_path) -> None:
    rep = build_corpus(
        BuildConfig(
            out_dir=tmp_path,
            sentences=0,
            languages=(),
            real_dirs=(shared_data / "speech" / "ljspeech",),
            force_align=True,
        )
    )
    utts = load_corpus(tmp_path)
    assert len(utts) >= 5 and all(u.source == "real" and u.speaker_group == "real:ljspeech" for u in utts)
    for u in utts:  # phones cover the speech and the rules open and close the mouth
        assert u.phonemes[-1].end_s <= u.duration_s + 0.02 and u.params[:, 2].max() > 0.1
        assert (u.params[:, 2] == 0.0).any()
    # LJ001-0003 says "woodcutters", which the dictionary lacks: skipped, with file and reason
    assert any("LJ001-0003.wav" in f and "woodcutters" in why for f, why in rep.skipped), rep.skipped
