"""Streaming synthesis: tiles become final as the input grows, frames follow at once.

Sketch: the spans received so far form the query. GreedyMatching is run from
the first undecided position: a tile that ends before the end of the query
can never grow (the phoneme after it is known and does not extend it), and a
tile that reached ``max_tile`` phonemes is cut, so either is final; only the
last, still-growing tile waits. (PQ-Matching: a window is final once its h
phonemes are known.) With audio, a tile also waits until the audio covers it.
A final tile is time-warped (DTW on the MFCCs, except over silence, which
has no speech to align) and joined to its predecessor at once. The track
is final up to the start of the last decided fragment (that fragment's right
join waits for the next tile); it is sampled on the model's frame grid
(k / fps_model), low-passed with zero-phase FIR kernels of half-width H, and
interpolated linearly onto the requested frame times. So a frame at t waits
for the span containing t + (H + 1) / fps_model to have ``max_tile`` whole
spans after it, and every frame is computed from final inputs only: any
chunking of the input gives the offline frames.

Per-phoneme emotion: each span is searched in the view of its own emotion
(else the request's). The query splits into runs of positions with the same
view, and tiles never cross a run's end: a tile that reaches the end of a
run the next span has closed is final too, so the lookahead is unchanged.
The first tile of a run continues from the anime shown last when the new
view holds it (unclustered node ids are anime ids in every view); the join
across the change of view is blended with the whole corpus's recorded pairs,
since no one emotion's recordings hold it.

Causal search (``causal``): one-phoneme tiles, final as their span arrives;
no audio (linear warps); forward joins (``blending``), so the track is final
up to the end of the last decided span; and instead of the zero-phase
low-pass, a critically damped filter per PCA component (``damped``, rate
from the component's learned cutoff) steps from frame to frame toward the
track at t + shift, evaluated at the output frame times themselves; the
shift makes up the filter's lag as far as ``lead_ms`` allows
(``AnimeGraphModel.causal_shift_s``). So the frame at t is final once the
input covers t + shift. While the new spans stay in the view of the one before
them, a streamed call is one compiled call (``causal_call.causal_step``: pick,
place, emit) on per-request arrays (span bounds, the track's buffers, the
filter's state) that it updates in place.
"""

from __future__ import annotations

import math
import time
from bisect import bisect_left, bisect_right
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import groupby
from typing import Any, TypeVar

import numpy as np
from numba import njit

from ...audio import Audio
from ...errors import InvalidRequestError
from ...features import mfcc
from ...phonemes import PHONEME_INDEX, SILENCE
from ...timeline import PhonemeSpan
from ..base import SynthesisRequest, Synthesizer, fill_gaps, frame_count
from ..damped import FilterState
from ..growable import Growable
from ..streamed_features import StreamedFeatures
from ..work import WorkGuard
from .animes import Curves, summarize
from .blending import Join, PairIndex, plan_join
from .costs import Ranking
from .emission import CausalClock
from .graph import AnimeGraph, SearchGraph
from .options import SearchOptions
from .pq import SearchTimeout, pq_window
from .search import Matcher, SuffixMatcher, count_jumps, missing
from .serving import AnimeGraphServing
from .stream_calls import SNAP
from .suffix_search import GreedySearch
from .track import MotionTrack, Placement
from .views import WHOLE, GraphView
from .warp import Alignment, Warp, dtw_warps, linear_warp

_FORGET_ROWS = 64
_Result = TypeVar("_Result")


@dataclass(frozen=True, eq=False)
class _Searcher:
    """One view, the graph searched in it and that graph's matcher."""

    view: GraphView
    graph: SearchGraph
    matcher: Matcher


class AnimeGraphSynthesizer(Synthesizer):
    """One request: feed spans (and audio), take final frames.

    ``view``, ``graph`` and ``matcher`` are the request emotion's; ``searchers[j]`` holds
    those of query position j, whose ``query`` label and ``nodes`` id are in its view.
    """

    def __init__(
        self, model: AnimeGraphServing, request: SynthesisRequest, options: SearchOptions
    ) -> None:
        self.model = model
        self.request = request
        self.fps = float(request.fps)
        self.options = options
        self._by_view: dict[str, _Searcher] = {}
        self._by_emotion: dict[str | None, _Searcher] = {}  # a span's own emotion (or None)
        own = self._searcher_for(request.emotion)
        self.view, self.graph, self.matcher = own.view, own.graph, own.matcher
        self.spans: list[PhonemeSpan] = []
        self.searchers: list[_Searcher] = []
        self.run_starts: list[int] = []
        self._labels = Growable(np.int64)
        self._bounds = Growable(np.float64, (2,))  # each span's start and end (s), if causal
        self.nodes: list[int] = []
        self.audio: StreamedFeatures | None = None
        self.audio_mode: bool | None = None
        self.summaries: Growable | None = None
        self.track = MotionTrack(model.anime_motion)
        self.half_width = model.half_width if options.smooth else 0
        self.kernels = model.kernels if options.smooth else np.ones((model.n_components, 1))
        self.raw = Growable(np.float64, (model.n_components,))
        self.smoothed = Growable(np.float64, (model.n_components,))
        self.emitted = 0
        self.finished = False
        # The causal filter's value and velocity per PCA component, at rest before frame 0.
        self.filter_state = FilterState(np.empty(model.n_components), np.zeros(model.n_components))
        self.lead_s = model.causal_shift_s(options.lead_ms)
        self.clock = CausalClock(self.fps, self.lead_s, options.blend)
        self.guard = request.guard
        self._searches: dict[str, GreedySearch] = {}  # without audio, by view
        self.calls = model.stream_calls
        self.search_guard = WorkGuard(options.pq_budget_s, time.perf_counter, _search_timeout)
        self.stats: dict[str, Any] = {
            "frames": 0,
            "tiles": 0,
            "jumps": 0,
            "search_ms": 0.0,
            "graph": options.graph,
            "search": options.search,
            "view": self.view.name,
        }

    @property
    def covered_until(self) -> float:
        return self.spans[-1].end if self.spans else 0.0

    # ---- input ---------------------------------------------------------------------------

    def span_position(self) -> tuple[float, int]:
        return self.covered_until, len(self.spans)

    def take(self, spans: Sequence[PhonemeSpan], audio: Audio | None) -> None:
        if audio is not None or self.audio_mode is None:  # else taking it changes nothing
            self._take_audio(audio)
        filled = fill_gaps(spans, self.covered_until)
        self.check_more_phonemes(len(filled))
        causal = self.options.causal
        for span in filled:
            searcher = self._by_emotion.get(span.emotion)
            if searcher is None:
                searcher = self._searcher_for(self.request.emotion_of(span))
                self._by_emotion[span.emotion] = searcher
            if self.searchers and searcher is not self.searchers[-1]:
                self.run_starts.append(len(self.searchers))
            self.spans.append(span)
            self.searchers.append(searcher)
            self._labels.append(searcher.view.label_of[span.phoneme])
            if causal:  # only the causal calls read the bounds
                self._bounds.append((span.start, span.end))

    @property
    def query(self) -> np.ndarray:
        """The searched label of every span so far (n,) int64, each in its span's view."""
        return self._labels.view()  # never dropped from: its length is ``_labels.count``

    def _searcher_for(self, emotion: str | None) -> _Searcher:
        view = self.model.view_for(emotion, self.options)
        if view.name not in self._by_view:
            self._by_view[view.name] = _Searcher(
                view,
                self.model.graph_of(view, self.options.graph),
                self.model.matcher_of(view, self.options.graph),
            )
        return self._by_view[view.name]

    @property
    def held_input_bytes(self) -> int:
        return self.audio.held_bytes if self.audio is not None else 0

    def check_more_phonemes(self, count: int) -> None:
        if self.options.search == "pq":
            self.options.check_size(len(self.spans) + count)

    def held_input_bytes_after(self, n_samples: int, sample_rate: int) -> int:
        if self.audio is None and (self.audio_mode is False or not self.model.has_audio):
            return 0  # audio this request takes is not kept
        audio = self.audio or self._audio_stream()
        return audio.held_bytes_after(n_samples, sample_rate)

    def _audio_stream(self) -> StreamedFeatures:
        """The request's MFCC frames, as its audio streams in."""
        config = self.model.mfcc
        return StreamedFeatures(config, config.n_coefficients, mfcc)

    def _take_audio(self, audio: Audio | None) -> None:
        if self.options.causal:
            self.audio_mode = False
            return
        if self.audio_mode is None:
            self.audio_mode = audio is not None and self.model.has_audio
            if self.audio_mode:
                self.audio = self._audio_stream()
        elif audio is not None and not self.audio_mode and self.model.has_audio:
            raise InvalidRequestError(
                "audio must come with the first feed of a request: this request started "
                "without audio",
                where="audio",
                code="audio_after_start",
            )
        if audio is not None and self.audio is not None:
            self.audio.add(audio)

    def frames(self) -> np.ndarray:
        if self.options.causal:
            return self._causal_frames()
        self._advance()
        return self._emit()

    def finish(self) -> np.ndarray:
        self.finished = True
        return self.frames()

    # ---- search --------------------------------------------------------------------------

    def _audio_ready(self, until_s: float) -> bool:
        return self.audio is None or self.audio.ready(until_s, self.finished)

    def ranking(self, graph: SearchGraph, start: int, stop: int) -> Ranking:
        """Costs over ``graph`` for query positions ``start:stop``: audio summaries are computed
        once each, in order, so those known are always positions 0..count-1."""
        if self.audio is None:
            return Ranking(graph, self.model.poses, self.model.summaries)
        if self.summaries is None:
            self.summaries = Growable(np.float64, (self.model.summaries.shape[1],))
        have = self.summaries.count
        if stop > have:
            frames = self.audio.describing(self.spans[stop - 1].end)  # one utterance's curve
            curves = Curves(frames, np.array([0, len(frames)]), self.model.mfcc.rate)
            starts = np.array([span.start for span in self.spans[have:stop]])
            ends = np.array([span.end for span in self.spans[have:stop]])
            self.summaries.extend(
                summarize(curves, np.zeros(stop - have, dtype=np.int64), starts, ends)
            )
        return Ranking(graph, self.model.poses, self.model.summaries, self.summaries.view())

    def _run_stop(self, start: int) -> int:
        """One past the last position of the run holding ``start``, as far as it is known."""
        index = bisect_right(self.run_starts, start)
        return self.run_starts[index] if index < len(self.run_starts) else self._labels.count

    def _previous(self, start: int) -> tuple[int | None, int | None]:
        """For a tile at ``start``, in its searcher's graph: the node it may continue from,
        and the node its first join is ranked from."""
        if start == 0:
            return None, None
        searcher, before = self.searchers[start], self.searchers[start - 1]
        node = self.nodes[start - 1]
        if before is searcher:
            return node, node
        anime = int(before.graph.motion_of(np.array([node]))[0])
        held = searcher.view.node_of(anime, searcher.graph)
        # Anime ids name the same nodes in every view's anime graph, so a join from an anime
        # outside the view can still be ranked there.
        return held, anime if searcher.graph is searcher.view.anime_graph else held

    def _next_tiles(self) -> list[list[int]] | None:
        """The next final tiles (runs of nodes), or None while they may still change."""
        start = len(self.nodes)
        searcher = self.searchers[start]
        stop = self._run_stop(start)
        closed = stop < self._labels.count or self.finished
        continuing, ranked = self._previous(start)
        if self.options.search == "pq":
            end = min(stop, start + self.options.pq_window)
            if end - start < self.options.pq_window and not closed:
                return None
            if not self._audio_ready(self.spans[end - 1].end):
                return None
            ranking = self.ranking(searcher.graph, start, end)
            result = self._timed(
                lambda: pq_window(
                    searcher.graph, ranking, self.query, start, end, ranked, self._check
                )
            )
            last_window = closed and end == stop
            keep = len(result.nodes) if last_window else self.options.pq_advance
            return [[int(node) for node in result.nodes[:keep]]]
        return self._greedy_tiles(start, stop, closed, continuing, ranked)

    def _greedy_tiles(
        self, start: int, stop: int, closed: bool, continuing: int | None, ranked: int | None
    ) -> list[list[int]] | None:
        """GreedyMatching of the run from ``start`` as far as the audio covers it; every tile
        but a last one that may still grow (it ends where the known input ends, below the
        cap) is final."""
        searcher = self.searchers[start]
        matcher = searcher.matcher
        if self.audio is None and isinstance(matcher, SuffixMatcher):
            return self._suffix_tiles(searcher, matcher, start, stop, closed, continuing, ranked)
        ready = self._audio_ready_stop(start, stop)
        if ready == start:
            return None
        ranking = self.ranking(searcher.graph, start, ready)
        cap = self.options.max_tile
        final_only = not (ready == stop and closed)
        tiles = self._timed(
            lambda: searcher.matcher.tiles(
                self.query, start, ready, cap, continuing, ranking, ranked, final_only
            )
        )
        return [tile.tolist() for tile in tiles] or None

    def _suffix_tiles(
        self,
        searcher: _Searcher,
        matcher: SuffixMatcher,
        start: int,
        stop: int,
        closed: bool,
        continuing: int | None,
        ranked: int | None,
    ) -> list[list[int]] | None:
        """``_greedy_tiles`` without audio by suffix automaton: ``SuffixMatcher.tiles`` with
        the view's kernel arguments kept (without audio they do not depend on the
        positions) and the search timed as ``_timed`` does, without its wrapping."""
        search = self._search_of(searcher, matcher, start, stop)
        guard = self.search_guard
        guard.check()
        started = time.perf_counter()
        nodes, ends, pending = self.calls.greedy_tiles(
            self._labels.data[start:stop],
            self.options.max_tile or 0,
            -1 if continuing is None else continuing,
            -1 if ranked is None else ranked,
            not closed,
            search,
        )
        spent = time.perf_counter() - started
        guard.spent_s += spent
        self.stats["search_ms"] += 1000.0 * spent
        if len(nodes) < stop - start and not pending:
            missing(self.query, start + len(nodes))
        if not len(ends):
            return None
        chosen, bounds = nodes.tolist(), [0, *ends.tolist()]
        return [chosen[low:high] for low, high in zip(bounds, bounds[1:])]

    def _search_of(
        self, searcher: _Searcher, matcher: SuffixMatcher, start: int, stop: int
    ) -> GreedySearch:
        """The view's ``greedy_tiles`` tables and ranking without audio, made once (without
        audio they do not depend on the positions)."""
        search = self._searches.get(searcher.view.name)
        if search is None:
            ranking = self.ranking(searcher.graph, start, stop)
            search = matcher.kernel_arguments(ranking, ranking.summaries_of(start, 0))
            self._searches[searcher.view.name] = search
        return search

    def _audio_ready_stop(self, start: int, stop: int) -> int:
        """The largest p in [start, stop] such that the audio covers spans start..p-1."""
        if self.audio is None:
            return stop
        # Span ends ascend, so readiness holds for a prefix of the spans.
        return start + bisect_left(
            range(start, stop), True, key=lambda p: not self._audio_ready(self.spans[p].end)
        )

    def _jumps(self, start: int, tile: list[int]) -> int:
        """Jumps into and inside a tile placed at ``start``; entering a view that does not
        hold the previous anime is one."""
        continuing, _ = self._previous(start)
        lead = [] if continuing is None else [continuing]
        entered = int(start > 0 and continuing is None)
        graph = self.searchers[start].graph
        if isinstance(graph, AnimeGraph):  # an edge is a recorded succession
            nodes, successor = lead + tile, graph.successor
            return entered + sum(int(successor[a]) != b for a, b in zip(nodes, nodes[1:]))
        return entered + count_jumps(graph, np.asarray(lead + tile))

    def _timed(self, call: Callable[[], _Result]) -> _Result:
        """Run one search step, adding its time to ``stats["search_ms"]`` and to what
        ``pq_budget_s`` allows."""
        started = time.perf_counter()
        try:
            with self.search_guard.metering():
                return call()
        finally:
            self.stats["search_ms"] += 1000.0 * (time.perf_counter() - started)

    def _check(self) -> None:
        """Stop here if the request's work was cancelled or its budgets are spent."""
        self.guard.check()
        self.search_guard.check()

    def _decide(self) -> None:
        if self.finished and self.audio is not None and self.spans:
            self.audio.describing(self.covered_until)
        placed = len(self.nodes)
        while len(self.nodes) < self._labels.count:
            self.guard.check()
            tiles = self._next_tiles()
            if tiles is None:
                break
            for tile in tiles:
                self.stats["jumps"] += self._jumps(len(self.nodes), tile)
                self.nodes.extend(tile)
                self.stats["tiles"] += 1
        if self.options.search == "pq":
            self.stats["tiles"] = self.stats["jumps"] + 1 if self.nodes else 0
        if placed == len(self.nodes):
            return
        positions = range(placed, len(self.nodes))
        animes = self._animes(positions)
        if self.audio is None:  # every warp is linear (``_alignment``): none is built
            for position, anime in zip(positions, animes):
                self.guard.check()
                self._place(position, anime, None)
            return
        for position, anime, warp in zip(positions, animes, self._warps(positions, animes)):
            self.guard.check()
            self._place(position, anime, warp)

    def _causal_frames(self) -> np.ndarray:
        """A causal request's new frames: while the new positions and the one before them
        share a view searched by suffix automaton, one compiled call (``causal_step``)
        picks their nodes, places each with its linear warp and forward join, and emits,
        without the general path's per-tile set-up; else ``_decide`` then
        ``_emit_causal``."""
        placed, total = len(self.nodes), self._labels.count
        if placed < total:
            searcher = self.searchers[placed]
            matcher = searcher.matcher
            if (not self.run_starts or self.run_starts[-1] < placed) and isinstance(
                matcher, SuffixMatcher
            ):
                return self._causal_step(searcher, matcher, placed, total)
            self._decide()
        return self._emit_causal()

    def _causal_step(
        self, searcher: _Searcher, matcher: SuffixMatcher, placed: int, total: int
    ) -> np.ndarray:
        """``_causal_frames`` by ``causal_step``, whose whole call counts as search time."""
        self.guard.check()
        search = self._search_of(searcher, matcher, placed, total)
        track, new = self.track, total - placed
        buffers = track.reserve(new, 2 * new)
        self.search_guard.check()
        started = time.perf_counter()
        frames: np.ndarray
        chosen, jumps, stop, frames = self.calls.causal_step(
            self._labels.data,
            self._bounds.data,
            placed,
            total,
            self.emitted,
            self.finished,
            self.clock,
            self.filter_state,
            buffers,
            track.knots,
            search,
            self.model.causal_emission,
        )
        spent = time.perf_counter() - started  # what ``_timed`` adds, without its wrapping
        self.search_guard.spent_s += spent
        stats = self.stats
        stats["search_ms"] += 1000.0 * spent
        if len(chosen) < new:
            missing(self._labels.view(), placed + len(chosen))
        self.nodes.extend(chosen.tolist())
        track.commit(new, 2 * new)
        stats["jumps"] += jumps
        stats["tiles"] += new
        if stop > self.emitted:
            self.emitted = stats["frames"] = stop
        return frames

    def _animes(self, positions: range) -> list[int]:
        """The anime each decided node at ``positions`` shows, one batch per run."""
        if self.options.graph == "unclustered":  # every view's anime graph: nodes are animes
            return self.nodes[positions.start : positions.stop]
        animes: list[int] = []
        for searcher, run in groupby(positions, key=lambda position: self.searchers[position]):
            nodes = np.asarray([self.nodes[position] for position in run], dtype=np.int64)
            animes.extend(np.asarray(searcher.graph.motion_of(nodes), dtype=np.int64).tolist())
        return animes

    # ---- post-processing -----------------------------------------------------------------

    def _warps(self, positions: range, animes: list[int]) -> list[Warp]:
        """Time warps of the fragments ``animes`` shown at query ``positions``; the DTW
        problems among them are solved as one batch."""
        problems = [self._alignment(position, anime) for position, anime in zip(positions, animes)]
        if self.audio is None:  # every warp is linear (``_alignment``): nothing to batch
            return [problem for problem in problems if isinstance(problem, Warp)]
        batch = iter(dtw_warps([p for p in problems if isinstance(p, Alignment)]))
        return [next(batch) if isinstance(p, Alignment) else p for p in problems]

    def _alignment(self, position: int, anime: int) -> Warp | Alignment:
        """The linear warp of a silence or audio-less fragment, else its DTW problem."""
        span = self.spans[position]
        animes = self.model.animes
        source = (float(animes.start[anime]), float(animes.end[anime]))
        if self.audio is None or animes.features is None or span.phoneme == SILENCE:
            return linear_warp(span.start, span.end, *source)
        rate = self.model.mfcc.rate
        target_curve = self.audio.describing(span.end)
        target_frames = np.arange(math.ceil(span.start * rate), math.floor(span.end * rate) + 1)
        owner = int(animes.utterance[anime])
        source_curve = animes.features.rows(owner)
        source_frames = np.arange(math.ceil(source[0] * rate), math.floor(source[1] * rate) + 1)
        source_frames = source_frames[source_frames < len(source_curve)]
        return Alignment(
            target_curve[target_frames],
            target_frames / rate,
            np.asarray(source_curve[source_frames], dtype=np.float64),
            source_frames / rate,
            (span.start, span.end),
            source,
        )

    def _place(self, position: int, anime: int, warp: Warp | None) -> None:
        """Lay ``anime`` on span ``position`` through ``warp`` (None: the linear warp onto
        its whole recording), joined to the placement before."""
        span = self.spans[position]
        join: Join | None = None
        if position > 0:
            left = self.track.anime_at(position - 1)
            join = plan_join(
                left,
                anime,
                self.model.poses,
                lambda: self._join_pairs(position),
                self.model.max_candidates,
                self.options.blend,
                forward=self.options.causal,
            )
        if warp is None:
            self.track.append_linear(span.start, span.end, anime, join)
        else:
            self.track.append(Placement(span.start, span.end, anime, warp), join)

    def _join_pairs(self, position: int) -> tuple[tuple[int, int], PairIndex]:
        """The labels of the join into ``position`` and the recorded pairs to blend it with:
        its view's, or across a change of view the whole corpus's."""
        view = self.searchers[position].view
        if self.searchers[position - 1].view is view:
            return (int(self.query[position - 1]), int(self.query[position])), view.pairs
        whole = self.model.views[WHOLE]
        left, right = (
            int(whole.substitution[PHONEME_INDEX[self.spans[index].phoneme]])
            for index in (position - 1, position)
        )
        return (left, right), whole.pairs

    def _track_final_until(self) -> float:
        """Time (s) before which the track is final; +inf once everything is decided."""
        if self.finished and len(self.nodes) == self._labels.count:
            return math.inf
        if len(self.nodes) < 1:
            return 0.0
        return self.spans[len(self.nodes) - 1].start

    def _extend_raw(self, count: int) -> None:
        """Track samples on the model grid up to index ``count`` (exclusive)."""
        have = self.raw.count - self.half_width if self.raw.count else 0
        if count <= have or not self.spans:
            return
        track = self.track
        values = self.calls.grid_samples(
            have,
            count,
            float(self.model.fps),
            self.covered_until,
            track.buffers,
            len(track),
            track.knots,
            track.motion,
        )
        if self.raw.count == 0:
            self.raw.extend(np.repeat(values[:1], self.half_width, axis=0))
        self.raw.extend(values)

    def _extend_smoothed(self, count: int) -> None:
        have = self.smoothed.count
        if count <= have:
            return
        width = 2 * self.half_width + 1
        offset = self.raw.first
        block = self.raw.view()[have - offset : count - 1 + width - offset]
        self.smoothed.extend(_filter(block, self.kernels))

    def _advance(self) -> None:
        self._decide()
        limit = self._track_final_until()
        fps_model = self.model.fps
        if math.isinf(limit):
            if not self.spans:  # finished with no input: no sample, and no frame, to make
                return
            last = frame_count(self.covered_until, self.fps) - 1
            needed = math.floor(last * fps_model / self.fps + SNAP) + 2
            self._extend_raw(needed + self.half_width)
            self._extend_smoothed(needed)
            return
        raw_final = max(0, math.ceil(limit * fps_model - SNAP))
        self._extend_raw(raw_final)
        self._extend_smoothed(max(0, raw_final - self.half_width))

    def _emittable(self, total: int) -> int:
        """One past the last frame (of ``total``) the smoothed samples so far can interpolate:
        the samples a frame needs grow with the frame, so a binary search finds it
        (``bisect_right``'s, compiled)."""
        return _emittable_stop(self.emitted, total, self.smoothed.count, self.model.fps, self.fps)

    def _emit(self) -> np.ndarray:
        total = frame_count(self.covered_until, self.fps) if self.spans else 0
        stop = self._emittable(total)
        if stop <= self.emitted:
            return np.zeros((0, len(self.model.channels)), dtype=np.float32)
        self.guard.check()
        model = self.model
        frames: np.ndarray = self.calls.interpolated_frames(
            self.emitted,
            stop,
            model.fps / self.fps,
            self.smoothed.view(),
            self.smoothed.first,
            self.smoothed.count,
            model.channel_map,
        )
        self.emitted = stop
        self.stats["frames"] = stop
        self._forget_consumed()
        return frames

    def _forget_consumed(self) -> None:
        """Drop the samples no later frame reads: raw ones already smoothed, smoothed ones
        before the sample below the next frame (so a request holds a window, not its
        whole utterance at the model's rate), once ``_FORGET_ROWS`` of them pile up, since
        dropping moves the rows kept."""
        raw, smoothed = self.raw, self.smoothed
        if smoothed.count - raw.first >= _FORGET_ROWS:
            raw.drop_before(smoothed.count)
        consumed = math.floor(self.emitted * self.model.fps / self.fps) - 1
        if consumed - smoothed.first >= _FORGET_ROWS:
            smoothed.drop_before(consumed)

    def _emit_causal(self) -> np.ndarray:
        """Frames whose time plus the lead lies within the decided spans (all, once
        finished): the damped filter stepped toward the track there (``causal_emit``)."""
        track = self.track
        frames: np.ndarray
        stop, frames = self.calls.causal_emit(
            self.emitted,
            self.finished,
            len(self.nodes),
            self._labels.count,
            self._bounds.data,
            self.clock,
            self.filter_state,
            track.buffers,
            len(track),
            track.knots,
            self.model.causal_emission,
        )
        if stop > self.emitted:
            self.guard.check()
            self.emitted = self.stats["frames"] = stop
        return frames


@njit(cache=True)
def _samples_needed(frame: int, fps_model: float, fps: float) -> int:
    """Smoothed samples (count) needed to interpolate output ``frame``."""
    position = frame * fps_model / fps
    nearest = np.round(position)  # within SNAP of position: how it rounds a tie is moot
    if abs(position - nearest) < SNAP:
        return int(nearest) + 1
    return math.floor(position) + 2


@njit(cache=True)
def _emittable_stop(emitted: int, total: int, count: int, fps_model: float, fps: float) -> int:
    """``emitted`` + ``bisect_right`` over frames ``emitted`` .. ``total`` - 1 of ``count``
    by ``_samples_needed``: the first of them that needs more than ``count`` samples."""
    low, high = 0, total - emitted
    while low < high:
        middle = (low + high) // 2
        if count < _samples_needed(emitted + middle, fps_model, fps):
            high = middle
        else:
            low = middle + 1
    return emitted + low


@njit(cache=True)
def _filter(block: np.ndarray, kernels: np.ndarray) -> np.ndarray:
    """Each component of ``block`` filtered by its kernel ('valid' correlation: output i
    reads block rows i .. i + width - 1)."""
    width = kernels.shape[1]
    out = np.empty((len(block) - width + 1, block.shape[1]))
    for component in range(block.shape[1]):
        for row in range(len(out)):
            total = 0.0
            for tap in range(width):
                total += block[row + tap, component] * kernels[component, tap]
            out[row, component] = total
    return out


def _search_timeout(spent_s: float, budget_s: float) -> SearchTimeout:
    return SearchTimeout(
        f"PQ-Matching searched for {spent_s:.3g} s, past pq_budget_s = {budget_s:g} s",
        where="search",
    )
