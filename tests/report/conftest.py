"""The report tests' one experiment file, built once per test session (report_session.py)."""

from __future__ import annotations

from typing import Any

import pytest
from report_session import build_session


@pytest.fixture(scope="session")
def full_session(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The experiment file with every kind of result, and what is known of it by construction."""
    pytest.importorskip("skinkit_plugins", reason="the lab session, fit and gap diagnosis need the plugins")
    return build_session(tmp_path_factory.mktemp("report"))
