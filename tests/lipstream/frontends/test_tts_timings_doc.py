"""docs/how-to/tts-timings.md: every example block is read as the format it is filed
under, detected from its content."""

from __future__ import annotations

import re

import pytest

from lipstream.frontends.formats import detect_format, parse_timings, read_timing_text
from lipstream.frontends.timings import TIMING_FORMATS
from tests.helpers import REPO

DOC = (REPO / "docs" / "how-to" / "tts-timings.md").read_text(encoding="utf-8")
EXAMPLES = re.findall(r"<!-- example: (\w+) -->\n```json\n(.*?)```", DOC, re.DOTALL)


def test_every_format_has_an_example() -> None:
    assert {name for name, _ in EXAMPLES} == set(TIMING_FORMATS)


@pytest.mark.parametrize(("format", "content"), EXAMPLES)
def test_each_example_is_detected_and_parsed(format: str, content: str) -> None:
    data = read_timing_text(content.replace('"..."', '""'))
    assert detect_format(data) == format
    timings = parse_timings(data)
    assert timings.words or timings.phonemes
