"""Benchmarks: ``lipstream bench`` and the engines' own benchmark tables.

``harness`` runs every engine against ``viseme-lerp`` on held-out utterances
(``lipstream bench``); each engine with its own benchmark has a module here,
named after the engine's package (``anime_graph``: Cao et al.'s Tables 1-2,
scaling, speed and quality), registered in ``harness.ENGINE_BENCHES``.
Runtime modules hold no benchmark code.
"""
