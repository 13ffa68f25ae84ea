"""The experiment-first order of positional arguments, and the old order kept for one release.

A command that imports into or writes an experiment file takes ``EXPERIMENT`` first, then what
it reads (see :mod:`skinkit.cli`). When a user evidently gave the old, source-first order —
the path in the experiment's place is not HDF5 (a folder, a file without the HDF5 signature, a
``.csv``) while the other one is HDF5 (by signature, or by its ``.h5``/``.hdf5`` name when it
does not exist yet) — the two are swapped and one warning line goes to stderr.
"""

from __future__ import annotations

from pathlib import Path

import click

#: the first bytes of an HDF5 superblock
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: where a superblock may start (after a user block of 512, 1024, ... bytes)
_SIGNATURE_OFFSETS = (0, 512, 1024, 2048, 4096, 8192, 16384, 32768, 65536)
HDF5_SUFFIXES = (".h5", ".hdf5")
#: names that are never an experiment file
SOURCE_SUFFIXES = (".csv", ".txt", ".tsv", ".dat")


def has_hdf5_signature(path: Path) -> bool:
    """Whether the file ``path`` starts with an HDF5 superblock (at any user-block offset)."""
    try:
        with open(path, "rb") as f:
            for off in _SIGNATURE_OFFSETS:
                f.seek(off)
                if f.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE:
                    return True
    except OSError:
        return False
    return False


def _is_hdf5(path: Path) -> bool:
    if path.is_file():
        return has_hdf5_signature(path)
    return not path.exists() and path.suffix.lower() in HDF5_SUFFIXES


def _not_hdf5(path: Path) -> bool:
    if path.is_dir():
        return True
    if path.is_file():
        return not has_hdf5_signature(path)
    return path.suffix.lower() in SOURCE_SUFFIXES


def experiment_first(experiment: Path, source: Path, command: str) -> tuple[Path, Path]:
    """``(experiment, source)`` in the order the command takes them: swapped, after one
    ``warning:`` line on stderr, when they were evidently given in the old source-first order."""
    if _not_hdf5(experiment) and _is_hdf5(source):
        click.echo(f"warning: '{command} {experiment} {source}' uses the deprecated order SOURCE "
                   f"EXPERIMENT; read as '{command} {source} {experiment}' (the experiment file comes "
                   "first; the old order will be refused in a later release)", err=True)
        return source, experiment
    return experiment, source
