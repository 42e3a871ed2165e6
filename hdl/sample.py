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
counter     unsigned(32)     number of sensor samples read since power-on (it goes on across
                             a bring-up after a fault: ``DriverStatus.restarts``), wrapping
                             after 2³² (50 days at 1 kHz); a gap means samples were read and
                             not passed on (``flags.overrun``; a burst that failed its checks)
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
- ``resumed``: the first sample after a bring-up that followed a fault (``restarts`` went up):
  the time since the sample before it is unknown, so ``skipped`` is 0 and means nothing here.
All magnetometer flags are 0 while the magnetometer is not up (``DriverStatus.mag_ok`` = 0),
and so is ``mag`` then. ``mag_new`` needs ST1.DRDY, and either a previous read without
DRDY (reading ST2 clears it, so DRDY coming back is a new measurement) or field bytes that
differ from the previous read's: the MPU9250's I2C master leaves EXT_SENS_DATA as it was when a
read of the AK8963 fails (NACK) or is paced to every n-th sample, so DRDY again with the same
bytes is an old measurement read again, never a new one. (At sample rates of 100 Hz or less,
where every read may find DRDY, a real AK8963 repeating all six bytes is rare — its noise is
several LSB — and that field was just delivered.)

The checks on every burst (``hdl/FAULTS.md``): INT_STATUS must have RAW_RDY and must not read
0xFF, and the fourteen accel/temp/gyro bytes must not all be 0xFF. A burst that fails is not
passed on (no sample; the next one counts it in ``skipped``).

``DriverStatus`` (the driver's ``status`` port, always valid):
- ``streaming``: bring-up finished and the driver is reading samples.
- ``whoami_error``: the last WHO_AM_I check read a value not in the accepted list.
- ``no_response``: that value was 0x00 or 0xFF: MISO stuck or the sensor absent.
- ``int_timeout``: no data-ready interrupt came within the timeout; the driver restarted
  bring-up. Cleared by the next sample.
- ``restarts``: bring-up restarts since power-on (after a failed check, a time-out or stuck
  data), saturating at 255.
- ``who_am_i``: the last WHO_AM_I value read.
- ``mag_ok``: the AK8963 is up (WIA right, fuse ROM read, continuous 100 Hz 16-bit mode).
- ``mag_absent``: the AK8963 did not acknowledge (I2C NACK, SLV4_NACK) or an SLV4 transfer
  timed out, at bring-up or at a re-initialisation, or (I2C wiring) a per-sample read failed;
  ``mag_ok`` is 0 meanwhile. Cleared when a re-initialisation brings it up again.
- ``mag_wia_error``: the AK8963 answered with a WIA other than 0x48; cleared likewise.
- ``mag_stale``: no new field for ``DriverTiming.mag_timeout_s`` (three AK8963 periods by
  default) while streaming: the AK8963 was lost, reset or stopped measuring. ``mag_ok`` drops
  and the driver re-initialises the AK8963 (the magnetometer part of bring-up, between
  samples, accel/gyro still flowing), again every time-out until it answers. Cleared by the
  next new field.
- ``bad_burst``: the last sample burst failed its checks (data line stuck, no data ready);
  after ``BAD_BURST_LIMIT`` in a row the driver restarts bring-up. Cleared by a good burst.
- ``bus_timeout``, ``bus_stuck``, ``bus_arbitration`` (I2C wiring; 0 with SPI): the I2C
  controller's last failure: a device held SCL low past the time-out, SDA stayed low through
  nine recovery clocks, or SDA read low while the controller sent a 1. Set by the failing
  operation, cleared by the next START that gets the bus.
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
    resumed: 1


class Sample(data.Struct):
    accel: Vector3
    temp: signed(16)
    gyro: Vector3
    mag: Vector3
    counter: 32
    flags: SampleFlags
    skipped: 4


class DriverStatus(data.Struct):
    streaming: 1
    whoami_error: 1
    no_response: 1
    int_timeout: 1
    restarts: 8
    who_am_i: 8
    mag_ok: 1
    mag_absent: 1
    mag_wia_error: 1
    mag_stale: 1
    bad_burst: 1
    bus_timeout: 1
    bus_stuck: 1
    bus_arbitration: 1


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
    counter: 32
    flags: AttitudeFlags


class ConfigWrite(data.Struct):
    """A write to the attitude engine's register map (``hdl/attitude_program.py``)."""
    addr: 8
    data: signed(32)
