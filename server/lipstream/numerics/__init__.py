"""Numerical kernels shared by engines (numpy/scipy/numba, no engine imports).

- ``basis``: the motion basis (PCA) and its reconstruction;
- ``banded``: banded and block-tridiagonal solves;
- ``trellis``: the Viterbi trellis and the fixed-lag decoder (``FixedLagViterbi``,
  ``ViterbiState``);
- ``resample``: linear interpolation of a curve's rows at fractional positions
  (``bracket``, ``blend_into``, ``extend_into``, ``sample_curves``) and
  ``np.interp`` per column (``interp_columns``);
- ``direct_call``: calling a compiled kernel without numba's per-call typing
  (``DirectCall``), for kernels that take named groups of arrays.
"""
