"""Per-request options of the anime-graph engine, validated.

``graph``: "unclustered" or "clustered" (default: the model's ``graph``
hyperparameter). ``search``: "greedy" (GreedyMatching) or "pq"
(PQ-Matching, the slow exact-in-windows baseline). ``pq_window`` (h, 1-6)
and ``pq_advance`` (h_q, 1-h). ``blend`` and ``smooth`` switch the two
post-processing stages, ``match_emotion`` the search of the request emotion's
recordings only (all on by default). ``max_tile`` (default: the model's) caps
a tile's phonemes; 0 lifts the cap, which makes GreedyMatching exactly
minimal in jumps but lets a frame wait for a whole tile, beyond the model's
declared lookahead. ``pq_budget_s`` (seconds, default unlimited) makes a
PQ-Matching request fail with ``search_timeout`` once its search has run that
long, since PQ-Matching can take minutes. PQ-Matching's work grows
exponentially with its window, so a request may hold at most
``MAX_PQ_STEPS`` // ``pq_window`` phonemes (``search_too_large`` beyond).
``causal`` (default off) selects the causal search: one-phoneme greedy tiles
committed as their span arrives, forward joins, no audio, and a critically
damped filter following the track ahead by its own lag, at most ``lead_ms``
(0-1000, default 0), so a frame waits for the input to cover t + that shift
only; it takes no ``search`` but greedy, and its tiles are one phoneme
whatever ``max_tile`` says.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from ...errors import InvalidRequestError
from ..base import check_options, lead_ms_option

GRAPHS = ("unclustered", "clustered")
SEARCHES = ("greedy", "pq")
MAX_PQ_WINDOW = 6
MAX_PQ_STEPS = 256
SEARCH_TOO_LARGE = "search_too_large"


@dataclass(frozen=True)
class SearchOptions:
    graph: str = "unclustered"
    search: str = "greedy"
    pq_window: int = 4
    pq_advance: int = 1
    blend: bool = True
    smooth: bool = True
    match_emotion: bool = True
    max_tile: int | None = 10
    pq_budget_s: float | None = None
    causal: bool = False
    lead_ms: float = 0.0

    def check_size(self, phonemes: int) -> None:
        """``InvalidRequestError`` (``search_too_large``) when a PQ-Matching request would hold
        more than ``MAX_PQ_STEPS`` window × phonemes."""
        if self.search == "pq" and self.pq_window * phonemes > MAX_PQ_STEPS:
            raise InvalidRequestError(
                f"PQ-Matching with pq_window {self.pq_window} takes at most "
                f"{MAX_PQ_STEPS // self.pq_window} phonemes per request (pq_window × phonemes "
                f"<= {MAX_PQ_STEPS}); this request would hold {phonemes}",
                where="options.search",
                code=SEARCH_TOO_LARGE,
            )


ENGINE = "anime-graph"
OPTION_NAMES: tuple[str, ...] = tuple(SearchOptions.__dataclass_fields__)


def _choice(options: Mapping[str, Any], name: str, allowed: tuple[str, ...], default: str) -> str:
    value = options.get(name, default)
    if value not in allowed:
        raise InvalidRequestError(
            f"{name} must be one of {', '.join(allowed)}, got {value!r}", where=f"options.{name}"
        )
    return str(value)


def _integer(options: Mapping[str, Any], name: str, low: int, high: int, default: int) -> int:
    value = options.get(name, default)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InvalidRequestError(
            f"{name} must be an integer in [{low}, {high}], got {value!r}", where=f"options.{name}"
        )
    return value


def _flag(options: Mapping[str, Any], name: str, default: bool = True) -> bool:
    value = options.get(name, default)
    if not isinstance(value, bool):
        raise InvalidRequestError(
            f"{name} must be true or false, got {value!r}", where=f"options.{name}"
        )
    return value


def parse_options(
    options: Mapping[str, Any], default_graph: str, has_clusters: bool, default_max_tile: int
) -> SearchOptions:
    """Validate ``options``; unknown names and a clustered request on a model trained without
    clusters raise ``InvalidRequestError``."""
    check_options(ENGINE, OPTION_NAMES, options)
    graph = _choice(options, "graph", GRAPHS, default_graph)
    if graph == "clustered" and not has_clusters:
        raise InvalidRequestError(
            "this model was trained without a clustered graph (clusters=0)", where="options.graph"
        )
    window = _integer(options, "pq_window", 1, MAX_PQ_WINDOW, SearchOptions.pq_window)
    causal = _flag(options, "causal", default=False)
    parsed = SearchOptions(
        graph=graph,
        search=_choice(options, "search", SEARCHES, "greedy"),
        pq_window=window,
        pq_advance=_integer(
            options, "pq_advance", 1, window, min(SearchOptions.pq_advance, window)
        ),
        blend=_flag(options, "blend"),
        smooth=_flag(options, "smooth"),
        match_emotion=_flag(options, "match_emotion"),
        max_tile=_integer(options, "max_tile", 0, 10**6, default_max_tile) or None,
        pq_budget_s=_budget(options),
        causal=causal,
        lead_ms=_lead(options, causal),
    )
    if causal:
        _check_causal(parsed)
        return replace(parsed, max_tile=1)
    return parsed


def _lead(options: Mapping[str, Any], causal: bool) -> float:
    value = lead_ms_option(options)
    if not causal and "lead_ms" in options:
        raise InvalidRequestError("lead_ms applies to causal: true only", where="options.lead_ms")
    return value


def _check_causal(parsed: SearchOptions) -> None:
    if parsed.search != "greedy":
        raise InvalidRequestError(
            "causal takes search greedy (PQ-Matching looks ahead)", where="options.search"
        )


def _budget(options: Mapping[str, Any]) -> float | None:
    value = options.get("pq_budget_s")
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise InvalidRequestError(
            f"pq_budget_s must be a positive number of seconds, got {value!r}",
            where="options.pq_budget_s",
        )
    return float(value)
