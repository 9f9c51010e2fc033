"""The compiled synthesis (``kernels``) against the straightforward search and sum, on random
inputs: the same modes, and the same frames; the causal rungs' modes and raw curve likewise."""

from __future__ import annotations

import random
from bisect import bisect_right

import numpy as np
import pytest

from lipstream.engines.base import Model, SynthesisRequest, fill_gaps, frame_count
from lipstream.engines.dam import DamModel
from lipstream.engines.dam.causal import CausalCurve
from lipstream.engines.dam.dominance import dominance, powers
from lipstream.phonemes import PHONEMES
from lipstream.timeline import EMOTIONS, PhonemeSpan
from tests.lipstream.engines.dam.reference import (
    ModeMemo,
    context_cost,
    led_by_hand,
    select_mode,
    smooth_cost,
)

FPS = 60.0
CASES = 12


def _random_spans(generator: random.Random, count: int) -> list[PhonemeSpan]:
    spans, clock = [], 0.0
    for _ in range(count):
        length = generator.uniform(0.02, 0.3)
        emotion = generator.choice([None, None, *EMOTIONS])
        spans.append(PhonemeSpan(generator.choice(PHONEMES), clock, clock + length, emotion))
        clock += length + (generator.uniform(0.01, 0.2) if generator.random() < 0.1 else 0.0)
    return fill_gaps(spans)


def _reference_render(
    model: DamModel, spans: list[PhonemeSpan], times: np.ndarray, request: SynthesisRequest
) -> np.ndarray:
    """Eq. 2 span by span with numpy, each mode from ``select_mode`` (the implementation the
    kernels replaced)."""
    resolved = model.resolve(request.options)
    assert not isinstance(resolved, float)
    search, ahead = resolved
    owner_low = min(bisect_right(spans, times[0], key=lambda s: s.end), len(spans) - 1)
    owner_high = min(bisect_right(spans, times[-1], key=lambda s: s.end), len(spans) - 1)
    first = max(0, owner_low - model.tail)
    last = min(len(spans) - 1, owner_high + ahead)
    ends = np.array([span.end for span in spans[first : last + 1]])
    owner = first + np.minimum(np.searchsorted(ends, times, side="right"), len(ends) - 1)
    frames = np.zeros((len(times), model.coefficients.shape[2]))
    memo = ModeMemo(model, spans, request)
    for k in range(first, last + 1):
        span = spans[k]
        mode = select_mode(model, spans, k, search, request, memo)
        local = (times - span.start) / (span.end - span.start)
        near = (owner - model.tail <= k) & (k <= owner + ahead)
        near &= (local >= -model.reach[mode]) & (local <= 1.0 + model.reach[mode])
        if near.any():
            u = local[near]
            weight = dominance(u, model.sigma[mode], model.eps)
            frames[near] += weight[:, None] * (
                powers(u, model.coefficients.shape[1] - 1) @ model.coefficients[mode]
            )
    return np.asarray(model.basis.reconstruct(frames))


@pytest.mark.parametrize("name", ["dam", "cohen-massaro"])
def test_the_compiled_search_and_sum_match_the_straightforward_ones(
    name: str, trained_models: dict[str, Model]
) -> None:
    model = trained_models[name]
    assert isinstance(model, DamModel)
    generator = random.Random(7)
    for _ in range(CASES):
        spans = _random_spans(generator, generator.randint(1, 30))
        search = generator.randint(0, model.search_ahead)
        tail = generator.randint(0, model.tail)
        request = SynthesisRequest(
            fps=FPS,
            emotion=generator.choice([None, *EMOTIONS]),
            options={"search_ahead": search, "tail_ahead": tail},
        )
        memo = ModeMemo(model, spans, request)
        expected = [select_mode(model, spans, k, search, request, memo) for k in range(len(spans))]
        low = generator.randint(0, len(spans) - 1)
        high = generator.randint(low, len(spans) - 1)
        chosen = model.choose_modes(spans, low, high, search, request)
        assert chosen.tolist() == expected[low : high + 1]
        times = np.arange(frame_count(spans[-1].end, FPS)) / FPS
        begin = generator.randint(0, len(times) - 1)
        stop = generator.randint(begin + 1, len(times))
        window = times[begin:stop]  # a streamed call renders a run of frames
        got = model.render(spans, window, request, None)
        led = led_by_hand(spans, model.bilabial_lead_s)  # render starts /p b m/ early
        np.testing.assert_allclose(
            got, _reference_render(model, led, window, request), rtol=0, atol=1e-6
        )


class _ReferenceCausalCurve:
    """The causal rungs' modes and raw curve with numpy, span by span (the implementation the
    kernels replaced): each mode the least w_c·E_c + w_s·E_s over its layer cut at itself,
    joined to the mode before; r(τ) summed over the latest span begun by τ and ``tail`` before
    it, each within its dominance reach."""

    def __init__(self, model: DamModel, spans: list[PhonemeSpan], request: SynthesisRequest):
        costs = model.costs
        self.model, self.spans, self.modes = model, spans, []
        position = -1
        for index in range(len(spans)):
            layer = model.layer(spans, index, index, request)
            cost = costs.w_context * context_cost(costs, layer)
            if index > 0:
                before = model.layer(spans, index - 1, index - 1, request)
                cost = cost + costs.w_smooth * smooth_cost(costs, before, layer)[position]
            position = int(np.argmin(cost))
            self.modes.append(int(layer.candidates[position]))

    def raw(self, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        model, spans = self.model, self.spans
        starts = np.array([span.start for span in spans])
        begun = np.maximum(np.searchsorted(starts, at - 1e-9, side="left") - 1, 0)
        values = np.zeros((len(at), model.coefficients.shape[2]))
        for k, (span, mode) in enumerate(zip(spans, self.modes, strict=True)):
            local = (at - span.start) / (span.end - span.start)
            near = (begun >= k) & (begun - model.tail <= k)
            near &= (local >= -model.reach[mode]) & (local <= 1.0 + model.reach[mode])
            u = local[near]
            weight = dominance(u, model.sigma[mode], model.eps)
            values[near] += weight[:, None] * (
                powers(u, model.coefficients.shape[1] - 1) @ model.coefficients[mode]
            )
        medians = [model.durations.expected_s(spans[k].phoneme) for k in begun.tolist()]
        return values, 1.0 / np.array(medians)


@pytest.mark.parametrize("name", ["dam", "cohen-massaro"])
def test_the_compiled_causal_modes_and_raw_curve_match_the_straightforward_ones(
    name: str, trained_models: dict[str, Model]
) -> None:
    model = trained_models[name]
    assert isinstance(model, DamModel)
    generator = random.Random(11)
    for _ in range(CASES):
        spans = _random_spans(generator, generator.randint(1, 30))
        request = SynthesisRequest(fps=FPS, emotion=generator.choice([None, *EMOTIONS]))
        reference = _ReferenceCausalCurve(model, spans, request)
        curve = CausalCurve(model, request)
        cut = generator.randint(0, len(spans))  # committed in two calls, as spans stream in
        curve.commit(spans[:cut])
        curve.commit(spans)
        assert curve.modes.view().tolist() == reference.modes
        times = np.arange(frame_count(spans[-1].end, FPS)) / FPS
        begin = generator.randint(0, len(times) - 1)
        at = times[begin : generator.randint(begin + 1, len(times))] + generator.uniform(0, 0.1)
        at = at[at <= spans[-1].end]
        if len(at) == 0:
            continue
        values, rates = curve.raw(at)
        expected_values, expected_rates = reference.raw(at)
        np.testing.assert_allclose(values, expected_values, rtol=0, atol=1e-12)
        np.testing.assert_allclose(rates, expected_rates, rtol=1e-12)
