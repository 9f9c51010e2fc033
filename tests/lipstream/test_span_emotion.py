"""Per-span emotion in the timeline and the engine contract; viseme-lerp ignores it."""

from __future__ import annotations

import numpy as np
import pytest

from lipstream.engines.base import SynthesisRequest, fill_gaps
from lipstream.engines.viseme_lerp import VisemeLerpEngine
from lipstream.errors import InvalidRequestError
from lipstream.timeline import PhonemeSpan, SpanLike, coerce_spans
from tests.lipstream.engines.anime_graph.anime_synthetic import make_corpus


def test_spans_carry_an_optional_emotion_in_every_accepted_form() -> None:
    spans = coerce_spans(
        [
            ("aa1", 0.0, 0.1, "happy"),
            ("B", 0.1, 0.2),
            {"phoneme": "M", "start": 0.2, "end": 0.3, "emotion": "sad"},
            {"phoneme": "IY", "start": 0.3, "end": 0.4},
            PhonemeSpan("S", 0.4, 0.5, "angry"),
        ]
    )
    assert spans == [
        PhonemeSpan("AA", 0.0, 0.1, "happy"),
        PhonemeSpan("B", 0.1, 0.2, None),
        PhonemeSpan("M", 0.2, 0.3, "sad"),
        PhonemeSpan("IY", 0.3, 0.4, None),
        PhonemeSpan("S", 0.4, 0.5, "angry"),
    ]
    assert PhonemeSpan("AA", 0.0, 0.1) == PhonemeSpan("AA", 0.0, 0.1, None)


@pytest.mark.parametrize(
    "span", [("AA", 0.0, 0.1, "bored"), {"phoneme": "AA", "start": 0.0, "end": 0.1, "emotion": 3}]
)
def test_an_unknown_span_emotion_is_refused_where_it_stands(span: SpanLike) -> None:
    with pytest.raises(InvalidRequestError) as caught:
        coerce_spans([("sil", 0.0, 0.05), span], first_index=4)
    assert (caught.value.code, caught.value.where) == ("unknown_emotion", "spans[5].emotion")


def test_a_span_emotion_overrides_the_requests_and_a_gap_takes_the_next_spans() -> None:
    request = SynthesisRequest(emotion="sad")
    assert request.emotion_of(PhonemeSpan("AA", 0.0, 0.1, "happy")) == "happy"
    assert request.emotion_of(PhonemeSpan("AA", 0.0, 0.1)) == "sad"
    assert SynthesisRequest().emotion_of(PhonemeSpan("AA", 0.0, 0.1)) is None
    filled = fill_gaps([PhonemeSpan("AA", 0.2, 0.3, "happy"), PhonemeSpan("B", 0.5, 0.6)])
    assert filled == [
        PhonemeSpan("sil", 0.0, 0.2, "happy"),
        PhonemeSpan("AA", 0.2, 0.3, "happy"),
        PhonemeSpan("sil", 0.3, 0.5, None),
        PhonemeSpan("B", 0.5, 0.6, None),
    ]


def test_viseme_lerp_ignores_emotion() -> None:
    model = VisemeLerpEngine().fit(
        make_corpus(seed=1, n_utterances=6, with_audio=False, emotions=("neutral", "happy"))
    )
    plain = [("sil", 0.0, 0.1), ("M", 0.1, 0.2), ("AA", 0.2, 0.4), ("sil", 0.4, 0.5)]
    moody = [(*span, emotion) for span, emotion in zip(plain, ["sad", "happy", None, "angry"])]
    expected = model.synthesize(plain, fps=60.0).frames
    np.testing.assert_array_equal(
        model.synthesize(moody, fps=60.0, emotion="happy").frames, expected
    )
