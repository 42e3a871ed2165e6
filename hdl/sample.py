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


__all__ = ["Vector3", "SampleFlags", "Sample", "DriverStatus"]


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
