"""The dam bench: rungs and truncation errors as the models record them, and the causal rungs'
call figures."""

from __future__ import annotations

from lipstream.bench.dam import CALL_SESSIONS, format_dam_bench, run_dam_bench, sentence
from lipstream.corpus import Corpus
from lipstream.engines.dam import DamEngine


def test_dam_bench_reports_every_rung_with_its_truncation_error(
    small_demo_corpus: Corpus,
) -> None:
    results = run_dam_bench(small_demo_corpus)
    assert set(results) == {"dam", "cohen-massaro"}
    model = DamEngine().fit(small_demo_corpus.split()[0])
    figures = results["dam"]
    assert figures["tail"] == model.tail and figures["modes"] == model.manifest.metrics["modes"]
    assert [r["name"] for r in figures["rungs"]] == [r.name for r in model.fidelity_ladder()]
    for rung, declared in zip(figures["rungs"], model.fidelity_ladder(), strict=True):
        assert rung["lookahead_phonemes"] == declared.lookahead.phonemes
        if declared.options.get("causal"):  # no tail to cut: the causal rungs have none
            assert rung["truncation_error"] is None
        else:
            assert rung["truncation_error"] < DamEngine().truncation_bound
    assert max(figures["cut_tail_errors"].values()) > DamEngine().truncation_bound
    speed = figures["synthesis"]
    assert (speed["phonemes"], speed["fps"], speed["repeats"]) == (40, 60.0, 200)
    causal = [rung for rung in model.fidelity_ladder() if rung.options.get("causal")]
    calls = figures["causal_calls"]
    assert [(c["rung"], c["lead_ms"]) for c in calls] == [
        (rung.name, rung.options["lead_ms"]) for rung in causal
    ]
    for call in calls:  # every span of every timed session is one call
        assert call["calls"] == CALL_SESSIONS * len(sentence())
        assert 0.0 <= call["cpu_ms_median"] <= call["cpu_ms_p90"]
    text = format_dam_bench(results)
    assert "rung full" in text and "rung causal      lookahead 0 phonemes" in text
    assert "synthesis of a 40-phoneme sentence at 60 fps" in text
    assert "rung causal fed a phoneme at a time at 60 fps" in text


def test_the_speed_sentence_is_40_contiguous_phonemes() -> None:
    spans = sentence()
    assert len(spans) == 40 and spans[0][1] == 0.0
    assert all(a[2] == b[1] for a, b in zip(spans, spans[1:]))
