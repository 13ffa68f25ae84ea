"""The experiment store: one HDF5 file per session (layout in :mod:`skinkit.store.layout`)."""

from skinkit.store.csv_import import read_robot_csv, write_robot_csv
from skinkit.store.experiment import (
    Experiment,
    RecordWriter,
    create_experiment,
    open_experiment,
    recover,
)
from skinkit.store.layout import SCHEMA_VERSION

__all__ = [
    "SCHEMA_VERSION",
    "Experiment",
    "RecordWriter",
    "create_experiment",
    "open_experiment",
    "read_robot_csv",
    "recover",
    "write_robot_csv",
]
