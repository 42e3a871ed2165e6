"""Data layouts shared by the sensor driver and everything downstream.

``Sample`` is one nine-axis reading in raw sensor counts, MPU9250 body axes:

==========  ===============  ===================================================================
field       shape            meaning
==========  ===============  ===================================================================
accel       3 × signed(16)   ACCEL_XOUT..ZOUT, LSB per g set by the accelerometer full scale
temp        signed(16)       TEMP_OUT: T = raw / 333.87 + 21 °C
gyro        3 × signed(16)   GYRO_XOUT..ZOUT, LSB per °/s set by the gyro full scale
mag         3 × signed(16)   AK8963 HX..HZ in the AK8963's own axes (0 until the magnetometer
                             path exists; ``flags.mag_valid`` says whether they are new)
counter     unsigned(16)     number of sensor samples read since bring-up, wrapping; a gap
                             means samples were dropped (see ``flags.overrun``)
flags       SampleFlags      per-sample status, below
==========  ===============  ===================================================================

``SampleFlags``:
- ``data_ready``: INT_STATUS.RAW_RDY as read in the same burst; 0 means the registers held no
  new sample (read triggered without fresh data).
- ``overrun``: one or more samples were dropped before this one because the consumer did not
  take the previous sample in time.
- ``mag_valid``, ``mag_overflow``: reserved for the magnetometer path (always 0 for now).

``DriverStatus`` (the driver's ``status`` port, always valid):
- ``streaming``: bring-up finished and the driver is reading samples.
- ``whoami_error``: the last WHO_AM_I check read a value not in the accepted list.
- ``no_response``: that value was 0x00 or 0xFF: MISO stuck or the sensor absent.
- ``int_timeout``: no data-ready interrupt came within the timeout; the driver restarted
  bring-up. Cleared by the next sample.
- ``retries``: bring-up restarts since power-on, saturating at 15.
- ``who_am_i``: the last WHO_AM_I value read.
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
