"""The contract's CORDIC ROM, written out in ``hdl/contract/numeric_contract.py``, equals the one
the reference computes from ``math.atan`` on its own; the register encodings round-trip."""

import numpy as np

from mpu9250_ahrs.hdl.contract import numeric_contract as contract
from mpu9250_ahrs.reference import fixed_point


def test_cordic_tables_agree():
    assert contract.CORDIC_ITERATIONS == fixed_point.CORDIC_ITERATIONS
    assert contract.CORDIC_SHORT_ITERATIONS == fixed_point.CORDIC_SHORT_ITERATIONS
    assert contract.ATAN_TABLE == fixed_point.ATAN_TABLE
    assert contract.INV_GAIN_Q30 == fixed_point.INV_GAIN_Q30


def test_calibration_registers_round_trip():
    cal = contract.CalibrationFixed.from_units(
        gyro_offset=np.array([35.3, -20.3, 11.8]), accel_offset=(121, -84, 198),
        accel_scale=np.array([1.01, 0.99, 1.0]), hard_iron=(150.7, -90.0, 60.8),
        soft_iron=np.array([[1.02, 0.01, 0], [0.01, 0.98, 0], [0, 0, 1]]))
    assert cal.gyro_offset == (35, -20, 12) and cal.accel_scale == (16548, 16220, 16384)
    assert cal.soft_iron[:2] == (16712, 164)
    assert contract.calibration_of(contract.calibration_registers(cal)) == cal
