"""Analytic sensitivities against differences of whole solves along one random direction.

Checking every parameter's column by its own central difference costs two solves per
parameter; the derivative along a direction v, ``J v``, against ``(f(p + h v) - f(p - h v)) / 2h``
costs two solves in all. A column that is wrong shows in ``J v`` unless the others drown it,
so v is weighted by the analytic columns themselves: on the channel where a parameter matters
most (relative to that channel's largest column over its parameter's scale) it moves the
prediction at least as much as any other parameter does there. A column computed too small
gets a large component, one computed too large a small one: either way the differences
disagree with ``J v``. Magnitudes and signs are random (seeded) so that wrong columns cannot
cancel by construction.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

#: a parameter whose analytic column is below this share of its best channel's largest column
#: gets no larger component: its step stays within 1.5 h / WEIGHT_FLOOR = 1.5e-4 of its scale
#: (h = 1e-6), where the difference's truncation error (step² |f'''|) is ~1e-8 of its share
WEIGHT_FLOOR = 1e-2


def direction(pred, pset, names: Sequence[str], scale: Mapping[str, float], h: float,
              seed: int) -> tuple[dict[str, float], bool]:
    """The direction ``{name: component}`` and whether it needs the one-sided formula.

    A parameter on (or within a step of) a bound steps into its admissible range, and then
    the whole direction is differenced one-sidedly."""
    rng = np.random.default_rng(seed)
    share = np.array([[np.abs(cp.d[nm]).max() * scale[nm] for nm in names] for _, _, cp in pred.items()])
    top = share.max(axis=1, keepdims=True)
    rel = np.divide(share, top, out=np.zeros_like(share), where=top > 0).max(axis=0)
    mag = rng.uniform(0.5, 1.5, len(names)) / np.maximum(rel, WEIGHT_FLOOR)
    sign = rng.choice([-1.0, 1.0], len(names))
    v, one_sided = {}, False
    for nm, m, s in zip(names, mag, sign, strict=True):
        p = pset.param(nm)
        step = h * m * scale[nm]
        if p.value - step < p.lower:
            s, one_sided = 1.0, True
        elif p.value + step > p.upper:
            s, one_sided = -1.0, True
        v[nm] = s * m * scale[nm]
    reach = 2 if one_sided else 1
    for nm, c in v.items():
        p = pset.param(nm)
        assert p.lower <= p.value + reach * h * c <= p.upper, (nm, "no room for the step")
    return v, one_sided


def check(model, obs, names: Sequence[str], scale: Mapping[str, float], *, seed: int, tol: float,
          tol_for: Callable[[str], float] | None = None, floor: float = 0.0, h: float = 1e-6,
          pred=None) -> tuple[object, float]:
    """Assert ``J v`` matches the differences of whole solves along v in every channel.

    ``pred``: the prediction at the parameters with the sensitivities of ``names`` (made here
    when not given). ``tol_for(method)``: the tolerance for a column found by that method
    (the largest among the direction's columns applies). ``floor``: an error below this share
    of the channel's largest value passes (a direction that hardly moves the channel).
    Returns the prediction and the worst relative error seen."""
    pset = model.parameters()
    if pred is None:
        pred = model.predict(pset, obs, sensitivities=list(names))
    v, one_sided = direction(pred, pset, names, scale, h, seed)
    at = {nm: pset.param(nm).value for nm in names}

    def moved(t: float):
        return model.predict(pset.with_values({nm: at[nm] + t * c for nm, c in v.items()}), obs)

    if one_sided:
        f1, f2 = moved(h), moved(2 * h)
        fds = [(-3 * x.values + 4 * a.values - b.values) / (2 * h)
               for (_, _, x), (_, _, a), (_, _, b) in zip(pred.items(), f1.items(), f2.items(), strict=True)]
    else:
        up, dn = moved(h), moved(-h)
        fds = [(u.values - d.values) / (2 * h) for (_, _, u), (_, _, d) in zip(up.items(), dn.items(),
                                                                             strict=True)]
    if tol_for is not None:
        tol = max([tol] + [tol_for(pred.methods[nm]) for nm in names])
    worst = 0.0
    for (proto, c, cp), fd in zip(pred.items(), fds, strict=True):
        jv = sum(cp.d[nm] * comp for nm, comp in v.items())
        size = max(np.abs(fd).max(), np.abs(jv).max())
        if size == 0:
            continue
        err = np.abs(jv - fd).max()
        worst = max(worst, err / size)
        assert err <= tol * size or err <= floor * np.abs(cp.values).max(), \
            (proto, c, err / size, {nm: round(float(comp / scale[nm]), 3) for nm, comp in v.items()})
    return pred, worst
