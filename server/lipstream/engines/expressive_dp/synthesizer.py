"""Streaming the search: fixed-lag commitment, the full search, and the causal rungs.

Method. Span j's node is committed once the input holds spans j .. j + lag
(``lag``): the fast search over those spans, starting from the node committed
at j − 1 (its TC into span j counts), taken at j and never revised, so the
committed path is one path and its cost (Eq. 4) is well defined. A stream's
windows of three or more layers reuse the last window's steps (``lag_search``):
a node whose best predecessor there descends from the node just committed, and
won by a margin, keeps it without a scan, so a call scans about the new layer,
the first layer and the nodes whose best way in ran through another node, and
commits the node the whole window's search commits. With
``lag: "full"`` nothing is committed before the input ends, then the whole
optimum is searched at once. A frame in span k reads the nodes of spans
k − 1 .. k + 2 (smoothing and silence reach one span each side; the output
interpolates between grid points, the next of which may lie in span k + 1),
so it is final once lag + 2 spans follow its span: the rung's lookahead.

The causal rungs commit at lag 0, as each span arrives, and follow the raw curve
r(τ), the committed node of the latest span begun by τ time-warped over that
span (a silence holds the last frame of the node before it, the rest pose at
the start), with the shared critically damped filter (``damped``) at
ω = κ / the median duration of that span's phoneme; the lead rung follows
r(t + shift). The frame at t is final once the input covers t + shift. Each span's
row and node are kept as it is committed and one compiled call reads the curve and steps
the filter for a call's frames (``causal_curve``), so no per-call work grows with the
request; a lag-0 commit is a one-layer search (``search.one_layer``).

A silence ends a search segment (``search``): it gets no node (``NO_NODE``),
and every node before it is committed as soon as it arrives, whatever the lag.
Adjacent silences (a gap filled beside a sent silence) are merged into one span
as they arrive, so a pause's line waits for one node after it.

Stats: ``nodes`` (the committed node of every span, silences filled into gaps
included, -1 at a silence, as space-separated ids: engine stats on the wire are
scalars), ``path_cost`` (their Eq. 4 cost) and ``candidates`` (nodes priced: of a
reused window, those of its first layer and those whose way in was searched).

Constraints name client phoneme indices (the spans as sent, not the silences
filled into gaps; ``SpanSynthesizer`` hands each span's index to ``_accepted``).
A constraint whose index the finished input never reached is an
``invalid_request`` error at ``options.constraints.<index>``, at ``finish``; a
constraint on a silence is one too, when the silence is fed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...errors import InvalidRequestError
from ...phonemes import PHONEME_INDEX, SILENCE
from ...timeline import EMOTION_INDEX, PhonemeSpan
from ..base import (
    Lookahead,
    LookaheadSynthesizer,
    ShiftedSynthesizer,
    SynthesisRequest,
    final_until,
    frame_count,
)
from ..damped import DampedState
from ..damped_fit import RawCurve
from ..growable import Growable
from ..work import WorkGuard
from .causal_curve import raw_rows
from .lag_search import LagMemory
from .postprocess import RenderCache
from .search import NO_NODE, LayerSpec, SearchSpace, one_layer, search
from .serving import ExpressiveDpServing


class PathSynthesizer(LookaheadSynthesizer):
    """Committed nodes of one request, and the spans they belong to."""

    model: ExpressiveDpServing

    def __init__(
        self,
        model: ExpressiveDpServing,
        request: SynthesisRequest,
        lag: int | None,
        constraints: Mapping[int, int],
    ) -> None:
        super().__init__(model, request)
        self.lag = lag
        self.constraints = dict(constraints)
        excluded = model.contamination.mask()
        self.excluded = excluded if excluded.any() else model.space.no_exclusion
        self.constrained: dict[int, int] = {}
        self.path: list[int] = []
        self.stats = {"frames": 0, "path_cost": 0.0, "candidates": 0, "nodes": ""}

    def _accepted(self, span: PhonemeSpan, sent: int | None) -> None:
        if span.phoneme == SILENCE:
            if sent is not None and sent in self.constraints:
                raise InvalidRequestError(
                    f"constraint on phoneme index {sent}, a silence: a silence gets no node "
                    "(it splits the search)",
                    where=f"options.constraints.{sent}",
                )
            if len(self.spans) > 1 and self.spans[-2].phoneme == SILENCE:
                # one silence per pause, so its line waits for one node after it
                before = self.spans[-2]
                self.spans[-2:] = [PhonemeSpan(SILENCE, before.start, span.end, before.emotion)]
            return
        if sent is not None and sent in self.constraints:
            self.constrained[len(self.spans) - 1] = self.constraints[sent]

    def layer(self, index: int) -> LayerSpec:
        span = self.spans[index]
        emotion = self.request.emotion_of(span) or "neutral"
        return LayerSpec(
            PHONEME_INDEX[span.phoneme], EMOTION_INDEX[emotion], self.constrained.get(index, -1)
        )

    memory: LagMemory | None = None
    """The last fixed-lag window's search, for the next (``lag_search``)."""

    def commit(self) -> None:
        """Commit every node the input (and the lag) now decides."""
        decided = len(self.path)
        layers = [self.layer(k) for k in range(decided, len(self.spans))]
        priced, cost = extend_path(
            self.model.space,
            layers,
            self.excluded,
            self.lag,
            self.path,
            self.finished,
            self.request.guard,
            self.memory,
        )
        self.stats["candidates"] += priced
        self.stats["path_cost"] += cost
        # appended, not rebuilt: rebuilding the whole path each call grew with the request
        added = " ".join(map(str, self.path[decided:]))
        if added:
            self.stats["nodes"] = f"{self.stats['nodes']} {added}".lstrip()

    def finish(self) -> np.ndarray:
        unreached = sorted(index for index in self.constraints if index >= self.sent)
        if unreached:
            raise InvalidRequestError(
                f"constraint on phoneme index {unreached[0]}, but the request has only "
                f"{self.sent} phonemes",
                where=f"options.constraints.{unreached[0]}",
            )
        return super().finish()


class LagSynthesizer(PathSynthesizer):
    """The fixed-lag rungs and the full search; the points of the spans a call made are kept
    for the next (``Renderer.grid``)."""

    def __init__(
        self,
        model: ExpressiveDpServing,
        request: SynthesisRequest,
        lag: int | None,
        constraints: Mapping[int, int],
    ) -> None:
        super().__init__(model, request, lag, constraints)
        self.kept = RenderCache()
        self.memory = LagMemory(model.nodes.size)

    def final_until(self) -> float:
        if not self.spans or self.lag is None:
            return 0.0
        return final_until(self.spans, Lookahead(phonemes=self.lag + 2))

    def _emit(self, stop: int) -> np.ndarray:
        if stop <= self.emitted:
            return np.zeros((0, len(self.model.channels)), dtype=np.float32)
        self.request.guard.check()
        self.commit()
        times = np.arange(self.emitted, stop, dtype=np.float64) / self.request.fps
        values = self.model.renderer.frames(self.spans, self.path, times, self.kept)
        self.emitted = stop
        self.stats["frames"] = stop
        return np.asarray(self.model.basis.reconstruct(values), dtype=np.float32)


class CausalSynthesizer(PathSynthesizer, ShiftedSynthesizer):
    """The causal and lead rungs: nodes committed on arrival, a damped filter after. Each
    span's row (``causal_curve``) and node are kept as it is committed, so a call's work
    is that of its new spans and frames."""

    def __init__(
        self,
        model: ExpressiveDpServing,
        request: SynthesisRequest,
        shift_s: float,
        constraints: Mapping[int, int],
    ) -> None:
        super().__init__(model, request, 0, constraints)
        self.shift_s = shift_s
        self.state: DampedState | None = None
        self.omegas = model.causal_omegas
        self.rows = Growable(np.float64, (3,))
        self.nodes = Growable(np.int64)

    def _emit(self, stop: int) -> np.ndarray:
        if stop <= self.emitted:
            return np.zeros((0, len(self.model.channels)), dtype=np.float32)
        self.request.guard.check()
        self.commit()
        _keep_rows(self.omegas, self.spans, self.path, self.rows, self.nodes)
        at_rest = self.state is None
        if self.state is None:
            self.state = DampedState.at_rest(self.model.rest_pose)
        values = np.empty((stop - self.emitted, len(self.state.x)))
        state = self.state
        self.model.follow(
            self.emitted,
            stop,
            float(self.request.fps),
            self.shift_s,
            self.rows.view(),
            self.nodes.view(),
            self.model.curves,
            state.x,
            state.v,
            state.t,
            at_rest,
            values,
        )
        self.state.t = (stop - 1) / self.request.fps
        self.emitted = stop
        self.stats["frames"] = stop
        return np.asarray(self.model.basis.reconstruct(values), dtype=np.float32)


def extend_path(
    space: SearchSpace,
    layers: Sequence[LayerSpec],
    excluded: np.ndarray,
    lag: int | None,
    path: list[int],
    finished: bool,
    guard: WorkGuard | None = None,
    memory: LagMemory | None = None,
) -> tuple[int, float]:
    """Append to ``path`` the nodes of ``layers`` (the spans after it) that ``lag`` decides
    now (``NO_NODE`` at a silence); the nodes priced and the Eq. 4 cost the new nodes add.
    A silence closes its segment: every node before it is decided at once. ``memory`` (a
    stream's) searches each window of two or more layers reusing the last one's steps
    (``lag_search``): the same nodes."""
    priced, added = 0, 0.0
    offset = 0
    while offset < len(layers):
        if layers[offset].silent:
            path.append(NO_NODE)
            offset += 1
            continue
        end = next((k for k in range(offset, len(layers)) if layers[k].silent), len(layers))
        closed = finished or end < len(layers)
        if closed and (lag is None or end <= offset + lag + 1):
            last, whole = end - 1, True
        elif lag is None or offset + lag >= end:
            break
        else:
            last, whole = offset + lag, False
        before = path[-1] if path else NO_NODE
        if last == offset:  # one layer (every call of the causal rungs): no DP to run
            node, candidates, tc = one_layer(space, layers[offset], excluded, before)
            priced += candidates
            added += space.unary_at(layers[offset], excluded, node)
            added += tc if before >= 0 else 0.0
            path.append(node)
            offset += 1
            continue
        window = layers[offset : last + 1]
        if memory is not None and last > offset + 1:  # a window of two has no layer to reuse
            found = memory.search(space, window, excluded, len(path), before, guard)
        else:
            found = search(space, window, excluded, before=before, guard=guard)
        priced += found.candidates
        for node in (found.path if whole else found.path[:1]).tolist():
            previous = path[-1] if path else NO_NODE
            added += space.unary_at(layers[offset], excluded, node)
            added += space.tc(previous, node) if previous >= 0 else 0.0
            path.append(node)
            offset += 1
    return priced, added


def _keep_rows(
    omegas: np.ndarray, spans: list[PhonemeSpan], path: list[int], rows: Growable, nodes: Growable
) -> None:
    """Append the rows (start, end, ω of its phoneme in ``omegas``) and nodes of the
    committed spans not yet kept. A silence merged into a kept one changes only its end,
    which a silence's row never reads."""
    for k in range(nodes.count, len(path)):
        span = spans[k]
        rows.append((span.start, span.end, float(omegas[PHONEME_INDEX[span.phoneme]])))
        nodes.append(path[k])


def raw_curve(
    model: ExpressiveDpServing, spans: list[PhonemeSpan], path: list[int], at: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """r at times ``at`` (ascending) and the latest span begun at each."""
    rows, nodes = Growable(np.float64, (3,)), Growable(np.int64)
    _keep_rows(model.causal_omegas, spans, path, rows, nodes)
    raw = np.empty((len(at), model.nodes.frames.shape[1]))
    begun = np.empty(len(at), dtype=np.int64)
    times = np.ascontiguousarray(at, dtype=np.float64)
    raw_rows(times, rows.view(), nodes.view(), model.curves, raw, begun)
    return raw, begun


def training_raw_curve(model: ExpressiveDpServing, utterance: Any) -> RawCurve:
    """The causal rung's raw curve of a training utterance, for choosing κ
    (``damped_fit.best_following_kappa``)."""
    request = SynthesisRequest(fps=float(utterance.fps), emotion=utterance.emotion)
    synthesizer = CausalSynthesizer(model, request, 0.0, {})
    synthesizer.feed(utterance.phones)
    synthesizer.finished = True
    synthesizer.commit()
    spans = synthesizer.spans
    times = np.arange(frame_count(spans[-1].end, request.fps)) / request.fps
    raw, begun = raw_curve(model, spans, synthesizer.path, times)
    medians = model.durations.expected_all_s()
    phonemes = [PHONEME_INDEX[spans[k].phoneme] for k in begun.tolist()]
    return raw, 1.0 / medians[phonemes], times
