"""The one-call Python API: :func:`fit` and :func:`diagnose`, also reachable as ``skinkit.fit``
and ``skinkit.diagnose``.

Both take the model as a model file's path, a description (the parsed model file as a dict) or a
loaded forward model (:func:`skinkit.forward.load`), and the session as a path (an experiment
file ``.h5`` or a CSV robot record ``.csv``) or :class:`~skinkit.schemas.Observations`. A CSV
record's one-axis columns (``displacement_mm``, ``force_N``) are read along the axis the model
acts on, as the command line reads them (:func:`skinkit.forward.session.read_session`).

Progress: by default a line on standard error for each stage of the work, and while a stage
runs at most one line every :data:`PROGRESS_INTERVAL_S` seconds; ``progress=False`` is silent,
and a callable ``progress(line)`` receives the same lines instead.

This module sits with the applications (it drives the engines: forward, inverse, gap); the
top-level package imports it on first use only, so ``import skinkit`` stays light.
"""

from __future__ import annotations

import copy
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from skinkit.errors import SkinkitError, StoreError
from skinkit.schemas import FitResult, GapReport, Observations

#: a model: a model file, its description, or a loaded forward model (any object: duck-typed)
ModelLike = str | os.PathLike[str] | Mapping[str, Any] | Any
#: a session: an experiment file or CSV record, or observations already read
SessionLike = str | os.PathLike[str] | Observations
#: True (lines on standard error), False (none) or a callable taking each line
ProgressLike = bool | Callable[[str], None] | None
#: names given as a list or one comma-separated string
Names = str | Sequence[str] | None

#: most seconds between two progress lines while one stage runs
PROGRESS_INTERVAL_S = 10.0


class Progress:
    """Where progress lines go: each stage's line always, lines from inside a stage (a fit's
    evaluations, say) at most one every ``interval_s`` seconds."""

    def __init__(self, progress: ProgressLike = True, interval_s: float = PROGRESS_INTERVAL_S) -> None:
        if progress is None or progress is True:
            self._sink: Callable[[str], None] | None = _to_stderr
        elif progress is False:
            self._sink = None
        elif callable(progress):
            self._sink = progress
        else:
            raise SkinkitError("progress: expected True, False or a callable taking a line, "
                               f"got {progress!r}")
        self.interval_s = float(interval_s)
        self._last = -float("inf")

    def stage(self, line: str) -> None:
        """A stage begins or ends: always said."""
        if self._sink is not None:
            self._last = time.monotonic()
            self._sink(line)

    def tick(self, line: str) -> None:
        """Work inside a stage: said when ``interval_s`` has passed since the last line."""
        if self._sink is not None and time.monotonic() - self._last >= self.interval_s:
            self.stage(line)


def _to_stderr(line: str) -> None:
    # looked up at each call, so that a redirected or captured sys.stderr gets the line
    print(f"skinkit: {line}", file=sys.stderr, flush=True)


def _names(names: Names, what: str) -> list[str] | None:
    """``"a, b"`` or ``["a", "b"]`` -> ``["a", "b"]``; None stays None."""
    if names is None:
        return None
    if isinstance(names, str):
        return [s.strip() for s in names.split(",") if s.strip()]
    if not all(isinstance(n, str) for n in names):
        raise SkinkitError(f"{what}: expected names (strings), got {list(names)!r}")
    return list(names)


def is_loaded(model: Any) -> bool:
    """Whether ``model`` is a loaded forward model rather than a model file or description."""
    return callable(getattr(model, "predict", None)) and callable(getattr(model, "parameters", None))


@contextmanager
def loaded(model: ModelLike, workers: int | None = None, scheduler: Any = None) -> Iterator[Any]:
    """The forward model of ``model``: a loaded one as it is (left open: it is the caller's),
    a path or description loaded (``workers``: processes of a finite-element model;
    ``scheduler``: a Dask scheduler address or cluster to solve its protocols on instead) and
    closed after the ``with`` block."""
    if is_loaded(model):
        yield model
        return
    from skinkit.forward import load

    m = load(_checked_model(model), workers=workers, scheduler=scheduler)
    try:
        yield m
    finally:
        m.close()


def _checked_model(model: ModelLike) -> str | os.PathLike[str] | Mapping[str, Any]:
    if isinstance(model, Mapping):
        return model
    if isinstance(model, (str, os.PathLike)):
        if not Path(model).is_file():
            raise SkinkitError(f"model {os.fspath(model)}: no such model file")
        return model
    raise SkinkitError(f"model: expected a model file's path, a description (dict) or a loaded forward "
                       f"model, got {type(model).__name__}")


def description(model: ModelLike) -> dict[str, Any] | str | os.PathLike[str]:
    """What :func:`skinkit.gap.diagnose.diagnose` takes: a path or description as given, and for a
    loaded model the description it was loaded from (its tables, its effects as ``[[effects]]``
    tables with their values [SI])."""
    if not is_loaded(model):
        return _checked_model(model)
    base = getattr(model, "base", None)
    if not isinstance(base, Mapping):
        raise SkinkitError(f"model {getattr(model, 'name', '?')!r}: this loaded model keeps no description, "
                           "which the diagnosis needs to add effects to; give its model file or description")
    spec = copy.deepcopy(dict(base))
    tables = [_effect_table(e) for e in getattr(model, "effects", []) or []]
    if tables:
        spec["effects"] = tables
    return spec


def _effect_table(e: Any) -> dict[str, Any]:
    """The ``[[effects]]`` table that loads as the applied effect ``e`` (values in SI)."""
    t: dict[str, Any] = {"name": e.effect}
    if e.name != e.effect:
        t["instance"] = e.name
    form = getattr(e.plugin, "form", None)
    if form is not None and getattr(e.plugin, "forms", None):
        t["form"] = form
    t.update({k: float(v) for k, v in e.values.items()})
    return t


def observations(model: Any, session: SessionLike, *, holdout: Names = None, protocols: Names = None,
                 segments: str | None = None, until: float | None = None,
                 noise: str = "auto") -> Observations:
    """The observations of ``session`` for the loaded ``model``: a path read along the model's
    axis (:func:`skinkit.forward.session.read_session`), or given observations narrowed alike:
    only ``protocols``, ``holdout`` marked held out (added to those already marked), records
    split into ``segments`` (``"cycles"``), samples up to ``until`` [s]."""
    hold, only = _names(holdout, "holdout") or [], _names(protocols, "protocols")
    if isinstance(session, Observations):
        obs = session.select(only) if only else session
        if segments is not None:
            from skinkit.forward.segments import split
            obs = split(obs, segments)
        if hold:
            obs = obs.with_held_out(sorted(set(hold) | set(obs.held_out().names)))
    elif isinstance(session, (str, os.PathLike)):
        if not Path(session).is_file():
            raise StoreError(os.fspath(session), "", "no such session file")
        from skinkit.forward.session import read_session
        obs = read_session(model, session, ",".join(hold) or None, segments,
                           protocols=",".join(only) if only else None, noise=noise)
    else:
        raise SkinkitError(f"session: expected a path (experiment file or CSV record) or Observations, "
                           f"got {type(session).__name__}")
    return obs if until is None else obs.until(float(until), "until")


def fit(model: ModelLike, session: SessionLike, *, free: Names = None, holdout: Names = None,
        protocols: Names = None, segments: str | None = None, until: float | None = None,
        noise: str = "auto", weighting: str = "noise", optimiser: str = "scipy-lsq",
        start: Mapping[str, float] | None = None, bounds: Mapping[str, tuple[float, float]] | None = None,
        ftol: float = 1e-6, xtol: float = 1e-3, max_iterations: int = 50, jacobian: str = "analytic",
        checkpoint: str | os.PathLike[str] | None = None, workers: int | None = None,
        scheduler: Any = None, progress: ProgressLike = True) -> FitResult:
    """Fit a model's free parameters to a session.

    ``model``: a model file's path, its description (dict) or a loaded forward model (left open).
    ``session``: an experiment file (``.h5``), a CSV robot record (its one-axis columns read
    along the model's axis) or :class:`~skinkit.schemas.Observations`. ``free``: the parameters
    to fit (names, list or ``"a,b"``; default the model file's free ones); ``holdout``:
    protocols kept out of the fit and predicted (their error in ``FitResult.held_out``);
    ``protocols``: only these records; ``segments``: ``"cycles"`` splits each record into its
    loading cycles first; ``until`` [s]: only each record's first seconds; ``noise``: how a
    record's noise is modelled (``"auto"``, ``"white"``, ``"ar"``). ``start``, ``bounds``: name
    -> value [SI] / (lower, upper) [SI]. ``weighting``, ``optimiser``, ``ftol``, ``xtol``,
    ``max_iterations``, ``jacobian``, ``checkpoint``: as :func:`skinkit.inverse.fit.fit`.
    ``workers``: processes of a finite-element model loaded here; ``scheduler``: a Dask scheduler
    address (or cluster) to solve its protocols on instead. ``progress``: True (lines on
    standard error), False, or a callable taking each line.

    Returns the :class:`~skinkit.schemas.FitResult`: ``parameters`` (values [SI]), ``se``
    (standard errors [SI]), ``covariance`` ``(n_free, n_free)``, ``objective`` (½ Σz² of the
    weighted residual), ``chi2_per_dof``; print it, or ``to_dataframe()`` for a table.
    """
    from skinkit.inverse.fit import fit as fit_observations

    say = Progress(progress)
    with loaded(model, workers, scheduler) as m:
        if not isinstance(session, Observations):
            say.stage(f"reading {os.fspath(session)} for {m.name}")
        obs = observations(m, session, holdout=holdout, protocols=protocols, segments=segments, until=until,
                           noise=noise)
        names = _names(free, "free")
        say.stage(f"fitting {m.name} to {len(obs.fitted())} protocol(s) of {obs.source or 'the session'}"
                  + (f": free {', '.join(names)}" if names else ""))
        t0 = time.perf_counter()

        def each(i: int, phi: float, _values: dict[str, float]) -> None:
            say.tick(f"evaluation {i}: objective {phi:.6g} ({time.perf_counter() - t0:.0f} s)")

        result = fit_observations(m, obs, names, weighting=weighting, optimiser=optimiser,
                                  start=dict(start) if start else None, ftol=ftol, xtol=xtol,
                                  max_iterations=max_iterations, jacobian=jacobian, checkpoint=checkpoint,
                                  bounds=dict(bounds) if bounds else None, progress=each)
    state = "converged" if result.converged else f"not converged ({result.message})"
    say.stage(f"fit {state}: {result.n_evaluations} evaluations, objective {result.objective:.6g}, "
              f"{result.wall_s:.1f} s")
    return result


def diagnose(model: ModelLike, session: SessionLike, *, effects: Names = None, holdout: Names = None,
             free: Names = None, protocols: Names = None, until: float | None = None, noise: str = "auto",
             max_effects: int = 2, candidates: int = 3, alpha: float = 0.05, max_iterations: int = 50,
             min_share: float | None = None, error_estimate: bool = True, model_error: bool = True,
             workers: int | None = None, scheduler: Any = None, progress: ProgressLike = True) -> GapReport:
    """Diagnose the sim-to-real gap of a model on a session: calibrate it, locate where its
    noise-normalised residual exceeds the noise, test the candidate unmodelled effects, refit the
    best and name those that explain the excess.

    ``model``: a model file's path, its description (dict) or a loaded forward model (its
    description and effects are used; it is left open). ``session``: an experiment file
    (``.h5``), a CSV robot record (read along the model's axis) or
    :class:`~skinkit.schemas.Observations`. ``effects``: the candidates (default every installed
    effect that applies and the model lacks); ``holdout``: protocols kept out of every fit and
    predicted; ``free``: the parameters calibrated (default the model file's free ones);
    ``protocols``: only these records; ``until`` [s]: only each record's first seconds;
    ``noise``: ``"auto"``, ``"white"`` or ``"ar"``; ``max_effects``: rounds of naming;
    ``candidates``: refits per round; ``alpha``: the level of every test; ``max_iterations``:
    evaluations each fit may make; ``min_share``: the share of the excess an effect must remove
    to be named (default 0.5); ``error_estimate``, ``model_error``: a finite-element model's
    discretisation error (:func:`skinkit.gap.diagnose.diagnose`); ``workers``: its processes;
    ``scheduler``: a Dask scheduler address (or cluster) to solve its protocols on instead.
    ``progress``: True (lines on standard error), False, or a callable taking each line.

    Returns the :class:`~skinkit.schemas.GapReport`; print it, or ``to_dataframe("candidates")``
    / ``to_dataframe("cells")`` for tables.
    """
    from skinkit.gap.diagnose import diagnose as diagnose_session

    say = Progress(progress)
    spec = description(model)
    obs: Any = session
    if isinstance(session, Observations):
        only = _names(protocols, "protocols")
        obs = session.select(only) if only else session
    elif not isinstance(session, (str, os.PathLike)):
        raise SkinkitError(f"session: expected a path (experiment file or CSV record) or Observations, "
                           f"got {type(session).__name__}")
    elif not Path(session).is_file():
        raise StoreError(os.fspath(session), "", "no such session file")
    if is_loaded(model):
        name = str(model.name)
    elif isinstance(spec, Mapping):
        name = str(dict(spec.get("model", {}) or {}).get("name", "the model"))
    else:
        from skinkit.forward import read_description
        name = str(dict(read_description(spec).get("model", {}) or {}).get("name", Path(spec).stem))
    where = obs.source if isinstance(obs, Observations) else os.fspath(obs)
    say.stage(f"diagnosing {name} on {where or 'the session'}")
    t0 = time.perf_counter()
    more: dict[str, Any] = {} if min_share is None else {"min_share": float(min_share)}
    # given observations were narrowed to ``protocols`` above; a path is narrowed as it is read
    only = None if isinstance(obs, Observations) else _names(protocols, "protocols")
    report = diagnose_session(spec, obs, effects=_names(effects, "effects"),
                              holdout=_names(holdout, "holdout") or (), free=_names(free, "free"),
                              max_effects=max_effects, candidates=candidates, alpha=alpha, workers=workers,
                              until=until, progress=say.stage, protocols=only,
                              error_estimate=error_estimate, noise=noise, max_iterations=max_iterations,
                              model_error=model_error, scheduler=scheduler, **more)
    named = ", ".join(report.named) or "no effect"
    say.stage(f"diagnosis done: {named} named, {time.perf_counter() - t0:.1f} s")
    return report


__all__ = ["PROGRESS_INTERVAL_S", "Progress", "description", "diagnose", "fit", "is_loaded", "loaded",
           "observations"]
