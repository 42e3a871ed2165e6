"""Self-test of the MPU9250 and the AK8963 at bring-up: the pass rules and the block that judges.

The MPU9250's self-test (InvenSense's self-test application note, AN-MPU-9250A-03): at ±250 °/s,
±2 g, 1 kHz and the 92 Hz filters, ``N`` samples are summed with self-test off and ``N`` with
it on (GYRO_CONFIG / ACCEL_CONFIG [7:5]); the response of an axis is the difference,
``STR = Σ on − Σ off`` (``N`` times the application note's averaged response). Each axis has a
factory code in SELF_TEST_X/Y/Z_ACCEL and _GYRO; code ``c`` ≠ 0 stands for the factory
response ``ST_OTP = round(2620 · 1.01^(c − 1))`` LSB (``otp``). An axis passes
(``mpu_axis_passes``):

- gyro, ``c`` ≠ 0: ``S / ST_OTP > 0.5``; ``c`` = 0: ``|S| ≥ 7860`` LSB (60 °/s at 131 LSB/°/s);
- accelerometer, ``c`` ≠ 0: ``0.5 < S / ST_OTP < 1.5``; ``c`` = 0: ``3687 ≤ |S| ≤ 11059`` LSB
  (225 mg and 675 mg at 16,384 LSB/g: 3686.4 and 11059.2),

with ``S = floor(STR / N)``, the average response in whole LSB.

All in integers, as the gateware compares: ``2·S > T`` and, for the accelerometer,
``2·S < 3·T``, with ``S`` the average response ``floor(STR / N)`` (its size for code 0) and
``T = ST_OTP`` (15719 or 7373 for code 0).

The AK8963's self-test (its datasheet, 8.3.14): ASTC.SELF = 1, CNTL1 = 16-bit self-test mode,
one measurement of an internal field; after the sensitivity adjustment ``H_adj = floor(H ·
(ASA + 128) / 256)`` an axis passes when X and Y are in −200..200 and Z in −3200..−800
(``mag_axis_passes``).

``SelfTest`` takes the bytes the bring-up sequencer reads for the test, each with an index:

====== ============================================================================
index  byte
====== ============================================================================
0..13  a sample burst from ACCEL_XOUT_H (temperature, 6 and 7, left out): added to the
       axis' sum, or subtracted (``subtract``); ``first``: the burst starts the sums
16..21 the factory codes of accel X, Y, Z and gyro X, Y, Z: that axis is judged
24..30 the AK8963's HXL..HZH and ST2 (ignored): an axis is judged on its high byte
====== ============================================================================
"""

from amaranth import *
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from .driver_status import SelfTestStatus
from ..primitives.memories import FrameRAM
from ..primitives.multiplier import BLACKBOX_NAME


__all__ = ["otp", "mpu_axis_passes", "mag_axis_passes", "SelfTest", "TestByte", "SUM_INDEX",
           "CODE_INDEX", "MAG_INDEX", "GYRO_CODE0", "ACCEL_CODE0", "MAG_LIMITS"]


# the bits of ``SelfTest.fail`` (and ``DriverStatus.self_test_fail``) are in the order of the
# contract's ``self_test_axes.AXES``
SUM_INDEX, CODE_INDEX, MAG_INDEX = 0, 16, 24
GYRO_CODE0 = 15719          # 2·|S| > 15719: |S| ≥ 7860 LSB (60 °/s at ±250 °/s)
ACCEL_CODE0 = 7373          # 2·|S| > 7373 and < 22119: 3687 ≤ |S| ≤ 11059 (225, 675 mg at ±2 g)
MAG_LIMITS = ((-200, 200), (-200, 200), (-3200, -800))     # H_adj, 16-bit mode


class TestByte(data.Struct):
    """A byte the bring-up sequencer's TEST steps read, for ``SelfTest`` (its docstring)."""
    valid: 1
    byte: 8
    index: 5
    subtract: 1
    first: 1


def otp(code):
    """The factory self-test response (LSB at ±250 °/s or ±2 g) a code 1..255 stands for."""
    if not 1 <= code <= 255:
        raise ValueError(f"a self-test code is 1..255, not {code}")
    return round(2620 * 1.01 ** (code - 1))


def mpu_axis_passes(response, code, samples, gyro):
    """Does an MPU9250 axis pass? ``response``: Σ on − Σ off over ``samples`` samples each."""
    average = response // samples                   # floored, as an arithmetic shift does
    if code == 0:
        s, t = abs(average), GYRO_CODE0 if gyro else ACCEL_CODE0
    else:
        s, t = average, otp(code)
    return 2 * s > t and (gyro or 2 * s < 3 * t)


def mag_axis_passes(h, asa, axis):
    """Does an AK8963 axis pass? ``h``: its self-test reading, ``asa`` its fuse-ROM value."""
    low, high = MAG_LIMITS[axis]
    return low * 256 <= h * (asa + 128) < (high + 1) * 256


class SelfTest(wiring.Component):
    """Sums the self-test's sample bursts and judges each axis (module docstring: the rules).

    Parameters
        ``samples_log2``: ``N`` = 2**this samples in each half of the MPU9250's test (0..8).
    Members
        ``i`` (in, ``TestByte``): ``valid``, ``byte``, ``index``: a byte of the test and what
            it is (the table above); ``subtract``: a sum byte is subtracted; ``first``: a sum
            byte belongs to the first burst (its high byte replaces the sum).
        ``asa`` (in, 3 × 8): the AK8963's sensitivity adjustment, read before its test.
        ``busy`` (out): a byte is still being worked on (the next may come meanwhile only
            when bytes are at least 4 cycles apart, as on the sensor's buses).
        ``status`` (out, ``SelfTestStatus``): ``fail`` (9), the axes that failed (``AXES``
            order), each as last judged; ``done``: the six MPU9250 axes were judged (the last
            code came); ``mag_done``: the three AK8963 axes were judged.
    Latency: a sum byte takes two cycles (a read and a write of its sum), a code three, a
    magnetometer high byte three. Sums are ``17 + samples_log2`` bits, exact for any data.
    The sums live in a ``FrameRAM`` (``sums``) and the factory table in a 256-word one
    (``table``): two M9K blocks, no logic for either; the magnetometer's product in one
    18 × 18 multiplier.
    """
    blackbox = False        # ``report``: the multiplier as an empty 18 x 18 block

    def __init__(self, *, samples_log2):
        if not 0 <= samples_log2 <= 8:
            raise ValueError("SelfTest.samples_log2 must be 0..8")
        self.samples_log2 = samples_log2
        self.width = 17 + samples_log2
        self.sums = FrameRAM(8, self.width)
        # the factory response T and 3·T for each code (16 + 17 bits: one M9K word)
        self.table = FrameRAM(256, 33, init=[0] + [otp(c) | 3 * otp(c) << 16
                                                   for c in range(1, 256)])
        super().__init__({"i": In(TestByte), "asa": In(data.ArrayLayout(8, 3)),
                          "busy": Out(1), "status": Out(SelfTestStatus)})

    def elaborate(self, platform):
        m = Module()
        k, w = self.samples_log2, self.width
        m.submodules.sums = sums = self.sums
        m.submodules.table = table = self.table

        i, status = self.i, self.status
        index = i.index
        word = index[1:4]
        # accel words 0..2 are sums 0..2; gyro words 4..6 are sums 3..5 (3: the temperature)
        sum_axis = Mux(word > 3, word - 1, word)
        axis = Signal(3)                    # the sum or the axis the byte is for
        hi = Signal()                       # a sum byte is its word's high byte
        # the RAMs read every cycle, their addresses from the byte offered (what IDLE reads is
        # what SUM and CODE use; addresses and data pass ungated, a LUT a bit)
        m.d.comb += [sums.r_en.eq(1), table.r_en.eq(1),
                     sums.r_addr.eq(Mux(index >= 16, index - 16, sum_axis)),
                     table.r_addr.eq(i.byte)]

        # what the byte was, kept while it is worked on
        byte = Signal(8, reset_less=True)
        sub = Signal(reset_less=True)
        replace = Signal(reset_less=True)
        code0 = Signal(reset_less=True)
        gyro = Signal(reset_less=True)
        mag_lo = Signal(8, reset_less=True)
        product = Signal(signed(26), reset_less=True)
        # S: the averaged response (the sum floored by N); T and 3·T: the factory response or
        # a code-0 limit. For code 0 the rules are on |S|: a negative S is kept as ~S = |S| - 1
        # (no negation: an adder) and the code-0 limits are lowered to match (2·|S| > T is
        # 2·~S > T - 2; 2·|S| < 3·T is 2·~S < 3·T - 2)
        s = Signal(signed(18), reset_less=True)
        t = Signal(16, reset_less=True)
        t3 = Signal(17, reset_less=True)
        asa = Signal(8)
        # a choice of three, not an indexed slice (which is a multiply by the element width)
        m.d.comb += asa.eq(Mux(axis == 0, self.asa[0], Mux(axis == 1, self.asa[1], self.asa[2])))

        # the magnetometer's reading times its adjustment: both operands signed at their own
        # widths (one 18 x 18 block); ``report`` counts the block apart (``blackbox``)
        mul_a, mul_b = Cat(mag_lo, byte).as_signed(), Cat(asa + 128, C(0, 1)).as_signed()
        mul_p = Signal(signed(36))
        if self.blackbox:
            m.submodules.mul = Instance(BLACKBOX_NAME, i_a=mul_a, i_b=mul_b, o_p=mul_p)
        else:
            m.d.comb += mul_p.eq(mul_a * mul_b)

        # SUM's write: the byte added at its place in the word to the sum read in IDLE (or
        # to 0), one adder (old - addend = old + ~addend + 1); written in SUM only
        addend = Signal(signed(w))
        m.d.comb += addend.eq(Mux(hi, byte.as_signed() << 8, byte))
        old = Mux(replace, 0, sums.r_data.as_signed())
        m.d.comb += [sums.w_addr.eq(axis), sums.w_data.eq(old + Mux(sub, ~addend, addend) + sub)]

        with m.FSM() as fsm:
            with m.State("IDLE"):
                with m.If(i.valid):
                    m.d.sync += [byte.eq(i.byte), sub.eq(i.subtract)]
                    with m.If(index < 14):
                        with m.If(word != 3):
                            m.d.sync += [axis.eq(sum_axis), hi.eq(~index[0]),
                                         replace.eq(i.first & ~index[0])]
                            m.next = "SUM"
                    with m.Elif((index >= 16) & (index < 22)):
                        m.d.sync += [axis.eq(index - 16), code0.eq(i.byte == 0),
                                     gyro.eq(index >= 19)]
                        m.next = "CODE"
                    with m.Elif((index >= 24) & (index < 30)):
                        m.d.sync += axis.eq((index - 24) >> 1)
                        with m.If(~index[0]):
                            m.d.sync += mag_lo.eq(i.byte)
                        with m.Else():
                            m.next = "MAG"
            with m.State("SUM"):
                # the sum was read in IDLE; the byte goes in at its place in the word (below)
                m.d.comb += sums.w_en.eq(1)
                m.next = "IDLE"
            with m.State("CODE"):
                average = sums.r_data.as_signed() >> k        # floor(sum / N)
                neg = code0 & average[-1]
                # constants, chosen (not a subtraction)
                limit = Mux(gyro, Mux(neg, GYRO_CODE0 - 2, GYRO_CODE0),
                            Mux(neg, ACCEL_CODE0 - 2, ACCEL_CODE0))
                limit3 = Mux(gyro, Mux(neg, 3 * GYRO_CODE0 - 2, 3 * GYRO_CODE0),
                             Mux(neg, 3 * ACCEL_CODE0 - 2, 3 * ACCEL_CODE0))
                m.d.sync += [s.eq(Mux(neg, ~average, average)),
                             t.eq(Mux(code0, limit, table.r_data[:16])),
                             t3.eq(Mux(code0, limit3, table.r_data[16:]))]
                m.next = "JUDGE"
            with m.State("JUDGE"):
                twice = s << 1
                passes = (twice > t) & (gyro | (twice < t3))
                m.d.sync += status.fail.bit_select(axis, 1).eq(~passes)
                with m.If(axis == 5):
                    m.d.sync += status.done.eq(1)
                m.next = "IDLE"
            with m.State("MAG"):
                # H · (ASA + 128) in one 18 x 18 block
                m.d.sync += product.eq(mul_p)
                m.next = "MAG_JUDGE"
            with m.State("MAG_JUDGE"):
                adjusted = product >> 8                     # floor(H · (ASA + 128) / 256)
                z = axis == 2
                (xy_low, xy_high), _, (z_low, z_high) = MAG_LIMITS
                passes = ((adjusted >= Mux(z, z_low, xy_low)) &
                          (adjusted <= Mux(z, z_high, xy_high)))
                m.d.sync += status.fail.bit_select(6 + axis, 1).eq(~passes)
                with m.If(axis == 2):
                    m.d.sync += status.mag_done.eq(1)
                m.next = "IDLE"
        m.d.comb += self.busy.eq(~fsm.ongoing("IDLE"))
        return m
