"""Bring-up sequencer of the MPU9250 driver: the bring-up program and the machine that runs it.

``bring_up_program`` writes the sequence (``hdl/sensor/mpu9250_driver.py`` describes it) as a list
of ``Step``: register writes, checked reads, stored reads, status polls and waits, each with what
to do on failure. ``BringUpSequencer`` runs it over a register port, one step at a time, and
owns the status a bring-up decides: WHO_AM_I, the magnetometer's, the restarts.
"""

from dataclasses import dataclass, replace
from types import SimpleNamespace

from amaranth import *
from amaranth.lib import data, enum, wiring
from amaranth.lib.wiring import In, Out

from ..primitives.clocking import ticks
from ..contract import ak8963_regs as A
from ..contract import mpu9250_regs as R
from ..primitives.memories import FrameRAM
from .register_port import RegisterPortSignature
from .self_test import CODE_INDEX, MAG_INDEX, SUM_INDEX, TestByte


__all__ = ["Op", "Fail", "Step", "SelfTestWaits", "bring_up_program", "BringUpSequencer",
           "BACKOFF_MAX_SHIFT"]


# A restart doubles the waits marked ``backoff`` (the one after H_RESET), up to 2**this times
# the datasheet's: a part whose reset takes longer than the driver's wait (each retry would
# reset it again and read it too early, for ever) is brought up by a later retry. 4 x 100 ms.
BACKOFF_MAX_SHIFT = 2


class Op(enum.Enum, shape=3):
    WAIT   = 0      # arg cycles
    WRITE  = 1      # reg <- value
    CHECK  = 2      # read reg; must be one of the check's values
    STORE  = 3      # read reg into asa[value]
    POLL   = 4      # read reg until (byte & value) != 0; fails on (byte & mask) or time-out;
                    # value 0: one read, whatever its byte (a clear-on-read register cleared)
    MARK   = 5      # status.mag_ok <- 1
    STREAM = 6
    TEST   = 7      # read ``length`` bytes ``repeat`` times (``wait`` apart) to the self-test


class Fail(enum.Enum, shape=1):
    RESTART = 0     # MPU9250 problem: flag it and run the program again from the start
    MAG     = 1     # magnetometer problem: flag it and jump to the end of the magnetometer part


@dataclass(frozen=True)
class Step:
    op: Op
    device: int = 0             # 0 = MPU9250, 1 = AK8963 directly (I2C wiring)
    reg: int = 0
    value: int = 0
    mask: int = 0
    wait: int = 0
    fail: Fail = Fail.RESTART
    check: str = ""             # "who_am_i" or "wia"
    mag: bool = False           # part of the magnetometer's set-up (run again from its first)
    backoff: bool = False       # a WAIT that doubles with each restart (BACKOFF_MAX_SHIFT)
    length: int = 1             # TEST: bytes per read, the first at index ``value``
    repeat: int = 1             # TEST: reads, ``wait`` cycles apart
    fast: bool = False          # TEST: a read of sensor registers (the fast SCLK)
    self_test: bool = False     # part of the MPU9250's self-test (a reconfiguration skips it)

    # TEST's ``mask``: bit 0 subtracts the bursts from the sums, bit 1 starts the sums afresh
    SUBTRACT = 0x01
    FIRST = 0x02


@dataclass(frozen=True)
class SelfTestWaits:
    """The self-test's waits, in cycles: ``settle`` after the self-test is switched on or off
    (the application note's 20 ms), ``interval`` between two sample reads (a 1 kHz period),
    ``mag`` for the AK8963's self-test measurement (its 9 ms at most; SPI wiring: and two
    sample periods for the MPU9250's I2C master to fetch it)."""
    settle: int
    interval: int
    mag: int


def bring_up_program(config, power_up_cycles, reset_cycles, mag_wait_cycles, self_test=None,
                     aux_idle_cycles=None):
    """The bring-up sequence for ``config.wiring``, as a list of ``Step`` (the driver's ROM).
    ``self_test`` (``SelfTestWaits``): with ``config.self_test``, the self-tests' waits.
    ``aux_idle_cycles`` (SPI wiring): the longest cycle of the MPU9250's I2C master (SLV0's
    read and an SLV4 transfer), which a magnetometer set-up waits out before it clears
    I2C_MST_STATUS (default ``mag_wait_cycles``)."""
    spi = config.wiring == "spi"
    if config.self_test and self_test is None:
        raise ValueError("bring_up_program needs the self-test's waits (SelfTestWaits)")
    steps = [Step(Op.WAIT, wait=power_up_cycles)]
    if spi:
        steps.append(Step(Op.WRITE, reg=R.USER_CTRL, value=R.USER_CTRL_I2C_IF_DIS))
    steps += [Step(Op.WRITE, reg=R.PWR_MGMT_1, value=R.PWR_MGMT_1_H_RESET),
              Step(Op.WAIT, wait=reset_cycles, backoff=True)]
    if spi:
        steps.append(Step(Op.WRITE, reg=R.USER_CTRL, value=R.USER_CTRL_I2C_IF_DIS))
    steps += [Step(Op.WRITE, reg=R.PWR_MGMT_1, value=R.PWR_MGMT_1_CLKSEL_AUTO),
              Step(Op.CHECK, reg=R.WHO_AM_I, check="who_am_i")]
    if config.self_test:
        steps += [replace(step, self_test=True)
                  for step in _mpu_self_test(config.self_test_samples, self_test)]
    steps += [Step(Op.WRITE, reg=reg, value=value) for reg, value in config.sensor_writes()]

    if config.magnetometer:
        mag = []
        # SLV4_CTRL also holds I2C_MST_DLY, the pacing of SLV0's reads above 1 kHz (written at
        # the end of this part): every SLV4 transfer keeps it. A set-up again while streaming
        # (a magnetometer lost, reset or stale) that cleared it had SLV0's eight bytes read at
        # every sample tick, longer than an 8 kHz period at 400 kHz: each SLV4 transfer then
        # waited past its poll's time-out, and the magnetometer never came back
        slv4_ctrl = R.I2C_SLV_EN | (config.aux_every - 1 if spi else 0)

        def mag_write(reg, value):
            if spi:
                mag.extend([Step(Op.WRITE, reg=R.I2C_SLV4_ADDR, value=A.I2C_ADDRESS),
                            Step(Op.WRITE, reg=R.I2C_SLV4_REG, value=reg),
                            Step(Op.WRITE, reg=R.I2C_SLV4_DO, value=value),
                            Step(Op.WRITE, reg=R.I2C_SLV4_CTRL, value=slv4_ctrl),
                            Step(Op.POLL, reg=R.I2C_MST_STATUS, value=R.I2C_MST_STATUS_SLV4_DONE,
                                 mask=R.I2C_MST_STATUS_SLV4_NACK, fail=Fail.MAG)])
            else:
                mag.append(Step(Op.WRITE, device=1, reg=reg, value=value, fail=Fail.MAG))

        def slv0_reads(reg, n):
            """SLV0 reads ``n`` bytes of the AK8963 from ``reg`` at every sample (SPI)."""
            return [Step(Op.WRITE, reg=R.I2C_SLV_ADDR[0], value=R.I2C_SLV_RNW | A.I2C_ADDRESS),
                    Step(Op.WRITE, reg=R.I2C_SLV_ADDR[0] + 1, value=reg),
                    Step(Op.WRITE, reg=R.I2C_SLV_ADDR[0] + 2, value=R.I2C_SLV_EN | n)]

        def mag_read(op, reg, **kw):
            if spi:
                mag.extend([Step(Op.WRITE, reg=R.I2C_SLV4_ADDR,
                                 value=R.I2C_SLV_RNW | A.I2C_ADDRESS),
                            Step(Op.WRITE, reg=R.I2C_SLV4_REG, value=reg),
                            Step(Op.WRITE, reg=R.I2C_SLV4_CTRL, value=slv4_ctrl),
                            Step(Op.POLL, reg=R.I2C_MST_STATUS, value=R.I2C_MST_STATUS_SLV4_DONE,
                                 mask=R.I2C_MST_STATUS_SLV4_NACK, fail=Fail.MAG),
                            Step(op, reg=R.I2C_SLV4_DI, fail=Fail.MAG, **kw)])
            else:
                mag.append(Step(op, device=1, reg=reg, fail=Fail.MAG, **kw))

        if spi:
            # A set-up takes a byte only from a transfer it saw complete. An SLV4 transfer
            # still enabled from a set-up that timed out (the I2C master stalled) would end
            # whenever the master runs again and leave SLV4_DONE set: the next set-up's first
            # poll took that stale DONE, and each of its reads the byte of the transfer
            # before (ASA (72, 176, 167): WIA, ASAX, ASAY). So a set-up first disables SLV4
            # (an enabled transfer that waits is dropped), waits out the master's longest
            # cycle (one that had begun ends) and reads I2C_MST_STATUS (clears on read).
            # After that every transfer's DONE is read by its own poll
            wait_es = R.I2C_MST_CTRL_WAIT_FOR_ES if config.aux_every == 1 else 0
            mag += [Step(Op.WRITE, reg=R.I2C_SLV4_CTRL, value=slv4_ctrl & ~R.I2C_SLV_EN),
                    Step(Op.WRITE, reg=R.USER_CTRL,
                         value=R.USER_CTRL_I2C_IF_DIS | R.USER_CTRL_I2C_MST_EN),
                    Step(Op.WRITE, reg=R.I2C_MST_CTRL, value=wait_es | R.I2C_MST_CLK_400KHZ),
                    Step(Op.WAIT, wait=aux_idle_cycles or mag_wait_cycles),
                    Step(Op.POLL, reg=R.I2C_MST_STATUS, value=0, fail=Fail.MAG)]
        else:
            # the whole INT_PIN_CFG (BYPASS_EN is in it): a re-initialisation runs this while
            # samples stream, and must not switch a latched INT to pulses meanwhile
            mag += [Step(Op.WRITE, reg=R.USER_CTRL, value=0x00),
                    Step(Op.WRITE, reg=R.INT_PIN_CFG, value=config.int_pin_cfg)]
        mag_read(Op.CHECK, A.WIA, check="wia")
        mag_write(A.CNTL2, A.CNTL2_SRST)
        mag_write(A.CNTL1, A.MODE_FUSE_ROM)
        for axis in range(3):
            mag_read(Op.STORE, A.ASAX + axis, value=axis)
        mag_write(A.CNTL1, A.MODE_POWER_DOWN)
        mag.append(Step(Op.WAIT, wait=mag_wait_cycles))
        if config.self_test:
            # the self-test field, one 16-bit measurement of it (the part is back in
            # power-down after it); SPI: SLV0 fetches HXL..ST2 at every sample meanwhile
            # (seven bytes: reading ST2 ends the read) and the bytes are read in one burst
            mag_write(A.ASTC, A.ASTC_SELF)
            mag_write(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_SELF_TEST)
            test = dict(value=MAG_INDEX, length=7, fail=Fail.MAG)
            if spi:
                mag += [*slv0_reads(A.HXL, 7), Step(Op.WAIT, wait=self_test.mag),
                        Step(Op.TEST, reg=R.EXT_SENS_DATA_00, **test)]
            else:
                mag += [Step(Op.WAIT, wait=self_test.mag),
                        Step(Op.TEST, device=1, reg=A.HXL, **test)]
            mag_write(A.ASTC, 0x00)
            mag.append(Step(Op.WAIT, wait=mag_wait_cycles))
        mag_write(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_CONT_100HZ)
        if spi:
            mag += slv0_reads(A.ST1, A.SAMPLE_BYTES)
            if config.aux_every > 1:
                mag += [Step(Op.WRITE, reg=R.I2C_SLV4_CTRL, value=config.aux_every - 1),
                        Step(Op.WRITE, reg=R.I2C_MST_DELAY_CTRL,
                             value=R.I2C_MST_DELAY_CTRL_DELAY_ES_SHADOW |
                             R.I2C_MST_DELAY_CTRL_SLV0_DLY_EN)]
        mag.append(Step(Op.MARK))
        steps += [replace(step, mag=True) for step in mag]

    steps += [Step(Op.WRITE, reg=R.INT_PIN_CFG, value=config.int_pin_cfg),
              Step(Op.WRITE, reg=R.INT_ENABLE, value=R.INT_ENABLE_RAW_RDY),
              Step(Op.STREAM)]
    return steps


def _mpu_self_test(samples, waits):
    """The MPU9250's self-test (``hdl/sensor/self_test.py``): at its settings, ``samples`` bursts
    with self-test off (subtracted), as many with it on (added), then the factory codes."""
    burst = dict(reg=R.ACCEL_XOUT_H, value=SUM_INDEX, length=R.SENSOR_BYTES, repeat=samples,
                 wait=waits.interval, fast=True)
    on = R.SELF_TEST_ENABLE
    return [Step(Op.WRITE, reg=R.SMPLRT_DIV, value=0),
            Step(Op.WRITE, reg=R.CONFIG, value=2),              # 92 Hz, 1 kHz
            Step(Op.WRITE, reg=R.GYRO_CONFIG, value=0),         # ±250 °/s
            Step(Op.WRITE, reg=R.ACCEL_CONFIG, value=0),        # ±2 g
            Step(Op.WRITE, reg=R.ACCEL_CONFIG2, value=2),       # 92 Hz
            Step(Op.WAIT, wait=waits.settle),
            Step(Op.TEST, mask=Step.SUBTRACT | Step.FIRST, **burst),
            Step(Op.WRITE, reg=R.GYRO_CONFIG, value=on),
            Step(Op.WRITE, reg=R.ACCEL_CONFIG, value=on),
            Step(Op.WAIT, wait=waits.settle),
            Step(Op.TEST, **burst),
            Step(Op.WRITE, reg=R.GYRO_CONFIG, value=0),
            Step(Op.WRITE, reg=R.ACCEL_CONFIG, value=0),
            Step(Op.TEST, reg=R.SELF_TEST_X_ACCEL, value=CODE_INDEX, length=3),
            Step(Op.TEST, reg=R.SELF_TEST_X_GYRO, value=CODE_INDEX + 3, length=3),
            Step(Op.WAIT, wait=waits.settle)]


class BringUpSequencer(wiring.Component):
    """Runs ``program`` (``bring_up_program``) over a register port.

    Parameters
        ``program``: the steps; those marked ``mag`` are the magnetometer's part, which runs
            again from its first step when the magnetometer is lost, and then goes to the
            STREAM step (the last), past the interrupt's set-up: an MPU9250 reset meanwhile
            leaves INT off, for the reader's time-out to find. ``accepted_who_am_i``: the
            WHO_AM_I values that pass. ``poll_cycles``: how long a POLL step may take.
            ``tick_cycles`` (1): the waits and the poll time-out are counted in ticks
            (``tick``, a pulse every ``tick_cycles`` cycles: the sample reader's prescaler in
            the driver: 750 cycles at 48 MHz and 1 kHz, at most 1,024), so that the timer is
            a count of ticks, not of cycles (15 bits rather than 25 at 48 MHz and 1 kHz).
            With ticks, a wait of w cycles counts ⌈w / tick_cycles⌉ + 1 of them
            (``clocking.ticks``): it lasts at least w cycles, at most two ticks more. With 1,
            every cycle is a tick and a wait lasts its cycles exactly.
    Members
        ``port`` (a register port's client side): the sequencer's commands.
        ``restart`` (in, pulse): run the program again from the start (the reader lost the
            sensor: no data-ready, bursts that fail their checks).
        ``mag_lost`` (in, pulse): the magnetometer gave no new field for its time-out: drop
            ``mag_ok`` and run the magnetometer's part again (``mag_setup`` while it runs).
        ``mag_nack`` (in, pulse): a per-sample read of the AK8963 failed (I2C wiring): it is
            flagged absent and ``mag_ok`` drops.
        ``reconfigure`` (in, pulse): the part runs at a rate it was not told: write the
            configuration again, from the step after the WHO_AM_I check through the interrupt
            set-up, leaving out the magnetometer's part, while samples go on (taken while
            streaming and idle; ignored while a set-up runs).
        ``streaming`` (out): the program reached its STREAM step; samples may be read. Drops
            on a restart. ``started`` (out, pulse): it just did, from the start of the program.
        ``restarted`` (out, pulse): a restart began (requested, or a failed MPU9250 step).
        ``mag_setup`` (out): the magnetometer's part is running while streaming.
        ``whoami_error``, ``no_response``, ``who_am_i``, ``restarts`` (6, saturating),
        ``mag_ok``, ``mag_absent``, ``mag_wia_error`` (out): as ``DriverStatus`` has them.
        ``asa`` (out, 3 × 8): the AK8963's sensitivity adjustment, stored by STORE steps.
        ``test`` (out, ``TestByte``): the bytes TEST steps read, for a ``SelfTest``;
            ``test_busy`` (in): its ``busy`` (a TEST step ends once it is low).
        ``tick`` (in, 1 unless driven): the timer's tick (``tick_cycles``).

    A step's command goes out in the cycle it is fetched; WRITE, CHECK, STORE and MARK take one
    command (or none), POLL repeats its read until the bit is set, a NACK or ``poll_cycles``
    (a POLL of value 0 reads once);
    WAIT counts its cycles; TEST reads ``repeat`` times, ``wait`` cycles between a read's end
    and the next. Failures: ``Fail.RESTART`` restarts the program, ``Fail.MAG`` flags
    the magnetometer and jumps past its part (samples flow without it).
    Latency: a step's command is offered in the cycle the step is fetched, and the next step
    is fetched three cycles after the response (two to read it from the program ROM); a
    restart waits for the step under way.
    """

    def __init__(self, program, *, accepted_who_am_i, poll_cycles, tick_cycles=1):
        self.program = program
        self.accepted_who_am_i = tuple(accepted_who_am_i)
        self.tick_cycles = tick_cycles
        if any(s.op == Op.WAIT and s.wait < 1 for s in program):
            raise ValueError("a WAIT step needs wait >= 1 cycle")
        # a word's ``wait`` is what the timer loads: counted in cycles, a WAIT's cycles less
        # one (its last cycle is the one the timer reads 0), a TEST's gap as it is; in ticks
        # of more than a cycle, ``ticks``. The ROM holds it so, and no subtractor sits between
        # the ROM and the timer
        timer_load = self.timer_loads = [
            ticks(s.wait, tick_cycles, exact=s.wait - (s.op == Op.WAIT)) for s in program]
        self.poll_cycles = poll_cycles
        self.poll_load = ticks(poll_cycles, tick_cycles, exact=poll_cycles - 1)
        self.step_layout = data.StructLayout({
            "op": Op, "device": 1, "reg": 8, "value": 8, "mask": 8, "fail": Fail,
            "check_wia": 1, "backoff": 1, "wait": range(max(timer_load) + 1),
            "length": range(max(s.length for s in program) + 1), "fast": 1,
            "more": range(max(s.repeat for s in program))})
        layout = self.step_layout
        # a word's length and fast bit are a TEST's; any other step's command reads one byte at
        # the slow clock, so its word says so (the command's payload is the word's, whatever
        # the step)
        words = [layout.const({
            "op": s.op, "device": s.device, "reg": s.reg, "value": s.value, "mask": s.mask,
            "fail": s.fail, "check_wia": s.check == "wia", "backoff": s.backoff,
            "wait": load, "length": s.length if s.op == Op.TEST else 1,
            "fast": s.fast and s.op == Op.TEST,
            "more": s.repeat - 1}).as_value().value for s, load in zip(program, timer_load)]
        # the program, one step a word (an M9K; ``report`` counts it)
        self.rom = FrameRAM(len(program), layout.size, init=words)
        super().__init__({
            "port": Out(RegisterPortSignature().flip()),
            "restart": In(1), "mag_lost": In(1), "mag_nack": In(1), "reconfigure": In(1),
            "streaming": Out(1), "started": Out(1), "restarted": Out(1), "mag_setup": Out(1),
            "whoami_error": Out(1), "no_response": Out(1), "who_am_i": Out(8),
            "restarts": Out(6), "mag_ok": Out(1), "mag_absent": Out(1),
            "mag_wia_error": Out(1),
            "asa": Out(data.ArrayLayout(8, 3)),
            "test": Out(TestByte), "test_busy": In(1),
            "tick": In(1, init=1),
        })

    def elaborate(self, platform):
        m = Module()
        program = self.program
        mark = next((i for i, s in enumerate(program) if s.op == Op.MARK), None)
        skip_mag = 0 if mark is None else mark + 1
        stream = len(program) - 1
        assert program[stream].op == Op.STREAM, "a program ends with its STREAM step"
        mag_start = next((i for i, s in enumerate(program) if s.mag), None)
        config_start = max(i + 1 for i, s in enumerate(program)
                           if s.check == "who_am_i" or s.self_test)

        # -- program ROM --------------------------------------------------------------------------
        # In an M9K (``FrameRAM`` with the program as its words: ``self.rom``, for ``report``),
        # not in logic (as a LUT ROM, about 60 LUTs more by ``report``'s count). The ROM
        # reads at ``pc`` and its word is registered again (``step``): no path runs from the
        # block RAM's output through the sequencer's logic back to its address (that loop
        # limited the routed Fmax, report --timing). So a step is fetched two cycles after
        # ``pc`` took its index (LOAD0, LOAD1), after a reset too.
        pc = Signal(range(len(program)))
        step_layout = self.step_layout
        step = Signal(step_layout, reset_less=True)
        m.submodules.rom = rom = self.rom
        m.d.comb += [rom.r_en.eq(1), rom.r_addr.eq(pc)]
        m.d.sync += step.eq(rom.r_data)

        def goto(index):
            m.d.sync += pc.eq(index)

        port = self.port
        last, command = self._port(m, step)

        # TEST: the read's bytes to the self-test, counted from the step's index
        # a TEST's reads after its first (the word's ``more``: its repeat less one, no
        # subtractor), and those still to come after the present one
        reads = Signal.like(step.more)
        offset = Signal(5)
        test = self.test
        m.d.comb += [test.byte.eq(port.rx.payload), test.index.eq(step.value[:5] + offset),
                     test.subtract.eq(step.mask[0]),
                     test.first.eq(step.mask[1] & (reads == step.more))]

        timer = Signal(range(max(self.poll_load, *self.timer_loads) + 1))
        # a WAIT marked ``backoff`` is its word's wait 2**backoff times over: ``repeats`` more
        # times after the first (``(w + 1) << k`` ticks in all, as one count of that length
        # would be, but the timer stays as wide as the longest word and needs no shifter)
        repeats = Signal(BACKOFF_MAX_SHIFT)

        # a requested restart waits for the step under way (at most a poll time-out), so that
        # no command is left half done on the port
        restart_pending = Signal()
        reconfiguring = Signal()        # a reconfiguration: the magnetometer's part is left out
        # restarts since the program last reached STREAM, at most BACKOFF_MAX_SHIFT: the waits
        # marked ``backoff`` last 2**backoff times their cycles (100, 200, 400, 400 ... ms)
        backoff = Signal(range(BACKOFF_MAX_SHIFT + 1))
        with m.If(self.restart):
            m.d.sync += restart_pending.eq(1)

        def restart():
            goto(0)
            m.d.sync += [self.streaming.eq(0), self.mag_ok.eq(0),
                         self.mag_setup.eq(0), restart_pending.eq(0), reconfiguring.eq(0)]
            m.d.comb += self.restarted.eq(1)
            with m.If(~self.restarts.all()):
                m.d.sync += self.restarts.eq(self.restarts + 1)
            with m.If(backoff != BACKOFF_MAX_SHIFT):
                m.d.sync += backoff.eq(backoff + 1)
            m.next = "LOAD0"

        # where the magnetometer's part ends (done, or failed): at bring-up the interrupt's
        # set-up after it; in a set-up again while streaming the STREAM step, past it. The
        # MPU9250 still has INT_ENABLE then, unless it was reset (a brown-out), and a reset
        # part must stay silent, to be found by the reader's INT time-out and brought up
        # whole: enabled again here, it came back at its reset rate and full scales (I2C
        # wiring below about 133 Hz, where the AK8963 is missed before the INT time-out)
        after_mag = Mux(self.mag_setup, stream, skip_mag)

        def mag_done():
            goto(after_mag)
            m.next = "LOAD0"

        def fail(absent):
            """The current step failed: ``absent`` = no acknowledge / time-out, else a bad value."""
            with m.If(step.fail == Fail.MAG):
                mag_done()
                m.d.sync += [self.mag_absent.eq(absent),
                             self.mag_wia_error.eq(~absent)]
            with m.Else():
                with m.If(absent):
                    m.d.sync += [self.no_response.eq(1), self.whoami_error.eq(0)]
                restart()

        def next_step():
            if mag_start is None:
                goto(pc + 1)
            else:
                goto(Mux(reconfiguring & (pc == mag_start - 1), skip_mag, pc + 1))
            m.next = "LOAD0"

        with m.If(self.mag_nack):
            # the AK8963 stopped answering: down until a set-up finds it (the reader stops
            # reading it, and asks for the set-up after its time-out)
            m.d.sync += [self.mag_absent.eq(1), self.mag_ok.eq(0)]

        # a command once offered stays offered until taken (a stream's rule): a restart
        # requested meanwhile waits for it like for any step under way
        offered = Signal()
        m.d.sync += offered.eq(port.cmd.valid & ~port.cmd.ready)

        with m.FSM(init="LOAD0"):
            self._states(m, SimpleNamespace(command=command, restart=restart, step=step,
                timer=timer, next_step=next_step, reconfiguring=reconfiguring, backoff=backoff,
                repeats=repeats, reads=reads, offset=offset, restart_pending=restart_pending,
                goto=goto, config_start=config_start, fail=fail, last=last, test=test, port=port,
                mag_start=mag_start, offered=offered, mag_done=mag_done))
        return m

    def _port(self, m, step):
        """The register port: ``last`` (every read here is one byte, kept) and ``command()``,
        which offers the step's command (returned)."""
        port = self.port
        last = Signal(8)
        m.d.comb += [port.rx.ready.eq(1), port.rsp.ready.eq(1)]
        with m.If(port.rx.valid):
            m.d.sync += last.eq(port.rx.payload)

        # the command is the step's word, whichever state offers it (a payload chosen per
        # state would cost a LUT a bit)
        p = port.cmd.payload
        m.d.comb += [p.device.eq(step.device), p.reg.eq(step.reg),
                     p.write.eq(step.op == Op.WRITE), p.data.eq(step.value),
                     p.length.eq(step.length), p.fast.eq(step.fast)]

        def command():
            m.d.comb += port.cmd.valid.eq(1)
        return last, command

    def _states(self, m, c):
        """The sequencer's states: a step loaded from the program ROM and fetched, then
        waited for, accessed, tested or polled, and RUNNING once the program is done.
        ``c``: the sequencer's signals and helpers (``elaborate``)."""
        (command, restart, step, timer, next_step, reconfiguring, backoff, repeats, reads,
         offset, restart_pending, goto, config_start, fail, last, test, port, mag_start,
         offered) = (
            c.command, c.restart, c.step, c.timer, c.next_step, c.reconfiguring, c.backoff,
            c.repeats, c.reads, c.offset, c.restart_pending, c.goto, c.config_start, c.fail,
            c.last, c.test, c.port, c.mag_start, c.offered)
        with m.State("LOAD0"):
            # the ROM reads the step at pc
            m.next = "LOAD1"
        with m.State("LOAD1"):
            # ``step`` takes it
            m.next = "FETCH"
        with m.State("FETCH"):
            with m.If(restart_pending & ~offered):
                restart()
            with m.Else():
                self._fetch(m, step, command, timer, next_step, reconfiguring, backoff, repeats,
                            reads, c.mag_done)
        with m.State("WAIT"):
            # the count of ``repeats`` passes of ``wait + 1`` ticks and ``timer``: a pass
            # ends with the tick that finds the timer at 0
            with m.If(timer != 0):
                m.d.sync += timer.eq(timer - self.tick)
            with m.Elif(repeats == 0):
                next_step()
            with m.Elif(self.tick):
                m.d.sync += [timer.eq(step.wait), repeats.eq(repeats - 1)]
        with m.State("ACCESS"):
            with m.If(port.rsp.valid):
                with m.If(port.rsp.payload.error):
                    fail(absent=1)
                with m.Elif(step.op == Op.CHECK):
                    with m.If(step.check_wia):
                        with m.If(last == A.WIA_VALUE):
                            next_step()
                        with m.Else():
                            fail(absent=0)
                    with m.Else():
                        good = Cat(last == v for v in self.accepted_who_am_i).any()
                        m.d.sync += [self.who_am_i.eq(last), self.whoami_error.eq(~good),
                                     self.no_response.eq((last == 0x00) | (last == 0xFF))]
                        with m.If(good):
                            next_step()
                        with m.Else():
                            restart()
                with m.Elif(step.op == Op.STORE):
                    m.d.sync += self.asa[step.value[:2]].eq(last)
                    next_step()
                with m.Else():
                    next_step()
        with m.State("TEST"):
            command()
            m.d.sync += offset.eq(0)
            with m.If(port.cmd.ready):
                m.next = "TEST_READ"
        with m.State("TEST_READ"):
            m.d.comb += test.valid.eq(port.rx.valid)
            with m.If(port.rx.valid):
                m.d.sync += offset.eq(offset + 1)
            with m.If(port.rsp.valid):
                with m.If(port.rsp.payload.error):
                    fail(absent=1)
                with m.Elif(reads == 0):
                    m.next = "TEST_END"
                with m.Else():
                    m.d.sync += [reads.eq(reads - 1), timer.eq(step.wait)]
                    m.next = "TEST_WAIT"
        with m.State("TEST_WAIT"):
            m.d.sync += timer.eq(timer - self.tick)
            with m.If(timer == 0):
                m.next = "TEST"
        with m.State("TEST_END"):
            with m.If(~self.test_busy):
                next_step()
        with m.State("POLL"):
            with m.If(timer != 0):
                m.d.sync += timer.eq(timer - self.tick)
            command()
            with m.If(port.cmd.ready):
                m.next = "POLL_WAIT"
        with m.State("POLL_WAIT"):
            with m.If(timer != 0):
                m.d.sync += timer.eq(timer - self.tick)
            with m.If(port.rsp.valid):
                with m.If(port.rsp.payload.error | (last & step.mask).any()):
                    fail(absent=1)
                with m.Elif((last & step.value).any() | ~step.value.any()):
                    next_step()
                with m.Elif(timer == 0):
                    fail(absent=1)
                with m.Else():
                    m.next = "POLL"
        with m.State("RUNNING"):
            # streaming; the magnetometer's part again when it went quiet
            with m.If(restart_pending):
                restart()
            with m.Elif(self.mag_lost):
                goto(mag_start or 0)
                m.d.sync += [self.mag_ok.eq(0), self.mag_setup.eq(1)]
                m.next = "LOAD0"
            with m.Elif(self.reconfigure):
                goto(config_start)
                m.d.sync += reconfiguring.eq(1)
                m.next = "LOAD0"

    def _fetch(self, m, step, command, timer, next_step, reconfiguring, backoff, repeats,
               reads, mag_done):
        """FETCH: start the step at ``pc`` (``mag_done``: MARK's way on, ``elaborate``)."""
        port = self.port
        with m.Switch(step.op):
            with m.Case(Op.WAIT):
                # ``step.wait`` is the cycles less one; a backoff's 2**k passes: 2**k - 1
                # repeats, which is k ones (no shifter, no adder)
                m.d.sync += [timer.eq(step.wait),
                             repeats.eq(Mux(step.backoff,
                                            Cat(*(backoff > k for k in range(len(repeats)))),
                                            0))]
                m.next = "WAIT"
            with m.Case(Op.WRITE):
                command()
                with m.If(port.cmd.ready):
                    m.next = "ACCESS"
            with m.Case(Op.CHECK, Op.STORE):
                command()
                with m.If(port.cmd.ready):
                    m.next = "ACCESS"
            with m.Case(Op.POLL):
                m.d.sync += timer.eq(self.poll_load)
                m.next = "POLL"
            with m.Case(Op.TEST):
                m.d.sync += reads.eq(step.more)
                m.next = "TEST"
            with m.Case(Op.MARK):
                m.d.sync += [self.mag_ok.eq(1), self.mag_absent.eq(0),
                             self.mag_wia_error.eq(0)]
                mag_done()
            with m.Case(Op.STREAM):
                with m.If(~self.streaming):
                    m.d.comb += self.started.eq(1)
                m.d.sync += [self.streaming.eq(1), self.mag_setup.eq(0), backoff.eq(0),
                             reconfiguring.eq(0)]
                m.next = "RUNNING"
