"""The model's discretisation error carried as noise: the approximation-error approach.

A finite-element model solved on a mesh of size h predicts y_h(θ); the skin (or a truth solved on
a finer, different mesh) behaves like the exact solution y(θ). Their difference ε(θ) = y − y_h is
not noise, but the data cannot tell it from a physical effect: a fit that ignores it biases its
parameters and a diagnosis names it as an effect. Following Kaipio & Somersalo (J Comput Appl
Math 198, 2007) and Arridge et al. (Inverse Problems 22, 2006), ε is modelled as a Gaussian
independent of the noise, with a mean and a covariance estimated where the model is used:

    y = y_h(θ) + ε + n,    ε ~ N(m, Γ),    n ~ N(0, Σ)
    χ²(θ) = (y − y_h(θ) − m)ᵀ (Σ + Γ)⁻¹ (y − y_h(θ) − m)

**Estimate.** At the calibrated θ̂ the model is solved on its own mesh and on one refined
``factor`` times, d = y_{h/f}(θ̂) − y_h(θ̂). With a convergence order p the exact minus coarse
prediction is R(p) d (Richardson, R = fᵖ/(fᵖ − 1)). The order is not known (quadratic elements
converge at 2–3 in smooth regions and near 1.3 at a bonded punch's edge), so R is taken uniform
between R(:data:`ORDER_HIGH`) and R(:data:`ORDER_LOW`), independently for each component of each
channel of each protocol, and for tracked points in each of :data:`BANDS` radial bands (a force
at a bonded edge converges near order 1, a displacement field far from the indenter near 2):
m = R̄ d, and Γ = B Bᵀ with B's columns, per group, the order's σ_R · d on that group alone
(σ_R = (R_hi − R_lo)/√12) and the error's change over the parameters' plausible spread (each
positive parameter scaled by exp(s ξ), ξ standard normal, s = :data:`SPREAD`): to first order
R̄ (∂d/∂θ_j) s θ_j per free parameter, from the derivatives both solves return with their
values (the fit's sensitivities on each mesh), with ``draws=None``. By default (and where a
derivative is not analytic) the spread is sampled instead: d_k at ``draws`` seeded points θ_k
besides θ̂, m = R̄ · mean_k d_k and columns (R̄ d_k − m)/√K. The tangent form is not the default:
it carries the spread in full (the sampled form, from one draw, a quarter of it in expectation),
and on the README tour's session (one seed) it left the fitted shear modulus more than three
standard errors from the truth, where the sampled form stays within them. Γ has rank ≤ the
number of groups (3 per tip channel, 9 per point channel and protocol) + the free parameters
(or K).

**Whiten.** In the objective's noise-whitened coordinates (z = W(y_h + m − y), V = W B), (I +
V Vᵀ)^(−1/2) = I − Q diag(1 − 1/√(1 + s²)) Qᵀ with V = Q S Rᵀ (thin SVD): a rank-r
correction of z and of its Jacobian (r = rank of Γ), applied by
:class:`skinkit.inverse.objective.Objective` to every residual of observations that carry the
estimate (:meth:`Observations.with_model_error`). A direction whose variance is thousands of
noise variances is in effect projected out; the projection of one refined-mesh direction the
diagnosis made before is its special case.

**Cost.** One solve on the model's mesh and one on the refined one (``factor³`` times the
unknowns), both with the free parameters' sensitivities (per step a few conjugate-gradient
iterations preconditioned by the Newton loop's factorisation, no tangent factorised again). Each
draw's difference is the calibration's moved to it by those derivatives, d_k ≈ d + (∂d/∂θ)(θ_k −
θ̂), not solved: within the draws' 10 % spread the error's change is close to linear (on the
virtual forearm the solved draw differs from the moved one by 2–3 % of its change, at the truth
and at a calibration far from it; ``skinkit bench mesh-error`` measures it), and a solved draw
costs a solve on each mesh, a third of the estimate on the forearm (the refined mesh's solve
there is 14 times the model's). Where a derivative is not analytic the draws are solved
(``solve_draws`` forces it), ``draws + 1`` solves on each mesh, the refined ones handed to the
workers as one batch. The tangent form uses the derivatives for its spread instead of draws.
The estimate is made once per calibration and reused by every refit and candidate of a
diagnosis (the mean and basis are stored with the observations).

**Passes.** :func:`refit` estimates, refits, and estimates again where the refit went. When no
free parameter went further than :data:`MOVE_SPREADS` of its draw spread, the next estimate is
the last one moved to first order — every difference shifted by ∂(fine − coarse)/∂θ · Δθ from
the calibration's sensitivities (:meth:`ModelError.moved`) — with no solve: near the spread the
covariance already samples the error's change, and the move's second-order error stays inside
the estimate's own sampling spread (one draw; measured at :data:`MOVE_SPREADS`). The first
pass's fit starts from the calibration, or from the calibration's own start when the χ² carrying
the error is lower there (:func:`_first_start`): a calibration the mesh's error dragged to a bound
is slow to leave.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from skinkit.inverse.discretisation import (
    DEFAULT_FACTOR,
    DiscretisationError,
    explained_share,
    has_mesh,
    richardson_factor,
)
from skinkit.inverse.lowrank import apply, whitening
from skinkit.schemas import Observations, ParameterSet, Prediction
from skinkit.schemas.observations import CHANNELS

#: convergence orders bracketing the model's (the bonded punch's singular edge, smooth regions)
ORDER_LOW, ORDER_HIGH = 1.0, 2.0
#: log-spread of each positive parameter in the draws around the calibration (10 %)
SPREAD = 0.1
#: draws besides the calibration point (the spread sampled; None: from derivatives)
DEFAULT_DRAWS = 1
#: radial bands of tracked points with an error amplitude of their own
BANDS = 3
#: estimate-and-refit passes (:func:`refit`)
DEFAULT_PASSES = 2
#: a later pass moves the previous estimate instead of solving again when every free parameter
#: moved by at most this many of the draws' spread (:meth:`ModelError.reaches`). On the virtual
#: forearm's final model (pre-stress angle 2.2 spreads, the rest within one) the moved estimate's
#: fit lies within 2.9 standard errors of the fit on an estimate solved again with the same draw,
#: while solving again with another draw moves it by up to 4.4: the move's error is inside the
#: estimate's own sampling spread.
MOVE_SPREADS = 3.0
#: whose discretisation error an estimate describes: the model's mesh, or its refined copy
MEMBERS = ("model", "refined")
#: the model's mesh cannot render a free parameter whose signature it misrepresents by more than
#: this share (:func:`resolution`; the gap verdict warns, ``refit(member="auto")`` moves the
#: fit to the refined mesh). Measured: on the two-pad
#: scar model (7,395 unknowns) at a scar 5.4 × 6.3 mm across the scar's centre along the pull,
#: its long semi-axis and its angle 0.97-1.15, the moduli 0.04-0.06; on the virtual forearm
#: (1,815 unknowns) c, k1, κ, g1 and the pre-stress 0.23-0.42. On that scar's session the fit on
#: the model's mesh, carrying its error, leaves the scar undetermined (the ratio on its bound);
#: on the refined mesh with nothing carried ratio, centre and semi-axes fall within one standard
#: error (the moduli 3-7 off), and carrying its own error from an estimate at the model mesh's
#: fit (one pass) the ratio and moduli within two.
RESOLUTION_LIMIT = 0.5


@dataclass
class ModelError:
    """The model's discretisation error as a Gaussian: per ``(protocol, channel)`` its ``mean``
    (the channel's shape [unit], exact minus model) and ``basis`` ``(r, *shape)`` [unit] with
    covariance Σ_j basis_j basis_jᵀ; ``summary``: JSON-ready figures (:func:`estimate`)."""

    mean: dict[tuple[str, str], np.ndarray]
    basis: dict[tuple[str, str], np.ndarray]
    rank: int
    summary: dict[str, Any] = field(default_factory=dict)
    #: what the estimate was made from, to move it to nearby parameters (:meth:`moved`); None
    #: when the refined-minus-model difference's derivatives were not computed
    source: _Source | None = None

    def cut(self, keep: Mapping[tuple[str, str], tuple[slice, ...]]) -> ModelError:
        """The same error on sliced channels (``keep``: key -> the slice of its values); not
        movable (:meth:`moved` works on whole channels): a later pass solves again."""
        mean = {k: v[keep[k]] for k, v in self.mean.items() if k in keep}
        basis = {k: v[(slice(None), *keep[k])] for k, v in self.basis.items() if k in keep}
        return ModelError(mean, basis, self.rank, self.summary)

    def reaches(self, params: ParameterSet) -> bool:
        """Whether :meth:`moved` may stand for a new estimate at ``params``: the difference's
        derivatives are known and every free parameter lies within :data:`MOVE_SPREADS` of the
        draws' spread of where the estimate was solved (not of where a move took it: moves do not
        chain beyond the reach)."""
        src = self.source
        if src is None:
            return False
        values = params.values()
        origin = src.origin or src.at
        return all(abs(float(values[n]) - origin[n]) <= MOVE_SPREADS * src.steps[n] for n in src.free)

    def moved(self, params: ParameterSet, observations: Observations) -> ModelError:
        """The estimate moved to ``params`` to first order: every difference (the calibration's
        and each draw's) shifted by ∂(fine − coarse)/∂θ · Δθ, with the derivatives at the
        estimate's own point; the order's amplitude columns follow the shifted mean, the
        spread's columns (differences of differences) do not change. No solve. ``observations``:
        those the estimate was made on (for the summary's figures)."""
        src = self.source
        if src is None:
            raise DiscretisationError("this model-error estimate has no derivatives to move it with")
        values = params.values()
        dtheta = np.array([float(values[n]) - src.at[n] for n in src.free])
        shift = {key: np.tensordot(dtheta, d, axes=1) for key, d in src.derivatives.items()}
        diffs = [{key: d[key] + shift[key] for key in d} for d in src.diffs]
        mean, basis, rank = _assemble(diffs, src.tangents, src.groups, src.factor, src.member)
        summary = dict(self.summary, **_figures(mean, observations.fitted()),
                       moved_from={n: src.at[n] for n in src.free})
        at = {n: float(values[n]) for n in src.free}
        moved = replace(src, diffs=diffs, at=at, origin=src.origin or src.at)
        return ModelError(mean, basis, rank, summary, moved)

    def as_member(self, member: str, observations: Observations) -> ModelError:
        """The same estimate for the other mesh of its pair: ``"refined"``, the error of the mesh
        refined ``factor`` times (exact − fine = (R − 1)(fine − coarse), the order's spread the
        same), or ``"model"``. No solve. ``observations``: those the estimate was made on."""
        src = self.source
        if member not in MEMBERS:
            raise DiscretisationError(f"member must be one of {', '.join(MEMBERS)}, got {member!r}")
        if src is None:
            raise DiscretisationError("this model-error estimate keeps no differences to re-scale")
        mean, basis, rank = _assemble(src.diffs, src.tangents, src.groups, src.factor, member)
        summary = dict(self.summary, **_figures(mean, observations.fitted()), member=member)
        return ModelError(mean, basis, rank, summary, replace(src, member=member))


@dataclass
class _Source:
    """A :class:`ModelError`'s making: the refined-minus-model differences (the calibration's
    first, then the draws'), the spread's tangent columns (or None), the amplitude groups, the
    refinement factor, and per channel ``derivatives`` ``(len(free), *shape)``: ∂(fine −
    coarse)/∂θ_j at ``origin`` (free parameter -> value [SI], where both meshes were solved);
    ``at``: where the differences stand now (``origin`` until moved); ``steps``: each one's draw
    spread [SI]; ``member``: whose error the estimate is (``"model"`` or ``"refined"``)."""

    diffs: list[dict[tuple[str, str], np.ndarray]]
    tangents: dict[tuple[str, str], np.ndarray] | None
    groups: dict[tuple[str, str], list[np.ndarray]]
    factor: int
    free: list[str]
    at: dict[str, float]
    steps: dict[str, float]
    derivatives: dict[tuple[str, str], np.ndarray]
    origin: dict[str, float] | None = None
    member: str = "model"


def not_estimated(exc: BaseException) -> str:
    """What to say when :func:`refit` failed with ``exc``: the estimate could not be made, and
    why (the solver's where and why, from ``exc``)."""
    return (f"the model's discretisation error could not be estimated (its mesh refined 2x, or the fit "
            f"carrying it, failed: {exc})")


def _scaled(params: ParameterSet, name: str) -> bool:
    """Whether ``name`` spreads on a log scale around the calibration: a positive value with a
    non-negative lower bound (a modulus); others spread by a share of their magnitude."""
    return float(params.values()[name]) > 0 and params.param(name).lower >= 0


def _draws(params: ParameterSet, free: Sequence[str], n: int, seed: int) -> list[dict[str, float]]:
    """The calibration's values and ``n`` draws around it (log-scaled parameters, :func:`_scaled`,
    multiplied by exp(SPREAD ξ), others shifted by SPREAD ξ |θ|; clipped to the bounds)."""
    rng = np.random.default_rng(seed)
    base = dict(params.values())
    out = [dict(base)]
    for _ in range(n):
        v = dict(base)
        for name in free:
            p = params.param(name)
            xi = float(rng.standard_normal())
            x = base[name] * math.exp(SPREAD * xi) if _scaled(params, name) else \
                base[name] + SPREAD * xi * max(abs(base[name]), 1e-12)
            v[name] = float(min(max(x, p.lower), p.upper))
        out.append(v)
    return out


def _kept(cp: Any, fp: Any, channel: Any) -> np.ndarray:
    """Entries observed, predicted on both meshes and not a measured reference frame."""
    m = cp.mask(channel)
    return m & np.asarray(fp.predicted, bool) if fp.predicted is not None else m


def _differences(coarse: Prediction, fine: Prediction, observations: Observations
                 ) -> dict[tuple[str, str], np.ndarray]:
    """fine − coarse per observed, predicted entry (0 where either is missing)."""
    out = {}
    for proto, cname, cp in coarse.items():
        if proto not in observations.names or cname not in observations[proto].channels:
            continue
        fp = fine.protocols.get(proto, {}).get(cname)
        if fp is None or np.shape(fp.values) != np.shape(cp.values):
            continue
        m = _kept(cp, fp, observations[proto].channels[cname])
        d = np.where(m, np.asarray(fp.values, float) - np.asarray(cp.values, float), 0.0)
        out[(proto, cname)] = np.nan_to_num(d)
    return out


def _groups(ch: Any) -> list[np.ndarray]:
    """Boolean masks (the channel's shape) over which the error's amplitude is one unknown: each
    component of a tip channel; each component of a point channel in each of :data:`BANDS`
    bands of the points' distance from their centroid (equal counts)."""
    shape = ch.values.shape
    out = []
    if not ch.is_points:
        for j in range(shape[-1]):
            m = np.zeros(shape, bool)
            m[..., j] = True
            out.append(m)
        return out
    ref = ch.reference if ch.reference is not None else np.nan_to_num(ch.values[:, 0])
    xy = np.asarray(ref, float)[:, :2]
    r = np.hypot(*(xy - xy.mean(axis=0)).T)
    edges = np.quantile(r, np.linspace(0, 1, BANDS + 1)[1:-1]) if r.size else []
    band = np.searchsorted(edges, r, side="right")
    for k in range(BANDS):
        for j in range(shape[-1]):
            m = np.zeros(shape, bool)
            m[band == k, :, j] = True
            if m.any():
                out.append(m)
    return out


def _channel_figures(mean: Mapping[tuple[str, str], np.ndarray], observations: Observations
                     ) -> dict[str, dict[str, Any]]:
    """Per channel name: RMS and largest |mean| [unit], the noise level, and their ratio."""
    acc: dict[str, list[np.ndarray]] = {}
    noise: dict[str, float] = {}
    for (proto, cname), m in mean.items():
        ch = observations[proto].channels[cname]
        sel = ch.fit_mask()
        acc.setdefault(cname, []).append(m[sel])
        noise[cname] = float(np.sqrt(np.mean(np.square(ch.sigma()[sel])))) if sel.any() else \
            float(np.sqrt(np.mean(np.square(ch.noise))))
    out = {}
    for cname, parts in acc.items():
        d = np.concatenate(parts)
        rms = float(np.sqrt(np.mean(d ** 2))) if d.size else 0.0
        out[cname] = {"rms": rms, "max": float(np.max(np.abs(d))) if d.size else 0.0,
                      "noise": noise[cname], "rms_over_noise": rms / noise[cname] if noise[cname] else None,
                      "unit": CHANNELS[cname][0]}
    return out


#: per ``(protocol, channel)`` an array of the channel's shape (or with a leading axis)
Diffs = dict[tuple[str, str], np.ndarray]


def _step(params: ParameterSet, name: str) -> float:
    """The draws' standard deviation of ``name`` to first order [its SI unit] (:func:`_draws`)."""
    v = float(params.values()[name])
    return SPREAD * abs(v) if _scaled(params, name) else SPREAD * max(abs(v), 1e-12)


def _derivatives(coarse: Prediction, fine: Prediction, observations: Observations, free: Sequence[str],
                 keys: Sequence[tuple[str, str]]) -> dict[tuple[str, str], np.ndarray] | None:
    """Per channel of ``keys`` (those :func:`_differences` kept) ``(len(free), *shape)``:
    ∂(fine − coarse)/∂θ_j [unit per SI unit]; None unless every one is analytic on both meshes
    (another route would cost the refined mesh two solves per parameter)."""
    if not all(str(p.methods.get(n, "")).startswith("analytic") for p in (coarse, fine) for n in free):
        return None
    out: dict[tuple[str, str], np.ndarray] = {}
    for key in keys:
        cp, fp = coarse.protocols[key[0]][key[1]], fine.protocols[key[0]][key[1]]
        m = _kept(cp, fp, observations[key[0]].channels[key[1]])
        cols = [np.nan_to_num(np.where(m, np.asarray(fp.d[n], float) - np.asarray(cp.d[n], float), 0.0))
                if n in fp.d and n in cp.d else np.zeros(np.shape(cp.values)) for n in free]
        out[key] = np.stack(cols) if cols else np.zeros((0, *np.shape(cp.values)))
    return out


def noise_weights(ch: Any) -> np.ndarray:
    """1/σ of channel ``ch`` per entry (its values' shape or broadcastable to it) [1/unit]; 0
    where the noise level is zero or unknown."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.nan_to_num(1.0 / np.asarray(ch.sigma(), float), nan=0.0, posinf=0.0)


def resolution(coarse: Prediction, derivatives: Mapping[tuple[str, str], np.ndarray],
               observations: Observations, free: Sequence[str]) -> dict[str, float]:
    """Per free parameter, how far the model's mesh misrepresents what it does: ‖∂(fine −
    coarse)/∂θ_j‖ / ‖∂coarse/∂θ_j‖, both noise-whitened, over the fitted entries (``derivatives``
    from :func:`_derivatives`, ``coarse`` the model mesh's prediction with its sensitivities).
    Near 0 the model's mesh renders the parameter's signature as the refined one does; near 1
    the refined mesh's signature differs from the model's by as much as the signature itself,
    and the parameter's value on the model's mesh is not the physical one (a region smaller
    than an element or two: its size and position). ``inf`` for a parameter the refined mesh
    sees and the model's does not (null in JSON); 0 for one neither sees."""
    num, den = np.zeros(len(free)), np.zeros(len(free))
    for (proto, cname), dd in derivatives.items():
        cp = coarse.protocols[proto][cname]
        ch = observations[proto].channels[cname]
        w = np.where(cp.mask(ch), noise_weights(ch), 0.0)
        for j, name in enumerate(free):
            num[j] += float(np.sum((w * dd[j]) ** 2))
            if name in cp.d:
                den[j] += float(np.sum((w * np.nan_to_num(np.asarray(cp.d[name], float))) ** 2))
    return {n: math.sqrt(num[j] / den[j]) if den[j] > 0 else (math.inf if num[j] > 0 else 0.0)
            for j, n in enumerate(free)}


def _predict_all(model: Any, calls: list[tuple[ParameterSet, Observations, Any]]) -> list[Prediction]:
    """Each ``(params, observations, sensitivities)`` predicted, in one batch of solves where the
    model can (:meth:`skinkit.forward.fe.FEForwardModel.predict_many`)."""
    many = getattr(model, "predict_many", None)
    return many(calls) if many is not None else [model.predict(*c) for c in calls]


def _solve_points(model: Any, fine_model: Any, fitted: Observations, params: ParameterSet,
                  free: Sequence[str], draws: int | None, seed: int, factor: int, say: Callable[[str], None],
                  solve_draws: bool = False
                  ) -> tuple[list[Diffs], Diffs | None, Diffs | None, dict[str, Any]]:
    """``(differences at each point, tangent columns or None, the calibration's difference's
    derivatives or None, unknowns and solves)`` (:func:`estimate`). The derivatives come with the
    calibration's two solves (a few preconditioned iterations per step and parameter). Each
    draw's difference is the calibration's moved to it to first order by those derivatives
    (:func:`_linear_draws`) unless ``solve_draws`` or a derivative is not analytic; then the
    draws are solved on both meshes, the refined mesh's solves handed to the workers as one
    batch."""
    sens = list(free) if free else False
    coarse = model.predict(params, fitted, sensitivities=sens)
    # derivatives another way than analytic would cost the refined mesh 2 solves per parameter
    analytic = all(str(v).startswith("analytic") for v in coarse.methods.values())
    tangent = draws is None and analytic
    # nothing free: the error does not vary, the calibration alone says it
    points = [] if tangent or not free else _draws(params, free, DEFAULT_DRAWS if draws is None else draws,
                                                   seed)[1:]
    linear = bool(points) and bool(sens) and analytic and not solve_draws
    say(f"model error: the calibration on the model's mesh and one refined {factor}x"
        + (", with the parameters' derivatives" if sens and analytic else "")
        + (f", and {len(points)} draw(s) around it" if points else "")
        + (" moved to by those derivatives" if linear else ""))
    fine_params = fine_model.parameters().with_values(params.values())
    draw_calls = [(fine_params.with_values(v), fitted, False) for v in points]
    fine = _predict_all(fine_model, [(fine_params, fitted, sens if analytic else False)]
                        + ([] if linear else draw_calls))
    diffs = [_differences(coarse, fine[0], fitted)]
    derivs = _derivatives(coarse, fine[0], fitted, free, list(diffs[0])) if sens and analytic else None
    if linear and derivs is None:     # the refined mesh's derivatives were not analytic after all
        linear = False
        fine += _predict_all(fine_model, draw_calls)
    if linear:
        diffs += _linear_draws(diffs[0], derivs, params, free, points)
    else:
        coarse_draws = _predict_all(model, [(params.with_values(v), fitted, False) for v in points])
        diffs += [_differences(c, f, fitted) for c, f in zip(coarse_draws, fine[1:], strict=True)]
    n_solved = 1 + (0 if linear else len(points))
    info: dict[str, Any] = {"unknowns": int(coarse.info.get("n_dof", 0)),
                            "unknowns_refined": int(fine[0].info.get("n_dof", 0)),
                            "draws_from": "derivatives" if linear else "solves",
                            "solves": {"model_mesh": n_solved, "refined_mesh": n_solved}}
    if derivs is not None:
        info["resolution"] = resolution(coarse, derivs, fitted, free)
    if not tangent or derivs is None:
        return diffs, None, derivs, info
    steps = np.array([_step(params, n) for n in free])
    tangents = {k: d * steps.reshape((-1,) + (1,) * (d.ndim - 1)) for k, d in derivs.items()}
    return diffs, tangents, derivs, info


def _linear_draws(d0: Diffs, derivs: Diffs, params: ParameterSet, free: Sequence[str],
                  points: Sequence[Mapping[str, float]]) -> list[Diffs]:
    """The refined-minus-model difference at each draw ``points`` to first order: ``d0`` (at
    ``params``) + Σ_j ∂d/∂θ_j (θ_kj − θ̂_j) (the module's cost says why and how far)."""
    base = params.values()
    out = []
    for v in points:
        dtheta = np.array([float(v[n]) - float(base[n]) for n in free])
        out.append({key: d + np.tensordot(dtheta, derivs[key], axes=1) for key, d in d0.items()})
    return out


def _assemble(diffs: Sequence[Diffs], tangents: Diffs | None,
              groups: Mapping[tuple[str, str], list[np.ndarray]], factor: int,
              member: str = "model") -> tuple[Diffs, Diffs, int]:
    """``(mean, basis, rank)`` from the differences at the calibration and the draws (and the
    spread's tangent columns, or None): see the module docstring. ``member``: whose error,
    the model mesh's (exact − coarse = R d) or the refined one's (exact − fine = (R − 1) d)."""
    r_lo, r_hi = richardson_factor(factor, ORDER_HIGH), richardson_factor(factor, ORDER_LOW)
    if member == "refined":
        r_lo, r_hi = r_lo - 1.0, r_hi - 1.0
    r_mid, r_sd = 0.5 * (r_lo + r_hi), (r_hi - r_lo) / math.sqrt(12.0)
    K = len(diffs)
    keys = list(diffs[0])
    n_amp = sum(len(groups[key]) for key in keys)
    n_var = len(next(iter(tangents.values()))) if tangents else (K if K > 1 else 0)
    rank = n_amp + n_var
    mean, basis = {}, {}
    col = 0
    for key in keys:
        ds = np.stack([d[key] for d in diffs])
        dbar = ds.mean(axis=0)
        mean[key] = r_mid * dbar
        b = np.zeros((rank, *dbar.shape))
        # the order differs from place to place (a force at a bonded edge near 1, a displacement
        # field far from the indenter near 2): one amplitude per component and radial band
        for sel in groups[key]:
            b[col][sel] = r_sd * dbar[sel]
            col += 1
        if tangents:
            # the error's change over the parameters' spread, to first order: the covariance
            # the draws sample, without their sampling noise
            b[n_amp:] = r_mid * tangents[key]
        elif K > 1:
            b[n_amp:] = np.stack([r_mid * (d - dbar) / math.sqrt(K) for d in ds])
        basis[key] = b
    return mean, basis, rank


def estimate(model: Any, observations: Observations, params: ParameterSet, free: Sequence[str], *,
             draws: int | None = DEFAULT_DRAWS, factor: int = DEFAULT_FACTOR, seed: int = 0,
             progress: Callable[[str], None] | None = None, solve_draws: bool = False) -> ModelError:
    """The model's discretisation error on the fitted protocols of ``observations`` (see the
    module): ``model`` a finite-element forward model, ``params`` the calibration, ``free`` the
    parameters around it, ``factor`` the refinement. ``draws``: that many random draws around
    the calibration (default :data:`DEFAULT_DRAWS`), or None for the error's variation with the
    parameters from its derivatives at the calibration (one solve on each mesh, with
    sensitivities; random draws when a derivative is not analytic). Each draw's difference is
    the calibration's moved to it by its derivatives (no solve) when they are analytic, unless
    ``solve_draws``.

    ``summary``: ``factor``, ``orders``, ``draws``, ``draws_from`` ("derivatives" or "solves"),
    ``variation`` ("tangent" or "draws"), ``unknowns``, ``unknowns_refined``, ``solves`` (on
    each mesh), ``channels`` (name -> ``rms``,
    ``max`` of the mean error [unit], ``noise``, ``rms_over_noise``), ``wall_s``.
    """
    if not has_mesh(model):
        raise DiscretisationError(f"model {getattr(model, 'name', '?')!r} has no mesh: the approximation "
                                  "error needs a finite-element model")
    if draws is not None and (isinstance(draws, bool) or not isinstance(draws, int) or draws < 0):
        raise DiscretisationError(f"draws must be a whole number >= 0 or None, got {draws!r}")
    if isinstance(factor, bool) or not isinstance(factor, int) or factor < 2:
        raise DiscretisationError(f"refinement factor must be a whole number >= 2, got {factor!r}")
    t0 = time.perf_counter()
    say = progress or (lambda _m: None)
    fitted = observations.fitted()
    fine_model = model.refined(factor)
    try:
        diffs, tangents, derivs, info = _solve_points(model, fine_model, fitted, params, free, draws, seed,
                                                      factor, say, solve_draws)
    finally:
        fine_model.close()
    K = len(diffs)
    groups = {key: _groups(fitted[key[0]].channels[key[1]]) for key in diffs[0]}
    mean, basis, rank = _assemble(diffs, tangents, groups, factor)
    summary = {"method": "approximation error (mean and covariance of the refined-minus-model prediction)",
               "member": "model", **_figures(mean, fitted),
               "factor": factor, "orders": [ORDER_LOW, ORDER_HIGH], "draws": K - 1, "spread": SPREAD,
               "variation": "tangent" if tangents is not None else "draws",
               **info, "wall_s": time.perf_counter() - t0}
    source = None if derivs is None else _Source(
        diffs, tangents, groups, factor, list(free), {n: float(params.values()[n]) for n in free},
        {n: _step(params, n) for n in free}, derivs)
    return ModelError(mean, basis, rank, summary, source)


def _figures(mean: Diffs, fitted: Observations) -> dict[str, Any]:
    """The summary's figures of the mean error: per channel (:func:`_channel_figures`), the
    largest over the noise, and the refinement that would bring it to the noise."""
    figures = _channel_figures(mean, fitted)
    worst = max((row["rms_over_noise"] or 0.0 for row in figures.values()), default=0.0)
    # error ∝ hᵖ: the refinement that brings the largest channel's error to the noise
    return {"largest_over_noise": worst,
            "refine_to_noise": {"order_1": max(worst, 1.0), "order_2": max(math.sqrt(worst), 1.0)},
            "channels": figures}


def refit(model: Any, observations: Observations, result: Any, free: Sequence[str], fit: Callable[..., Any],
          *, draws: int | None = DEFAULT_DRAWS, factor: int = DEFAULT_FACTOR, passes: int = DEFAULT_PASSES,
          seed: int = 0, progress: Callable[[str], None] | None = None, move: bool = True,
          member: str = "model", **options: Any) -> tuple[Any, Observations]:
    """Estimate the model's error at ``result`` (a calibration of ``free``) and fit again, from
    there, with the error carried as noise; ``passes`` times, each estimate made at the previous
    pass's parameters (the error of a mesh too stiff grows with the modulus the first
    calibration underestimated: two passes move the parameters, a third no more than their
    standard error). Returns ``(the last result, the observations carrying the last estimate)``.
    ``fit(model, observations, free, start=..., **options)`` is the fit to run
    (:func:`skinkit.inverse.fit`). The result's ``extra["model_error"]`` holds the last
    estimate's summary plus ``passes``, ``chi2_without`` (the first calibration's χ²),
    ``chi2_with``, ``dof`` and ``accounts_for`` (the share of the excess it removed:
    :func:`skinkit.inverse.discretisation.explained_share`), ``moved`` (the passes whose
    estimate was the previous one moved, not solved again) and ``member`` (the mesh fitted).

    ``move``: a pass whose parameters stayed within the previous estimate's reach
    (:meth:`ModelError.reaches`) moves that estimate to first order instead of solving both
    meshes again (:meth:`ModelError.moved`). ``member``: the mesh the refits run on — the
    model's (``"model"``), its refined copy carrying its own, smaller error from the same pair
    (``"refined"``: each solve ``factor³`` times the elements), or ``"auto"``: the refined copy
    when the first estimate finds a free parameter the model's mesh misrepresents by more than
    :data:`RESOLUTION_LIMIT` (:func:`resolution`), else the model's."""
    if isinstance(passes, bool) or not isinstance(passes, int) or passes < 1:
        raise DiscretisationError(f"passes must be a whole number >= 1, got {passes!r}")
    if member not in (*MEMBERS, "auto"):
        raise DiscretisationError(f"member must be one of {', '.join((*MEMBERS, 'auto'))}, got {member!r}")
    say = progress or (lambda _m: None)
    first, new, carried = result, result, observations
    err, moved, chosen, fitted_on = None, 0, member, None
    try:
        for k in range(passes):
            if move and err is not None and err.reaches(new.parameters):
                say("model error: the last estimate moved to where the fit went (within its spread)")
                err, moved = err.moved(new.parameters, observations), moved + 1
            else:
                err = estimate(model, observations, new.parameters, free, draws=draws, factor=factor,
                               seed=seed + k, progress=progress)
                if chosen == "auto":
                    chosen = _choose_member(err, say)
                if chosen == "refined":
                    err = err.as_member("refined", observations)
            if chosen == "refined" and fitted_on is None:
                fitted_on = model.refined(factor)
            carried = observations.with_model_error(err)
            values = new.parameters.values() if k else _first_start(fitted_on or model, carried, result, free,
                                                                    options.get("weighting", "noise"), say)
            say("model error: calibrating again with the mesh's error carried as noise "
                f"(pass {k + 1}/{passes}{', on the refined mesh' if fitted_on is not None else ''})")
            new = fit(fitted_on or model, carried, list(free), start={n: float(values[n]) for n in free},
                      **options)
    finally:
        if fitted_on is not None:
            fitted_on.close()
    c0, c1 = sum(first.residual_by_protocol.values()), sum(new.residual_by_protocol.values())
    dof = c0 / float(first.chi2_per_dof) if first.chi2_per_dof else float("nan")
    err.summary.update(passes=passes, moved=moved, chi2_without=c0, chi2_with=c1, dof=dof,
                       accounts_for=explained_share(c0, c1, dof),
                       member="refined" if fitted_on is not None else "model")
    new.extra["model_error"] = err.summary
    return new, carried


def unresolved(resolution: Mapping[str, float | None]) -> list[str]:
    """The free parameters whose signature the model's mesh misrepresents by more than
    :data:`RESOLUTION_LIMIT` (``resolution``: :func:`resolution`'s, None for one only the refined
    mesh sees, as JSON writes ``inf``), the worst first."""
    res = {n: math.inf if v is None else float(v) for n, v in resolution.items()}
    return sorted((n for n, v in res.items() if v > RESOLUTION_LIMIT), key=lambda n: -res[n])


def _first_start(model: Any, carried: Observations, result: Any, free: Sequence[str], weighting: str,
                 say: Callable[[str], None]) -> dict[str, float]:
    """Where the first pass's fit starts: ``result``'s parameters (the calibration without the
    mesh's error), or that fit's own start when the χ² carrying the error is lower there. A
    calibration on the model's mesh alone absorbs the mesh's error into its parameters — on the
    quick benchmark's model it drives the fibre modulus k1 from 20 kPa to 0.05 Pa and κ to its
    bound — and from such a point a trust-region fit climbs back by a factor of about two per
    evaluation (28 evaluations there, against 11 for the second pass); the start is the user's
    prior. Two plain predictions."""
    from skinkit.errors import SkinkitError
    from skinkit.inverse.objective import Objective

    at = {n: float(result.parameters.values()[n]) for n in free}
    hist, names = result.extra.get("history") or [], list(result.extra.get("free") or [])
    if not hist or sorted(names) != sorted(free):
        return at
    start = {n: float(x) for n, x in zip(names, hist[0]["x"], strict=True)}
    if all(math.isclose(start[n], at[n], rel_tol=1e-9, abs_tol=1e-300) for n in free):
        return at
    obj = Objective(model, carried.fitted(), [], weighting)
    base = model.parameters().with_values(dict(result.parameters.values()))
    chi2 = {}
    for label, values in (("calibration", at), ("start", start)):
        try:
            res, _ = obj.evaluate(base.with_values(values), jacobian=False)
            chi2[label] = float(res.z @ res.z)
        except SkinkitError:
            chi2[label] = math.inf
    if not chi2["start"] < chi2["calibration"]:
        return at
    say(f"model error: the calibration's own start fits better with the mesh's error carried (χ² "
        f"{chi2['start']:.6g} against {chi2['calibration']:.6g}): the first pass starts there")
    return start


def _choose_member(err: ModelError, say: Callable[[str], None]) -> str:
    """``"refined"`` when ``err`` found a free parameter whose signature the model's mesh
    misrepresents by more than :data:`RESOLUTION_LIMIT` (and can be re-scaled), else ``"model"``."""
    res = err.summary.get("resolution") or {}
    over = unresolved(res)
    if not over or err.source is None:
        return "model"
    say(f"model error: the model's mesh misrepresents what {over[0]} does by {res[over[0]]:.2g} of its "
        f"signature (more than {RESOLUTION_LIMIT:g}): refitting on the mesh refined "
        f"{err.summary.get('factor', DEFAULT_FACTOR)}x, carrying that mesh's own error")
    return "refined"


def describe(summary: Mapping[str, Any]) -> list[str]:
    """Lines for a terminal: per channel the model's mesh error against the noise."""
    lines = [f"model error (mesh refined {summary['factor']}x, {summary.get('unknowns', 0):,} -> "
             f"{summary.get('unknowns_refined', 0):,} unknowns; carried as noise):"]
    for cname, row in summary.get("channels", {}).items():
        unit, k = row.get("unit") or "", 1.0
        if unit == "m":
            unit, k = "µm", 1e6
        ratio = row.get("rms_over_noise")
        times = "?" if ratio is None else f"{ratio:.3g}"
        lines.append(f"  {cname}: {k * row['rms']:.3g} {unit} RMS ({times} "
                     f"noise levels), {k * row['max']:.3g} {unit} largest")
    share = summary.get("accounts_for")
    if share is not None:
        lines.append(f"  accounts for {100 * share:.0f} % of the residual's excess over the noise")
    if summary.get("member") == "refined":
        lines.append(f"  fitted on the refined mesh ({summary.get('unknowns_refined', 0):,} unknowns), "
                     "carrying that mesh's own error")
    res = summary.get("resolution") or {}
    over = unresolved(res)
    if over and summary.get("member") != "refined":
        def shown(v: float | None) -> str:
            return format(v, ".2g") if v is not None and math.isfinite(v) else "refined mesh only"
        listed = ", ".join(f"{n} ({shown(res[n])})" for n in over)
        lines.append(f"  warning: this mesh misrepresents what {listed} "
                     f"{'does' if len(over) == 1 else 'do'} by more than {RESOLUTION_LIMIT:g} of the "
                     f"signature: the value is the mesh's more than the skin's (the mesh refined "
                     f"{summary.get('factor', DEFAULT_FACTOR)}x renders it)")
    return lines


__all__ = ["DEFAULT_DRAWS", "DEFAULT_PASSES", "MEMBERS", "MOVE_SPREADS", "ModelError", "ORDER_HIGH",
           "ORDER_LOW", "RESOLUTION_LIMIT", "SPREAD", "apply", "describe", "estimate", "noise_weights",
           "not_estimated", "refit", "resolution", "unresolved", "whitening"]
