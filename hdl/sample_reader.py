"""Sample reader of the MPU9250 driver: a burst per data-ready edge, its checks, the sample.

The rules it applies (``hdl/FAULTS.md`` has what each catches):

- every burst is checked (``burst_is_plausible``): one that fails is not passed on, sets
  ``bad_burst`` and counts in the next sample's ``skipped``; ``BAD_BURST_LIMIT`` in a row ask
  for a restart of bring-up;
- no data-ready edge for the time-out asks for a restart (``int_timeout``);
- a magnetometer field is new only on ST1.DRDY after a read without it, or with bytes other
  than the last read's; no new field for ``mag_timeout_periods`` sample periods makes it stale
  (``mag_stale``) and asks for the magnetometer to be set up again (``mag_lost``);
- data-ready intervals against the sample period give ``skipped`` (samples made and never read).
"""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from . import ak8963_regs as A
from . import mpu9250_regs as R
from .register_port import RegisterPortSignature
from .sample import Sample


__all__ = ["SAMPLE_BYTES", "MPU_BYTES", "BAD_BURST_LIMIT", "burst_is_plausible", "SampleReader"]


SAMPLE_BYTES = 1 + R.SENSOR_BYTES + A.SAMPLE_BYTES   # INT_STATUS, accel/temp/gyro, ST1..ST2
MPU_BYTES = 1 + R.SENSOR_BYTES

# Sample bursts that fail their checks in a row before the driver restarts bring-up: one bad
# burst is dropped and flagged; four (four sample periods) mean the data line or the part is
# gone, and bring-up's WHO_AM_I check then says which.
BAD_BURST_LIMIT = 4


def burst_is_plausible(burst):
    """The check every sample burst passes before it becomes a sample (the gateware computes
    the same): ``burst`` is INT_STATUS followed by the fourteen accel/temp/gyro bytes. It fails
    when RAW_RDY is 0 (the registers hold no new sample: a data line stuck low reads all
    zeros), when INT_STATUS reads 0xFF (its reserved bits read 0 on a working part) or when
    the fourteen data bytes are all 0xFF (a data line stuck high or floating)."""
    status, data_bytes = burst[0], burst[1:MPU_BYTES]
    return bool(status & R.INT_STATUS_RAW_RDY) and status != 0xFF and \
        not all(b == 0xFF for b in data_bytes)


class SampleReader(wiring.Component):
    """Reads a nine-axis sample per data-ready edge while ``enable``.

    Parameters
        ``wiring``: "spi" (one fast burst of ``SAMPLE_BYTES`` from INT_STATUS: the AK8963's bytes
            are in EXT_SENS_DATA) or "i2c" (the MPU9250's ``MPU_BYTES``, then the AK8963's eight
            from ST1 directly). ``int_active_low``: the INT pin's polarity.
        ``magnetometer``: the configuration has one (else no freshness check).
        ``period_cycles``: the sample period. ``first_timeout_cycles``: the data-ready time-out
            after streaming starts; ``timeout_cycles`` after each sample.
        ``mag_timeout_periods``: sample periods without a new field before it is stale.
    Members
        ``port`` (a register port's client side): the reader's commands.
        ``int_pin`` (in): INT, raw (synchronised here).
        ``samples`` (out, stream of ``Sample``): one per burst that passes its checks; valid
            never waits for ready: a sample read while the last is still offered is dropped,
            and the next one carries ``flags.overrun`` and counts it in ``skipped``.
        ``enable`` (in): read samples (bring-up is done). ``start`` (in, pulse): streaming
            begins (a data-ready already active counts as an edge). ``restarted`` (in, pulse):
            bring-up was restarted: the next sample carries ``flags.resumed``.
        ``mag_ok`` (in): the magnetometer is up; ``mag_setup`` (in): it is being set up (its
            time-out waits).
        ``restart`` (out, pulse): no data-ready for the time-out, or ``BAD_BURST_LIMIT`` bad
            bursts in a row. ``mag_lost`` (out, pulse): no new field for the time-out.
            ``mag_nack`` (out, pulse): the AK8963's read failed (I2C wiring).
        ``int_timeout``, ``bad_burst``, ``mag_stale``, ``read_error`` (out): status, as
            ``DriverStatus`` has them (``read_error``: the MPU9250's read failed, I2C).

    Latency: a sample is valid two cycles after its last byte. Throughput: one sample per
    data-ready edge, as fast as the bus reads them.
    """

    def __init__(self, *, wiring="spi", int_active_low=False, magnetometer=True,
                 period_cycles, first_timeout_cycles, timeout_cycles, mag_timeout_periods):
        self.wiring = wiring
        self.int_active_low = int_active_low
        self.magnetometer = magnetometer
        self.period_cycles = period_cycles
        self.first_timeout_cycles = first_timeout_cycles
        self.timeout_cycles = timeout_cycles
        self.mag_timeout_periods = mag_timeout_periods
        super().__init__({
            "port": Out(RegisterPortSignature().flip()),
            "int_pin": In(1),
            "samples": Out(stream.Signature(Sample)),
            "enable": In(1), "start": In(1), "restarted": In(1),
            "mag_ok": In(1), "mag_setup": In(1),
            "restart": Out(1), "mag_lost": Out(1), "mag_nack": Out(1),
            "int_timeout": Out(1), "bad_burst": Out(1), "mag_stale": Out(1),
            "read_error": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        spi = self.wiring == "spi"

        # -- bytes of the burst -------------------------------------------------------------------
        port = self.port
        # reset-less: a sample is only read once all its bytes are in
        buf = Array(Signal(8, name=f"rx{i}", reset_less=True) for i in range(SAMPLE_BYTES))
        rx_index = Signal(range(SAMPLE_BYTES + 1))
        m.d.comb += [port.rx.ready.eq(1), port.rsp.ready.eq(1)]
        with m.If(port.rx.valid & (rx_index < SAMPLE_BYTES)):
            m.d.sync += [buf[rx_index].eq(port.rx.payload), rx_index.eq(rx_index + 1)]

        # -- interrupt ----------------------------------------------------------------------------
        int_sync = Signal()
        m.submodules.int_sync = FFSynchronizer(self.int_pin, int_sync)
        int_active, int_prev, int_edge, int_pending = Signal(), Signal(), Signal(), Signal()
        m.d.comb += [int_active.eq(int_sync ^ int(self.int_active_low)),
                     int_edge.eq(int_active & ~int_prev)]
        m.d.sync += int_prev.eq(int_active)
        with m.If(int_edge):
            m.d.sync += int_pending.eq(1)

        # Sensor samples missed: data-ready edges are one sample period apart; an interval of
        # n periods (rounded: the phase starts half a period in) means n - 1 samples the sensor
        # made and the driver never read (e.g. a latched INT still high from the sample before).
        period = self.period_cycles
        phase = Signal(range(period))
        tick = Signal()                         # a sample period has gone by
        periods = Signal(4)                     # whole periods since the last edge, saturating
        skipped = Signal(4)                     # for the sample this edge announces
        seen_edge = Signal()                    # an edge since streaming began
        dropped = Signal(4)                     # read but not passed on (consumer busy, checks)
        m.d.comb += tick.eq(phase == period - 1)
        with m.If(int_edge):
            m.d.sync += [phase.eq(period // 2), periods.eq(0), seen_edge.eq(1),
                         skipped.eq(Mux(seen_edge & (periods > 1), periods - 1, 0))]
        with m.Elif(tick):
            m.d.sync += [phase.eq(0), periods.eq(Mux(periods == 15, 15, periods + 1))]
        with m.Else():
            m.d.sync += phase.eq(phase + 1)

        timer = Signal(range(max(self.first_timeout_cycles, self.timeout_cycles) + 1))
        m.d.sync += timer.eq(timer - (timer != 0))
        counter = Signal(32)                    # samples read since power-on
        overrun = Signal()
        resumed = Signal()
        bad_bursts = Signal(range(BAD_BURST_LIMIT + 1))
        with m.If(self.restarted):
            m.d.sync += resumed.eq(1)
        with m.If(self.start):
            # a latched INT already active gives no edge: it counts as one
            m.d.sync += [timer.eq(self.first_timeout_cycles - 1), int_pending.eq(int_active),
                         seen_edge.eq(0), skipped.eq(0), bad_bursts.eq(0)]

        # -- magnetometer freshness ---------------------------------------------------------------
        limit = self.mag_timeout_periods
        mag_age = Signal(range(limit + 1))      # sample periods since the last new field
        if self.magnetometer:
            with m.If(self.start | self.mag_setup):
                m.d.sync += mag_age.eq(0)
            with m.Elif(self.enable & tick):
                with m.If(mag_age == limit - 1):
                    # flagged at once, whatever the reader is doing; the set-up runs beside it
                    m.d.comb += self.mag_lost.eq(1)
                    m.d.sync += [self.mag_stale.eq(1), mag_age.eq(0)]
                with m.Else():
                    m.d.sync += mag_age.eq(mag_age + 1)
        prev_field = Signal(7 * 8, reset_less=True)     # HX..HZ and ST2 of the previous read
        prev_drdy = Signal()                            # and its ST1.DRDY
        mag_read_failed = Signal()                      # I2C: this sample's AK8963 read

        with m.If(self.samples.valid & self.samples.ready):
            m.d.sync += self.samples.valid.eq(0)

        def command(device, reg, length):
            p = port.cmd.payload
            m.d.comb += [port.cmd.valid.eq(1), p.device.eq(device), p.reg.eq(reg),
                         p.length.eq(length), p.fast.eq(1)]

        # A command once offered stays offered until taken (a stream's rule), even if
        # ``enable`` drops or ``start`` clears the pending edge meanwhile: its sample is then
        # read and passed on as usual.
        offered = Signal()
        m.d.sync += offered.eq(port.cmd.valid & ~port.cmd.ready)

        with m.FSM():
            with m.State("IDLE"):
                m.d.sync += rx_index.eq(0)
                with m.If(offered | (self.enable & int_pending)):
                    command(0, R.INT_STATUS, SAMPLE_BYTES if spi else MPU_BYTES)
                    with m.If(port.cmd.ready):
                        m.d.sync += [int_pending.eq(int_edge), mag_read_failed.eq(0)]
                        m.next = "READ_MPU"
                with m.Elif(self.enable & ~self.start & (timer == 0)):
                    m.d.sync += self.int_timeout.eq(1)
                    m.d.comb += self.restart.eq(1)
                    m.next = "HALT"
            with m.State("HALT"):
                # until bring-up has restarted (``enable`` drops)
                with m.If(~self.enable):
                    m.next = "IDLE"
            with m.State("READ_MPU"):
                with m.If(port.rsp.valid):
                    with m.If(port.rsp.payload.error):
                        # the read failed on the bus (I2C): no sample; a restart if it persists.
                        # It never reached INT_STATUS, so a latched INT is still active and will
                        # give no new edge: read again at once.
                        m.d.sync += [buf[0].eq(0), self.read_error.eq(1),
                                     int_pending.eq(int_pending | int_active)]
                        m.next = "CHECK"
                    with m.Else():
                        m.next = "CHECK"
                        if not spi:                 # the AK8963 is a second read on this bus
                            with m.If(self.mag_ok):
                                m.next = "MAG_CMD"
            with m.State("MAG_CMD"):
                command(1, A.ST1, A.SAMPLE_BYTES)
                with m.If(port.cmd.ready):
                    m.next = "READ_MAG"
            with m.State("READ_MAG"):
                with m.If(port.rsp.valid):
                    # a failed read leaves the bytes stale: no field this sample
                    m.next = "CHECK"
                    with m.If(port.rsp.payload.error):
                        m.d.comb += self.mag_nack.eq(1)
                        m.d.sync += mag_read_failed.eq(1)
            with m.State("CHECK"):
                m.d.sync += [counter.eq(counter + 1), timer.eq(self.timeout_cycles - 1),
                             self.int_timeout.eq(0)]
                m.next = "IDLE"
                data_ones = Cat(buf[k] == 0xFF for k in range(1, MPU_BYTES)).all()
                plausible = buf[0][0] & (buf[0] != 0xFF) & ~data_ones
                with m.If(~plausible):
                    m.d.sync += [self.bad_burst.eq(1), bad_bursts.eq(bad_bursts + 1),
                                 dropped.eq(Mux(dropped == 15, 15, dropped + 1))]
                    with m.If(bad_bursts == BAD_BURST_LIMIT - 1):
                        m.d.comb += self.restart.eq(1)
                        m.d.sync += bad_bursts.eq(0)
                        m.next = "HALT"
                with m.Else():
                    m.d.sync += [self.bad_burst.eq(0), bad_bursts.eq(0)]
                    if not spi:
                        m.d.sync += self.read_error.eq(0)
                    self._emit(m, buf, counter, overrun, dropped, skipped, resumed,
                               prev_field, prev_drdy, mag_age, mag_read_failed)
        return m

    def _emit(self, m, buf, counter, overrun, dropped, skipped, resumed, prev_field, prev_drdy,
              mag_age, mag_read_failed):
        """A burst that passed its checks becomes the sample (or, with the last still offered,
        a dropped one). The magnetometer's freshness is decided here."""
        def be16(k):
            return Cat(buf[k + 1], buf[k]).as_signed()

        def le16(k):
            return Cat(buf[k], buf[k + 1]).as_signed()

        st1, st2 = buf[MPU_BYTES], buf[MPU_BYTES + 7]
        field = Cat(*(buf[MPU_BYTES + 1 + k] for k in range(6)), st2)
        mag_up = self.mag_ok & ~mag_read_failed
        # ST1.DRDY after a read without it is a new measurement (reading ST2 clears DRDY);
        # DRDY again with the same bytes as the last read is an old one read again (the I2C
        # master left EXT_SENS_DATA alone: a NACK, or reads paced to every n-th sample)
        mag_new = mag_up & st1[0] & (~prev_drdy | (field != prev_field))
        with m.If(mag_up):
            m.d.sync += [prev_field.eq(field), prev_drdy.eq(st1[0])]
        with m.If(mag_new):
            m.d.sync += [mag_age.eq(0), self.mag_stale.eq(0)]
        hofl = st2[3]
        with m.If(self.samples.valid):
            m.d.sync += [overrun.eq(1), dropped.eq(Mux(dropped == 15, 15, dropped + 1))]
        with m.Else():
            p = self.samples.payload
            m.d.sync += [self.samples.valid.eq(1), overrun.eq(0), resumed.eq(0),
                         p.counter.eq(counter), dropped.eq(0),
                         # after a restart the time since the last sample is unknown
                         p.skipped.eq(Mux(resumed, 0, Mux(skipped + dropped > 15, 15,
                                                          skipped + dropped))),
                         p.flags.data_ready.eq(buf[0][0]),
                         p.flags.overrun.eq(overrun),
                         p.flags.resumed.eq(resumed),
                         p.flags.mag_new.eq(mag_new),
                         p.flags.mag_dor.eq(mag_new & st1[1]),
                         p.flags.mag_overflow.eq(mag_new & hofl),
                         p.flags.mag_valid.eq(mag_new & ~hofl),
                         p.temp.eq(be16(1 + 6))]
            for axis in range(3):
                m.d.sync += [p.accel[axis].eq(be16(1 + 2 * axis)),
                             p.gyro[axis].eq(be16(1 + 8 + 2 * axis)),
                             p.mag[axis].eq(Mux(mag_up, le16(MPU_BYTES + 1 + 2 * axis), 0))]
