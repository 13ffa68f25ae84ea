"""``skinkit import-csv``: put a plain CSV robot record into an experiment file."""

from __future__ import annotations

from pathlib import Path

import click

from skinkit.cli._order import experiment_first
from skinkit.cli._paths import check_name, check_out_file, staged_file
from skinkit.errors import StoreError
from skinkit.store import create_experiment, open_experiment, read_robot_csv


@click.command("import-csv")
@click.argument("experiment", type=click.Path(path_type=Path))
@click.argument("csv_file", type=click.Path(path_type=Path))
@click.option("--protocol", default=None, help="Record name (default: the CSV file's stem); "
              "no '/' or '..'.")
@click.option("--axis", type=click.Choice(["x", "y", "z"]), default="z", show_default=True,
              help="Tip axis of one-axis columns (force_N, position_m, displacement_mm).")
def import_csv(experiment: Path, csv_file: Path, protocol: str | None, axis: str) -> None:
    """Import CSV_FILE (header with units, e.g. time_s,tip_force_z_N,tip_position_z_mm) as a
    robot record into EXPERIMENT (created if it does not exist).

    The old order CSV_FILE EXPERIMENT is still read, with a warning, when it is evident (the
    first is not HDF5, the second is)."""
    experiment, csv_file = experiment_first(experiment, csv_file, "skinkit import-csv")
    check_name(protocol if protocol is not None else csv_file.stem, "--protocol", "protocol name")
    check_out_file(experiment, "EXPERIMENT")
    record = read_robot_csv(csv_file, protocol, axis)
    if experiment.exists():
        with open_experiment(experiment) as exp:  # refuse a duplicate before opening to write
            if record.protocol.name in exp.record_names():
                raise StoreError(str(experiment), f"records/{record.protocol.name}",
                                 "already exists; choose another --protocol")
        with open_experiment(experiment, "a") as exp:
            exp.write_record(record)
    else:
        with staged_file(experiment) as tmp:  # a failed import leaves no new file
            with create_experiment(tmp) as exp:
                exp.write_record(record)
    click.echo(f"imported {record.n_samples} samples at {record.rate_hz:.6g} Hz "
               f"({', '.join(record.channels)}) as record {record.protocol.name!r} into {experiment}")
