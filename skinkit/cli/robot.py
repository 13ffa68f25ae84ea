"""``skinkit robot``: list the measurement protocols and run one through a robot driver.

Other distributions add subcommands through the entry-point group ``skinkit.commands.robot``
(skinkit-hardware adds ``skinkit robot emulate``); the core imports no driver.
"""

from __future__ import annotations

import json
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import click

from skinkit.errors import SkinkitError

#: entry-point group for ``skinkit robot`` subcommands contributed by other distributions
ROBOT_COMMANDS_GROUP = "skinkit.commands.robot"


class _RobotGroup(click.Group):
    def _ext(self) -> dict[str, Any]:
        return {ep.name: ep for ep in entry_points(group=ROBOT_COMMANDS_GROUP)}

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(super().list_commands(ctx)) | set(self._ext()))

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        cmd = super().get_command(ctx, name)
        if cmd is not None:
            return cmd
        ep = self._ext().get(name)
        if ep is None:
            return None
        try:
            return ep.load()
        except Exception as exc:  # a broken extension must not break the other commands
            raise click.ClickException(
                f"robot command {name!r} ({ep.value}) failed to import: {type(exc).__name__}: {exc}"
            ) from exc


@click.group(cls=_RobotGroup)
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
            json.dumps(
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
@click.option("--contact-force", default=0.01, show_default=True, type=float, help="homing contact force [N]")
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
    from skinkit.store import create_experiment, open_experiment

    protocol = make_protocol(protocol_name, **_parse_kv(params, "--param"))
    driver = registry.create("skinkit.drivers", driver_name)
    opts = _parse_kv(options, "--option")
    if port:
        opts["port"] = port
    path = Path(out)
    try:
        driver.connect(**opts)
        driver.home(contact_force)
        exp = open_experiment(path, mode="a") if path.exists() else create_experiment(path)
        with exp:
            summary = run_protocol(driver, protocol, exp, progress=not as_json)
    finally:
        try:
            driver.disconnect()
        except SkinkitError:
            pass
    if as_json:
        click.echo(json.dumps(summary.to_dict(), indent=1))
    else:
        click.echo(f"{protocol.name}: {summary.samples} samples, {summary.duration_s:.2f} s -> {path}")
    if summary.lost:
        click.echo(
            f"warning: {summary.lost} samples lost on the link; the samples after each gap carry "
            "the samples_lost flag",
            err=True,
        )
