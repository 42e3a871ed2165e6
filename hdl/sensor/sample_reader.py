"""Sample reader of the MPU9250 driver: a burst per data-ready edge, its checks, the sample.

Three parts: the data-ready timer (``DataReadyTimer``, ``data_ready_timer.py``: the INT pin's
edges, their intervals against the sample period, the time-out), the burst capture here (the
reads, their checks, the magnetometer's freshness) and the hand-over (``SampleOffer``,
``sample_offer.py``: the sample offered, its early start, the sample store's writes). The rules
they apply (``hdl/FAULTS.md`` has what each catches):

- every burst is checked (``burst_is_plausible``, and a gyro jump of ``GYRO_JUMP_DPS`` from the
  last sample passed on: ``gyro_jumps``): one that fails is not passed on, sets
  ``bad_burst`` and counts in the next sample's ``skipped``; ``BAD_BURST_LIMIT`` in a row ask
  for a restart of bring-up;
- no data-ready edge for the time-out asks for a restart (``int_timeout``);
- a magnetometer field is new only on ST1.DRDY after a read without it, or with bytes other
  than the last read's; no new field for ``mag_timeout_periods`` sample periods makes it stale
  (``mag_stale``) and asks for the magnetometer to be set up again (``mag_lost``);
- data-ready intervals against the sample period give ``skipped`` (samples made and never read:
  the timer's rules);
- a data-ready interval shorter than ``EARLY_FRACTION`` (7/8) of the period (less the edge's
  allowed jitter, ``drdy_jitter_cycles``: the timer's ``early``) whose burst holds a new sample
  means the sensor runs faster than configured (SMPLRT_DIV or CONFIG changed under the driver:
  a glitch, a brown-out of that register): ``rate_error`` is set and the reader asks for the
  configuration to be written again (``reconfigure``, a pulse the board counts). The sample
  itself is real and is passed on (flagged).
"""

from types import SimpleNamespace

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out, connect, flipped

from ..contract import ak8963_regs as A
from ..contract import mpu9250_regs as R
from .data_ready_timer import DataReadyTimer
from .register_port import RegisterPortSignature
from .sample import Sample
from .sample_offer import MPU_BYTES, SAMPLE_BYTES, SampleOffer
from .sample_store import SLOTS, SampleStoreWriteSignature


__all__ = ["SAMPLE_BYTES", "MPU_BYTES", "BAD_BURST_LIMIT", "burst_is_plausible", "GYRO_JUMP_DPS",
           "gyro_jump_limit", "gyro_jumps", "SampleReader"]

# Sample bursts that fail their checks in a row before the driver restarts bring-up: one bad
# burst is dropped and flagged; four (four sample periods) mean the data line or the part is
# gone, and bring-up's WHO_AM_I check then says which.
BAD_BURST_LIMIT = 4

def burst_is_plausible(burst):
    """The check every sample burst passes before it becomes a sample (the gateware computes
    the same): ``burst`` is INT_STATUS followed by the fourteen accel/temp/gyro bytes. It fails
    when RAW_RDY is 0 (the registers hold no new sample: a data line stuck low reads all
    zeros), when a reserved bit of INT_STATUS reads 1 (``INT_STATUS_RESERVED``: they read 0
    on a working part; a line stuck high sets them, and so does a read whose sample point
    slipped a bit late) or when the fourteen data bytes are all 0xFF (a data line stuck high
    or floating)."""
    status, data_bytes = burst[0], burst[1:MPU_BYTES]
    return bool(status & R.INT_STATUS_RAW_RDY) and not status & R.INT_STATUS_RESERVED and \
        not all(b == 0xFF for b in data_bytes)


# A change of angular rate no rigid body behind the gyro's low-pass makes within one sample:
# 1000 °/s from one sample to the next. The shared BROAD trials change by 274 °/s at most
# (trial 24, tapping, at 286 Hz: 4,497 counts at ±2000 °/s). A bit flipped on the data line in
# the top bits of a gyro word (the flips whose rate error, integrated, would tilt the attitude
# by a degree or more at 1 kHz) is a larger jump; lower bits do not matter to the attitude.
GYRO_JUMP_DPS = 1000


def gyro_jump_limit(gyro_fs_dps):
    """The jump, in counts at the full scale ``gyro_fs_dps``, that fails a burst: a power of
    two (the gateware tests the bits above it), or None where it is beyond the words' range
    (±500 °/s and less: no check). ±2000 °/s: 16,384 counts (1000 °/s); ±1000: 32,768."""
    counts = GYRO_JUMP_DPS * 32768 / gyro_fs_dps
    limit = 1 << (round(counts) - 1).bit_length()
    return limit if limit <= 32768 else None


def gyro_jumps(previous, gyro, limit):
    """True where a gyro triple (counts) jumped on some axis from the ``previous`` one (the
    gateware's check, for arrays of N × 3): by ``limit`` or more up, by more than ``limit``
    down. The gateware tests whether the difference lies in [-limit, limit), two's
    complement's range: its bits from log2(limit) up all equal its sign."""
    import numpy as np
    if limit is None:
        return np.zeros(len(gyro), bool)
    delta = np.asarray(gyro, np.int64) - np.asarray(previous, np.int64)
    return np.any((delta >= limit) | (delta < -limit), axis=-1)


class SampleReader(wiring.Component):
    """Reads a nine-axis sample per data-ready edge while ``enable``.

    Parameters
        ``wiring``: "spi" (one fast burst of ``SAMPLE_BYTES`` from INT_STATUS: the AK8963's bytes
            are in EXT_SENS_DATA) or "i2c" (the MPU9250's ``MPU_BYTES``, then the AK8963's eight
            from ST1 directly). ``int_active_low``: the INT pin's polarity; ``int_latched``:
            INT is latched until INT_STATUS is read (else a 50 µs pulse). ``gyro_jump``:
            ``gyro_jump_limit`` of the full scale (None: no check): a burst whose gyro moved
            that far on an axis from the last sample passed on fails its checks.
        ``magnetometer``: the configuration has one (else no freshness check).
        ``period_cycles``: the sample period. ``first_timeout_cycles``: the data-ready time-out
            after streaming starts; ``timeout_cycles`` after each sample (each counted in
            ticks, ``tick_cycles``: it lasts its cycles to two ticks more).
        ``mag_timeout_periods``: sample periods without a new field before it is stale.
        ``drdy_jitter_cycles`` (0): how much sooner a data-ready edge may come from a part that
            keeps its rate: an interval is early under ``EARLY_FRACTION`` of the period less
            this (rounded up to 4 ticks of its clocks: a sixteenth of a period at most), but
            never under half a period (``DriverTiming.drdy_jitter_cycles``: with WAIT_FOR_ES,
            the I2C master's read of the AK8963, which ends at once on a NACK).
    Members
        ``port`` (a register port's client side): the reader's commands.
        ``int_pin`` (in): INT, raw (to the ``DataReadyTimer`` inside, ``timer``).
        ``samples`` (out, stream of ``Sample``): one per burst that passes its checks; valid
            never waits for ready: a sample read while the last is still offered is dropped,
            and the next one carries ``flags.overrun`` and counts it in ``skipped``.
        ``enable`` (in): read samples (bring-up is done). ``start`` (in, pulse): streaming
            begins (a data-ready already active counts as an edge). ``restarted`` (in, pulse):
            bring-up was restarted: the next sample carries ``flags.resumed``.
        ``mag_ok`` (in): the magnetometer is up; ``mag_setup`` (in): it is being set up (its
            time-out waits).
        ``restart`` (out, pulse): no data-ready for the time-out, or ``BAD_BURST_LIMIT`` bad
            bursts in a row. ``reconfigure`` (out, pulse): a sample came early (above).
            ``mag_lost`` (out, pulse): no new field for the time-out.
            ``mag_nack`` (out, pulse): the AK8963's read failed (I2C wiring).
            ``trained_failed`` (out, pulse): a burst read at the trained rate failed its
            checks (the driver falls back to the safe rate). ``burst_done`` (out, pulse): a
            burst's checks (whatever their verdict).
        ``trained`` (in): read the bursts at the trained rate (SPI wiring; the command's
            ``trained`` bit, taken with each burst's command: issue #58).
        ``int_timeout``, ``bad_burst``, ``mag_stale``, ``read_error``, ``rate_error`` (out):
            status, as ``DriverStatus`` has them (``read_error``: the MPU9250's read failed,
            I2C; ``rate_error``: the last sample came early, cleared by one on time).
            ``reconfigure`` is also the pulse per early sample that the board counts
            (RATE_ERRORS, in the command decoder's counters).
        ``tick`` (out): the timer's (``data_ready_timer.tick_cycles``), free-running (the
            prescaler of its clocks and time-outs; the driver's sequencer counts it too).
        ``store`` (out, ``SampleStoreWriteSignature``): the burst's sensor bytes, written into
            the sample store's slot as they arrive (``hdl/sensor/sample_store.py``), and, in the
            cycles after a sample's ``valid`` rose (two, four if its magnetometer is not up),
            the payload's other words and, so, zeros over its field (as ``mag`` in the
            payload): the slot holds the payload from the fifth cycle of ``valid``. These
            three and ``samples`` are the ``SampleOffer``'s inside (``offer``).
            ``sample_slot`` (out): the store's slot of the sample offered, beside ``samples``
            (it changes only as a sample is offered or ``imu_ready`` rises, and holds while
            either is high).
        ``imu_ready`` (out; SPI wiring): the early start (issue #58). It rises the cycle after
            a burst's fifteenth byte (INT_STATUS and the MPU9250's fourteen) when they pass the
            burst's checks and no sample is offered: the payload then holds every field of the
            sample but the magnetometer's (``mag`` and the ``mag_*`` flags), its gyro and
            accelerometer are in its slot (``sample_slot``), and ``valid`` follows, always,
            when the AK8963's eight bytes are in (the checks look at the MPU9250's bytes only,
            and a bus transfer always ends); it falls as ``valid`` rises. The engine starts its
            update on it and waits for ``valid`` where its program needs the field.

    Latency: a sample is valid two cycles after its last byte, ``imu_ready`` two cycles after
    its fifteenth (SPI: 8 bytes, 256 cycles at 12 MHz from 48, before). Throughput: one sample per
    data-ready edge, as fast as the bus reads them (a read starts ten cycles after the last
    check at the soonest: the sample count's update, ``_counts``).
    """

    def __init__(self, *, wiring="spi", int_active_low=False, int_latched=True, magnetometer=True,
                 gyro_jump=None, period_cycles, first_timeout_cycles, timeout_cycles,
                 mag_timeout_periods, drdy_jitter_cycles=0):
        self.wiring = wiring
        self.gyro_jump = gyro_jump
        self.magnetometer = magnetometer
        self.mag_timeout_periods = mag_timeout_periods
        # the data-ready edges, their intervals and the time-out
        self.timer = DataReadyTimer(
            int_active_low=int_active_low, int_latched=int_latched, period_cycles=period_cycles,
            first_timeout_cycles=first_timeout_cycles, timeout_cycles=timeout_cycles,
            drdy_jitter_cycles=drdy_jitter_cycles)
        super().__init__({
            "port": Out(RegisterPortSignature().flip()),
            "int_pin": In(1),
            "samples": Out(stream.Signature(Sample)),
            "enable": In(1), "start": In(1), "restarted": In(1),
            "mag_ok": In(1), "mag_setup": In(1),
            "restart": Out(1), "reconfigure": Out(1), "mag_lost": Out(1), "mag_nack": Out(1),
            "int_timeout": Out(1), "bad_burst": Out(1), "mag_stale": Out(1),
            "read_error": Out(1), "rate_error": Out(1),
            "trained": In(1), "trained_failed": Out(1), "burst_done": Out(1),
            "imu_ready": Out(1),
            "tick": Out(1),
            "store": Out(SampleStoreWriteSignature()),
            "sample_slot": Out(range(SLOTS), init=SLOTS - 1),
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

        # the parts below share their signals and helpers through ``n``
        n = SimpleNamespace()
        (n.spi, n.port, n.buf, n.rx_index) = (
            spi, port, buf, rx_index)
        m.submodules.timer = n.timer = timer = self.timer
        n.reading = Signal()                    # a burst in flight, before its check
        m.d.comb += [timer.int_pin.eq(self.int_pin), timer.start.eq(self.start),
                     timer.reading.eq(n.reading), self.tick.eq(timer.tick)]
        # the sample offered, its slot of the store and the early start
        m.submodules.offer = n.offer = offer = SampleOffer()
        connect(m, offer.samples, flipped(self.samples))
        connect(m, offer.store, flipped(self.store))
        m.d.comb += [offer.burst.eq(Cat(*buf)), offer.data.eq(port.rx.payload),
                     offer.index.eq(rx_index),
                     offer.arriving.eq(port.rx.valid & (rx_index < SAMPLE_BYTES)),
                     offer.reading.eq(n.reading), offer.skipped.eq(timer.skipped),
                     offer.restarted.eq(self.restarted),
                     self.sample_slot.eq(offer.sample_slot), self.imu_ready.eq(offer.imu_ready)]
        self._sample_register(m, n)
        self._burst_checks(m, n)
        self._early_start(m, n)
        self._states(m, n)
        return m

    def _early_start(self, m, n):
        """The burst's verdict (``n.plausible``: ``burst_is_plausible`` and the gyro's jump,
        on the MPU9250's bytes only) and the early start (SPI: one burst; ``imu_ready``): once
        those bytes are in and pass, the offer's ``early`` (with no sample offered, the
        sample's fields but the AK8963's become the payload and its slot ``sample_slot``),
        while the AK8963's bytes come. The check then offers it (``valid``) with its field: it
        cannot fail it (the same bytes), and nothing else offers meanwhile."""
        buf = n.buf
        n.plausible = plausible = Signal()
        n.in_read_mpu = Signal()                # the reader's state is READ_MPU (``_states``)
        verdict = buf[0][0] & ((buf[0] & R.INT_STATUS_RESERVED) == 0) & ~n.data_ones
        if self.gyro_jump is not None:
            m.d.comb += n.gyro_jumped.eq(n.have_base & n.gyro_moved)
            verdict = verdict & ~n.gyro_jumped
        m.d.comb += plausible.eq(verdict)
        if not n.spi:
            return
        early_done = Signal()                   # this burst's early check was made
        with m.If(~n.reading):                  # between bursts (and at the check: after it)
            m.d.sync += early_done.eq(0)
        with m.Elif(n.in_read_mpu & (n.rx_index == MPU_BYTES) & ~early_done):
            m.d.sync += early_done.eq(1)
            m.d.comb += n.offer.early.eq(plausible)

    def _burst_checks(self, m, n):
        """The checks that look at every byte, made as the bytes come in (one comparator and
        one subtractor for the burst, not one per byte and per axis): whether the fourteen
        data bytes are all 0xFF (``n.data_ones``), and whether a gyro word moved by
        ``gyro_jump`` or more from the sample passed on (``n.gyro_moved``; that sample changes
        only at a burst's check, so it holds still while the burst is read)."""
        rx, rx_index, sample = n.port.rx, n.rx_index, self.samples.payload
        n.data_ones = data_ones = Signal()
        n.gyro_moved = gyro_moved = Signal()
        arriving = Signal()
        m.d.comb += arriving.eq(rx.valid & (rx_index < SAMPLE_BYTES))
        with m.If(arriving & (rx_index >= 1) & (rx_index < MPU_BYTES)):
            m.d.sync += data_ones.eq(data_ones & (rx.payload == 0xFF))
        if self.gyro_jump is None:
            return
        # new - last passed on outside [-2**b, 2**b): the 17-bit difference's bits b..16 are
        # not all its sign (``gyro_jumps``); each word is judged when its low byte comes,
        # its high byte the one before
        b = self.gyro_jump.bit_length() - 1
        is_low = [rx_index == 1 + 8 + 2 * axis + 1 for axis in range(3)]
        axis = Signal(range(3))
        m.d.comb += axis.eq(Mux(is_low[0], 0, Mux(is_low[1], 1, 2)))
        high = Signal(8, reset_less=True)      # the byte before this one: the word's high
        with m.If(arriving):
            m.d.sync += high.eq(rx.payload)
        new = Cat(rx.payload, high).as_signed()
        delta = Signal(signed(17))
        m.d.comb += delta.eq(new - Array(sample.gyro)[axis])
        top = delta[b:17]
        with m.If(arriving & Cat(*is_low).any()):
            with m.If(~((top == 0) | top.all())):
                m.d.sync += gyro_moved.eq(1)


    def _sample_register(self, m, n):
        """The sample offered, the time-outs, the start and the magnetometer's freshness."""
        port, tick = n.port, n.timer.period
        gyro_jumped = Signal()                  # the gyro moved too far (``gyro_jump``)
        have_base = Signal()                    # a sample was passed on since ``start``
        m.d.comb += n.offer.counter.eq(self._counts(m, n))     # samples read since power-on
        bad_bursts = Signal(range(BAD_BURST_LIMIT + 1))
        with m.If(self.start):
            m.d.sync += [bad_bursts.eq(0), have_base.eq(0)]

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

        def command(device, reg, length):
            p = port.cmd.payload
            m.d.comb += [port.cmd.valid.eq(1), p.device.eq(device), p.reg.eq(reg),
                         p.length.eq(length), p.fast.eq(1), p.trained.eq(cmd_trained)]

        # A command once offered stays offered until taken (a stream's rule), even if
        # ``enable`` drops or ``start`` clears the pending edge meanwhile: its sample is then
        # read and passed on as usual.
        offered = Signal()
        m.d.sync += offered.eq(port.cmd.valid & ~port.cmd.ready)
        # the rate asked for, held while a command waits (a fallback meanwhile must not change
        # the payload under ``valid``: it applies from the next burst)
        cmd_trained, held_trained = Signal(), Signal()
        m.d.comb += cmd_trained.eq(Mux(offered, held_trained, self.trained))
        m.d.sync += held_trained.eq(cmd_trained)
        n.burst_trained = Signal()              # this burst is read at the trained rate
        n.cmd_trained = cmd_trained
        (n.gyro_jumped, n.have_base, n.bad_bursts, n.mag_age, n.prev_field, n.prev_drdy,
         n.mag_read_failed, n.command, n.offered) = (
            gyro_jumped, have_base, bad_bursts, mag_age, prev_field, prev_drdy, mag_read_failed,
            command, offered)


    def _states(self, m, n):
        """The reader's states: waiting for an edge, the burst's reads, its check."""
        (reading, command, rx_index, spi, buf, prev_field, prev_drdy, mag_age, mag_read_failed,
         offered, timer, have_base, port, bad_bursts, plausible) = (
            n.reading, n.command, n.rx_index, n.spi, n.buf, n.prev_field, n.prev_drdy, n.mag_age,
            n.mag_read_failed, n.offered, n.timer, n.have_base, n.port, n.bad_bursts,
            n.plausible)
        with m.FSM() as fsm:
            m.d.comb += [reading.eq(fsm.ongoing("READ_MPU") | fsm.ongoing("MAG_CMD") |
                                    fsm.ongoing("READ_MAG")),
                         n.in_read_mpu.eq(fsm.ongoing("READ_MPU"))]
            with m.State("IDLE"):
                m.d.sync += [rx_index.eq(0), n.data_ones.eq(1), n.gyro_moved.eq(0)]
                with m.If(offered | (self.enable & timer.pending & ~n.counting_busy)):
                    command(0, R.INT_STATUS, SAMPLE_BYTES if spi else MPU_BYTES)
                    with m.If(port.cmd.ready):
                        m.d.comb += timer.burst_start.eq(1)
                        m.d.sync += [mag_read_failed.eq(0), n.burst_trained.eq(n.cmd_trained)]
                        m.next = "READ_MPU"
                with m.Elif(self.enable & ~self.start & timer.timed_out):
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
                        # give no new edge: read again at once (``retry``).
                        m.d.comb += timer.retry.eq(1)
                        m.d.sync += [buf[0].eq(0), self.read_error.eq(1)]
                        m.next = "CHECK"
                    with m.Else():
                        m.next = "CHECK"
                        if not spi:                 # the AK8963 is a second read on this bus
                            # only for a burst with a sample (RAW_RDY): a spurious pulse's read
                            # of it took the AK8963's new field (reading ST2 ends it) into a
                            # burst dropped, and the next came two AK8963 periods later, past
                            # the magnetometer's time-out at 200 Hz: a false "lost" (#60)
                            with m.If(self.mag_ok & buf[0][0]):
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
                m.d.comb += self.burst_done.eq(1)
                m.d.sync += [n.counting.eq(1), self.int_timeout.eq(0)]
                m.next = "IDLE"
                # no RAW_RDY: no new sample in this burst (a spurious INT pulse, a read made
                # again) or none readable (a line stuck low reads zeros): either way the
                # intervals from the last sample's edge count what was lost, not ``dropped``
                spurious = ~buf[0][0]
                m.d.comb += [timer.check.eq(1), timer.spurious.eq(spurious)]
                with m.If(~plausible):
                    m.d.sync += [self.bad_burst.eq(1), bad_bursts.eq(bad_bursts + 1)]
                    m.d.comb += self.trained_failed.eq(n.burst_trained)
                    m.d.comb += n.offer.lost.eq(~spurious)     # a sample was made and lost
                    with m.If(bad_bursts == BAD_BURST_LIMIT - 1):
                        m.d.comb += self.restart.eq(1)
                        m.d.sync += bad_bursts.eq(0)
                        m.next = "HALT"
                with m.Else():
                    m.d.sync += [self.bad_burst.eq(0), bad_bursts.eq(0),
                                 self.rate_error.eq(timer.early)]
                    with m.If(timer.early):
                        # a new sample too soon: the part runs faster than it was told
                        m.d.comb += self.reconfigure.eq(1)
                    if not spi:
                        m.d.sync += self.read_error.eq(0)
                    self._field_freshness(m, buf, prev_field, prev_drdy, mag_age, mag_read_failed,
                                          n.offer)
                    with m.If(~self.samples.valid):
                        m.d.sync += have_base.eq(1)     # this one becomes the payload

    def _counts(self, m, n):
        """The samples read (returned: 32 bits, wrapping): a check (``n.counting`` set) is
        counted in the nine cycles after it, a nibble a cycle in the last eight: the count
        turns once through a 4-bit adder (not a 32-bit incrementer) while
        ``n.counting_busy``, and the next read is not started meanwhile (the count is read at
        a check, which a read precedes)."""
        head = Signal(32)                       # the count of samples read
        n.counting = Signal()
        carry = Signal()
        steps = Signal(range(len(head) // 4 + 1))     # the nibbles still to go
        n.counting_busy = n.counting | (steps != 0)
        with m.If(steps != 0):
            nibble = head[:4] + carry
            m.d.sync += [head.eq(Cat(head[4:], nibble[:4])), carry.eq(nibble[4]),
                         steps.eq(steps - 1)]
        with m.If(n.counting):
            m.d.sync += [steps.eq(len(head) // 4), carry.eq(1), n.counting.eq(0)]
        return head

    def _field_freshness(self, m, buf, prev_field, prev_drdy, mag_age, mag_read_failed, offer):
        """A burst that passed its checks: whether its field is new (decided here), offered
        (``offer``: ``SampleOffer`` places the sample, or drops it with the last still
        offered)."""
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
        m.d.comb += [offer.offer.eq(1), offer.mag_up.eq(mag_up), offer.mag_new.eq(mag_new)]
