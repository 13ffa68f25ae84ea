"""Step 2 of the gap diagnosis ("Which"): score tests at the effects' nulls.

The statistics are checked on linear problems built from numpy, where everything is known in
closed form: z = (I − P_θ)(ε + J_e δ) with ε white. Then on the lumped forward model: one
prediction gives every candidate's sensitivities, the null leaves the residual unchanged, and
parameters without a signature at the null are held, not tested.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy import stats

from skinkit.gap.score import (
    ABSORBED,
    COS_NOT_SEPARABLE,
    EffectColumns,
    Sensitivities,
    collect,
    corrected,
    fitted_basis,
    score_all,
    score_test,
    separability,
)

M = 400


def _linear(seed: int, J_theta: np.ndarray, J_e: np.ndarray, delta: np.ndarray | None = None) -> np.ndarray:
    """z = prediction − data after a linear least-squares fit of θ to data ε + J_e δ: the data
    carry the effect at δ, the model does not (what a converged fit leaves)."""
    rng = np.random.default_rng(seed)
    y = rng.standard_normal(M) + (J_e @ delta if delta is not None else 0.0)
    U = fitted_basis(J_theta)
    return -(y - U @ (U.T @ y))


def _cols(name: str, J: np.ndarray, sides=None) -> EffectColumns:
    q = J.shape[1]
    names = [f"{name}.p{i}" for i in range(q)]
    return EffectColumns(name, names, J, {n: "analytic" for n in names},
                         np.zeros(q) if sides is None else np.asarray(sides, float),
                         {n: 0.0 for n in names}, {n: 1.0 for n in names},
                         bounds={n: (0.0 if sides is not None else -1.0, 1.0) for n in names})


@pytest.fixture(scope="module")
def design():
    rng = np.random.default_rng(0)
    t = np.linspace(0, 1, M)
    J_theta = np.stack([np.ones(M), t], axis=1)            # an offset and a slope are fitted
    J_e = np.stack([np.sin(6 * t), t ** 2 + 0.1 * rng.standard_normal(M)], axis=1)
    return J_theta, J_e


def test_statistic_is_the_linear_refit_drop(design):
    """LM equals the drop of Σz² when θ and e are refitted together on a linear problem (exact)."""
    J_theta, J_e = design
    z = _linear(1, J_theta, J_e, np.array([0.3, -0.2]))
    t = score_test(z, fitted_basis(J_theta), _cols("e", J_e))
    A = np.hstack([J_theta, J_e])
    r_full = z - A @ np.linalg.lstsq(A, z, rcond=None)[0]
    assert t.statistic == pytest.approx(z @ z - r_full @ r_full, rel=1e-9)
    assert t.dof == 2
    # the step is the joint least-squares estimate of e (θ already at its optimum)
    coef = np.linalg.lstsq(A, -z, rcond=None)[0][2:]
    assert [t.step["e.p0"], t.step["e.p1"]] == pytest.approx(coef, rel=1e-8)


def test_null_distribution_is_chi2(design):
    """Under the null LM ~ χ²_2: over 1000 draws the mean is 2 (sd of the mean 0.063) and a KS test
    against χ²_2 does not reject at the 1 % level; the 5 % test rejects 5 % ± 2 % (binomial sd 0.7 %)."""
    J_theta, J_e = design
    U = fitted_basis(J_theta)
    lm = np.array([score_test(_linear(s, J_theta, J_e), U, _cols("e", J_e)).statistic
                   for s in range(100, 1100)])
    assert abs(lm.mean() - 2) < 4 * 2 / math.sqrt(1000)
    assert stats.kstest(lm, stats.chi2(2).cdf).pvalue > 0.01
    p = np.array([stats.chi2.sf(x, 2) for x in lm])
    assert abs(np.mean(p < 0.05) - 0.05) < 0.02


def test_one_sided_null_is_a_half_mixture(design):
    """A null on a bound: the residual pointing out of the admissible range gives LM = 0, p = 1
    (half of the null draws, binomial sd 1.6 % over 1000); the rest are χ²_1, p = ½ P(χ²_1 > LM)."""
    J_theta, J_e = design
    U = fitted_basis(J_theta)
    one = J_e[:, :1]
    tests = [score_test(_linear(s, J_theta, one), U, _cols("g", one, sides=[1])) for s in range(100, 1100)]
    zero = np.array([t.statistic == 0 for t in tests])
    assert abs(zero.mean() - 0.5) < 0.05
    assert all(t.p_value == 1.0 for t, z0 in zip(tests, zero, strict=True) if z0)
    pos = [t for t in tests if t.statistic > 0]
    assert all(t.p_value == pytest.approx(0.5 * stats.chi2.sf(t.statistic, 1)) for t in pos)
    assert all(t.step["g.p0"] > 0 for t in pos)
    # an effect in the admissible direction is found; the same size the other way is not
    z_in = _linear(3, J_theta, one, np.array([0.5]))
    z_out = _linear(3, J_theta, one, np.array([-0.5]))
    assert score_test(z_in, U, _cols("g", one, sides=[1])).p_value < 1e-6
    assert score_test(z_out, U, _cols("g", one, sides=[1])).statistic == 0.0


def test_absorbed_direction_is_dropped(design):
    """A signature inside span(J_θ) (an offset the model already fits) cannot be told from the fit."""
    J_theta, J_e = design
    z = _linear(4, J_theta, J_e)
    cols = _cols("offset", np.stack([2.0 * J_theta[:, 0], J_e[:, 0]], axis=1))
    t = score_test(z, fitted_basis(J_theta), cols)
    assert t.absorbed == ["offset.p0"] and t.tested == ["offset.p1"] and t.dof == 1


def test_a_parameter_the_fit_all_but_absorbs_names_what_it_resembles(design):
    """A candidate column that is the fitted slope plus 1 % of something else keeps about 1 % of
    its norm once the fit is projected out: it is reported as resembling the slope (|cos| ≈ 1),
    with that share, and the verdict says its test says little; a column well apart is not."""
    from skinkit.gap.sentences import resemble_sentence

    J_theta, J_e = design
    other = J_e[:, 0] - fitted_basis(J_theta) @ (fitted_basis(J_theta).T @ J_e[:, 0])
    like = J_theta[:, 1] + 0.01 * np.linalg.norm(J_theta[:, 1]) * other / np.linalg.norm(other)
    cols = _cols("slip", np.stack([like, J_e[:, 0]], axis=1))
    z = _linear(5, J_theta, J_e)
    (t,) = score_all(_sens(z, J_theta, [cols]))
    (r,) = t.resembles
    # the leftover is the 1 % added, over a norm of about the slope's
    assert r["parameter"] == "slip.p0" and r["fitted"] == "t1"
    assert r["kept"] == pytest.approx(0.01, rel=0.01) and r["cosine"] > 0.999
    assert t.record()["resembles"] == [r]
    text = resemble_sentence("slip", r)
    assert text.startswith("slip.p0 cannot be told") and "that of t1" in text and "1 %" in text
    # a column in the fitted span to rounding is the fitted parameter offered again: said so
    same = _cols("again", np.stack([J_theta[:, 1], J_e[:, 0]], axis=1))
    (t,) = score_all(_sens(z, J_theta, [same]))
    (r,) = t.resembles
    assert r["kept"] < ABSORBED and t.absorbed == ["again.p0"]
    assert resemble_sentence("again", r).startswith("again.p0 is t1 itself on these protocols")


def _sens(z, J_theta, cols) -> Sensitivities:
    return Sensitivities(z, J_theta, ["t0", "t1"], {c.effect: c for c in cols}, {}, None)


def test_ranking_bonferroni_and_separability(design):
    """The true effect ranks first; a near copy of it (|cos| 0.99) is reported not separable when
    the signal is small, and separable when it is strong enough for the conditional test."""
    J_theta, J_e = design
    rng = np.random.default_rng(7)
    a = J_e[:, :1]
    b = a + 0.1 * np.std(a) * rng.standard_normal((M, 1))          # nearly the same signature
    c = J_e[:, 1:]
    U = fitted_basis(J_theta)
    pa, pb = (a - U @ (U.T @ a))[:, 0], (b - U @ (U.T @ b))[:, 0]
    cos = abs(pa @ pb) / np.linalg.norm(pa) / np.linalg.norm(pb)
    assert COS_NOT_SEPARABLE < cos < 0.999
    cols = [_cols("a", a), _cols("b", b), _cols("c", c)]
    # strong: a explains what b cannot, the conditional test sees it
    z = _linear(8, J_theta, a, np.array([3.0]))
    sens = _sens(z, J_theta, cols)
    tests = score_all(sens)
    assert tests[0].effect == "a"
    ok = corrected(tests, 0.05)
    assert ok["a"] and ok["b"]
    sep = separability(sens, tests, 0.05)
    assert len(sep) == 1 and set(sep[0]["effects"]) == {"a", "b"} and sep[0]["separable"]
    # weak: both significant, but the data cannot tell them apart
    z = _linear(9, J_theta, a, np.array([0.35]))
    sens = _sens(z, J_theta, cols)
    tests = score_all(sens)
    sep = separability(sens, tests, 0.05)
    assert corrected(tests, 0.05)["a"]
    assert len(sep) == 1 and not sep[0]["separable"]


# ------------------------------------------------------------------------ on a forward model
SPEC = {"model": {"kind": "lumped", "name": "gap-score-lumped"},
        "lumped": {"test": "indentation", "family": "quasi-static", "axis": "-z", "drive": "tip_position",
                   "elastic": "exponential", "parameters": {"a": "15 mN", "b": 800.0}},
        "session": {"protocols": ["normal_indentation"],
                    "parameters": {"normal_indentation": {"periods": 1}}}}


@pytest.mark.needs_plugins
def test_collect_on_a_lumped_model():
    """One prediction gives every lumped effect's columns; the null leaves the residual exactly as
    the model without the effects; parameters without a signature at the null are held."""
    from skinkit.forward import load
    from skinkit.forward.visibility import applicable_effects
    from skinkit.inverse.coverage import LabSessions
    from skinkit.inverse.objective import Objective

    truth = copy.deepcopy(SPEC)
    truth["effects"] = [{"name": "viscoelastic", "g1": 0.3, "tau1": 2.0}]
    obs = LabSessions(truth)(0)
    model = load(SPEC)
    vals = model.parameters().values()
    effects = applicable_effects("lumped")
    sens = collect(SPEC, obs, vals, ["lumped.a", "lumped.b"], effects, load=load)
    assert sens.n_forward == 1 and not sens.skipped and set(sens.columns) == set(effects)
    base = Objective(model, obs, ["lumped.a", "lumped.b"]).evaluate(model.parameters())[0]
    assert np.array_equal(sens.z, base.z)                  # the null is exact
    assert np.allclose(sens.J_theta, base.J, rtol=1e-10, atol=0)
    held = {n for c in sens.columns.values() for n in c.held}
    # the axis model predicts one force component; τ means nothing while g = 0
    assert {"force-offset.x", "force-offset.y", "viscoelastic.tau1"} <= held
    assert sens.columns["viscoelastic"].names == ["viscoelastic.g1"]
    assert sens.columns["viscoelastic"].sides.tolist() == [1.0]        # g ≥ 0: one-sided
    assert sens.columns["force-offset"].sides.tolist() == [0.0]
    tests = score_all(sens)
    assert tests[0].effect == "viscoelastic" and corrected(tests, 0.05)["viscoelastic"]


@pytest.mark.needs_plugins
def test_separating_protocol_ranks_the_library():
    """A force offset and a force drift overlap on one sinusoid (|cos| ≈ 0.7); each library protocol
    is predicted once, the session augmented with it, and the ranking is by the |cos| left; the best
    protocol separates them better than the session alone."""
    from skinkit.forward import load
    from skinkit.gap.score import cosine, separating_protocol
    from skinkit.inverse import fit
    from skinkit.inverse.coverage import LabSessions
    from skinkit.inverse.design import default_candidates

    truth = copy.deepcopy(SPEC)
    truth["effects"] = [{"name": "force-offset", "z": 0.01}]
    obs = LabSessions(truth)(0)
    model = load(SPEC)
    r = fit(model, obs)
    vals = r.parameters.values()
    sens = collect(SPEC, obs, vals, r.parameters.free_names, ["force-offset", "force-drift"], load=load)
    tests = score_all(sens)
    by = {t.effect: t for t in tests}
    before = cosine(by["force-offset"].signature, by["force-drift"].signature)
    best = separating_protocol(SPEC, obs, vals, r.parameters.free_names, sens, tests,
                               ("force-offset", "force-drift"), load=load)
    cos = [row["cosine"] for row in best["ranking"]]
    assert cos == sorted(cos) and best["cosine"] == cos[0] < before
    assert {row["protocol"] for row in best["ranking"]} <= set(default_candidates(model))
    assert len(cos) >= len(default_candidates(model)) - 1      # the session's own protocol is skipped
