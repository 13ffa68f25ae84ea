"""Output paths of CLI commands: checked before work starts, written under a temporary name
and renamed into place on success, so a refused or failed command leaves nothing behind and
never changes an existing file."""

from __future__ import annotations

import contextlib
import fnmatch
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from skinkit.errors import SkinkitError


def _existing_ancestor_problem(path: Path) -> str | None:
    for parent in path.parents:
        if parent.exists() or parent.is_symlink():
            if not parent.is_dir():
                return f"{parent} is not a directory"
            if not os.access(parent, os.W_OK | os.X_OK):
                return f"{parent} is not writable"
            return _cannot_write_in(parent)
    return None


def _cannot_write_in(folder: Path) -> str | None:
    """Why no file can be created in ``folder``, or None. A file is created and removed: the
    permission bits alone do not tell (a read-only mount, a pseudo-filesystem, or a user such as
    root whom the bits do not stop)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".skinkit-probe-", dir=folder)
    except OSError as exc:
        return f"{folder} is not writable: {exc.strerror or exc}"
    os.close(fd)
    os.unlink(probe)
    return None


def check_out_dir(path: str | os.PathLike, option: str) -> Path:
    """An output directory that can be created or replaced: not a file, not a symbolic link,
    not under a file. Raises a one-line :class:`SkinkitError` naming ``option``."""
    p = Path(path)
    if p.is_symlink():
        raise SkinkitError(f"{option} {p}: is a symbolic link; give the directory it points to")
    if p.exists() and not p.is_dir():
        raise SkinkitError(f"{option} {p}: is a file, not a directory")
    problem = _existing_ancestor_problem(p)
    if problem:
        raise SkinkitError(f"{option} {p}: cannot create it ({problem})")
    return p


def check_out_file(path: str | os.PathLike, option: str, *, parents: bool = False) -> Path:
    """An output file path whose directory exists (or, with ``parents``, can be created) and
    which is not a directory or a symbolic link."""
    p = Path(path)
    if p.is_symlink():
        raise SkinkitError(f"{option} {p}: is a symbolic link; give the file it points to")
    if p.is_dir():
        raise SkinkitError(f"{option} {p}: is a directory, not a file")
    if not parents and not p.parent.is_dir():
        what = "is not a directory" if p.parent.exists() else "does not exist"
        raise SkinkitError(f"{option} {p}: its folder {p.parent} {what}")
    problem = _existing_ancestor_problem(p)
    if problem:
        raise SkinkitError(f"{option} {p}: cannot create it ({problem})")
    return p


def check_result_dir(path: str | os.PathLike, option: str, *, overwrite: bool,
                     owned: Sequence[str], command: str) -> Path:
    """A results directory that a command replaces as a whole (:func:`staged_dir`): absent, empty,
    or -- with ``overwrite`` -- holding only files the command writes (``owned``, glob patterns).
    An earlier result is never replaced silently, and a folder of other files never at all.
    Raises a one-line :class:`SkinkitError` naming ``option``."""
    p = check_out_dir(path, option)
    if not p.is_dir():
        return p
    entries = sorted(e.name for e in p.iterdir())
    others = [e for e in entries if not any(fnmatch.fnmatch(e, pat) for pat in owned)]
    if others:
        raise SkinkitError(f"{option} {p}: holds files {command} did not write ({others[0]}); "
                           "give a new or empty folder")
    if entries and not overwrite:
        raise SkinkitError(f"{option} {p}: already holds a result ({entries[0]}); give another "
                           f"{option}, or --overwrite to replace it")
    return p


def check_result_files(folder: str | os.PathLike, names: Sequence[str], option: str, *,
                       overwrite: bool) -> Path:
    """A folder a command writes the files ``names`` into (beside whatever else it holds): none of
    them may exist already unless ``overwrite``. Raises a one-line :class:`SkinkitError`."""
    p = check_out_dir(folder, option)
    there = [n for n in names if (p / n).exists() or (p / n).is_symlink()]
    if there and not overwrite:
        raise SkinkitError(f"{option} {p}: already holds {there[0]} (an earlier result); give another "
                           f"{option}, or --overwrite to replace it")
    return p


def check_name(name: str, option: str, what: str = "name") -> str:
    """A record, protocol or image-set name: non-empty, no path separator, no ``..``; ``what``
    says in a refusal what ``option`` expects (e.g. ``"protocol name"``)."""
    if not name or not name.strip():
        got = "an empty string" if not name else f"only blanks ({name!r})"
        article = "an" if what[:1] in "aeiou" else "a"
        raise SkinkitError(f"{option}: expected {article} {what}, got {got}")
    if "/" in name or "\\" in name or "\0" in name or ".." in name:
        raise SkinkitError(f"{option} {name!r}: a name must not contain '/', '\\', '..' or NUL")
    return name


def name_callback(what: str) -> Callable[[Any, Any, str | None], str | None]:
    """Click callback of a name option whose default (None) is made later: a value given is
    :func:`check_name`-ed as ``what`` (e.g. ``"fit name"``), so an empty one is refused rather
    than taken as the default."""
    def callback(ctx: Any, param: Any, value: str | None) -> str | None:
        return None if value is None else check_name(value, param.opts[0], what)
    return callback


@contextlib.contextmanager
def staged_dir(out: Path) -> Iterator[Path]:
    """Yield a fresh temporary directory beside ``out``; on success it replaces ``out`` (an
    existing ``out`` is removed only then), on failure it is deleted."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=_anchor(out)))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    out.parent.mkdir(parents=True, exist_ok=True)  # only now: a failure creates no folder
    old = None
    if out.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.replace(out, old / "x")
    os.replace(tmp, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def staged_file(out: Path) -> Iterator[Path]:
    """Yield a temporary file path beside ``out`` (a copy of ``out`` if it exists, for an
    append); on success it replaces ``out``, on failure it is deleted."""
    fd, name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=_anchor(out))
    os.close(fd)
    tmp = Path(name)
    try:
        if out.exists():
            shutil.copy2(out, tmp)
        else:
            tmp.unlink()
        yield tmp
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    out.parent.mkdir(parents=True, exist_ok=True)
    os.replace(tmp, out)


def _anchor(out: Path) -> Path:
    """The nearest existing folder of ``out`` (same file system, so the rename is atomic)."""
    for parent in Path(os.path.abspath(out)).parents:
        if parent.is_dir():
            return parent
    return Path.cwd()
