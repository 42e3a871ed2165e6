"""Data layouts shared by the sensor driver and everything downstream.

``Sample`` is one nine-axis reading in raw sensor counts, MPU9250 body axes:

==========  ===============  ===================================================================
field       shape            meaning
==========  ===============  ===================================================================
accel       3 × signed(16)   ACCEL_XOUT..ZOUT, LSB per g set by the accelerometer full scale
temp        signed(16)       TEMP_OUT: T = raw / 333.87 + 21 °C
gyro        3 × signed(16)   GYRO_XOUT..ZOUT, LSB per °/s set by the gyro full scale
mag         3 × signed(16)   AK8963 HX..HZ, 0.15 µT/LSB (16-bit mode), in the AK8963's own axes:
                             mag x = accel y, mag y = accel x, mag z = −accel z. Raw: no ASA
                             sensitivity adjustment (``DriverStatus``'s ``asa`` port has it).
                             0 while the magnetometer is not up.
counter     unsigned(16)     number of sensor samples read since bring-up, wrapping; a gap
                             means samples were dropped (see ``flags.overrun``)
skipped     unsigned(4)      samples since the previous one that never came out: made by the
                             sensor but never read (data-ready edges n > 1 sample periods
                             apart: n − 1) or read and dropped (``flags.overrun``); saturating
                             at 15; 0 normally. The engine integrates 1 + skipped periods.
flags       SampleFlags      per-sample status, below
==========  ===============  ===================================================================

``SampleFlags``:
- ``data_ready``: INT_STATUS.RAW_RDY as read in the same burst; 0 means the registers held no
  new sample (read triggered without fresh data).
- ``overrun``: one or more samples were dropped before this one because the consumer did not
  take the previous sample in time.
- ``mag_new``: ST1.DRDY: ``mag`` holds a measurement not delivered before (the AK8963 measures
  at 100 Hz, so most samples at higher rates carry 0 here and the previous field values).
- ``mag_dor``: ST1.DOR: a magnetometer measurement was skipped before this one.
- ``mag_overflow``: ST2.HOFL: |X|+|Y|+|Z| ≥ 4912 µT; the field values are not valid.
- ``mag_valid``: ``mag_new`` and not ``mag_overflow``: the filter may use ``mag`` now.
All magnetometer flags are 0 while the magnetometer is not up (``DriverStatus.mag_ok`` = 0).

``DriverStatus`` (the driver's ``status`` port, always valid):
- ``streaming``: bring-up finished and the driver is reading samples.
- ``whoami_error``: the last WHO_AM_I check read a value not in the accepted list.
- ``no_response``: that value was 0x00 or 0xFF: MISO stuck or the sensor absent.
- ``int_timeout``: no data-ready interrupt came within the timeout; the driver restarted
  bring-up. Cleared by the next sample.
- ``retries``: bring-up restarts since power-on, saturating at 15.
- ``who_am_i``: the last WHO_AM_I value read.
- ``mag_ok``: the AK8963 is up (WIA right, fuse ROM read, continuous 100 Hz 16-bit mode).
- ``mag_absent``: the AK8963 did not acknowledge (I2C NACK, SLV4_NACK) or an SLV4 transfer
  timed out; set at bring-up (then ``mag_ok`` stays 0) or on a failed per-sample read.
- ``mag_wia_error``: the AK8963 answered with a WIA other than 0x48.
"""

from amaranth.hdl import signed
from amaranth.lib import data


__all__ = ["Vector3", "SampleFlags", "Sample", "DriverStatus", "AttitudeFlags", "Attitude",
           "ConfigWrite"]


Vector3 = data.ArrayLayout(signed(16), 3)


class SampleFlags(data.Struct):
    data_ready: 1
    overrun: 1
    mag_valid: 1
    mag_overflow: 1
    mag_new: 1
    mag_dor: 1


class Sample(data.Struct):
    accel: Vector3
    temp: signed(16)
    gyro: Vector3
    mag: Vector3
    counter: 16
    flags: SampleFlags
    skipped: 4


class DriverStatus(data.Struct):
    streaming: 1
    whoami_error: 1
    no_response: 1
    int_timeout: 1
    retries: 4
    who_am_i: 8
    mag_ok: 1
    mag_absent: 1
    mag_wia_error: 1


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
    - ``filter``: the filter that produced this result: 0 per-axis Kalman, 1 complementary,
      2 flagship.
    - ``overrun``: the sample's own ``overrun`` flag: samples were dropped before it.
    """
    acc_used: 1
    mag_used: 1
    mag_disturbed: 1
    mag_new_ref: 1
    at_rest: 1
    bias_updated: 1
    saturated: 1
    filter: 2
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
    counter: 16
    flags: AttitudeFlags


class ConfigWrite(data.Struct):
    """A write to the attitude engine's register map (``hdl/attitude_program.py``)."""
    addr: 8
    data: signed(32)
