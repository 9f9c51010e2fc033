"""Numerical kernels shared by engines (numpy/scipy, no engine imports): ``basis``, the
motion basis (PCA)."""
