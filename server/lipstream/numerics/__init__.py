"""Numerical kernels shared by engines (numpy/scipy/numba, no engine imports).

- ``basis``: the motion basis (PCA) and its reconstruction;
- ``banded``: banded and block-tridiagonal solves;
- ``trellis``: the Viterbi trellis and the fixed-lag decoder (``FixedLagViterbi``,
  ``ViterbiState``);
- ``layered``: the cheapest path through layers of candidates (min-plus dynamic
  programme: ``Trellis``, ``sliding_positions``), for DAM's mode search and
  expressive-dp's exact search;
- ``direct_call``: calling a compiled kernel without numba's per-call typing
  (``DirectCall``), for kernels that take named groups of arrays.
"""
