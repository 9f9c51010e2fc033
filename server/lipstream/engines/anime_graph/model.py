"""The trained anime-graph model: every structure the searches and post-processing read.

Sketch: one flat dictionary of arrays (``arrays``) is the whole model, so the
same constructor serves a fresh fit and a memory-mapped load, and a saved
model answers exactly like the one that was trained. Derived structures
(Anime Graphs and Anime Arrays, clustered graphs, recorded neighbour pairs,
poses at fragment ends, smoothing kernels) are rebuilt from them in
milliseconds; the suffix automata and the K-means results are stored.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from ...audio import Audio
from ...errors import InvalidRequestError, ModelStoreError
from ...features import MfccConfig
from ...numerics.basis import MotionBasis
from ...numerics.resample import interp_columns
from ...store import ModelManifest, require_arrays
from ...timeline import PhonemeSpan
from ..base import Lookahead, RenderingModel, Rung, SynthesisRequest, causal_rungs, resolved_rung
from ..damped import omega_for_cutoff
from .animes import AnimeTable, Curves
from .checks import check_stored_model
from .costs import Poses
from .emission import CausalEmission, ChannelMap, channel_frames
from .graph import SearchGraph
from .options import ENGINE, MAX_PQ_WINDOW, OPTION_NAMES, SearchOptions, parse_options
from .search import LayeredMatcher, Matcher, SuffixMatcher
from .smoothing import lowpass_kernels
from .stream_calls import StreamCalls
from .synthesizer import AnimeGraphSynthesizer
from .track import anime_motion
from .views import WHOLE, GraphView, load_view

REQUIRED_ARRAYS = (
    "basis_mean basis_components channel_low channel_high anime_label anime_utterance "
    "anime_start anime_end motion motion_offsets features feature_offsets anime_summary cutoffs"
).split()
LADDER_TILES = (10, 4, 2, 1)
MIN_CAUSAL_CUTOFF_HZ = 2.0
CAUSAL_CUTOFF_FACTOR = 2.0
"""The causal filter's -3 dB point over the learned cutoff: a second-order filter already
damps below its -3 dB point, and at twice the cutoff it keeps 90% of the gain there."""


class AnimeGraphModel(RenderingModel):
    """Anime Graph + GreedyMatching (Cao et al. 2004).

    See ``docs/explanation/engines/anime-graph.md``.
    """

    engine = ENGINE
    option_names = OPTION_NAMES
    uses_audio = True

    def __init__(self, manifest: ModelManifest, arrays: Mapping[str, np.ndarray]) -> None:
        super().__init__(manifest)
        self._arrays = dict(arrays)
        arrays = {key: np.asarray(value) for key, value in arrays.items()}
        settings = manifest.hyperparameters
        self.fps = float(manifest.fps)
        self.mfcc = MfccConfig(**manifest.extra["mfcc"])
        self.has_audio = bool(manifest.extra["audio_features"])
        self.max_tile = int(settings["max_tile"])
        self.max_candidates = int(settings["max_candidates"])
        self.default_graph = str(settings["graph"])
        self.basis = MotionBasis(
            np.asarray(arrays["basis_mean"], dtype=np.float64),
            np.asarray(arrays["basis_components"], dtype=np.float64),
        )
        self.channel_low = np.asarray(arrays["channel_low"], dtype=np.float64)
        self.channel_high = np.asarray(arrays["channel_high"], dtype=np.float64)
        self.animes = _anime_table(arrays, self.fps, self.mfcc, self.has_audio)
        self.anime_motion = anime_motion(self.animes)
        self.channel_map = ChannelMap(
            np.ascontiguousarray(self.basis.components),
            np.ascontiguousarray(self.basis.mean),
            np.ascontiguousarray(self.channel_low),
            np.ascontiguousarray(self.channel_high),
        )
        successor = self.animes.successors()
        everything = np.arange(self.animes.size)
        self.poses = Poses(
            self.animes.poses_at(everything, 0.0), self.animes.poses_at(everything, 1.0), successor
        )
        self.summaries = np.asarray(arrays["anime_summary"])
        self.views = {
            name: load_view(name, arrays, self.animes.labels, successor)
            for name in manifest.extra["views"]
        }
        if WHOLE not in self.views:
            raise ModelStoreError(f"the model has no {WHOLE!r} view", where="model.json")
        self.has_clusters = self.views[WHOLE].cluster_graph is not None
        self._matchers: dict[tuple[str, str], Matcher] = {}
        self._matchers_lock = threading.Lock()
        self.cutoffs = np.asarray(arrays["cutoffs"], dtype=np.float64)
        self.half_width = round(float(settings["smoothing_window"]) * self.fps)
        self.kernels = lowpass_kernels(self.cutoffs, self.fps, self.half_width)
        self.causal_omegas = omega_for_cutoff(
            CAUSAL_CUTOFF_FACTOR * np.maximum(self.cutoffs, MIN_CAUSAL_CUTOFF_HZ)
        )
        self.causal_emission = CausalEmission(
            np.ascontiguousarray(self.causal_omegas, dtype=np.float64),
            self.channel_map,
            self.anime_motion,
        )
        self.stream_calls = StreamCalls()

    @property
    def n_components(self) -> int:
        return self.basis.n_components

    @property
    def lookahead(self) -> Lookahead:
        """A frame at t waits for the span containing t + seconds to have ``phonemes`` whole
        spans after it (the tile cap, or a PQ window): the worst over every request option
        but an uncapped tile; ``fidelity_ladder`` gives each greedy rung's own."""
        return Lookahead(
            seconds=(self.half_width + 1) / self.fps,
            phonemes=max(self.max_tile, MAX_PQ_WINDOW),
            audio_seconds=self.audio_wait_s,
        )

    def greedy_lookahead(self, max_tile: int, smooth: bool) -> Lookahead:
        """What a frame waits for under GreedyMatching with tiles of at most ``max_tile``
        phonemes: the next model-grid sample past t plus the smoothing half-width (when
        ``smooth``), then ``max_tile`` spans, which decide the fragment after it."""
        if max_tile < 1:
            raise InvalidRequestError(
                f"a bounded lookahead needs max_tile >= 1, got {max_tile}", where="options.max_tile"
            )
        half_width = self.half_width if smooth else 0
        return Lookahead(
            seconds=(half_width + 1) / self.fps, phonemes=max_tile, audio_seconds=self.audio_wait_s
        )

    def lookahead_for(self, options: Mapping[str, Any]) -> Lookahead | None:
        """Greedy with tiles of at most ``max_tile`` (none when uncapped: a tile may wait for
        the end of the input), or PQ, whose window of h phonemes decides its first
        fragments; the filter's reach only when ``smooth``."""
        parsed = self.parse(options)
        if parsed.causal:
            return Lookahead(seconds=self.causal_shift_s(parsed.lead_ms))
        if parsed.search == "pq":
            smoothing = self.half_width if parsed.smooth else 0
            return Lookahead(
                seconds=(smoothing + 1) / self.fps,
                phonemes=parsed.pq_window,
                audio_seconds=self.audio_wait_s,
            )
        if parsed.max_tile is None:
            return None
        return self.greedy_lookahead(parsed.max_tile, parsed.smooth)

    @property
    def audio_wait_s(self) -> float:
        """How far past a span's end the audio must reach before the span's MFCC frames are
        final (``StreamedFeatures.ready``): two frame steps plus half a window; 0 without audio
        features."""
        if not self.has_audio:
            return 0.0
        return 2.0 / self.mfcc.rate + self.mfcc.window_s / 2.0

    def causal_shift_s(self, lead_ms: float) -> float:
        """How far ahead (s) the causal search's filter follows the track: its lag at low
        frequencies (2 / ω) for the first, most varied, PCA component, at most the lead."""
        return min(lead_ms / 1000.0, 2.0 / float(self.causal_omegas[0]))

    def fidelity_ladder(self) -> tuple[Rung, ...]:
        """GreedyMatching with ever shorter tiles, the model's ``max_tile`` first (fewest
        jumps), then 10, 4, 2 and 1 phonemes below it; last, one-phoneme tiles without the
        low-pass filter, which waits H frames; below it the causal search following the
        track as far ahead as its filter lags (at most 120 ms), and last the causal floor,
        which waits for nothing past t. A rung pins ``search`` and ``max_tile``
        (``smooth`` off on the unsmoothed one, ``causal``, ``lead_ms`` and ``max_tile`` 1 on
        the causal ones, so a client's ``max_tile`` cannot clash with them), the options its
        lookahead depends on."""
        tiles = sorted(
            {self.max_tile, *(t for t in LADDER_TILES if t < self.max_tile)}, reverse=True
        )
        rungs = [
            Rung(
                f"greedy_tile{tile}",
                self.greedy_lookahead(tile, smooth=True),
                {"search": "greedy", "max_tile": tile},
            )
            for tile in tiles
        ]
        if self.half_width > 0:
            rungs.append(
                Rung(
                    "greedy_tile1_unsmoothed",
                    self.greedy_lookahead(1, smooth=False),
                    {"search": "greedy", "max_tile": 1, "smooth": False},
                )
            )
        pinned = {"search": "greedy", "max_tile": 1}
        return (*rungs, *causal_rungs(self.causal_shift_s, pinned=pinned))

    def rung_for(self, options: Mapping[str, Any]) -> Rung | None:
        """The rung whose options resolve to the same search as ``options`` (defaults filled
        in), so a client that also names a rung's default graph still gets its measured
        cost. PQ-Matching never selects a rung: its work per window grows exponentially with
        h and no calibration bounds it, so ``call_cost`` leaves it unbounded (such calls
        always leave the server's event loop), and the request's guard and ``pq_budget_s``
        stop it."""
        return resolved_rung(self.fidelity_ladder(), options, self.parse)

    def parse(self, options: Mapping[str, Any]) -> SearchOptions:
        """The search ``options`` ask for, this model's defaults filled in."""
        return parse_options(options, self.default_graph, self.has_clusters, self.max_tile)

    def view_for(self, emotion: str | None, options: SearchOptions) -> GraphView:
        """The view searched for a span spoken with ``emotion`` (its own, else the
        request's): that emotion's when it was recorded and ``match_emotion`` is on, else
        the whole corpus."""
        if options.match_emotion and emotion is not None and emotion in self.views:
            return self.views[emotion]
        return self.views[WHOLE]

    def graph_of(self, view: GraphView, name: str) -> SearchGraph:
        if name == "clustered" and view.cluster_graph is not None:
            return view.cluster_graph
        return view.anime_graph

    def matcher_of(self, view: GraphView, name: str) -> Matcher:
        """The view's matcher, built on first use and kept (the clustered one flattens its
        graph into CSR arrays, which takes a while and is only needed for the views a
        request asks for). Thread-safe: every synthesis thread shares the model, so the
        first build happens under a lock and the rest read the finished matcher."""
        key = (view.name, name)
        matcher = self._matchers.get(key)
        if matcher is not None:
            return matcher
        with self._matchers_lock:
            if key not in self._matchers:
                if name == "clustered" and view.cluster_graph is not None:
                    self._matchers[key] = LayeredMatcher(view.cluster_graph)
                else:
                    self._matchers[key] = SuffixMatcher(
                        view.index, view.anime_graph, self.max_candidates
                    )
            return self._matchers[key]

    def to_channels(self, coefficients: np.ndarray) -> np.ndarray:
        """PCA coefficients (n, n_pc) to channel frames (n, n_channels) float32, held inside
        the range the recordings span."""
        return channel_frames(
            np.ascontiguousarray(coefficients, dtype=np.float64), self.channel_map
        )

    def start(
        self, request: SynthesisRequest | None = None, **settings: Any
    ) -> AnimeGraphSynthesizer:
        """The contract's ``start`` (option names checked), typed as this engine's."""
        return cast(AnimeGraphSynthesizer, super().start(request, **settings))

    def synthesizer(self, request: SynthesisRequest) -> AnimeGraphSynthesizer:
        return AnimeGraphSynthesizer(self, request, self.parse(request.options))

    def render(
        self,
        spans: Sequence[PhonemeSpan],
        times: np.ndarray,
        request: SynthesisRequest,
        audio: Audio | None,
    ) -> np.ndarray:
        """Frames at arbitrary ``times`` (s): the offline track, interpolated."""
        fine = SynthesisRequest(self.fps, request.emotion, request.options, request.guard)
        synthesizer = self.start(fine)
        synthesizer.feed(spans, audio)
        frames = synthesizer.finish().astype(np.float64)
        grid = np.arange(len(frames)) / self.fps
        return interp_columns(times, grid, frames).astype(np.float32)

    def arrays(self) -> dict[str, np.ndarray]:
        return dict(self._arrays)

    @classmethod
    def from_arrays(
        cls, manifest: ModelManifest, arrays: Mapping[str, np.ndarray], path: Path
    ) -> AnimeGraphModel:
        require_arrays(arrays, REQUIRED_ARRAYS, path)
        check_stored_model(manifest, arrays, path)
        return cls(manifest, arrays)


def _anime_table(
    arrays: Mapping[str, np.ndarray], fps: float, mfcc: MfccConfig, has_audio: bool
) -> AnimeTable:
    features = Curves(arrays["features"], np.asarray(arrays["feature_offsets"]), mfcc.rate)
    return AnimeTable(
        labels=np.asarray(arrays["anime_label"]),
        utterance=np.asarray(arrays["anime_utterance"]),
        start=np.asarray(arrays["anime_start"], dtype=np.float64),
        end=np.asarray(arrays["anime_end"], dtype=np.float64),
        motion=Curves(arrays["motion"], np.asarray(arrays["motion_offsets"]), fps),
        features=features if has_audio else None,
    )
