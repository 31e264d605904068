"""--expression on a file: changes anywhere in the file, the live limits otherwise."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from facecast.commands.speech_options import expression_intensities
from realtime_core.expressions import EXPRESSIONS, ExpressionError


def _args(*specs: str) -> argparse.Namespace:
    return argparse.Namespace(expression=list(specs), expression_ease=0.0)


def test_an_expression_late_in_a_long_file_is_scheduled():
    # 13 minutes of speech: a smile at 700 s was refused as "more than 600 s ahead of the media time 0 s"
    n = 13 * 60 * 30
    alpha = expression_intensities(_args("smile:0.5@700"), n)
    smile = alpha[:, EXPRESSIONS.index("smile")]
    assert np.all(smile[: 700 * 30] == 0) and np.all(smile[700 * 30 + 1 :] == 0.5)
    with pytest.raises(ExpressionError, match="ahead"):  # beyond the file's end: still refused
        expression_intensities(_args("smile@900"), n)
