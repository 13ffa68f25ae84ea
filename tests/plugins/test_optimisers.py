"""Built-in optimiser plugins solve a bound-constrained least-squares problem with a known answer."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit import registry

pytestmark = pytest.mark.needs_plugins


@pytest.mark.parametrize("name", ["scipy-lsq", "nlopt-bobyqa"])
def test_exponential_fit(name):
    # y = a (1 - exp(-b t)) sampled without noise: the minimiser is exactly (a, b) = (8.6, 0.51).
    t = np.linspace(0, 10, 50)
    y = 8.6 * (1 - np.exp(-0.51 * t))
    opt = registry.create("skinkit.optimisers", name)
    res = opt.minimise(lambda x: x[0] * (1 - np.exp(-x[1] * t)) - y, np.array([5.0, 1.0]),
                       np.array([0.0, 0.0]), np.array([20.0, 5.0]))
    assert res.success, res.message
    np.testing.assert_allclose(res.x, [8.6, 0.51], rtol=1e-5)
    assert res.fun < 1e-9 and res.nfev > 0


@pytest.mark.parametrize("name", ["scipy-lsq", "nlopt-bobyqa"])
def test_active_bound(name):
    # The unconstrained minimum is x = 3; the bound holds it at 2.
    opt = registry.create("skinkit.optimisers", name)
    res = opt.minimise(lambda x: np.array([x[0] - 3.0]), np.array([0.5]), np.array([0.0]), np.array([2.0]))
    assert res.x[0] == pytest.approx(2.0, abs=1e-6)
