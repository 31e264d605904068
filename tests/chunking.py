"""The chunk-invariance property every streaming stage of ``realtime_core`` promises.

A stage is anything with ``push(*arrays) -> (k, ...) array`` (the rows that became ready) and
``flush() -> (k, ...) array`` (the rest at end of stream). Fed the same input whole, one row at a
time, or in any chunking (including empty chunks), the concatenated output must be the same.
:func:`assert_chunk_invariant` checks the first two directly and draws random chunkings with
hypothesis, which shrinks a failure to a small list of cut points.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st


class Stage(Protocol):
    def push(self, *arrays: np.ndarray) -> np.ndarray: ...
    def flush(self) -> np.ndarray: ...


def run_chunked(make_stage: Callable[[], Any], inputs: Sequence[np.ndarray], cuts: Sequence[int]) -> np.ndarray:
    """A fresh stage fed ``inputs`` (arrays of equal length, split together along axis 0 at ``cuts``),
    then flushed; its outputs concatenated along axis 0."""
    stage = make_stage()
    outs = [stage.push(*parts) for parts in zip(*(np.split(x, list(cuts)) for x in inputs), strict=True)]
    outs.append(stage.flush())
    return np.concatenate(outs, axis=0)


def assert_chunk_invariant(
    make_stage: Callable[[], Any],
    *inputs: np.ndarray,
    atol: float = 0.0,
    rtol: float = 0.0,
    max_examples: int = 20,
    one_by_one: bool = True,
    empty_chunks: bool = True,
) -> np.ndarray:
    """Assert that ``make_stage()`` gives the same output for ``inputs`` pushed whole, row by row
    (``one_by_one``: sample by sample for audio) and in ``max_examples`` random chunkings drawn by
    hypothesis (with zero-length chunks when ``empty_chunks``). Returns the whole-input output.

    ``atol``/``rtol``: tolerance against the whole-input output (0 = bit-identical).
    """
    arrays = [np.asarray(x) for x in inputs]
    n = len(arrays[0])
    if any(len(x) != n for x in arrays):
        raise ValueError(f"inputs must have equal lengths, got {[len(x) for x in arrays]}")
    whole = run_chunked(make_stage, arrays, [])

    def check(got: np.ndarray, how: str) -> None:
        assert got.shape == whole.shape, f"{how}: output shape {got.shape}, whole input gave {whole.shape}"
        np.testing.assert_allclose(got, whole, rtol=rtol, atol=atol, err_msg=f"{how} differs from the whole input")

    if one_by_one:
        check(run_chunked(make_stage, arrays, range(1, n)), "one row at a time")
    if n < 2:
        return whole

    low = 0 if empty_chunks else 1
    cut_lists = st.lists(st.integers(low, n), min_size=1, max_size=min(40, n)).map(sorted)
    if not empty_chunks:
        cut_lists = cut_lists.map(lambda c: sorted(set(c)))

    @settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )
    @given(cuts=cut_lists)
    def random_chunkings(cuts: list[int]) -> None:
        check(run_chunked(make_stage, arrays, cuts), f"chunks cut at {cuts}")

    random_chunkings()
    return whole
