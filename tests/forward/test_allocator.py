"""A solving process keeps large arrays in its heap even where its environment fixed glibc's
thresholds low (Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536`` in every worker): counted by
the page faults of allocating and filling the same 4 MiB array again and again — mapped afresh,
each fill touches its 1,024 pages anew; from the heap, only the first does."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

_PROBE = r"""
import json, resource
import numpy as np
from skinkit.forward.allocator import keep_large_blocks

def faults():
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(100):
        a = np.ones(2**19)          # 4 MiB
        del a
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

first = faults()
changed = keep_large_blocks()
print(json.dumps({"before": first, "changed": changed, "after": faults(), "again": keep_large_blocks()}))
"""

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")


def _probe(env: dict[str, str]) -> dict:
    out = subprocess.run([sys.executable, "-c", _PROBE], env={**os.environ, **env}, capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout)


def test_fixed_low_thresholds_are_raised_once():
    r = _probe({"MALLOC_TRIM_THRESHOLD_": "65536"})
    pages = 100 * 1024
    assert r["changed"] and not r["again"]
    # mapped afresh, every array faults its pages in (the kernel may map a few per fault)
    assert r["before"] > 0.25 * pages
    assert r["after"] < 0.02 * pages          # the heap's pages reused


def test_adaptive_thresholds_are_left_alone():
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True)
    r = json.loads(out.stdout)
    assert not r["changed"]
    assert r["after"] < 0.02 * 100 * 1024     # glibc's own adaptation already keeps them
