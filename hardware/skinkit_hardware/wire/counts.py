"""Samples on the wire are the sensors' native counts, so no link adds quantisation:
position ADC counts (uint16), current in steps of ``current_lsb_A`` (int16), F/T force and
torque in steps of the Nano17's resolution (int16). Setpoints: positions in nm and forces in
uN (int32) on serial, 0.5 um and 1 mN (int16) on CAN."""

from __future__ import annotations

import numpy as np

from skinkit_hardware.params import RobotParameters


def rows_to_counts(rows: np.ndarray, p: RobotParameters) -> dict[str, np.ndarray]:
    """Device rows ``(n, 15)`` -> integer fields (index, tick, pos, cur, force, torque, flags)."""
    lo, hi = p.adc_span_m
    lsb = (hi - lo) / ((1 << p.adc_bits) - 1)
    return {
        "index": rows[:, 0].astype(np.int64),
        "tick": rows[:, 1].astype(np.int64),
        "pos": np.rint((rows[:, 2:5] - lo) / lsb).astype(np.int64),
        "cur": np.rint(rows[:, 5:8] / p.current_lsb_A).astype(np.int64),
        "force": np.rint(rows[:, 8:11] / p.ft_force_resolution_N).astype(np.int64),
        "torque": np.rint(rows[:, 11:14] / p.ft_torque_resolution_Nm).astype(np.int64),
        "flags": rows[:, 14].astype(np.int64),
    }


def counts_to_rows(c: dict[str, np.ndarray], p: RobotParameters) -> np.ndarray:
    """Inverse of :func:`rows_to_counts`: SI rows ``(n, 15)``."""
    lo, hi = p.adc_span_m
    lsb = (hi - lo) / ((1 << p.adc_bits) - 1)
    n = c["index"].shape[0]
    rows = np.empty((n, 15))
    rows[:, 0] = c["index"]
    rows[:, 1] = c["tick"]
    rows[:, 2:5] = lo + c["pos"] * lsb
    rows[:, 5:8] = c["cur"] * p.current_lsb_A
    rows[:, 8:11] = c["force"] * p.ft_force_resolution_N
    rows[:, 11:14] = c["torque"] * p.ft_torque_resolution_Nm
    rows[:, 14] = c["flags"]
    return rows
