"""The load-test command line: which engines a capacity run searches."""

from __future__ import annotations

from lipstream.loadtest.command import _capacity_engines

UNREACHABLE = "ws://127.0.0.1:9/v1/stream"  # a named list never asks the server


def test_a_comma_separated_list_names_the_engines_in_order() -> None:
    engines = _capacity_engines(UNREACHABLE, "anime-graph, hmm,,expressive-dp", "demo", None)
    assert engines == ["anime-graph", "hmm", "expressive-dp"]


def test_one_engine_is_searched_alone() -> None:
    assert _capacity_engines(UNREACHABLE, "viseme-lerp", "demo", None) == ["viseme-lerp"]
