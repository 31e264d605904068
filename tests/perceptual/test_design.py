"""The pure parts: balanced plans, eq. 13, noise at an SNR, response validation, the statistics helpers."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from scipy import stats

from perceptual.analysis import mean_ci95, paired_test, relative_visual_contribution
from perceptual.design import Block, block_trials, plan, validate_response
from perceptual.errors import AnswerError, ManifestError
from perceptual.stimuli import add_white_noise, set_level


def _block(per_cell: int = 2) -> Block:
    return Block(
        name="grid",
        kind="keywords",
        design="latin",
        conditions=("A", "N", "S"),
        snrs_db=(-5.0, -10.0, -15.0),
        items=tuple(f"s{i:02d}" for i in range(9 * per_cell)),
        per_cell=per_cell,
    )


def test_latin_square_balances_cells_and_never_repeats_an_item():
    b = _block()
    seen = Counter()
    for ordinal in range(9):
        ids = block_trials(b, ordinal, f"test|p{ordinal}")
        items = [s.split("|")[1] for s in ids]
        cells = Counter(tuple(s.split("|")[2:]) for s in ids)
        assert len(set(items)) == len(items) == 18  # no sentence twice for one person
        assert set(cells.values()) == {2} and len(cells) == 9  # every condition x SNR cell equally often
        seen.update(ids)
    # Nine consecutive participants: every sentence in every cell exactly once.
    assert len(seen) == 18 * 9 and set(seen.values()) == {1}


def test_plans_are_seeded_per_participant():
    b = _block()
    a1, a2 = plan([b], 0, "t|x"), plan([b], 0, "t|x")
    assert a1 == a2
    other = [t.stimulus for t in plan([b], 0, "t|y")]
    assert sorted(other) == sorted(t.stimulus for t in a1) and other != [t.stimulus for t in a1]


def test_too_few_items_for_the_design_is_refused():
    with pytest.raises(ManifestError, match="cannot fill"):
        Block(
            name="g", kind="keywords", design="latin", conditions=("A", "N"), snrs_db=(-5.0,), items=("a",), per_cell=1
        )


@pytest.mark.parametrize(
    ("c_a", "c_n", "c_s", "c_v"),
    [  # seed 000 Table 2
        (0.5704, 0.8426, 0.7407, 0.7628),
        (0.4852, 0.7944, 0.6796, 0.7770),
        (0.3704, 0.7389, 0.5963, 0.7735),
    ],
)
def test_eq13_reproduces_the_papers_table(c_a, c_n, c_s, c_v):
    assert relative_visual_contribution(c_a, c_n, c_s) == pytest.approx(c_v, abs=1e-4)
    assert relative_visual_contribution(1.0, 1.0, 1.0) is None


@pytest.mark.parametrize("snr_db", [-5.0, -10.0, -15.0])
def test_white_noise_has_the_asked_snr_over_the_speech(snr_db):
    rng = np.random.default_rng(1)
    n = 200_000
    clean = np.zeros(n)
    active = np.zeros(n, dtype=bool)
    active[50_000:150_000] = True
    clean[active] = np.sin(np.arange(100_000) * 0.05) * (0.3 + 0.2 * rng.random(100_000))
    mix = add_white_noise(clean, active, snr_db, seed=7)
    noise = mix - clean
    got = 10 * np.log10(np.mean(clean[active] ** 2) / np.mean(noise**2))
    assert got == pytest.approx(snr_db, abs=0.05)
    assert np.array_equal(mix, add_white_noise(clean, active, snr_db, seed=7))  # same noise in A, N and S
    leveled = set_level(mix, active, -20.0)
    assert 20 * np.log10(np.sqrt(np.mean(leveled[active] ** 2))) == pytest.approx(-20.0, abs=0.01)


@pytest.mark.parametrize(
    ("kind", "response", "match"),
    [
        ("keywords", {"letter": "w", "digit": "1"}, "letter"),  # GRID has no W
        ("keywords", {"letter": "a"}, "digit"),
        ("syllable", {"syllable": "za"}, "syllable"),
        ("mos", {"accuracy": 6, "naturalness": 3}, "accuracy"),
        ("mos", {"accuracy": True, "naturalness": 3}, "accuracy"),
        ("emotion", "happy", "object"),
    ],
)
def test_bad_responses_are_named(kind, response, match):
    with pytest.raises(AnswerError, match=match):
        validate_response(kind, response)


def test_statistics_helpers_agree_with_direct_formulas():
    x = [3.0, 4.0, 5.0, 4.0, 2.0]
    m, lo, hi = mean_ci95(x)
    half = stats.t.ppf(0.975, 4) * np.std(x, ddof=1) / np.sqrt(5)
    assert (m, lo, hi) == pytest.approx((3.6, 3.6 - half, 3.6 + half))
    assert paired_test([0.5, 0.5], [0.5, 0.5])["p"] is None
    r = paired_test([0.9, 0.8, 0.7, 0.95, 0.85, 0.9], [0.5, 0.4, 0.6, 0.5, 0.3, 0.45])
    assert r["p"] == pytest.approx(stats.wilcoxon([0.4, 0.4, 0.1, 0.45, 0.55, 0.45]).pvalue)
