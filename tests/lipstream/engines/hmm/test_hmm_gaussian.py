"""Full-covariance log-densities against scipy's multivariate normal, both evaluation paths."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from lipstream.engines.hmm.gaussian import Gaussians


@pytest.mark.parametrize(
    "frames", [1, 7, 60000]
)  # the last exceeds the all-states batch (2^20 values)
def test_log_density_matches_scipy(frames: int) -> None:
    rng = np.random.default_rng(frames)
    states, dim = 5, 4
    means = rng.normal(size=(states, dim))
    factors = rng.normal(size=(states, dim, dim))
    covariances = factors @ factors.transpose(0, 2, 1) + 0.2 * np.eye(dim)
    x = rng.normal(size=(frames, dim)) * 2.0
    got = Gaussians(means, covariances).log_density(x)
    expected = np.stack(
        [multivariate_normal(means[i], covariances[i]).logpdf(x) for i in range(states)], axis=-1
    ).reshape(frames, states)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-9)
