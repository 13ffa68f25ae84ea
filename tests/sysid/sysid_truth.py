"""Shared truth for the sysid tests: thesis Table 7 forearm values plus the robot's moving
mass (about 25 g, thesis Fig. 4-9), Table 8 nonlinearity. (A uniquely named module, not
``conftest``, so that imports cannot collide with other test folders.)"""

from __future__ import annotations

from skinkit.sysid.lti import SecondOrder
from skinkit.sysid.robot import RobotDynamics

SKIN = SecondOrder(K=1450.0, B=4.76, I=0.0155)
ROBOT = RobotDynamics(mass_kg=0.025)
C1_M, C2_PER_N = 8.6e-3, 0.51
SEEDS = (1, 2, 3)
