"""Regenerating a markdown report keeps the sections other commands wrote into the same file."""

from __future__ import annotations

from training.latency import DIAL_BEGIN, DIAL_END, existing_dial_section, splice_dial_section
from training.report import carry_over_sections


def test_regeneration_keeps_foreign_sections_and_the_dial_once():
    old = (
        "# t\n\n## 1. Mine\n\nold numbers\n\n## Paper 002\n\nmu text\n\n"
        f"{DIAL_BEGIN}\n## Latency dial\n\ndial rows\n{DIAL_END}\n\n## Unit selection\n\nunits text\n"
    )
    new = "# t\n\n## 1. Mine\n\nnew numbers\n"
    dial = existing_dial_section(old)
    text = splice_dial_section(carry_over_sections(new, old, skip=dial), dial)
    assert "new numbers" in text and "old numbers" not in text
    assert text.count("## Paper 002") == 1 and text.count("## Unit selection") == 1
    assert text.count("## Latency dial") == 1 and text.count(DIAL_BEGIN) == 1 and "dial rows" in text
    assert text.index("mu text") < text.index("units text")
    # regenerating the result again changes nothing
    dial2 = existing_dial_section(text)
    assert splice_dial_section(carry_over_sections(new, text, skip=dial2), dial2) == text
