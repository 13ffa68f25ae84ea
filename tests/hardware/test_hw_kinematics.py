"""Kinematics of the parallel mechanism: round trips to 1 um over the workspace (property
based) and the closed-form small-motion behaviour the docstring promises."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytestmark = pytest.mark.needs_hardware

kin = pytest.importorskip("skinkit_hardware.kinematics")

G = kin.Geometry()
LO, HI = G.travel_m
arm = st.floats(min_value=LO, max_value=HI, allow_nan=False)
TOL = 1e-6  # the acceptance figure: 1 um


@settings(max_examples=200, deadline=None)
@given(arm, arm, arm)
def test_inverse_of_forward_returns_the_arm_positions(q1: float, q2: float, q3: float) -> None:
    q = np.array([q1, q2, q3])
    back = kin.inverse(kin.forward(q, G), G)
    assert np.max(np.abs(back - q)) < TOL


@settings(max_examples=200, deadline=None)
@given(arm, arm, arm)
def test_forward_of_inverse_returns_the_tip(q1: float, q2: float, q3: float) -> None:
    tip = kin.forward(np.array([q1, q2, q3]), G)  # a tip the mechanism can reach
    again = kin.forward(kin.inverse(tip, G), G)
    assert np.max(np.abs(again - tip)) < TOL


@settings(max_examples=50, deadline=None)
@given(st.floats(0.015, 0.05), st.floats(0.01, 0.06), arm, arm, arm)
def test_round_trip_holds_for_other_geometries(r: float, h: float, q1: float, q2: float, q3: float) -> None:
    g = kin.Geometry(base_radius_m=r, tip_height_m=h)
    q = np.array([q1, q2, q3])
    assert np.max(np.abs(kin.inverse(kin.forward(q, g), g) - q)) < TOL


def test_batched_round_trip_over_a_grid() -> None:
    axis = np.linspace(LO, HI, 9)
    q = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    assert np.max(np.abs(kin.inverse(kin.forward(q, G), G) - q)) < TOL


def test_equal_arms_move_the_tip_along_the_normal_only() -> None:
    a = kin.forward(np.full(3, 0.004), G)
    b = kin.forward(np.full(3, 0.006), G)
    np.testing.assert_allclose(b - a, [0, 0, 0.002], atol=1e-12)
    np.testing.assert_allclose(a, [0, 0, 0.004 + G.tip_height_m], atol=1e-12)


@pytest.mark.parametrize("motor", [0, 1, 2])
def test_one_arm_swings_the_tip_sideways_away_from_it(motor: int) -> None:
    # Small-angle closed form: raising one pin by dq tilts the platform plane by dq/(1.5 r)
    # towards that pin, so the tip moves by -h dq/(1.5 r) along the arm's radial direction
    # and the platform centre rises dq/3. The leading neglected term is the tip's drop
    # h (1 - cos theta) ~ h theta^2 / 2 with theta = dq / (1.5 r); bound it by h theta^2.
    dq = 1e-5
    q0 = np.full(3, G.home_m)
    dq_vec = np.zeros(3)
    dq_vec[motor] = dq
    d = kin.forward(q0 + dq_vec, G) - kin.forward(q0, G)
    u = G.radial[motor]
    expected = -G.tip_height_m * dq / (1.5 * G.base_radius_m) * u + np.array([0, 0, dq / 3])
    theta = dq / (1.5 * G.base_radius_m)
    np.testing.assert_allclose(d, expected, rtol=0, atol=G.tip_height_m * theta**2)


def test_jacobian_maps_small_arm_motions_to_tip_motions() -> None:
    rng = np.random.default_rng(1)
    q = rng.uniform(0.002, 0.008, 3)
    dq = rng.normal(0, 1e-7, 3)
    J = kin.jacobian(q, G)
    # linearisation error O(|dq|^2 / r) < 1e-12 m
    np.testing.assert_allclose(kin.forward(q + dq, G) - kin.forward(q, G), J @ dq, atol=1e-12)


def test_bad_inputs_are_refused_with_a_reason() -> None:
    with pytest.raises(kin.KinematicsError, match="shape"):
        kin.inverse(np.zeros(2), G)
    with pytest.raises(kin.KinematicsError, match="home_m"):
        kin.Geometry(home_m=0.02)
    assert not kin.in_travel(np.array([0.0, 0.011, 0.005]), G)
