"""A solving process keeps large arrays in its heap even where its environment fixed glibc's
thresholds low (Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536`` in every worker): told by
glibc's own count of the bytes it holds in mapped blocks (``mallinfo2().hblkhd``) while a 4 MiB
array lives — mapped afresh, each such array adds its 4 MiB there; from the heap, nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

_PROBE = r"""
import ctypes, json
import numpy as np
from skinkit.forward.allocator import keep_large_blocks

class Mallinfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd",
                                               "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = Mallinfo2

def mapped_by_one_array():
    a = np.ones(2**19)              # 4 MiB
    held = libc.mallinfo2().hblkhd
    del a
    return held - libc.mallinfo2().hblkhd

mapped_by_one_array()              # glibc's adaptation, where it is on, learns from a first one
first = mapped_by_one_array()
changed = keep_large_blocks()
print(json.dumps({"before": first, "changed": changed, "after": mapped_by_one_array(),
                  "again": keep_large_blocks()}))
"""

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
MIB4 = 4 * 2**20


def _probe(env: dict[str, str]) -> dict:
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def _clean() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if not k.startswith(("MALLOC_", "GLIBC_TUNABLES"))}


def test_fixed_low_thresholds_are_raised_once():
    r = _probe({**_clean(), "MALLOC_TRIM_THRESHOLD_": "65536"})
    assert r["changed"] and not r["again"]
    assert r["before"] >= MIB4        # every large array mapped afresh
    assert r["after"] == 0            # from the heap


def test_adaptive_thresholds_are_left_alone():
    r = _probe(_clean())
    assert not r["changed"]
    assert r["before"] == 0 and r["after"] == 0    # glibc's own adaptation already keeps them
