"""Numerical kernels shared by engines (numpy/scipy/numba, no engine imports).

- ``basis``: the motion basis (PCA, ``MotionBasis``, ``fit_basis``) and its compiled
  reconstruction as float32 channel frames (``basis_frames``: BLAS or in-order sums,
  optional per-channel bounds);
- ``banded``: banded and block-tridiagonal solves (``solve_spd_banded``; the factor-once,
  solve-many pair ``factor_spd_banded`` / ``solve_with_factor``;
  ``solve_spd_block_tridiagonal``; ``windowed_least_squares``);
- ``trellis``: the Viterbi trellis and the fixed-lag decoder (``FixedLagViterbi``,
  ``ViterbiState``);
- ``resample``: linear interpolation of a curve's rows at fractional positions
  (``bracket``, ``blend_into``, ``extend_into``, ``sample_curves``) and
  ``np.interp`` per column (``interp_columns``);
- ``nnls``: Lawson–Hanson non-negative least squares for a fixed design matrix, its Gram
  matrix precomputed and each solve warm-started from an active set (``NnlsSystem``,
  ``solve_nnls``, ``solve_nnls_rows``);
- ``layered``: the cheapest path through layers of candidates (min-plus dynamic
  programme: ``Trellis``, ``sliding_positions``), for DAM's mode search and
  expressive-dp's exact search;
- ``direct_call``: calling a compiled kernel without numba's per-call typing
  (``DirectCall``), for kernels that take named groups of arrays.
"""
