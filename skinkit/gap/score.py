"""Which unmodelled effect: score (Lagrange-multiplier) tests at every candidate's null.

The calibrated model is loaded once more with every candidate effect added at its **null** value
(where the model with the effect *is* the model without it: same predictions, to rounding) and
predicted **once**, with sensitivities to the fitted parameters θ and to every effect parameter e.
In the fit's residual space (``Objective.residual``: z = whiten((y − Y)/σ), so Σz² is the fit's
χ²) that gives z, J_θ and J_e. With the fitted directions projected out,
J_e⊥ = (I − P_θ) J_e, the score statistic of effect e is

    LM_e = zᵀ J_e⊥ (J_e⊥ᵀ J_e⊥)⁺ J_e⊥ᵀ z,

the drop of Σz² that adding e would bring to first order, and under "e is absent" (z white,
unit variance, e's null inside the admissible range) LM_e ~ χ²_q with q the rank of J_e⊥
(Rao's score test; Engle 1984, "Wald, likelihood ratio and Lagrange multiplier tests"). No refit.

Three refinements the effects need:

* **One-sided nulls.** A null on a bound (a relaxation fraction g ≥ 0, a softening ≥ 0, a
  compliance ≥ 0, a slip ratio ≤ 1) admits moves one way only. The step δ that minimises
  ‖z + J_e⊥ δ‖² is then sought with those components of δ kept admissible (an exact small
  quadratic programme over the active sets); the statistic is the drop it achieves, zero when
  the residual points out of the admissible range (the effect cannot explain it: p = 1). One
  constrained parameter: the null distribution is the mixture ½χ²₀ + ½χ²₁ (Chernoff 1954;
  Self & Liang 1987), so p = ½ P(χ²₁ > LM); several: χ²_q, conservative.
* **Parameters without a signature at the null.** A relaxation time when the relaxation fraction
  is 0, an inclusion's position when its stiffness ratio is 1, an in-plane force offset the model
  does not predict: ∂z/∂e = 0 there. They are held at their null for the test (nuisance
  parameters identified only jointly with the others; Davies 1977) and freed in the refit once
  the effect is switched on. If *every* parameter of an effect is flat at the null (a quadratic
  onset), its sensitivity is a **secant** to a quarter of its typical magnitude (one more
  prediction per parameter, without sensitivities), and the candidate record says so.
* **Absorbed directions.** A column of J_e that lies in span(J_θ) (an offset the model already
  fits) is indistinguishable from the fitted parameters: it is dropped and named.

**More of the same.** An effect the model already has and that is repeatable (a second Prony
term: ``viscoelastic`` declares ``repeatable = True``) is a candidate again under an instance
label ``"<effect>-<k>"`` (:func:`repeat_candidates`); everywhere below a candidate is such a
label or an effect's name, and its parameters are ``"<label>.<local>"``.

**Separability.** Two effects leave "nearly the same signature" when the residual parts they
explain, s_e = J_e⊥ δ_e, have |cos| > :data:`COS_NOT_SEPARABLE`; they are then *not separable*
unless the data still tell them apart: the conditional score test of each given the other
(project out J_θ and the other effect's columns) is significant for at least one of them.
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from skinkit import registry
from skinkit.errors import SkinkitError
from skinkit.schemas import Observations, Prediction

#: a parameter whose linearised effect over its whole typical magnitude moves the residual
#: vector by less than this (in noise units, ‖J_j‖·|typical − null|) has no signature there
FLAT = 1e-3
#: a column keeping less than this fraction of its length once the fitted directions are
#: projected out lies in their span (numerical sensitivities are accurate to ~1e-6 relative)
ABSORBED = 1e-4
#: singular values (of unit columns) below this are rank deficiency
RANK_TOL = 1e-6
#: a signature keeping less than this share of its norm after the fitted parameters are projected
#: out (a variance inflation factor above 1000) cannot open the gate on its own (:func:`directed_p`)
KEPT_GATE = 1000 ** -0.5
#: a secant's step, as a fraction of the way from the null to the typical magnitude
SECANT_STEP = 0.25
#: a candidate's parameter keeping less than this share of its column's norm once the fitted
#: parameters are projected out (a variance inflation factor above 100) is reported with the
#: fitted parameter it resembles most (:func:`resemblance`)
RESEMBLE_KEPT = 0.1
#: |cos| between two effects' explained signatures above which they "look the same"
COS_NOT_SEPARABLE = 0.9


# ----------------------------------------------------------------------------------- columns
@dataclass
class EffectColumns:
    """One effect's sensitivities at its null in the fit's residual space.

    Attributes:
        effect: the effect's name.
        names: the tested parameters (model names ``"<effect>.<local>"``).
        J: ``(m, q)`` ∂z/∂e [1 per SI unit] (analytic, complex-step or secant).
        methods: name -> how its column was obtained.
        sides: ``(q,)`` +1 where only increases from the null are admissible, −1 only
            decreases, 0 both.
        null: name -> null value [SI]; typical: name -> the plugin's typical magnitude [SI].
        held: parameters held at their null for the test, name -> why.
        bounds: name -> (lower, upper) admissible [SI], for every parameter of the effect.
    """

    effect: str
    names: list[str]
    J: np.ndarray
    methods: dict[str, str]
    sides: np.ndarray
    null: dict[str, float]
    typical: dict[str, float]
    held: dict[str, str] = field(default_factory=dict)
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)


@dataclass
class Colour:
    """Where the residual space holds series prewhitened by an AR noise model fitted to a rest
    segment: per block of ``Objective.residual`` (``sl``), the channel's ``mask`` ``(T, k)``
    (the block's entries are ``full[mask]``) and per component ``(φ (p,), bias (p,), cov (p, p))``
    (:func:`skinkit.gap.where.ar_uncertainty`), and ``n_rest`` the rest samples the noise level
    came from. A direction of the residual space then carries noise of level 1 only up to the
    coefficients' error: its variance is 1 + h·δ, h the gradient of log|A|² averaged over the
    direction's spectrum (:func:`colour_variance`)."""

    blocks: list[tuple[slice, np.ndarray, tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...], int]]


@dataclass
class Sensitivities:
    """What one round of the score step measured: z and J_θ of the calibrated model, the
    columns of every candidate, the candidates that could not be added, and the cost."""

    z: np.ndarray
    J_theta: np.ndarray
    theta: list[str]
    columns: dict[str, EffectColumns]
    skipped: dict[str, str]
    prediction: Prediction
    n_forward: int = 0
    notes: list[str] = field(default_factory=list)
    colour: Colour | None = None


def _repeatable(effect: str) -> bool:
    """Whether the installed effect ``effect`` declares ``repeatable = True`` (False if unknown)."""
    try:
        return bool(getattr(registry.create("skinkit.effects", effect), "repeatable", False))
    except SkinkitError:
        return False


def effect_of(label: str) -> str:
    """The effect a candidate stands for: ``label`` itself when it is an installed effect's name,
    ``<effect>`` for an instance label ``"<effect>-<k>"`` (k ≥ 2) of a repeatable installed
    effect, else ``label`` unchanged (loading it then names what is wrong)."""
    installed = registry.names("skinkit.effects")
    if label in installed:
        return label
    head, _, k = label.rpartition("-")
    if head in installed and k.isdigit() and int(k) >= 2 and _repeatable(head):
        return head
    return label


def repeat_candidates(tables: Sequence[Mapping[str, Any]]) -> list[tuple[str, str]]:
    """``(label, effect)`` of one more instance of each repeatable effect among the model's
    ``[[effects]]`` ``tables``: with k instances of ``effect`` there, ``label`` is
    ``"<effect>-<k+1>"`` (the next free number when the model's own labels took it). Effects in
    the order of their first table."""
    count: dict[str, int] = {}
    labels = set()
    for t in tables:
        name = str(t.get("name"))
        count[name] = count.get(name, 0) + 1
        labels.add(str(t.get("instance", name)))
    out = []
    for effect, k in count.items():
        if not _repeatable(effect):
            continue
        n = k + 1
        while f"{effect}-{n}" in labels:
            n += 1
        out.append((f"{effect}-{n}", effect))
    return out


def effect_table(name: str, values: Mapping[str, float] | None = None, *,
                 effect: str | None = None) -> dict[str, Any]:
    """An ``[[effects]]`` table for candidate ``name`` (an effect's name or an instance label):
    its parameters from ``values`` (model names ``"<name>.<local>"`` -> SI), the others at their
    null. An instance label gives ``{"name": <effect>, "instance": <label>, ...}``; ``effect``:
    the effect of a label not of the form :func:`repeat_candidates` gives."""
    of = effect or effect_of(name)
    out: dict[str, Any] = {"name": of} if of == name else {"name": of, "instance": name}
    for k, v in (values or {}).items():
        head, _, local = k.partition(".")
        if head == name and local:
            out[local] = float(v)
    return out


def with_effects(spec: Mapping[str, Any], tables: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """A copy of the description ``spec`` with the ``[[effects]]`` ``tables`` appended."""
    out = copy.deepcopy(dict(spec))
    out["effects"] = list(out.get("effects") or []) + [dict(t) for t in tables]
    return out


def _declared(name: str) -> tuple[dict[str, Any], dict[str, float]]:
    """Local name -> declared parameter, and local name -> null [SI], of candidate ``name``."""
    plugin = registry.create("skinkit.effects", effect_of(name))
    declared = {p.name: p for p in plugin.parameters()}
    null = {k: float(dict(plugin.null()).get(k, d.value)) for k, d in declared.items()}
    return declared, null


def _only(pred: Prediction, names: Sequence[str]) -> Prediction:
    keep = set(names)
    return Prediction({p: c for p, c in pred.protocols.items() if p in keep}, pred.methods, pred.inputs,
                      pred.info)


def _load_group(spec: Mapping[str, Any], effects: Sequence[str], load: Callable[..., Any]) -> Any:
    return load(with_effects(spec, [effect_table(e) for e in effects]))


def collect(spec: Mapping[str, Any], observations: Observations, values: Mapping[str, float],
            theta: Sequence[str], effects: Sequence[str], *, load: Callable[..., Any],
            progress: Callable[[str], None] | None = None) -> Sensitivities:
    """Sensitivities of the calibrated model ``spec`` (at ``values``: name -> SI, the fitted
    ones) to ``theta`` and to every effect of ``effects`` at its null, on the fitted protocols
    of ``observations``. ``load(spec)`` builds a forward model (workers bound by the caller).
    ``effects``: effects' names or instance labels of effects ``spec`` already has
    (:func:`repeat_candidates`).

    All candidates go into one model and one prediction; if the combination is refused (two
    effects editing the same thing), each effect is first tried alone (those refused alone
    are skipped with the reason), then the rest together, then one model per effect.
    """
    say = progress or (lambda _m: None)
    fitted = observations.fitted()
    skipped: dict[str, str] = {}
    groups: list[list[str]] = [list(effects)] if effects else [[]]
    notes: list[str] = []

    def run(group: list[str]) -> tuple[Any, Prediction, list[str]]:
        return _predict_group(spec, group, load, values, theta, fitted)

    results: list[tuple[list[str], Any, Prediction, list[str]]] = []
    say(f"score step: one prediction with {len(theta)} fitted and the candidate effects' sensitivities"
        f" ({len(effects)} effect(s))")
    try:
        model, pred, names = run(groups[0])
        results.append((groups[0], model, pred, names))
    except SkinkitError as exc:
        notes.append(f"the candidates together were refused ({exc}); tried one by one")
        _predict_apart(spec, effects, load, run, results, skipped, say)
    if not results:
        # nothing could be added: the calibrated model alone, for z and J_θ
        model, pred, names = run([])
        results.append(([], model, pred, names))
    n_forward = len(results)
    z0, J_theta, base_pred, columns, n_sec = _columns(results, fitted, theta, values, say)
    colour = colour_of(fitted, base_pred)
    if colour is not None and colour.blocks[-1][0].stop != z0.size:
        colour = None          # not the residual's layout: test as if the coefficients were known
    return Sensitivities(z0, J_theta, list(theta), columns, skipped, base_pred, n_forward + n_sec, notes,
                         colour)


def colour_of(fitted: Observations, prediction: Prediction) -> Colour | None:
    """The :class:`Colour` of the residual space of ``prediction`` on ``fitted`` (``"noise"``
    weighting); None when no block is prewhitened by a rest segment's AR model, or when a model
    error's covariance mixes the blocks (its whitening is not per series)."""
    from skinkit.forward import noise_model as nm
    from skinkit.gap.where import ar_uncertainty
    from skinkit.inverse.objective import Objective

    if fitted.model_error is not None:
        return None
    obj = Objective(None, fitted, [], "noise")
    blocks, start, any_ar = [], 0, False
    for proto, cname, cp in prediction.items():
        if proto not in fitted.names:
            continue
        ch = fitted[proto].channels[cname]
        _, keep = obj.weights(proto, cname, ch)
        m = cp.mask(ch) & keep
        n = int(m.sum())
        if not n:
            continue
        ar = ar_uncertainty(ch)
        any_ar = any_ar or any(a[0].size for a in ar)
        blocks.append((slice(start, start + n), m, ar, nm.rest_samples(ch.noise_source or "") or 0))
        start += n
    return Colour(blocks) if any_ar else None


def colour_variance(colour: Colour | None, direction: np.ndarray) -> tuple[float, float]:
    """``(m, v)``: the mean and relative variance of the noise's level along ``direction``
    ``(m,)`` of the residual space that the AR noise models' estimation brings:
    m = 1 + Σ_g w_g h_g·bias_g, v = Σ_g w_g² (h_gᵀ cov_g h_g + 2/n_rest), w_g the share of the
    direction's energy in series g, h_g the mean of ∂ log|A_g|²/∂φ over the series' spectrum
    weighted by the direction's power there ((1, 0) without a :class:`Colour`)."""
    from skinkit.forward import noise_model as nm

    if colour is None:
        return 1.0, 0.0
    d = np.asarray(direction, float)
    total = float(d @ d)
    if not total > 0:
        return 1.0, 0.0
    m, v = 1.0, 0.0
    for sl, mask, ar, n_rest in colour.blocks:
        if not ar:
            continue
        full = np.zeros(mask.shape)
        full[mask] = d[sl]
        power = np.abs(np.fft.rfft(full, axis=0)) ** 2                   # (F, k)
        w = np.full(power.shape[0], 2.0)
        w[0] = 1.0
        if mask.shape[0] % 2 == 0:
            w[-1] = 1.0
        power = power * w[:, None]
        omega = 2 * np.pi * np.fft.rfftfreq(mask.shape[0])
        for j, (phi, bias, cov) in enumerate(ar):
            pw = power[:, j]
            e = float(pw.sum())
            if not (phi.size and e > 0):
                continue
            h = (pw / e) @ nm.log_gain_gradient(phi, omega)              # (p,)
            share = e / mask.shape[0] / total            # Parseval: the series' Σ d² over the whole
            m += share * float(h @ bias)
            v += share ** 2 * (float(h @ cov @ h) + (2.0 / n_rest if n_rest > 3 else 0.0))
    return m, v



def _predict_group(spec: Mapping[str, Any], group: list[str], load: Callable[..., Any],
                   values: Mapping[str, float], theta: Sequence[str], fitted: Observations
                   ) -> tuple[Any, Prediction, list[str]]:
    """The model with the effects of ``group`` added (open), its prediction at ``values`` with the
    sensitivities to ``theta`` and to the group's parameters, and those names (columns' order)."""
    model = _load_group(spec, group, load)
    try:
        ps = model.parameters()
        ps = ps.with_values({k: v for k, v in values.items() if k in ps.names})
        names = list(theta) + [n for e in group for n in ps.names if n.startswith(e + ".")]
        pred = model.predict(ps, fitted, sensitivities=names)
        return model, pred, names
    except BaseException:
        model.close()
        raise


def _predict_apart(spec: Mapping[str, Any], effects: Sequence[str], load: Callable[..., Any],
                   run: Callable[[list[str]], tuple[Any, Prediction, list[str]]],
                   results: list[tuple[list[str], Any, Prediction, list[str]]], skipped: dict[str, str],
                   say: Callable[[str], None]) -> None:
    """The candidates that were refused together: those refused alone at load go to ``skipped``;
    the rest are predicted in groups halved until the refusal stands alone (appended to
    ``results``; a single effect refused at prediction time goes to ``skipped``)."""
    good = []
    for e in effects:
        try:
            _load_group(spec, [e], load).close()
            good.append(e)
        except SkinkitError as exc1:
            skipped[e] = str(exc1)
    # a refusal at prediction time (e.g. robot compliance under a displacement drive):
    # halve the group until the refused effect stands alone, so one bad candidate costs
    # about log2(K) extra predictions, not K
    pending = [good] if good else []
    while pending:
        group = pending.pop(0)
        if len(group) == 1:
            say(f"score step: {group[0]} alone")
        try:
            model, pred, names = run(group)
            results.append((group, model, pred, names))
        except SkinkitError as exc2:
            if len(group) == 1:
                skipped[group[0]] = str(exc2)
            else:
                half = len(group) // 2
                pending[:0] = [group[:half], group[half:]]


def _columns(results: Sequence[tuple[list[str], Any, Prediction, list[str]]], fitted: Observations,
             theta: Sequence[str], values: Mapping[str, float], say: Callable[[str], None]
             ) -> tuple[np.ndarray, np.ndarray, Prediction, dict[str, EffectColumns], int]:
    """From the group predictions (whose models it closes): the whitened residual z (n,) and
    J_θ (n, len(theta)) of the first, its prediction, every effect's columns, and the number of
    extra predictions the secants cost."""
    from skinkit.inverse.objective import Objective

    columns: dict[str, EffectColumns] = {}
    z0 = J_theta = None
    n_forward = 0
    try:
        for group, model, pred, names in results:
            obj = Objective(model, fitted, names, "noise")
            res = obj.residual(_only(pred, fitted.names))
            k = len(theta)
            if z0 is None:
                z0, J_theta = res.z, res.J[:, :k]
                base_pred = pred
            for e in group:
                idx = [i for i, n in enumerate(names) if n.startswith(e + ".")]
                cols, extra = _classify(e, [names[i] for i in idx], res.J[:, idx], pred.methods)
                if extra:   # every parameter flat at the null: secants
                    cols, n_sec = _secants(cols, extra, model, fitted, values, res.z, say)
                    n_forward += n_sec
                columns[e] = cols
    finally:
        for _, model, _, _ in results:
            model.close()
    return z0, J_theta, base_pred, columns, n_forward


def _classify(effect: str, names: list[str], J: np.ndarray, methods: Mapping[str, str]
              ) -> tuple[EffectColumns, list[str]]:
    """Columns with a signature at the null, held ones, and (second) the parameters needing a
    secant (all of them when none has a signature)."""
    declared, null = _declared(effect)
    typical = {f"{effect}.{k}": float(d.value) for k, d in declared.items()}
    nul = {f"{effect}.{k}": v for k, v in null.items()}
    bounds = {f"{effect}.{k}": (float(d.lower), float(d.upper)) for k, d in declared.items()}
    size = {n: abs(typical[n] - nul[n]) or abs(typical[n]) or 1.0 for n in names}
    signal = {n: float(np.linalg.norm(J[:, i])) * size[n] for i, n in enumerate(names)}
    seen = [n for n in names if signal[n] > FLAT]
    held = {}
    secant = []
    if not seen:
        secant = [n for n in names if typical[n] != nul[n]]
        held = {n: "no signature at the null, and its typical value is its null" for n in names
                if n not in secant}
    else:
        held = {n: "no signature at the null (identified only with the effect switched on)" for n in names
                if n not in seen}
    keep = [names.index(n) for n in seen]
    sides = np.array([_side(nul[n], *bounds[n]) for n in seen], dtype=float)
    cols = EffectColumns(effect, seen, J[:, keep], {n: methods.get(n, "analytic") for n in seen}, sides,
                         nul, typical, held, bounds)
    return cols, secant


def _side(null: float, lower: float, upper: float) -> int:
    if null <= lower:
        return 1
    if null >= upper:
        return -1
    return 0


def _secants(cols: EffectColumns, names: list[str], model: Any, fitted: Observations,
             values: Mapping[str, float], z0: np.ndarray, say: Callable[[str], None]
             ) -> tuple[EffectColumns, int]:
    """Secant columns (z(null + h) − z(null))/h for ``names``, h a :data:`SECANT_STEP` of the way
    to the typical magnitude; those still without a signature stay held."""
    from skinkit.inverse.objective import Objective

    seen, Js, sides, n_forward = [], [], [], 0
    ps = model.parameters()
    ps = ps.with_values({k: v for k, v in values.items() if k in ps.names})
    for n in names:
        h = SECANT_STEP * (cols.typical[n] - cols.null[n])
        say(f"score step: {n} is flat at its null; secant to {cols.null[n] + h:g}")
        try:
            pred = model.predict(ps.with_values({n: cols.null[n] + h}), fitted, sensitivities=False)
            n_forward += 1
            z = Objective(model, fitted, [], "noise").residual(_only(pred, fitted.names), jacobian=False).z
        except SkinkitError as exc:
            cols.held[n] = f"flat at the null and not solvable a step away ({exc})"
            continue
        if z.shape != z0.shape:
            cols.held[n] = "flat at the null; a step away predicts other samples"
            continue
        col = (z - z0) / h
        if np.linalg.norm(col) * abs(cols.typical[n] - cols.null[n]) <= FLAT:
            cols.held[n] = "no signature on these protocols, at the null or a step away"
            continue
        seen.append(n)
        Js.append(col)
        sides.append(_side(cols.null[n], *cols.bounds[n]))
        cols.methods[n] = f"secant ({SECANT_STEP:g} of the typical magnitude)"
    J = np.stack(Js, axis=1) if Js else np.zeros((z0.size, 0))
    return EffectColumns(cols.effect, seen, J, cols.methods, np.array(sides, float), cols.null, cols.typical,
                         cols.held, cols.bounds), n_forward


# ------------------------------------------------------------------------------------- tests
def fitted_basis(J_theta: np.ndarray) -> np.ndarray:
    """``(m, r)`` orthonormal basis of span(J_θ) (columns normalised first: SI units differ)."""
    m = J_theta.shape[0]
    if J_theta.shape[1] == 0:
        return np.zeros((m, 0))
    nrm = np.linalg.norm(J_theta, axis=0)
    A = J_theta[:, nrm > 0] / nrm[nrm > 0]
    if A.shape[1] == 0:
        return np.zeros((m, 0))
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    return U[:, s > RANK_TOL * s.max()]


def _project(U: np.ndarray, J: np.ndarray) -> np.ndarray:
    return J - U @ (U.T @ J) if U.shape[1] else J.copy()


@dataclass
class ScoreTest:
    """The score test of one effect.

    Attributes:
        effect: its name. statistic: LM [1]. dof: q, the rank of its projected signature.
        p_value: upper tail (½χ²₁ for one constrained parameter, else χ²_q); log_p its log.
        step: name -> the linearised step from the null that explains most of the residual [SI].
        signature: ``(m,)`` J_e⊥ δ: the residual part the effect explains (−z's projection).
        tested, held, absorbed, methods: which parameters entered, which were held at the null
            (and why), which lie in the fitted parameters' span, how each column was obtained.
        one_sided: some tested parameter has its null on a bound.
        kept: the smallest share of a tested column's norm left once the fitted parameters are
            projected out (1/kept² is its variance inflation factor).
        resembles: the parameters the fitted ones all but absorb (:func:`resemblance`).
    """

    effect: str
    statistic: float
    dof: int
    p_value: float
    log_p: float
    step: dict[str, float]
    signature: np.ndarray
    tested: list[str]
    held: dict[str, str]
    absorbed: list[str]
    methods: dict[str, str]
    one_sided: bool
    kept: float = 1.0
    resembles: list[dict[str, Any]] = field(default_factory=list)

    def record(self) -> dict[str, Any]:
        """JSON-ready facts for the candidate record (no arrays)."""
        return {"log10_p": self.log_p / math.log(10), "tested": self.tested, "held": self.held,
                "absorbed": self.absorbed, "sensitivity": self.methods, "one_sided": self.one_sided,
                "step": self.step, "kept": self.kept, "resembles": self.resembles}


def _qp(G: np.ndarray, g: np.ndarray, sides: np.ndarray) -> np.ndarray:
    """argmin ½δᵀGδ − gᵀδ with δ_i·side_i ≥ 0 where side_i ≠ 0: every active set is tried
    (q is a handful); rank-deficient blocks through the pseudo-inverse."""
    q = g.size
    cons = [i for i in range(q) if sides[i] != 0]
    best, best_val = np.zeros(q), 0.0
    for k in range(len(cons) + 1):
        for fixed in itertools.combinations(cons, k):
            free = [i for i in range(q) if i not in fixed]
            d = np.zeros(q)
            if free:
                d[free] = np.linalg.pinv(G[np.ix_(free, free)], rcond=RANK_TOL) @ g[free]
            if any(d[i] * sides[i] < -1e-12 * (abs(d[i]) + 1) for i in cons):
                continue
            val = 0.5 * d @ G @ d - g @ d
            if val < best_val - 1e-12 * abs(best_val):
                best, best_val = d, val
    return best


def _tail(lm: float, q: int, level: tuple[float, float]) -> tuple[float, float]:
    """(p, log p) of LM against χ²_q, or, when the noise's level along the tested direction has
    the mean m and relative variance v > 0 (``level``, :func:`colour_variance`), of LM/q against
    m·F(q, ν) with 2/(ν − 4) = v/m²: matched as :func:`skinkit.gap.where._noise_dof_of` does."""
    m, v = max(level[0], 1.0), level[1]    # a level shifted down is not credited (as in where)
    if v > 0:
        nu = 4.0 + 2.0 * m ** 2 / v
        return float(stats.f.sf(lm / q / m, q, nu)), float(stats.f.logsf(lm / q / m, q, nu))
    return float(stats.chi2.sf(lm / m, q)), float(stats.chi2.logsf(lm / m, q))


def score_test(z: np.ndarray, U: np.ndarray, cols: EffectColumns, colour: Colour | None = None,
               fitted: tuple[np.ndarray, Sequence[str]] | None = None) -> ScoreTest:
    """The score test of ``cols`` against the residual ``z`` with span ``U`` projected out.

    ``fitted``: ``(J_theta, theta)``, the fitted parameters' columns and names, to name what a
    nearly absorbed column resembles (:func:`resemblance`; None: not named).

    ``colour``: where the noise is prewhitened by AR models fitted to rest segments; the
    statistic is then referred to an F distribution that allows for the error of their
    coefficients along the effect's signature (a slow signature meets the prewhitened noise
    where a coefficient's error moves its level most: ((1 − φ̂)/(1 − φ))² near frequency 0)."""
    Jp = _project(U, cols.J)
    raw = np.linalg.norm(cols.J, axis=0)
    nrm = np.linalg.norm(Jp, axis=0)
    keep = [i for i in range(len(cols.names)) if raw[i] > 0 and nrm[i] > ABSORBED * raw[i]]
    absorbed = [cols.names[i] for i in range(len(cols.names)) if i not in keep]
    tested = [cols.names[i] for i in keep]
    share = np.divide(nrm, raw, out=np.ones_like(raw), where=raw > 0)
    like = [] if fitted is None else resemblance(cols, share, *fitted)
    if not keep:
        return ScoreTest(cols.effect, 0.0, 0, 1.0, 0.0, {}, np.zeros(z.size), [], dict(cols.held), absorbed,
                         dict(cols.methods), False, resembles=like)
    A = Jp[:, keep] / nrm[keep]
    sides = cols.sides[keep]
    G = A.T @ A
    g = -(A.T @ z)
    s = np.linalg.svd(G, compute_uv=False)
    q = int(np.sum(np.sqrt(np.maximum(s, 0)) > RANK_TOL))
    d = _qp(G, g, sides)
    lm = max(float(2 * g @ d - d @ G @ d), 0.0)
    one_sided = bool(np.any(sides != 0))
    level = colour_variance(colour, A @ d) if lm > 0 else (1.0, 0.0)
    if one_sided and q == 1:
        # Chernoff: ½χ²₀ + ½χ²₁; an explanation outside the admissible range has LM = 0, p = 1
        p, logp = _tail(lm, 1, level) if lm > 0 else (2.0, 0.0)
        p, logp = (0.5 * p, math.log(0.5) + logp) if lm > 0 else (1.0, 0.0)
    else:
        p, logp = _tail(lm, max(q, 1), level) if q else (1.0, 0.0)
    step = {n: float(d[j] / nrm[keep[j]]) for j, n in enumerate(tested)}
    return ScoreTest(cols.effect, lm, q, min(max(p, 0.0), 1.0), min(logp, 0.0), step, A @ d, tested,
                     dict(cols.held), absorbed, {n: cols.methods[n] for n in tested}, one_sided,
                     float(np.min(share[keep])), like)


def score_all(sens: Sensitivities, nuisance: np.ndarray | None = None) -> list[ScoreTest]:
    """Every candidate's score test, most significant first (by log p, then the statistic).

    ``nuisance`` ``(m, r)``: further directions projected out beside the fitted parameters'
    (the discretisation error's signature, of unknown size: what a candidate would explain
    along it, a finer mesh would explain too)."""
    J = sens.J_theta if nuisance is None else np.column_stack([sens.J_theta, nuisance])
    U = fitted_basis(J)
    fitted = (sens.J_theta, sens.theta)
    out = [score_test(sens.z, U, c, sens.colour, fitted=fitted) for c in sens.columns.values()]
    return sorted(out, key=lambda t: (t.log_p, -t.statistic))


def resemblance(cols: EffectColumns, share: np.ndarray, J_theta: np.ndarray, theta: Sequence[str],
                threshold: float = RESEMBLE_KEPT) -> list[dict[str, Any]]:
    """The parameters of ``cols`` whose column keeps less than ``threshold`` of its norm once the
    fitted directions are projected out (``share`` ``(q,)``: what each keeps, as
    :func:`score_test` measures it; 1 for a zero column): the data cannot tell a step in them
    from a change of the fitted parameters (``J_theta`` ``(m, p)``, named ``theta``), and their
    score test says little. One dict each: ``parameter``, ``kept`` (that share), ``fitted`` (the
    fitted parameter whose column is closest to it) and ``cosine`` (|cos| of the two columns; near
    1: a step in one is a step in the other)."""
    if not len(theta):
        return []
    tn = np.linalg.norm(J_theta, axis=0)
    out: list[dict[str, Any]] = []
    for i in np.flatnonzero(share < threshold):
        col = cols.J[:, i]
        cos = np.abs(J_theta.T @ col) / (np.where(tn > 0, tn, np.inf) * np.linalg.norm(col))
        j = int(np.argmax(cos))
        out.append({"parameter": cols.names[i], "kept": float(share[i]), "fitted": theta[j],
                    "cosine": float(cos[j])})
    return out


def _n_tested(tests: Sequence[ScoreTest]) -> int:
    """K of the Bonferroni correction: the effects that could be tested (those with a signature)."""
    return max(sum(1 for t in tests if t.dof > 0), 1)


def _log_adjusted(tests: Sequence[ScoreTest]) -> dict[str, float]:
    """Effect -> log(p·K) of each test that can reject (a signature and a positive statistic),
    in logs because p underflows."""
    log_k = math.log(_n_tested(tests))
    return {t.effect: t.log_p + log_k for t in tests if t.dof > 0 and t.statistic > 0}


def corrected(tests: Sequence[ScoreTest], alpha: float) -> dict[str, bool]:
    """Effect -> whether its score test survives the Bonferroni correction over the K effects
    that could be tested (those with a signature): p·K < alpha, in logs (p underflows)."""
    adj = _log_adjusted(tests)
    return {t.effect: t.effect in adj and adj[t.effect] < math.log(alpha) for t in tests}


def directed_p(tests: Sequence[ScoreTest]) -> float:
    """The score tests' family p-value for the gate: the smallest Bonferroni-adjusted p (p·K over
    the K effects with a signature) of the tests whose signature keeps at least :data:`KEPT_GATE`
    of its norm once the fitted parameters are projected out; 1 when no such test has a positive
    statistic.

    A signature nearly inside the fitted parameters' span is tested along the small difference
    that is left, where the score's linearisation is weakest: the fitted parameters' own error
    enters the residual at second order (the model's curvature), and on strongly coloured noise
    that error is large. Such a test stays in :func:`corrected` (an effect can still be named once
    the gap is open) but does not open the gate alone."""
    sound = {t.effect for t in tests if t.kept >= KEPT_GATE}
    adj = [v for k, v in _log_adjusted(tests).items() if k in sound]    # K still counts every test
    return float(min(1.0, math.exp(min(adj)))) if adj else 1.0


def cosine(a: np.ndarray, b: np.ndarray) -> float | None:
    """|cos| of the angle between two signatures (None if either is zero)."""
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na == 0 or nb == 0:
        return None
    return abs(float(a @ b)) / (na * nb)


def conditional_test(sens: Sensitivities, a: str, given: str) -> ScoreTest:
    """The score test of effect ``a`` with J_θ *and* effect ``given``'s columns projected out:
    what ``a`` explains that ``given`` cannot."""
    J = np.hstack([sens.J_theta, sens.columns[given].J])
    return score_test(sens.z, fitted_basis(J), sens.columns[a], sens.colour)


def separability(sens: Sensitivities, tests: Sequence[ScoreTest], alpha: float,
                 effects: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Pairs of effects with |cos| of their explained signatures above :data:`COS_NOT_SEPARABLE`,
    each with ``cosine``, the conditional tests' ``p_value`` both ways (``a_given_b``,
    ``b_given_a``) and ``separable`` (True when either survives the correction over the K
    tested effects). ``effects``: restrict pairs to those involving these."""
    by = {t.effect: t for t in tests}
    K = _n_tested(tests)
    out = []
    names = [t.effect for t in tests if t.dof > 0 and t.statistic > 0]
    for a, b in itertools.combinations(names, 2):
        if effects is not None and a not in effects and b not in effects:
            continue
        c = cosine(by[a].signature, by[b].signature)
        if c is None or c <= COS_NOT_SEPARABLE:
            continue
        ab, ba = conditional_test(sens, a, b), conditional_test(sens, b, a)
        sep = any(t.dof > 0 and t.log_p + math.log(K) < math.log(alpha) for t in (ab, ba))
        out.append({"effects": [a, b], "cosine": c,
                    "a_given_b": {"statistic": ab.statistic, "p_value": ab.p_value},
                    "b_given_a": {"statistic": ba.statistic, "p_value": ba.p_value}, "separable": sep})
    return out


# ----------------------------------------------------------------------- separating protocol
def separating_protocol(spec: Mapping[str, Any], observations: Observations, values: Mapping[str, float],
                        theta: Sequence[str], sens: Sensitivities, tests: Sequence[ScoreTest],
                        pair: Sequence[str], *, load: Callable[..., Any],
                        candidates: Sequence[str] | None = None,
                        progress: Callable[[str], None] | None = None) -> dict[str, Any] | None:
    """The library protocol that would best separate the two effects of ``pair``: for each
    candidate protocol, the session augmented with it (one prediction with the sensitivities to
    θ and to both effects), the fitted directions projected out over the augmented session,
    and |cos| of the two effects' signatures J_e⊥ δ_e with the steps δ_e the session gave.
    Returns ``{"protocol", "cosine", "ranking": [{"protocol", "cosine"}]}`` (smallest |cos|
    first), or None when no candidate applies."""
    from skinkit.inverse.design import _drive_with, candidate_observations, default_candidates
    from skinkit.inverse.objective import Objective

    say = progress or (lambda _m: None)
    by = {t.effect: t for t in tests}
    a, b = pair
    names_ab = by[a].tested + by[b].tested
    names = list(theta) + names_ab
    model = _load_group(spec, [a, b], load)
    rows = []
    try:
        ps = model.parameters()
        ps = ps.with_values({k: v for k, v in values.items() if k in ps.names})
        cands = list(candidates) if candidates is not None else default_candidates(model)
        # the session's own rows: z-space columns already measured
        col = {n: sens.columns[e].J[:, sens.columns[e].names.index(n)] for e in (a, b)
               for n in by[e].tested}
        base_rows = np.hstack([sens.J_theta, np.stack([col[n] for n in names_ab], axis=1)])
        for i, c in enumerate(cands, 1):
            if c in observations.names:
                continue
            say(f"separating {a} from {b}: candidate {i}/{len(cands)} {c}")
            try:
                obs_c, drive = candidate_observations(model, observations, c)
                obs_c = _drive_with(model, ps, obs_c, drive)
                pred = model.predict(ps, obs_c, sensitivities=names)
                res = Objective(model, obs_c, names, "noise").residual(pred)
            except SkinkitError:
                continue
            J = np.vstack([base_rows, res.J])
            k = len(theta)
            U = fitted_basis(J[:, :k])
            sig = {}
            for e in (a, b):
                idx = [k + names_ab.index(n) for n in by[e].tested]
                d = np.array([by[e].step[n] for n in by[e].tested])
                sig[e] = _project(U, J[:, idx]) @ d
            cs = cosine(sig[a], sig[b])
            if cs is not None:
                rows.append({"protocol": c, "cosine": cs})
    finally:
        model.close()
    if not rows:
        return None
    rows.sort(key=lambda r: r["cosine"])
    return {"protocol": rows[0]["protocol"], "cosine": rows[0]["cosine"], "ranking": rows}


__all__ = ["COS_NOT_SEPARABLE", "RESEMBLE_KEPT", "Colour", "EffectColumns", "ScoreTest", "Sensitivities",
           "collect", "colour_of", "colour_variance", "conditional_test", "corrected", "cosine", "directed_p",
           "effect_of", "effect_table", "fitted_basis", "repeat_candidates", "resemblance", "score_all",
           "score_test", "separability", "separating_protocol", "with_effects"]
