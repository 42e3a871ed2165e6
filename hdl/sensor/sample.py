"""The sample layout: what the sensor driver passes downstream, one per reading.

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
"""

from amaranth.hdl import signed
from amaranth.lib import data


__all__ = ["Vector3", "SampleFlags", "Sample"]


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
