"""``skinkit robot``: list the measurement protocols and run one through a robot driver.

Other distributions add subcommands through the entry-point group ``skinkit.commands.robot``
(skinkit-hardware adds ``skinkit robot emulate``); the core imports no driver.
"""

from __future__ import annotations

import datetime as _dt
import inspect
import json
from pathlib import Path
from typing import Any

import click

from skinkit import jsonio
from skinkit.cli._progress import progress
from skinkit.cli._types import FiniteFloat
from skinkit.cli.registry import LazyGroup
from skinkit.errors import OptionError, RefusedError, SkinkitError


@click.group("robot", cls=LazyGroup)
def robot() -> None:
    """Drive the microrobot: list protocols, run one into an experiment file."""


@robot.command("protocols")
@click.option("--json", "as_json", is_flag=True, help="machine-readable output")
def protocols(as_json: bool) -> None:
    """List the built-in measurement protocols with their parameters and durations."""
    from skinkit.acquisition import catalogue

    items = catalogue()
    if as_json:
        click.echo(
            jsonio.dumps(
                {
                    "protocols": [
                        {
                            "name": p.name,
                            "kind": p.kind,
                            "parameters": p.to_dict()["parameters"],
                            "units": p.units,
                            "duration_s": p.duration_s,
                            "description": p.description,
                        }
                        for p in items
                    ]
                },
                indent=1,
            )
        )
        return
    for p in items:
        params = ", ".join(
            f"{k}={v:g}{' ' + p.units[k] if p.units.get(k, '1') not in ('1', '') else ''}"
            if isinstance(v, (int, float))
            else f"{k}={v}"
            for k, v in p.parameters.items()
        )
        click.echo(f"{p.name:28s} {p.kind:10s} {p.duration_s:8.1f} s  {params}")


def _parse_kv(items: tuple[str, ...], what: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SkinkitError(f"{what} {item!r} is not KEY=VALUE")
        try:
            out[key] = float(value) if any(c in value for c in ".eE") else int(value)
        except ValueError:
            out[key] = value
    return out


#: driver connect options the CLI checks before connecting: (type, lowest, highest)
_OPTION_RANGES: dict[str, tuple[type, float, float]] = {
    "seed": (int, 0, 2**32 - 1),
    "decimation": (int, 1, 1000),
    "baudrate": (int, 300, 12_000_000),
    "baud": (int, 300, 12_000_000),
    "bitrate": (int, 10_000, 8_000_000),
    "block_s": (float, 1e-4, 10.0),
}


def _check_options(opts: dict[str, Any]) -> None:
    """Type and range of the driver options the CLI knows; the driver checks the rest."""
    for key, (kind, lo, hi) in _OPTION_RANGES.items():
        if key not in opts:
            continue
        v = opts[key]
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and lo <= v <= hi
        if kind is int:
            ok = ok and float(v).is_integer()
        if not ok:
            what = "a whole number" if kind is int else "a number"
            raise SkinkitError(f"--option {key}={v}: must be {what} in [{kind(lo)}, {kind(hi)}]")
        opts[key] = kind(v)


@robot.command("run")
@click.argument("protocol_name", metavar="PROTOCOL")
@click.option(
    "--driver",
    "driver_name",
    default="sim",
    show_default=True,
    help="driver plugin (skinkit.drivers): sim, serial, can, ...",
)
@click.option("--port", default=None, help="serial port, or INTERFACE:CHANNEL for can")
@click.option("--param", "params", multiple=True, metavar="KEY=VALUE", help="protocol parameter (SI units)")
@click.option("--option", "options", multiple=True, metavar="KEY=VALUE", help="driver connect option")
@click.option("--contact-force", default=0.01, show_default=True,
              type=FiniteFloat(0.0, 5.0, min_open=True), help="homing contact force [N]")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="experiment file (HDF5)")
@click.option("--json", "as_json", is_flag=True, help="print the run summary as JSON")
def run(
    protocol_name: str,
    driver_name: str,
    port: str | None,
    params: tuple[str, ...],
    options: tuple[str, ...],
    contact_force: float,
    out: str,
    as_json: bool,
) -> None:
    """Home the robot and run PROTOCOL, streaming its samples into --out."""
    from skinkit import registry
    from skinkit.acquisition import make_protocol, run_protocol
    from skinkit.cli._paths import check_out_file
    from skinkit.store import create_experiment, open_experiment

    path = check_out_file(out, "--out")
    protocol = make_protocol(protocol_name, **_parse_kv(params, "--param"))
    opts = _parse_kv(options, "--option")
    _check_options(opts)
    if port:
        opts["port"] = port
    if path.exists():  # a record of this name would be refused after homing: refuse now
        with open_experiment(path) as exp:
            if protocol.name in exp.record_names():
                raise SkinkitError(f"--out {path}: already holds a record {protocol.name!r}")
    driver = registry.create("skinkit.drivers", driver_name)
    created = not path.exists()
    attempt = {"driver": driver_name, "options": {k: str(v) for k, v in opts.items()},
               "contact_force_N": contact_force, "stage": "connect",
               "started": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    exp: _LazyExperiment | None = None
    try:
        refused = f"--option: driver {driver_name!r} refused its options"
        try:  # an unknown option: checked against connect's signature, not by calling it
            inspect.signature(driver.connect).bind(**opts)
        except TypeError as exc:
            raise OptionError(f"{refused}: {exc}") from None
        try:
            driver.connect(**opts)
        except ValueError as exc:  # OptionError, or how a driver refuses a value; else a bug
            raise OptionError(f"{refused}: {exc}") from None
        attempt["stage"] = "home"
        driver.home(contact_force)
        attempt["stage"] = "run"
        exp = _LazyExperiment(path, open_experiment, create_experiment)
        try:
            with progress(transient=True) as bar:   # on stderr, also with --json
                summary = run_protocol(driver, protocol, exp, progress=lambda t, end, n, lost: bar.update(
                    protocol.name, min(t / end, 1.0) if end > 0 else None, f"{n} samples, {lost} lost"))
        finally:
            exp.close()
    except RefusedError:  # nothing was done: leave no trace (a device-side refusal may have
        if created:       # opened the record already)
            _drop_if_empty(path)
        elif exp is not None and exp.opened:
            with open_experiment(path, mode="a") as exp_:
                exp_.discard_empty_record(protocol.name)
        raise
    except BaseException as exc:
        # the run was attempted: the file says so, whatever stopped it
        _record_attempt(path, protocol, driver, attempt, exc)
        raise
    finally:
        try:
            driver.disconnect()
        except SkinkitError:
            pass
    _report(summary, protocol, path, as_json)


def _record_attempt(path: Path, protocol: Any, driver: Any, attempt: dict[str, Any],
                    exc: BaseException) -> None:
    """Write a failed run into ``path`` (created if need be): an empty record is replaced by
    an ``/attempts`` entry with the stage, the reason and the driver's link accounting, so a
    retry can still write the record; a record with samples stays beside the entry."""
    from skinkit.store import create_experiment, open_experiment

    stats = getattr(driver, "last_run", None) if attempt["stage"] == "run" else None
    facts = {**attempt, "reason": str(exc) or type(exc).__name__, "error": type(exc).__name__,
             "link": stats.to_dict() if hasattr(stats, "to_dict") else None}
    try:
        with (open_experiment(path, mode="a") if path.exists() else create_experiment(path)) as exp:
            exp.discard_empty_record(protocol.name)
            kept = protocol.name in exp.record_names()
            facts["samples"] = exp.record_info(protocol.name)["samples"] if kept else 0
            facts["record"] = protocol.name if kept else None
            exp.add_attempt(protocol, **json.loads(jsonio.dumps(facts, default=str)))
    except (SkinkitError, OSError) as write_exc:  # never hide the run's own error behind this
        click.echo(f"warning: the failed attempt could not be written to {path}: {write_exc}", err=True)


class _LazyExperiment:
    """The experiment file, opened (or created) only when the run starts its record: a
    protocol the driver refuses before motion leaves an existing file untouched."""

    def __init__(self, path: Path, open_experiment: Any, create_experiment: Any) -> None:
        self.path = path
        self._open_fn, self._create_fn = open_experiment, create_experiment
        self._exp: Any = None

    def _get(self) -> Any:
        if self._exp is None:
            self._exp = (self._open_fn(self.path, mode="a") if self.path.exists()
                         else self._create_fn(self.path))
        return self._exp

    @property
    def opened(self) -> bool:
        """Whether the run got as far as opening the file (to start its record)."""
        return self._exp is not None

    def record_writer(self, *args: Any, **kwargs: Any) -> Any:
        return self._get().record_writer(*args, **kwargs)

    def set_record_attrs(self, *args: Any, **kwargs: Any) -> Any:
        if self._exp is not None:  # no record was started: nothing to account for
            return self._exp.set_record_attrs(*args, **kwargs)
        return None

    def close(self) -> None:
        if self._exp is not None:
            self._exp.close()


def _drop_if_empty(path: Path) -> None:
    """Remove an experiment file this run created if it holds no sample (a refused run);
    a run that faulted after recording keeps its samples."""
    from skinkit.store import open_experiment

    if not path.exists():
        return
    try:
        with open_experiment(path) as exp:
            empty = all(r["samples"] == 0 for r in exp.summary()["records"])
    except SkinkitError:
        empty = True  # not even a readable file: nothing worth keeping
    if empty:
        path.unlink()


def _report(summary: Any, protocol: Any, path: Path, as_json: bool) -> None:
    if as_json:
        click.echo(jsonio.dumps(summary.to_dict(), indent=1))
    else:
        click.echo(f"{protocol.name}: {summary.samples} samples, {summary.duration_s:.2f} s -> {path}")
    if summary.lost:
        click.echo(
            f"warning: {summary.lost} samples lost on the link; the samples after each gap carry "
            "the samples_lost flag",
            err=True,
        )
