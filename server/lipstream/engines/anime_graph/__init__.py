"""Engine ``anime-graph``: Anime Graph + greedy search (Cao, Faloutsos, Kohler & Pighin 2004).

The corpus is cut into phoneme-long motion fragments (animes) linked in
recording order; a query is tiled with the fewest graph paths (GreedyMatching,
optimal by the paper's Theorem 1, found through a suffix automaton in time
linear in the query), then time-warped, blended at the jumps and low-passed.
See ``docs/explanation/engines/anime-graph.md``.
"""

from .engine import AnimeGraphEngine
from .model import AnimeGraphModel

__all__ = ["AnimeGraphEngine", "AnimeGraphModel"]
