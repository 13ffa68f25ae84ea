"""``skinkit effects``: the candidate-effect plugins, and which protocols can see them."""

from __future__ import annotations

import click

from skinkit import jsonio
from skinkit.cli._types import FiniteFloat
from skinkit.cli.registry import LazyGroup
from skinkit.units import unit_suffix


@click.group("effects", cls=LazyGroup)
def effects() -> None:
    """Candidate unmodelled effects (plugins of the skinkit.effects group)."""


@effects.command("list")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
def list_effects(as_json: bool) -> None:
    """Every installed effect: the model kinds it fits, its parameters with null and typical values."""
    from skinkit import registry

    out = {}
    for name in registry.names("skinkit.effects"):
        try:
            e = registry.create("skinkit.effects", name)
        except Exception as exc:  # listed with its error, as `skinkit plugins` does
            out[name] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        null = dict(e.null())
        out[name] = {"kinds": list(e.kinds), "parameters": [
            {"name": p.name, "unit": p.unit, "null": null.get(p.name), "typical": p.value,
             "lower": p.lower, "upper": p.upper} for p in e.parameters()]}
    if as_json:
        click.echo(jsonio.dumps(out, indent=2))
        return
    for name, d in out.items():
        if "error" in d:
            click.echo(f"{name}: error: {d['error']}")
            continue
        pars = ", ".join(f"{p['name']} {p['null']:g} -> {p['typical']:g}{unit_suffix(p['unit'])}"
                         for p in d["parameters"])
        click.echo(f"{name:20s} [{', '.join(d['kinds'])}]  {pars}")


def _forces_from_trajectories(spec, obs, workers):
    import copy

    from skinkit.forward import load
    from skinkit.schemas import Channel, Observations, ProtocolObservations

    disp = copy.deepcopy(spec)
    disp.pop("effects", None)
    disp["indenter"] = {**dict(disp.get("indenter", {}) or {}), "mode": "displacement"}
    with load(disp, workers=workers) as m:
        pred = m.predict(m.parameters(), obs)
    out = {}
    for po in obs:
        ch = dict(po.channels)
        f = ch["tip_force"]
        forces = pred.protocols[po.name]["tip_force"].values
        ch["tip_force"] = Channel("tip_force", f.time_s, forces, noise=f.noise)
        out[po.name] = ProtocolObservations(po.protocol, ch)
    return Observations(out, None, obs.source)


def _requested_effects(text: str, kind: str) -> list[str]:
    """The effects --effects names, each installed; refused when none applies to a ``kind`` model
    (some may not: each is then reported as not applying)."""
    from skinkit import registry
    from skinkit.errors import SkinkitError
    from skinkit.forward.session import split_names
    from skinkit.forward.visibility import applicable_effects

    wanted = list(dict.fromkeys(split_names(text)))
    if not wanted:
        raise SkinkitError("--effects: no effect named")
    installed = registry.names("skinkit.effects")
    for e in wanted:
        if e not in installed:
            raise SkinkitError(f"--effects {e!r}: no such effect is installed "
                               f"(installed: {', '.join(installed)})")
    ok = applicable_effects(kind)
    if not set(wanted) & set(ok):
        which = f"{wanted[0]!r} does not apply" if len(wanted) == 1 else f"{', '.join(wanted)}: none applies"
        raise SkinkitError(f"--effects {which} to a {kind!r} model "
                           f"(effects for {kind} models: {', '.join(ok)})")
    return wanted


@effects.command("visibility")
@click.argument("model_file", type=click.Path(dir_okay=False))
@click.option("--session", type=click.Path(dir_okay=False), default=None,
              help="predict this session's protocols with its noise (default: the model's [session] "
                   "protocols driven by their programmes, with the robot's and the cameras' noise)")
@click.option("--effects", "names", default=None, help="only these effects (comma-separated)")
@click.option("--threshold", type=FiniteFloat(min=0, min_open=True), default=5.0, show_default=True,
              help="a channel sees an effect that changes it by more than this many noise levels")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="worker processes")
@click.option("--json", "as_json", is_flag=True, help="print JSON")
def visibility(model_file: str, session: str | None, names: str | None, threshold: float,
               workers: int | None, as_json: bool) -> None:
    """Each effect at its null (exact?) and typical magnitude: which protocols and channels see it."""
    from skinkit.bench.forward import trajectory_observations
    from skinkit.cli._progress import progress
    from skinkit.errors import SkinkitError
    from skinkit.forward import load, model_kind, read_description, read_observations
    from skinkit.forward.visibility import DEFAULT_NOISE, effect_visibility

    spec = read_description(model_file)
    kind = model_kind(spec)
    # checked before any prediction: an effect that cannot apply would only be reported after them
    wanted = None if names is None else _requested_effects(names, kind)
    noise = None
    if session:
        obs = read_observations(session)
    else:
        protos = tuple(dict(spec.get("session", {}) or {}).get("protocols", ()))
        if not protos:
            raise SkinkitError(f"{model_file}: no [session] protocols; give --session")
        obs = trajectory_observations(protos)
        noise = DEFAULT_NOISE
    mode = str(dict(spec.get("indenter", {}) or {}).get("mode", "force"))
    # progress on stderr, also with --json (stdout carries only the result)
    with progress() as bar:
        if not session and mode == "force":
            # the protocols' programmes give tip trajectories: the model driven by them gives the
            # tip forces that then drive it as the model file says (by the recorded force)
            with bar.feeding("tip forces of the trajectories"):
                obs = _forces_from_trajectories(spec, obs, workers)
        with bar.feeding("effect visibility"):
            res = effect_visibility(spec, obs, wanted, noise, threshold,
                                    load=lambda s: load(s, workers=workers))
    if wanted and not any(e["applicable"] for e in res["effects"].values()):
        # e.g. an effect the model's own law already holds: the model refuses it when loaded
        first = next(iter(res["effects"].items()))
        raise SkinkitError(f"--effects {', '.join(wanted)}: none applies to this {kind} model "
                           f"({first[0]}: {first[1]['reason']})")
    if as_json:
        click.echo(jsonio.dumps(res, indent=2))
        return
    for name, e in res["effects"].items():
        if not e["applicable"]:
            click.echo(f"{name:20s} does not apply: {e['reason']}")
            continue
        seen = "; ".join(f"{p}: {', '.join(cs)}" for p, cs in e["seen_by"].items()) or "not seen"
        click.echo(f"{name:20s} null change {e['null_relative_change']:.1e}   {seen}")
    if res["invisible"]:
        click.echo(f"not visible in these protocols: {', '.join(res['invisible'])}")
