"""Protocol solves kept on disk for a second run of the same command.

A finite-element prediction solves one job per protocol (:class:`skinkit.forward.fe.ProtocolJob`):
the model description with its effects, the mesh fitted to the session, the drive at the solver's
steps, the tracked points' embedding and the parameters differentiated. A second run of a command
on the same model and session file (a diagnosis run again with other options, a fit after a
crash) solves many of the same jobs. With a cache directory — the environment
variable ``SKINKIT_SOLVE_CACHE`` — each job's outputs are
stored under a key of its content and read back instead of solved.

**Key.** SHA-256 over the job's content, pickled (every number to the bit), and a fingerprint of
the code that solves it: the source files of skinkit and of every installed package that
provides skinkit plugins, and the versions of the numerical libraries. A job that differs in
any input, or any change of that code, is a miss: the cache never answers for another model,
session or release. Jobs that write field files (``options["vtu"]``) are always solved.

**Store.** One file per job (``<key>.npz``, written to a temporary name and renamed, so a crash
leaves no partial entry); an entry that cannot be read is solved again and replaced. When the
directory holds more than :data:`MAX_BYTES` (8 GiB; ``SKINKIT_SOLVE_CACHE_GB`` sets another size),
the least recently used entries go. A hit's
``info`` says ``"cached": True`` (its ``wall_s`` is the original solve's): benchmarks, which
measure solves, run without a cache.
"""

from __future__ import annotations

import functools
import hashlib
import io
import math
import os
import pickle
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from skinkit.errors import SkinkitError

#: the environment variable naming the cache directory (unset or empty: no cache)
ENVIRONMENT = "SKINKIT_SOLVE_CACHE"
#: the most bytes the cache directory keeps by default (a quick demo stores about 2.5 GB: a
#: region scan's prediction carries a hundred sensitivity columns); beyond, least recently used
#: entries are removed
MAX_BYTES = 8 * 1024**3
#: the environment variable overriding :data:`MAX_BYTES`, in GiB
ENVIRONMENT_SIZE = "SKINKIT_SOLVE_CACHE_GB"
#: numerical libraries whose version is part of the key (their arithmetic is in every answer)
LIBRARIES = ("numpy", "scipy", "scikit-fem", "pypardiso", "mkl")


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 [hex] of the source of skinkit and of the packages providing skinkit plugins,
    and of the numerical libraries' versions."""
    from importlib import metadata
    from importlib.util import find_spec

    from skinkit.registry import GROUP_NAMES

    roots = {"skinkit"}
    eps = metadata.entry_points()
    for group in GROUP_NAMES:
        for ep in eps.select(group=group):
            roots.add(ep.value.split(":")[0].split(".")[0])
    h = hashlib.sha256()
    for root in sorted(roots):
        spec = find_spec(root)
        if spec is None or not spec.submodule_search_locations:
            h.update(f"{root}: missing".encode())
            continue
        for base in spec.submodule_search_locations:
            for path in sorted(Path(base).rglob("*.py")):
                h.update(str(path.relative_to(base)).encode())
                h.update(path.read_bytes())
    for lib in LIBRARIES:
        try:
            h.update(f"{lib}={metadata.version(lib)}".encode())
        except metadata.PackageNotFoundError:
            h.update(f"{lib}=none".encode())
    h.update(sys.version.encode())
    return h.hexdigest()


class SolveCache:
    """Protocol-solve outputs on disk under ``directory``, keyed by job content and code."""

    def __init__(self, directory: str | os.PathLike[str], max_bytes: int = MAX_BYTES) -> None:
        self.directory = Path(directory)
        self.max_bytes = int(max_bytes)
        self.hits = 0
        self.misses = 0

    @classmethod
    def from_environment(cls) -> SolveCache | None:
        """The cache named by ``SKINKIT_SOLVE_CACHE`` (at most ``SKINKIT_SOLVE_CACHE_GB`` GiB), or
        None when it is unset or empty. Raises :class:`SkinkitError` for a size that is not a
        positive number."""
        d = os.environ.get(ENVIRONMENT, "").strip()
        if not d:
            return None
        size = os.environ.get(ENVIRONMENT_SIZE, "").strip()
        if not size:
            return cls(d)
        try:
            gib = float(size)
        except ValueError:
            gib = float("nan")
        if not (math.isfinite(gib) and gib > 0):
            raise SkinkitError(f"{ENVIRONMENT_SIZE}={size!r}: expected a positive number of GiB")
        return cls(d, int(gib * 1024**3))

    def key(self, job: Any) -> str:
        """SHA-256 [hex] of the code fingerprint and the job's pickled content."""
        h = hashlib.sha256(code_fingerprint().encode())
        h.update(pickle.dumps(job, protocol=5))
        return h.hexdigest()

    def _path(self, key: str) -> Path:
        return self.directory / f"{key}.npz"

    def get(self, job: Any, key: str | None = None) -> dict[str, Any] | None:
        """The stored outputs of ``job`` (a :func:`skinkit.forward.fe.solve_protocol` result), or
        None (not stored, or unreadable: then removed); ``key``: :meth:`key` of ``job`` when
        already known."""
        path = self._path(key or self.key(job))
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files if k != "__meta__"}
                meta = pickle.loads(z["__meta__"].tobytes())
        except FileNotFoundError:
            self.misses += 1
            return None
        except Exception:   # a damaged entry is a miss, and goes
            path.unlink(missing_ok=True)
            self.misses += 1
            return None
        os.utime(path)      # recently used
        self.hits += 1
        out = {**meta, **arrays}
        out["info"] = {**out.get("info", {}), "cached": True}
        return out

    def put(self, job: Any, result: dict[str, Any], key: str | None = None) -> None:
        """Store ``result`` for ``job`` (atomically; ``key``: :meth:`key` of ``job`` when already
        known), then trim the directory to ``max_bytes``."""
        self.directory.mkdir(parents=True, exist_ok=True)
        arrays = {k: v for k, v in result.items() if isinstance(v, np.ndarray)}
        meta = {k: v for k, v in result.items() if not isinstance(v, np.ndarray)}
        buf = io.BytesIO()
        np.savez(buf, __meta__=np.frombuffer(pickle.dumps(meta, protocol=5), dtype=np.uint8), **arrays)
        path = self._path(key or self.key(job))
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(buf.getvalue())
        os.replace(tmp, path)
        self._trim()

    def _trim(self) -> None:
        entries = [(p.stat().st_mtime, p.stat().st_size, p) for p in self.directory.glob("*.npz")]
        total = sum(s for _, s, _ in entries)
        for _, size, p in sorted(entries, key=lambda e: e[0]):
            if total <= self.max_bytes:
                break
            p.unlink(missing_ok=True)
            total -= size


def solve_jobs(jobs: Sequence[Any], solve: Callable[[list[Any]], dict[str, dict[str, Any]]],
               cache: SolveCache | None = None) -> dict[str, dict[str, Any]]:
    """``solve(jobs)`` for the jobs not in ``cache`` (default: the environment's), the rest read
    back; the solved ones are stored. Returns protocol name -> outputs, in the jobs' order."""
    cache = cache if cache is not None else SolveCache.from_environment()
    if cache is None:
        return solve(list(jobs))
    found, todo, keys = {}, [], {}
    for job in jobs:
        if job.options.get("vtu"):      # files written as a side effect: always solved
            todo.append(job)
            continue
        # hashing pickles the job's mesh and state: once per job
        keys[job.name] = cache.key(job)
        hit = cache.get(job, keys[job.name])
        if hit is None:
            todo.append(job)
        else:
            found[job.name] = hit
    solved = solve(todo) if todo else {}
    for job in todo:
        if job.name in keys:
            cache.put(job, solved[job.name], keys[job.name])
    return {job.name: found.get(job.name, solved.get(job.name)) for job in jobs}


__all__ = ["ENVIRONMENT", "ENVIRONMENT_SIZE", "MAX_BYTES", "SolveCache", "code_fingerprint", "solve_jobs"]
