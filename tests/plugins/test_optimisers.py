"""Every installed optimiser solves bound-constrained least-squares problems with known answers
(the optimisers' conformance kit), and the derivative-free ones do so without a Jacobian."""

from __future__ import annotations

import numpy as np
import pytest

from skinkit import registry
from skinkit.plugin.conformance.optimisers import check_optimiser

pytestmark = pytest.mark.needs_plugins


@pytest.mark.parametrize("name", registry.names("skinkit.optimisers"))
def test_every_optimiser_conforms(name):
    report = check_optimiser(name)
    assert report.passed, str(report)


def _derivative_free() -> list[str]:
    """Optimisers that do not need the Jacobian: they accept a problem without one."""
    out = []
    for name in registry.names("skinkit.optimisers"):
        opt = registry.create("skinkit.optimisers", name)
        try:
            opt.minimise(lambda x: x - 1.0, np.array([0.0]), np.array([-2.0]), np.array([2.0]))
        except ValueError:
            continue
        out.append(name)
    return out


@pytest.mark.parametrize("name", _derivative_free())
def test_exponential_fit_without_a_jacobian(name):
    # y = a (1 - exp(-b t)) sampled without noise: the minimiser is exactly (a, b) = (8.6, 0.51).
    t = np.linspace(0, 10, 50)
    y = 8.6 * (1 - np.exp(-0.51 * t))
    opt = registry.create("skinkit.optimisers", name)
    res = opt.minimise(lambda x: x[0] * (1 - np.exp(-x[1] * t)) - y, np.array([5.0, 1.0]),
                       np.array([0.0, 0.0]), np.array([20.0, 5.0]))
    assert res.success, res.message
    # a global search refines its best point locally, so it meets a local method's tolerance
    np.testing.assert_allclose(res.x, [8.6, 0.51], rtol=1e-4)
    assert res.fun < 1e-8 and res.nfev > 0


@pytest.mark.parametrize("name", _derivative_free())
def test_the_same_seed_gives_the_same_answer(name):
    # a stochastic search is seeded by default: the same fit twice gives the same answer
    t = np.linspace(0, 10, 50)
    y = 8.6 * (1 - np.exp(-0.51 * t)) + 0.05 * np.sin(7 * t)
    opt = registry.create("skinkit.optimisers", name)
    runs = [opt.minimise(lambda x: x[0] * (1 - np.exp(-x[1] * t)) - y, np.array([5.0, 1.0]),
                         np.array([0.0, 0.0]), np.array([20.0, 5.0]))
            for _ in range(2)]
    np.testing.assert_array_equal(runs[0].x, runs[1].x)
