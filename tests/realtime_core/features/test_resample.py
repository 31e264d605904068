"""The streaming resampler: scipy's resample_poly whole, bit-identical for any chunking, prompt output."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal

from realtime_core.features.resample import StreamingResampler, resample_audio
from tests.chunking import assert_chunk_invariant


@pytest.mark.parametrize("rates", [(48000, 16000), (44100, 16000), (8000, 16000), (22050, 16000), (16000, 16000)])
def test_resampler_equals_resample_poly_for_any_chunking(rates):
    fr, to = rates
    rng = np.random.default_rng(1)
    x = rng.standard_normal(9001)
    g = math.gcd(fr, to)
    ref = scipy.signal.resample_poly(x, to // g, fr // g)
    # bit-identical whatever the chunking (sample by sample and hypothesis-drawn chunkings)
    whole = assert_chunk_invariant(lambda: StreamingResampler(fr, to), x, max_examples=10)
    assert whole.shape == ref.shape
    np.testing.assert_allclose(whole, ref, atol=1e-12)
    np.testing.assert_allclose(resample_audio(x, fr, to), ref, atol=1e-12)


def test_resampler_emits_as_soon_as_inputs_arrive():
    r = StreamingResampler(48000, 16000)
    y = r.push(np.ones(3000))
    # Output m needs input n_hi(m); everything with n_hi <= 2999 is out, nothing more.
    assert r.n_hi(len(y) - 1) <= 2999 < r.n_hi(len(y))
