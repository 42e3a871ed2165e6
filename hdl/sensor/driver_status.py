"""The driver's status layout (``MPU9250Driver.status``, framed with every sample).

``DriverStatus`` (the driver's ``status`` port, always valid):
- ``streaming``: bring-up finished and the driver is reading samples.
- ``whoami_error``: the last WHO_AM_I check read a value not in the accepted list.
- ``no_response``: that value was 0x00 or 0xFF: MISO stuck or the sensor absent.
- ``int_timeout``: no data-ready interrupt came within the timeout; the driver restarted
  bring-up. Cleared by the next sample.
- ``restarts``: bring-up restarts since power-on (after a failed check, a time-out or stuck
  data), saturating at 63. (The last WHO_AM_I value read is the driver's ``who_am_i`` port:
  the board register WHO_AM_I.)
- ``spi_trained``: the sample bursts are read at the trained SPI rate now (issue #58: the read
  levelling found the eye; else the safe rate), as the board register SPI_TRAINING's bit 0,
  which has the sample delay, the eye and the falls back too (``ReadLevelStatus``). 0 in a
  build without a trained rate. It takes the bit ``restarts`` had above 63, so no other
  field of a frame moved.
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
- ``rate_error``: the last sample's data-ready came less than 3/4 of a period after the one
  before (``data_ready_timer.EARLY_FRACTION``) with a new sample in it: the part runs faster than
  configured (SMPLRT_DIV or CONFIG changed under the driver). The driver writes the
  configuration again (``BringUpSequencer.reconfigure``); cleared by the next sample on time.
  Counted in the board register RATE_ERRORS. A spurious INT pulse (no new sample) sets
  ``bad_burst`` instead, and counts no lost sample.
- ``bus_timeout``, ``bus_stuck``, ``bus_arbitration`` (I2C wiring; 0 with SPI): the I2C
  controller's last failure: a device held SCL low past the time-out, SDA stayed low through
  nine recovery clocks, or SDA read low while the controller sent a 1. Set by the failing
  operation, cleared by the next START that gets the bus.
- ``self_test_fail`` (9 bits): the axes that failed their self-test at bring-up, bit 0..8 =
  accel X, Y, Z, gyro X, Y, Z, magnetometer X, Y, Z (``hdl/sensor/self_test.py``: the application
  note's rules). The MPU9250's six are judged in every bring-up before streaming starts, the
  AK8963's three in every set-up of it before ``mag_ok``: while ``streaming`` (``mag_ok``)
  they are this bring-up's (set-up's) verdict. A failing axis is flagged, not left out:
  samples flow on with it, and the host decides. All 0 in a build without the self-test
  (``MPU9250Config.self_test``); the board register SELF_TEST says whether each part's ran.

The status is 29 bits, so that a ``SensorFrame`` (``Sample`` and status) is whole bytes and an
attitude frame at 921,600 baud still fits a 1 kHz period.
"""

from amaranth.lib import data


__all__ = ["DriverStatus", "SelfTestStatus", "ReadLevelStatus"]


class DriverStatus(data.Struct):
    streaming: 1
    whoami_error: 1
    no_response: 1
    int_timeout: 1
    restarts: 6
    spi_trained: 1
    mag_ok: 1
    mag_absent: 1
    mag_wia_error: 1
    mag_stale: 1
    bad_burst: 1
    bus_timeout: 1
    bus_stuck: 1
    bus_arbitration: 1
    rate_error: 1
    self_test_fail: 9


class SelfTestStatus(data.Struct):
    """The driver's ``self_test`` port (board register SELF_TEST): ``done``: the MPU9250's
    self-test ran at this bring-up; ``mag_done``: the AK8963's at its last set-up; ``fail``:
    as ``DriverStatus.self_test_fail``. All 0 in a build without the self-test."""
    done: 1
    mag_done: 1
    fail: 9


class ReadLevelStatus(data.Struct):
    """The driver's ``level`` port (board register SPI_TRAINING, issue #58): the trained SPI
    sample point (``hdl/sensor/read_leveller.py``). All 0 in a build without a trained rate
    (I2C wiring, or a clock at which it would be no faster than the safe rate).

    - ``trained``: the sample bursts are read at the trained rate now (else the safe one).
    - ``scanned``: a scan has ended since streaming began.
    - ``sample_delay``: the delay chosen (cycles from a rising SCLK edge to CIPO's sample).
    - ``first``, ``last``: the widest run of delays the last scan read right (``first`` >
      ``last``: none).
    - ``fallbacks``: falls from the trained rate to the safe one since power-on (a trained
      burst that failed its checks, or a guard delay that read wrong), saturating at 255.
    """
    trained: 1
    scanned: 1
    sample_delay: 5
    first: 5
    last: 5
    fallbacks: 8
