"""Fixtures of the sysid tests (constants live in ``sysid_truth``)."""

from __future__ import annotations

import pytest
from sysid_truth import ROBOT, SKIN

from skinkit.sysid.lti import SecondOrder


@pytest.fixture(scope="session")
def total() -> SecondOrder:
    """Skin (thesis Table 7 forearm) plus the robot's moving mass: what the robot measures."""
    return ROBOT.add(SKIN)
