"""The verification suite: every case passes within its stated tolerance."""

from __future__ import annotations

import pytest

from skinkit.fem import verify

pytestmark = pytest.mark.needs_plugins


@pytest.mark.parametrize("name", verify.names())
def test_verification_case(name):
    res = verify.run([name])["cases"][0]
    assert res["passed"], res
    assert res["tolerance"] > 0
