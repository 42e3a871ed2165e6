"""The balance controller (issue #57): a self-balancing robot's loop closed on the chip, from
the attitude to two H-bridge motors, with the trips that keep it safe without a host."""

from amaranth import *
from amaranth.lib import data, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from ..contract.balance_regs import (BALANCE_REGS, BALANCE_RESET, BALANCE_WIDTHS, CONTROL_BITS,
                                     DUTY_BITS, GAIN_BITS, GAIN_SHIFT, INTEGRAL_BITS,
                                     INTEGRAL_SHIFT, PWM_STEPS_MAX_HZ, TRIPS, W_FRACTION)
from ..link.board_bus import BoardBusSignature
from ..primitives.memories import FrameRAM
from ..primitives.multiplier import BLACKBOX_NAME


__all__ = ["BalanceController"]

GAINS = ("BAL_KP", "BAL_KD", "BAL_KI", "BAL_KV")


class BalanceController(wiring.Component):
    """A PID on the tilt with a term on the low-passed duty (``reference/balance_control.py``
    states the law and every format; this block matches its ``BalanceFixed`` bit for bit),
    driving two H-bridge motors alike: channel 0 forward and 1 reverse of motor A, 2 and 3 of
    motor B (a DRV8833's inputs: one channel pulses, the other stays low).

    Safety: disarmed at reset, and while disarmed every output is low (the outputs are AND-ed
    with ``armed``) and the duty, integral and low-pass are 0. Armed by a write of
    BAL_CONTROL bit 0 (the host: the watchdog applies) or by the arming pin's rising edge
    (with BAL_CONTROL bit 3; its falling edge disarms). Disarmed at once, in the cycles after
    the result that shows it: a tilt beyond BAL_CUTOFF ("fallen"), ``fault``; and at a sample
    period's end: more than BAL_STALE periods without a result ("stale"), host-armed, more
    than BAL_WATCHDOG without ``kick`` ("watchdog"; each counts from its register's value
    at the last result, command or arming). BAL_STATUS says which (``TRIPS``).

    Parameters
        ``clk_freq``: the clock; the motor PWM has 1024 steps of ``prescale`` cycles, the
            fewest that keep it at most ``PWM_STEPS_MAX_HZ`` (23.4 kHz at 48 MHz).
        ``kv_shift`` (8): the duty's low-pass: 2^-kv_shift of the way a sample (a build
            constant: a shift by a register would cost a barrel shifter).
        ``reset``: register values at reset, by name (``BALANCE_REGS``), over
            ``BALANCE_RESET`` (the rest 0: no gain, the output limit 0).
    Members
        ``bus`` (in, ``BoardBusSignature`` flipped): the registers (``BALANCE_REGS``).
        ``done`` (in): a result is taken: ``angles`` (in, roll and pitch, BAM32) and ``bias``
            (in, x and y, Q16.16 counts) are its.
        ``sample_taken`` (in): the engine takes a sample: ``gyro`` (in, x and y counts) is its
            (held here for its result).
        ``fault`` (in): the driver flags a fault (sampled with each result).
        ``period`` (in): a pulse per sample period (the stale and watchdog counts).
        ``kick`` (in): a pulse per accepted command.
        ``arm_pin`` (in, asynchronous): the arming input (synchronised here).
        ``pwm`` (out, 4), ``armed`` (out), ``duty`` (out, signed 11).
    The integral adds e only while the sum stays within ±BAL_I_LIMIT (conditional
    integration), and a write of BAL_I_LIMIT sets it to 0.
    Latency: the duty is new 9 cycles after ``done``; a trip disarms 2 cycles after it.
    Throughput: a result every 9 cycles.
    """

    blackbox = False        # ``report``: the multiplier as an empty 18 x 18 block

    def __init__(self, *, clk_freq, kv_shift=8, reset=None):
        self.kv_shift = kv_shift
        self.prescale = max(1, -(-int(clk_freq) // (1024 * PWM_STEPS_MAX_HZ)))
        self.reset = {**BALANCE_RESET, **(reset or {})}
        unknown = set(self.reset) - set(BALANCE_WIDTHS)
        if unknown:
            raise ValueError(f"no writable register {', '.join(sorted(unknown))}")
        # the read-back of the registers a write sets: a copy of each accepted write in a block
        # RAM (``_read_back``), its words at configuration the reset values
        self.stored = [name for name in BALANCE_WIDTHS if name != "BAL_CONTROL"]
        init = [0] * 16
        for name in self.stored:
            init[BALANCE_REGS[name]] = self.reset.get(name, 0) & 0xFFFFFFFF
        self.shadow = FrameRAM(16, 32, init=init)
        # the gains, for the multiplier: a block RAM of their own, read by the products' index
        # (no multiplexer of four 18-bit registers); their reset values until written
        assert [BALANCE_REGS[name] for name in GAINS] == \
            list(range(BALANCE_REGS[GAINS[0]], BALANCE_REGS[GAINS[0]] + len(GAINS)))
        self.gains = FrameRAM(len(GAINS), GAIN_BITS,
                              init=[self.reset.get(name, 0) & ((1 << GAIN_BITS) - 1)
                                    for name in GAINS])
        super().__init__({
            "bus": In(BoardBusSignature()),
            "done": In(1),
            "angles": In(data.ArrayLayout(signed(32), 2)),
            "bias": In(data.ArrayLayout(signed(32), 2)),
            "sample_taken": In(1),
            "gyro": In(data.ArrayLayout(signed(16), 2)),
            "fault": In(1),
            "period": In(1),
            "kick": In(1),
            "arm_pin": In(1),
            "pwm": Out(4),
            "armed": Out(1),
            "duty": Out(signed(DUTY_BITS)),
        })

    def elaborate(self, platform):
        m = Module()
        regs = self._registers(m)
        status = self._arming(m, regs)
        self._step(m, regs, status)
        self._outputs(m)
        return m

    def _registers(self, m):
        """The registers (a ``Signal`` each, by name), their writes and read-back."""
        bus = self.bus
        regs = {}
        for name, (bits, is_signed, _, _) in BALANCE_WIDTHS.items():
            if name in GAINS:
                continue                            # in ``gains``, a block RAM (``_step``)
            shape = signed(bits) if is_signed else unsigned(bits)
            regs[name] = Signal(shape, init=self.reset.get(name, 0), name=name.lower())
        addressed = {name: bus.addr == a for name, a in BALANCE_REGS.items()}
        in_range = Signal()
        with m.Switch(bus.addr):
            for name in BALANCE_WIDTHS:
                with m.Case(BALANCE_REGS[name]):
                    m.d.comb += in_range.eq(self._fits(bus.w_data, name))
        m.d.comb += [bus.exists.eq(Cat(*addressed.values()).any()), bus.ok.eq(in_range)]
        with m.If(bus.w_en & bus.ok):
            for name in BALANCE_WIDTHS:
                if name == "BAL_CONTROL" or name in GAINS:
                    continue                        # ``_arming``, ``_gains``
                with m.If(addressed[name]):
                    m.d.sync += regs[name].eq(bus.w_data)
        regs["write_control"] = bus.w_en & bus.ok & addressed["BAL_CONTROL"]
        regs["addressed"] = addressed
        return regs

    @staticmethod
    def _fits(word, name):
        """1 where ``word`` is in ``name``'s range (``BALANCE_WIDTHS``): every range is a
        field's whole span (signed: the bits above it copies of its sign bit; unsigned: 0), but
        BAL_STALE's, which leaves out 0: bit patterns, no 32-bit comparators."""
        bits, is_signed, low, high = BALANCE_WIDTHS[name]
        if is_signed:
            assert (low, high) == (-(1 << (bits - 1)), (1 << (bits - 1)) - 1)
            above = word[bits - 1:]
            fits = (above == 0) | above.all()
        else:
            assert high == (1 << bits) - 1 and low in (0, 1)
            fits = word[bits:] == 0
        return fits & (word[:bits] != 0) if low == 1 else fits

    def _arming(self, m, regs):
        """Armed, by whom, the last trip; returns ``status`` (its fields, for the read-back and
        the step), with ``trip`` (a dict of pulses by reason, set by the step and here)."""
        control = regs["BAL_CONTROL"]
        by_host = Signal()
        tripped = Signal(len(TRIPS))
        trip = {reason: Signal(name=f"trip_{reason}") for reason in TRIPS}
        pin = Signal()
        m.submodules.arm_sync = FFSynchronizer(self.arm_pin, pin)
        pin_was = Signal()
        m.d.sync += pin_was.eq(pin)
        pin_arms = control[CONTROL_BITS["pin_arms"]]
        w_data = self.bus.w_data
        arm = Signal()                  # arms this cycle (from disarmed: its state cleared)
        disarm = Signal()
        with m.If(regs["write_control"]):
            m.d.sync += control.eq(w_data[:4] & ~(1 << CONTROL_BITS["arm"]))
            with m.If(w_data[CONTROL_BITS["arm"]]):
                m.d.comb += arm.eq(~self.armed)
                m.d.sync += by_host.eq(1)
            with m.Else():
                m.d.comb += disarm.eq(1)
        with m.Elif(pin_arms & pin & ~pin_was):
            m.d.comb += arm.eq(~self.armed)
            m.d.sync += by_host.eq(0)
        with m.Elif(pin_arms & ~pin & pin_was):
            m.d.comb += disarm.eq(1)
        tripping = Cat(*trip.values()).any()
        with m.If(arm | disarm):
            m.d.sync += tripped.eq(0)
        with m.If(arm):
            m.d.sync += self.armed.eq(1)
        with m.If(disarm | tripping):
            m.d.sync += [self.armed.eq(0), by_host.eq(0)]
        with m.If(tripping & self.armed):
            m.d.sync += tripped.eq(Cat(*trip.values()))
        # The sample periods left before a trip: BAL_STALE's at each result, BAL_WATCHDOG's at
        # each command, and both while disarmed (so at arming); counted down each period, a
        # trip in the period that finds 0 (down counters with a load: no comparator of a count
        # with a register)
        stale_left = Signal(8)
        idle_left = Signal(BALANCE_WIDTHS["BAL_WATCHDOG"][0])
        with m.If(self.done | ~self.armed):
            m.d.sync += stale_left.eq(regs["BAL_STALE"])
        with m.Elif(self.period & (stale_left != 0)):
            m.d.sync += stale_left.eq(stale_left - 1)
        with m.If(self.kick | ~self.armed):
            m.d.sync += idle_left.eq(regs["BAL_WATCHDOG"])
        with m.Elif(self.period & (idle_left != 0)):
            m.d.sync += idle_left.eq(idle_left - 1)
        watchdog = regs["BAL_WATCHDOG"]
        m.d.comb += [
            trip["stale"].eq(self.armed & self.period & ~self.done & (stale_left == 0)),
            trip["watchdog"].eq(self.armed & by_host & self.period & ~self.kick &
                                (watchdog != 0) & (idle_left == 0) & ~trip["stale"]),
        ]
        read = {"BAL_CONTROL": Cat(self.armed, control[1:]),
                "BAL_STATUS": Cat(self.armed, by_host, C(0, 2), tripped),
                "BAL_DUTY": self.duty}
        self._read_back(m, regs, read)
        return {"trip": trip, "arm": arm, "disarm": disarm}

    def _read_back(self, m, regs, read):
        """The bus's reads, a cycle after the address: a register a write sets from the
        shadow RAM (every accepted write is copied there: its word is the register's, sign
        extended), or its reset value until written after a reset (the RAM keeps its words
        through a reset: a bit each, ``written``); CONTROL, STATUS and DUTY live. What a read
        returns is chosen with the address, as the RAM's word is read: no multiplexer of the
        registers' 250 bits."""
        bus = self.bus
        m.submodules.shadow = shadow = self.shadow
        stored = {name: bus.addr == BALANCE_REGS[name] for name in self.stored}
        written = Signal(len(self.stored))
        index = Cat(*stored.values())
        m.d.comb += [shadow.r_en.eq(1), shadow.r_addr.eq(bus.addr[:4]),
                     shadow.w_addr.eq(bus.addr[:4]), shadow.w_data.eq(bus.w_data),
                     shadow.w_en.eq(bus.w_en & bus.ok & index.any())]
        with m.If(bus.w_en & bus.ok):
            m.d.sync += written.eq(written | index)
        from_ram = Signal()
        other = Signal(32)                  # a reset value, or a live register's word
        constant_next, live_next = Signal(32), Signal(32)
        with m.Switch(bus.addr):
            for name in self.stored:
                if self.reset.get(name, 0):
                    with m.Case(BALANCE_REGS[name]):
                        m.d.comb += constant_next.eq(self.reset[name] & 0xFFFFFFFF)
            for name, value in read.items():
                with m.Case(BALANCE_REGS[name]):
                    m.d.comb += live_next.eq(value.as_signed() if value.shape().signed
                                             else value)
        chosen_written = (index & written).any()
        m.d.sync += [from_ram.eq(chosen_written),
                     other.eq(Mux(chosen_written, 0, constant_next) | live_next)]
        m.d.comb += bus.r_data.eq(Mux(from_ram, shadow.r_data, 0) | other)

    def _step(self, m, regs, status):
        """One result's step: e and the rate latched with it, the trips, the integral and the
        low-pass, four products through one multiplier, the duty (the reference's order)."""
        roll = regs["BAL_CONTROL"][CONTROL_BITS["roll"]]
        # the gyro count of the axis chosen, as the engine takes the sample
        g = Signal(signed(16))
        with m.If(self.sample_taken):
            m.d.sync += g.eq(Mux(roll, self.gyro[0], self.gyro[1]))
        # e: the angle less the set-point·2^16, its high half (the set-point has no low half)
        angle = Mux(roll, self.angles[0], self.angles[1])
        bias = Mux(roll, self.bias[0], self.bias[1])
        e = Signal(signed(16))
        rate = Signal(signed(17))               # 17 bits: no saturation (the operand has 18)
        fault = Signal()
        with m.If(self.done):
            m.d.sync += [e.eq(angle[16:] - regs["BAL_SETPOINT"]),
                         rate.eq(g - bias[16:].as_signed()),
                         fault.eq(self.fault)]
        # the integral within ±BAL_I_LIMIT (< 2^23): 24 bits, 0 again when the limit is
        # written (it integrates only within the limit: one it passes would hold it); the
        # low-pass of the duty·2^8 (|duty| < 1024): within ±2^18, 19 bits
        integral = Signal(signed(INTEGRAL_BITS))
        w = Signal(signed(DUTY_BITS + W_FRACTION))
        acc = Signal(signed(GAIN_BITS * 2 + 2))
        index = Signal(range(4))
        operand = Signal(signed(GAIN_BITS))
        with m.Switch(index):
            for k, x in enumerate(self._operands(e, rate, integral, w)):
                with m.Case(k):
                    m.d.comb += operand.eq(x)
        read_next = Signal(range(4))            # the gain the next cycle multiplies by
        gain = self._gains(m, read_next, index)
        # one 18 x 18 block for the four products; ``report`` counts it apart (``blackbox``)
        product = Signal(signed(GAIN_BITS * 2))
        if self.blackbox:
            m.submodules.mul = Instance(BLACKBOX_NAME, i_a=gain, i_b=operand, o_p=product)
        else:
            m.d.comb += product.eq(gain * operand)
        # the product registered (the multiplier block's own output register where it has
        # one): the multiplier and the accumulator's adder in different cycles
        product_r = Signal.like(product)
        m.d.sync += product_r.eq(product)
        trip = status["trip"]
        with m.If(~self.armed | status["arm"]):
            m.d.sync += [integral.eq(0), w.eq(0), self.duty.eq(0)]
        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.done):
                    m.next = "CHECK"
            with m.State("CHECK"):
                fallen = self._beyond(m, e, regs["BAL_CUTOFF"], "cutoff")
                m.d.comb += [trip["fault"].eq(self.armed & fault),
                             trip["fallen"].eq(self.armed & ~fault & fallen)]
                with m.If(self.armed & ~fault & ~fallen):
                    total = Signal(signed(INTEGRAL_BITS + 1))
                    m.d.comb += total.eq(integral + e)
                    # conditional integration: i + e if it is within the limit, else i held
                    # (the anti-windup of a clamp without its bound's negation and multiplexer)
                    over = self._beyond(m, total, regs["BAL_I_LIMIT"], "i_limit")
                    with m.If(~over):
                        m.d.sync += integral.eq(total)
                    m.d.sync += [
                        w.eq(w + ((Cat(C(0, W_FRACTION), self.duty).as_signed() - w) >>
                                  self.kv_shift)),
                        index.eq(0), acc.eq(0)]
                    m.d.comb += read_next.eq(0)
                    m.next = "MAC"
                with m.Else():
                    m.next = "IDLE"
            with m.State("MAC"):
                # product ``index`` now, the one before it into the sum
                m.d.comb += read_next.eq(index + 1)
                m.d.sync += index.eq(index + 1)
                with m.If(index != 0):
                    m.d.sync += acc.eq(acc + product_r)
                with m.If(index == 3):
                    m.next = "SUM"
            with m.State("SUM"):
                m.d.sync += acc.eq(acc + product_r)
                m.next = "DUTY"
            with m.State("DUTY"):
                limit = regs["BAL_OUT_LIMIT"]
                scaled = acc >> GAIN_SHIFT
                # saturated to the duty's 11 bits first (a bit pattern, not a comparator
                # of 30 bits), then clamped to the limit (< 1024: the same result)
                short = Signal(signed(DUTY_BITS))
                fits = (scaled[DUTY_BITS - 1:] == 0) | scaled[DUTY_BITS - 1:].all()
                m.d.comb += short.eq(Mux(fits, scaled, Mux(scaled < 0, -(1 << (DUTY_BITS - 1)),
                                                           (1 << (DUTY_BITS - 1)) - 1)))
                # clamped to ±limit: the bound on the duty's side, -limit as ~limit + 1
                over = self._beyond(m, short, limit, "out_limit")
                sign = short[-1]
                bound = Signal(signed(len(limit) + 1))
                m.d.comb += bound.eq((Cat(limit, C(0, 1)) ^ sign.replicate(len(limit) + 1)) +
                                     sign)
                with m.If(self.armed):
                    m.d.sync += self.duty.eq(Mux(over, bound, short))
                m.next = "IDLE"
        # after the step's own assignment: a write of the limit always leaves the integral 0
        with m.If(self.bus.w_en & self.bus.ok & regs["addressed"]["BAL_I_LIMIT"]):
            m.d.sync += integral.eq(0)

    @staticmethod
    def _beyond(m, x, limit, name):
        """Whether |``x``| > ``limit`` (unsigned): one carry chain, not two comparators and a
        negation. With s the sign of x and x' = x XOR s (|x| - s), x' + ~limit + s carries
        out of x's width exactly when |x| > limit."""
        width = len(x)
        assert len(limit) < width and not limit.shape().signed
        sign = x[-1]
        chain = Signal(width + 1, name=f"{name}_chain")
        wide = Cat(limit, C(0, width - len(limit)))         # zero-extended, then inverted
        m.d.comb += chain.eq((x.as_unsigned() ^ sign.replicate(width)) + ~wide + sign)
        return chain[width]

    def _gains(self, m, read_next, index):
        """The gain of product ``index`` (signed 18): the gains' RAM read the cycle before at
        ``read_next``, or a gain's reset value until it is written after a reset (the RAM
        keeps its words through one: a bit each)."""
        bus = self.bus
        m.submodules.gains = ram = self.gains
        first = BALANCE_REGS[GAINS[0]]
        is_gain = (bus.addr >= first) & (bus.addr < first + len(GAINS))
        slot = (bus.addr - first)[:2]
        written = Signal(len(GAINS))
        m.d.comb += [ram.r_en.eq(1), ram.r_addr.eq(read_next), ram.w_addr.eq(slot),
                     ram.w_data.eq(bus.w_data[:GAIN_BITS]),
                     ram.w_en.eq(bus.w_en & bus.ok & is_gain)]
        with m.If(bus.w_en & bus.ok & is_gain):
            m.d.sync += written.eq(written | (1 << slot))
        at_reset = Array(C(self.reset.get(name, 0), signed(GAIN_BITS)) for name in GAINS)
        gain = Signal(signed(GAIN_BITS))
        m.d.comb += gain.eq(Mux(written.bit_select(index, 1), ram.r_data.as_signed(),
                                at_reset[index]))
        return gain

    def _operands(self, e, rate, integral, w):
        """The four products' variable operands, in the order of ``GAINS`` (the integral's
        word, 24 - 8 bits, fits 18 without saturating)."""
        return [e, rate, integral >> INTEGRAL_SHIFT, w >> W_FRACTION]

    def _outputs(self, m):
        """Motor A and B alike: forward on channels 0 and 2, reverse on 1 and 3, each high for
        |duty| of a period's 1024 steps, all low while disarmed."""
        step = Signal(range(self.prescale))
        count = Signal(10)
        with m.If(step == self.prescale - 1):
            m.d.sync += [step.eq(0), count.eq(count + 1)]
        with m.Else():
            m.d.sync += step.eq(step + 1)
        magnitude = Mux(self.duty < 0, -self.duty, self.duty)
        on = self.armed & (count < magnitude)
        forward, reverse = on & (self.duty > 0), on & (self.duty < 0)
        # registered (no glitch on a pin), then AND-ed with ``armed`` again: low in the cycle
        # it disarms
        pulses = Signal(4)
        m.d.sync += pulses.eq(Cat(forward, reverse, forward, reverse))
        m.d.comb += self.pwm.eq(pulses & self.armed.replicate(4))
