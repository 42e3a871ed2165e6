"""The attitude engine's result layout: quaternion, angles, bias, counter and flags."""

from amaranth.hdl import signed
from amaranth.lib import data

from ..contract.filter_registry import FILTER_CODE_BITS


__all__ = ["AttitudeFlags", "Attitude"]


class AttitudeFlags(data.Struct):
    """Per-result status of the attitude engine: what this update did.

    - ``acc_used``: the accelerometer corrected the tilt (0: the calibrated vector was zero,
      e.g. free fall, or — flagship — had no horizontal part to correct; tilt is gyro-only).
    - ``mag_used``: the magnetometer corrected the heading (0: no new valid field this sample —
      ``mag_valid`` was 0, e.g. between the AK8963's 100 Hz measurements, on overflow, or with
      the magnetometer down — a zero field, or the field was rejected).
    - ``mag_disturbed``: (flagship) a valid field was rejected: its norm or dip is off the
      reference (a magnet, iron nearby).
    - ``mag_new_ref``: (flagship) a magnetic reference was adopted: the one learnt after start,
      or a disturbed field that stayed steady long enough (K_NEW samples).
    - ``at_rest``: (flagship) the rest detector holds (gyro and accelerometer still for K_REST
      samples).
    - ``bias_updated``: the gyro bias estimate changed (flagship: at rest; Kalman: with every
      measurement update).
    - ``saturated``: some intermediate result of this update was clamped (a calibrated value
      beyond 16 bits, a covariance or gain beyond its format, R ≤ 0): check the coefficients.
    - ``filter``: the filter that produced this result, its code (``filter_registry``: 0
      per-axis Kalman, 1 complementary, 2 flagship, 3 Madgwick), ``FILTER_CODE_BITS`` wide.
    - ``overrun``: the sample's own ``overrun`` flag: samples were dropped before it.
    """
    acc_used: 1
    mag_used: 1
    mag_disturbed: 1
    mag_new_ref: 1
    at_rest: 1
    bias_updated: 1
    saturated: 1
    filter: FILTER_CODE_BITS
    overrun: 1


class Attitude(data.Struct):
    """One result of the attitude engine.

    ``quat``: the attitude quaternion w, x, y, z (body to East-North-Up, Hamilton, Q2.30:
    signed 32 bits, 2³⁰ = 1), for every filter. ``angles``: roll, pitch, yaw derived from it
    (ZYX Euler, body axes of the MPU9250, yaw from East towards North) in BAM32: signed 32 bits,
    2³² = 360°. ``bias``: the gyro bias estimate in gyro counts, Q16.16 (the Kalman filter's
    and the flagship's; held while the complementary filter runs). ``counter``: the sample's
    counter."""
    quat: data.ArrayLayout(signed(32), 4)
    angles: data.ArrayLayout(signed(32), 3)
    bias: data.ArrayLayout(signed(32), 3)
    counter: 32
    flags: AttitudeFlags
