"""PWM outputs for closing a control loop around the attitude: four channels, servo or motor
style, set through the command channel, low until enabled, and returned to low by a command
watchdog when the host goes silent."""

import math
from typing import NamedTuple

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .board_bus import BoardBusSignature
from ..primitives.memories import FrameRAM
# the registers, channels and limits (the host reads the same)
from ..contract.pwm_regs import (MOTOR_MAX_HZ, PERIOD_BITS, PWM_CHANNELS, PWM_REGS,
                                 SERVO_PERIOD_US, WATCHDOG_MS_AT_RESET)


__all__ = ["shadow_index", "PWMOutputs"]


def shadow_index(addr):
    """A register's word in ``PWMOutputs.shadow`` (its address's bits 0-2 and 4: every
    register of ``PWM_REGS`` has a word of its own): of an integer, or of the bus's address
    (a ``Value``: wiring, no logic)."""
    return (addr & 0b111) | ((addr >> 1) & 0b1000)


assert len({shadow_index(a) for a in PWM_REGS.values()}) == len(PWM_REGS)


class _Registers(NamedTuple):
    """What ``PWMOutputs._registers`` builds, for the watchdog and the outputs."""
    enable: Signal
    mode: Signal
    watchdog_ms: Signal
    watchdog_on: Signal
    period: list
    high: list
    given: Signal
    write: Value
    restart: Signal


class PWMOutputs(wiring.Component):
    """Four PWM channels behind a ``BoardBusSignature`` register bus.

    Each channel is servo or motor style. The servo channels share one frame (period) and the
    motor channels another, as on most flight controllers (a timer per group): two counters
    and, per channel, a high time. That keeps the block small (the MAX10's logic is mostly
    the attitude engine's).

    Registers (``PWM_REGS``; unused bits read 0)

    ==================  =======================================================================
    PWM_ENABLE (0x00)   bits 3:0: channel enabled. 0 at reset: every output low. Writing it
                        clears the watchdog's ``tripped``.
    PWM_MODE (0x01)     bits 3:0: 0 = servo (high time in µs), 1 = motor (in clock cycles). A
                        change to the mode of an enabled channel is refused. A channel whose
                        mode changes has its high time set to 0 (it reads 0): the value it
                        held was in the other unit (1,500 µs read as 1,500 cycles could
                        exceed the motor period), so it stays low until a high time is
                        written in its new unit.
    PWM_WATCHDOG_MS     0..65535: with a channel enabled, no accepted command for this long disables
    (0x02)              every channel (outputs low) and sets ``tripped``; 0 = off. 500 at
                        reset. Writing it starts the count again, as a command does.
    PWM_STATUS (0x03)   read only: bit 0 ``tripped``; bits 7:4 the channels enabled now.
    PWM_SERVO_PERIOD    the servo channels' frame: 2,500..20,000 µs (400..50 Hz); 20,000 at
    (0x04)              reset. Writing it sets the high time of every servo channel (enabled
                        or not) to 0: write the period first, then the high times.
    PWM_MOTOR_PERIOD    the motor channels' period: ⌈clk/20 kHz⌉ .. 65,535 cycles; the
    (0x05)              20 kHz one at reset. Writing it sets every motor channel's high time
                        to 0, likewise.
    PWM_HIGHk (0x10+k)  channel k's high time per period in its unit, ≤ its group's period (a
                        motor duty d/1024 is round(period · d / 1024) cycles: the host
                        converts). 0 at reset.
    ==================  =======================================================================

    Safety invariant: every channel's high time is at most its group's period, whatever the
    order of writes (the checks above keep it; ``tests/hdl/test_pwm.py`` drives random
    register sequences against it). An output is therefore high for a whole period only when
    a high time equal to the period was written in that channel's unit.

    A write outside these ranges is refused (``ok`` low: nothing changes). A new period or
    high time takes effect at the start of the group's next period (a period written while no
    channel of its group is enabled, at once), so a pulse is never cut short or stretched by
    an update; a channel enabled starts at its group's next period.

    The 16-bit registers are read back from ``shadow`` (a ``FrameRAM``, one M9K, written with
    every accepted write; ``shadow_index`` places them), not through a multiplexer of the
    registers: the bus's reads are registered (``BoardBusSignature``). A block RAM keeps its
    words through a reset, so a register not written since the last reset reads its reset
    value instead (a bit each for the three whose reset value is not 0).

    Parameters
        ``clk_freq``: the clock (Hz); the servo unit is ``round(clk_freq / 1e6)`` cycles.
    Members
        ``bus`` (in, ``BoardBusSignature`` flipped): the registers.
        ``kick`` (in): a pulse per accepted command: restarts the watchdog.
        ``pwm`` (out, 4): the outputs.
        ``tripped`` (out): the watchdog disabled the outputs (cleared by a PWM_ENABLE write).
        ``shadow``: the ``FrameRAM`` of the read-back (for ``report``).
    Latency: a register write is acknowledged in the cycle it is made and takes effect at the
    start of its group's next period (above); a read's word is on ``r_data`` the cycle after
    its address.
    """
    def __init__(self, *, clk_freq):
        self.clk_freq = clk_freq
        self.us_cycles = max(1, round(clk_freq / 1e6))
        self.motor_min = math.ceil(clk_freq / MOTOR_MAX_HZ)
        if self.motor_min >= 1 << PERIOD_BITS:
            raise ValueError(f"a {MOTOR_MAX_HZ} Hz motor period at {clk_freq / 1e6:g} MHz "
                             f"does not fit {PERIOD_BITS} bits")
        # the registers whose reset value is not 0, by name: their inits, and what they read
        # back until written after a reset (the read-back's block RAM keeps its words)
        self.at_reset = {"PWM_WATCHDOG_MS": WATCHDOG_MS_AT_RESET,
                         "PWM_SERVO_PERIOD": SERVO_PERIOD_US[1],
                         "PWM_MOTOR_PERIOD": self.motor_min}
        self.shadow = FrameRAM(16, PERIOD_BITS)
        super().__init__({
            "bus": In(BoardBusSignature()),
            "kick": In(1),
            "pwm": Out(PWM_CHANNELS),
            "tripped": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        regs = self._registers(m)
        us_tick = self._watchdog(m, regs)
        self._outputs(m, regs, us_tick)
        return m

    def _registers(self, m):
        """The registers, their read-back and the range checks of a write (``_Registers``)."""
        n = PWM_CHANNELS
        bus = self.bus
        enable = Signal(n)
        mode = Signal(n)
        watchdog_ms = Signal(16, init=self.at_reset["PWM_WATCHDOG_MS"])
        watchdog_on = Signal(init=watchdog_ms.init != 0)         # ``watchdog_ms`` is not 0
        # the two groups: 0 servo (µs), 1 motor (cycles). Each period is held complemented
        # (``~P``): it is where the group's count starts (``_outputs``), and a high time is
        # held added to it (below)
        mask = (1 << PERIOD_BITS) - 1
        period = [Signal(PERIOD_BITS, init=~self.at_reset["PWM_SERVO_PERIOD"] & mask,
                         name="servo_period_n"),
                  Signal(PERIOD_BITS, init=~self.at_reset["PWM_MOTOR_PERIOD"] & mask,
                         name="motor_period_n")]
        # each channel's high time ``h`` held as ``h + ~P`` (mod 2**16), ``P`` its group's
        # period when ``h`` was written: the group's count where the pulse ends. A period or
        # mode written since drops ``given`` (below), so a high time in use always holds the
        # period in use
        high = [Signal(PERIOD_BITS, name=f"high{k}") for k in range(n)]
        # a high time other than 0 given in the channel's present unit and period. A mode or
        # period change clears this bit rather than the high time (the register then reads 0
        # and the output stays low): one bit per channel to clear instead of sixteen
        given = Signal(n)

        # register reads, existence and the range checks of a write
        value = bus.w_data
        small = value[PERIOD_BITS:] == 0
        low = value[:PERIOD_BITS]
        # a high time fits its channel's group period: one adder for all channels (the
        # addressed channel's mode picks the period), ``h + ~P``: what the channel holds, and
        # ``h <= P`` exactly when it does not carry
        ends = low + Mux(mode.bit_select(bus.addr[:2], 1), period[1], period[0])
        high_fits = small & ~ends[PERIOD_BITS]
        # the 16-bit registers' read-back: a copy of each accepted write in a block RAM (a
        # multiplexer of the six would cost about a LUT per bit per register), read a cycle
        # after the address; a high time masked by ``given``
        m.submodules.shadow = shadow = self.shadow
        index = shadow_index(bus.addr)[:4]
        # A block RAM keeps its words through a reset: the registers whose reset value is not
        # 0 read it until they are written after one (``written``, a bit each, 0 at reset).
        # What a read returns is chosen a cycle ahead, with the address, as the RAM's word is
        # read (the bus holds the address): each source of the read-back an AND with its own
        # registered select, OR-ed (the RAM's word, a reset value, the small registers), not a
        # multiplexer on the address in front of the RAM's output
        kept = list(self.at_reset)              # the registers whose reset value is not 0
        written = Signal(len(kept))
        m.d.comb += [shadow.r_en.eq(1), shadow.r_addr.eq(index), shadow.w_addr.eq(index),
                     shadow.w_data.eq(low)]
        addressed = {name: bus.addr == a for name, a in PWM_REGS.items()}
        is_high = (bus.addr >> 2) == (PWM_REGS["PWM_HIGH0"] >> 2)
        from_ram = Signal()                     # the RAM's word: written since, or a high time
        at_reset = Signal(len(kept))            # a reset value: ``kept[j]``'s
        read_enable, read_mode, read_status = Signal(), Signal(), Signal()
        m.d.sync += [
            from_ram.eq((is_high & given.bit_select(bus.addr[:2], 1)) |
                        (Cat(*(addressed[name] for name in kept)) & written).any()),
            at_reset.eq(Cat(*(addressed[name] for name in kept)) & ~written),
            read_enable.eq(addressed["PWM_ENABLE"]), read_mode.eq(addressed["PWM_MODE"]),
            read_status.eq(addressed["PWM_STATUS"]),
        ]
        read_back = shadow.r_data & from_ram.replicate(PERIOD_BITS)
        for j, name in enumerate(kept):
            read_back = read_back | Mux(at_reset[j], self.at_reset[name], 0)
        read_back = (read_back | Mux(read_enable, enable, 0) | Mux(read_mode, mode, 0) |
                     Mux(read_status, Cat(self.tripped, C(0, 3), enable), 0))
        m.d.comb += bus.r_data.eq(read_back)
        checks = {
            PWM_REGS["PWM_ENABLE"]: value < (1 << n),
            # the mode of an enabled channel stays
            PWM_REGS["PWM_MODE"]: (value < (1 << n)) & (((value[:n] ^ mode) & enable) == 0),
            PWM_REGS["PWM_WATCHDOG_MS"]: small,
            PWM_REGS["PWM_STATUS"]: C(0),
            PWM_REGS["PWM_SERVO_PERIOD"]: small & (low >= SERVO_PERIOD_US[0]) &
                                          (low <= SERVO_PERIOD_US[1]),
            PWM_REGS["PWM_MOTOR_PERIOD"]: small & (low >= self.motor_min),
            **{PWM_REGS[f"PWM_HIGH{k}"]: high_fits for k in range(n)},
        }
        with m.Switch(bus.addr):
            for addr, ok in checks.items():
                with m.Case(addr):
                    m.d.comb += [bus.exists.eq(1), bus.ok.eq(ok)]
        write = bus.w_en & bus.ok
        m.d.comb += shadow.w_en.eq(write)
        with m.If(write):
            m.d.sync += written.eq(written | Cat(*(addressed[name] for name in kept)))
        nonzero = low != 0
        restart = Signal()              # the watchdog's count starts again (next cycle)
        m.d.sync += restart.eq(self.kick)
        with m.If(write):
            with m.Switch(bus.addr):
                with m.Case(PWM_REGS["PWM_ENABLE"]):
                    m.d.sync += [enable.eq(value[:n]), self.tripped.eq(0)]
                with m.Case(PWM_REGS["PWM_MODE"]):
                    m.d.sync += mode.eq(value[:n])
                with m.Case(PWM_REGS["PWM_WATCHDOG_MS"]):
                    m.d.sync += [watchdog_ms.eq(low), watchdog_on.eq(nonzero), restart.eq(1)]
                for g, name in enumerate(("PWM_SERVO_PERIOD", "PWM_MOTOR_PERIOD")):
                    with m.Case(PWM_REGS[name]):
                        m.d.sync += period[g].eq(~low)
                for k in range(n):
                    with m.Case(PWM_REGS[f"PWM_HIGH{k}"]):
                        m.d.sync += high[k].eq(ends[:PERIOD_BITS])
        # ``given``: a high time written sets a channel's bit (if not 0); a write drops it where
        # the high time no longer means what it did: a mode change (the high time was in the
        # other unit), or its group's period written (it was a duty of the old period; a
        # period shrunk under it would hold that output high)
        for k in range(n):
            dropped = ((addressed["PWM_MODE"] & (value[k] ^ mode[k])) |
                       (addressed["PWM_SERVO_PERIOD"] & ~mode[k]) |
                       (addressed["PWM_MOTOR_PERIOD"] & mode[k]))
            with m.If(write & addressed[f"PWM_HIGH{k}"]):
                m.d.sync += given[k].eq(nonzero)
            with m.Elif(write & dropped):
                m.d.sync += given[k].eq(0)
        return _Registers(enable, mode, watchdog_ms, watchdog_on, period, high, given, write,
                          restart)

    def _watchdog(self, m, r):
        """The microsecond tick of the time bases (returned) and the command watchdog."""
        us_timer = Signal(range(self.us_cycles), reset_less=True)
        us_tick = us_timer == 0
        m.d.sync += us_timer.eq(Mux(us_tick, self.us_cycles - 1, us_timer - 1))

        # the watchdog: the milliseconds left, counted down from ``watchdog_ms`` after each
        # accepted command (``kick``) or a write of the limit; the milliseconds are counted
        # in microsecond ticks, so a restart lands within a microsecond of the command
        ms_us = Signal(range(1000), init=999)
        ms_tick = us_tick & (ms_us == 0)
        left = Signal(16, init=r.watchdog_ms.init)
        with m.If(us_tick):
            m.d.sync += ms_us.eq(Mux(ms_us == 0, 999, ms_us - 1))
        with m.If(r.restart):
            m.d.sync += [left.eq(r.watchdog_ms), ms_us.eq(999)]
        with m.Elif(ms_tick & (left != 0)):
            m.d.sync += left.eq(left - 1)
        with m.If(r.watchdog_on & (left == 0) & ~r.restart & (r.enable != 0) & ~r.write):
            m.d.sync += [r.enable.eq(0), self.tripped.eq(1)]
        return us_tick

    def _outputs(self, m, r, us_tick):
        """The two time bases (servo in microseconds, motor in cycles) and the channels."""
        n = PWM_CHANNELS
        enable, mode, period, high, given = r.enable, r.mode, r.period, r.high, r.given

        # the two time bases: a counter each, from the group's ``~P`` (its period register,
        # taken at each wrap) up to ``2**16 - 2``: ``P`` ticks, and the wrap an equality with
        # a constant, not a comparison with the period in use. While no channel runs on it,
        # ``idle`` makes the next tick a wrap (a channel enabled starts there).
        # The time bases and each channel's active high time and state need no reset: with
        # every channel disabled (PWM_ENABLE is 0 at reset) they are reloaded each cycle
        last = (1 << PERIOD_BITS) - 1               # the step at a wrap
        count = [Signal(PERIOD_BITS, name="servo_count", reset_less=True),
                 Signal(PERIOD_BITS, name="motor_count", reset_less=True)]
        idle = [Signal(name="servo_idle", reset_less=True),
                Signal(name="motor_idle", reset_less=True)]
        wrap = [Signal(name="servo_wrap"), Signal(name="motor_wrap")]
        tick = [us_tick, C(1)]
        step = [Signal(PERIOD_BITS, name="servo_next"), Signal(PERIOD_BITS, name="motor_next")]
        in_use = [(enable & ~mode) != 0, (enable & mode) != 0]
        for g in range(2):
            m.d.comb += [step[g].eq(count[g] + 1),
                         wrap[g].eq(tick[g] & (idle[g] | (step[g] == last)))]
            with m.If(~in_use[g]):
                # no channel runs on it: a wrap at the next tick
                m.d.sync += idle[g].eq(1)
            with m.Elif(wrap[g]):
                m.d.sync += [count[g].eq(period[g]), idle[g].eq(0)]
            with m.Elif(tick[g]):
                m.d.sync += count[g].eq(step[g])

        for k in range(n):
            active_high = Signal(PERIOD_BITS, name=f"active_high{k}", reset_less=True)
            # ``count < active_high`` of the channel's group while it runs (``h + ~P``, where
            # ``h`` ticks after the wrap end), kept as a bit: the count starts at ``~P`` at
            # the wrap and goes up by one a tick, so it is set at the wrap (if a high time was
            # given: ``given``, never for 0) and cleared when the count reaches the high time
            # (equality; a high time equal to the period is reached only at the wrap: high all
            # period). 0 while the channel is disabled and until its group's next wrap, so an
            # enabled channel starts at a wrap: its first pulse is a whole one
            below = Signal(name=f"below{k}", reset_less=True)
            group_wrap = Mux(mode[k], wrap[1], wrap[0])
            # one comparison with the group's count chosen first (a LUT a bit holds the
            # choice and the XOR), not one per group
            reaches = Mux(mode[k], tick[1], tick[0]) & (
                Mux(mode[k], step[1], step[0]) == active_high)
            # a disabled channel takes its high time at once; an enabled one at its group's
            # wrap
            with m.If(~enable[k]):
                m.d.sync += [active_high.eq(high[k]), below.eq(0)]
            with m.Elif(group_wrap):
                m.d.sync += [active_high.eq(high[k]), below.eq(given[k])]
            with m.Elif(reaches):
                m.d.sync += below.eq(0)
            m.d.comb += self.pwm[k].eq(enable[k] & below)
