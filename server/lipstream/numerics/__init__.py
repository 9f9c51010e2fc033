"""Numerical kernels shared by engines (numpy/scipy/numba, no engine imports).

- ``basis``: the motion basis (PCA) and its reconstruction;
- ``banded``: banded and block-tridiagonal solves;
- ``trellis``: the Viterbi trellis and the fixed-lag decoder (``FixedLagViterbi``,
  ``ViterbiState``);
- ``nnls``: Lawson–Hanson non-negative least squares for a fixed design matrix, its Gram
  matrix precomputed and each solve warm-started from an active set (``NnlsSystem``,
  ``solve_nnls``, ``solve_nnls_rows``);
- ``direct_call``: calling a compiled kernel without numba's per-call typing
  (``DirectCall``), for kernels that take named groups of arrays.
"""
