"""Platform for an Intel MAX10 10M08SCU169C8G board.

The default pinout follows the Arrow/Trenz MAX1000 (same 169-ball UBGA package): 12 MHz clock on
H6, eight user LEDs, the FTDI UART, and the MPU9250 on the 8-pin PMOD header. Every pin is an
entry of ``DEFAULT_PINOUT`` and can be overridden (``MAX10Platform(pinout={"imu_sclk": "J1"})``
or ``build --pin imu_sclk=J1``). Check the table against your board's schematic before you
program a device: a wrong clock or UART pin is harmless, a pin driven against another driver
is not.

========================  =====  ====================================================
name                      pin    what
========================  =====  ====================================================
clk12                     H6     12 MHz oscillator (system clock)
led0 .. led7              A8 A9 A11 A10 B10 C9 C10 D8  (status LEDs, active high)
uart_tx                   B4     FPGA -> host (FTDI BDBUS1 on the MAX1000)
uart_rx                   A4     host -> FPGA (FTDI BDBUS0): the command channel
imu_cs_n                  M3     PMOD pin 1: MPU9250 NCS
imu_copi                  L3     PMOD pin 2: MPU9250 SDI/SDA
imu_cipo                  M2     PMOD pin 3: MPU9250 SDO/AD0
imu_sclk                  M1     PMOD pin 4: MPU9250 SCLK/SCL
imu_int                   N3     PMOD pin 5: MPU9250 INT
pwm0 .. pwm3              H4 J2 L12 K11  Arduino header D3 D5 D6 D9: PWM outputs (servo or
                                 motor style, low until enabled; ``hdl/link/pwm.py``)
arm                       H5     Arduino header D2: the balance controller's arming input
                                 (``build --controller balance`` only; active high, its
                                 rising edge arms where BAL_CONTROL bit 3 allows; give it an
                                 external pull-down: the MAX10 has only weak pull-ups)
========================  =====  ====================================================

An I2C-wired MPU9250 board uses the same header: SCL on ``imu_sclk``, SDA on ``imu_copi``
(both open drain, with the board's pull-ups), AD0 driven on ``imu_cipo``, NCS held high on
``imu_cs_n``. The ``imu_i2c`` resource names them so; ``build --wiring i2c`` requests it.
"""

import re

from amaranth.build import Attrs, Clock, Pins, PinsN, Resource, Subsignal
from amaranth.vendor import AlteraPlatform

from ..primitives.clocking import OSCILLATOR_HZ, SystemPLL


__all__ = ["DEFAULT_PINOUT", "MAX10Platform", "check_pinout"]


DEFAULT_PINOUT = {
    "clk12": "H6",
    **{f"led{i}": pin for i, pin in enumerate("A8 A9 A11 A10 B10 C9 C10 D8".split())},
    "uart_tx": "B4",
    "uart_rx": "A4",
    "imu_cs_n": "M3",
    "imu_copi": "L3",
    "imu_cipo": "M2",
    "imu_sclk": "M1",
    "imu_int": "N3",
    **{f"pwm{i}": pin for i, pin in enumerate("H4 J2 L12 K11".split())},
    "arm": "H5",
}


# Balls of the 169-ball UBGA: rows A..N without I, columns 1..13. (Which of them are user I/O
# rather than power, ground or configuration balls is in Intel's pin-out file for the 10M08SC,
# not here: Quartus's fitter refuses those.)
_BALL = re.compile(r"[A-HJ-N](1[0-3]|[1-9])")


def check_pinout(pinout):
    """A pinout (name: ball) checked: known names, balls that exist on the U169 package, no
    ball used twice. Raises ValueError with one line."""
    unknown = set(pinout) - set(DEFAULT_PINOUT)
    if unknown:
        raise ValueError(f"unknown pin names {sorted(unknown)}; known: {sorted(DEFAULT_PINOUT)}")
    for name, ball in pinout.items():
        if not isinstance(ball, str) or not _BALL.fullmatch(ball):
            raise ValueError(f"pin {name}={ball}: not a ball of the 169-ball UBGA (rows A-N "
                             f"without I, columns 1-13, e.g. J1)")
    seen = {}
    for name, ball in pinout.items():
        if ball in seen:
            raise ValueError(f"pins {seen[ball]} and {name} are both on ball {ball}")
        seen[ball] = name


class MAX10Platform(AlteraPlatform):
    device = "10M08SC"
    package = "U169"
    speed = "C8"
    suffix = "G"
    default_clk = "clk12"
    clk_freq = OSCILLATOR_HZ
    resources = []      # filled per instance from the pinout
    connectors = []

    def __init__(self, *, pinout=None, toolchain="Quartus"):
        pinout = {**DEFAULT_PINOUT, **(pinout or {})}
        check_pinout(pinout)
        self.pinout = pinout
        io = Attrs(io_standard="3.3-V LVTTL")
        self.resources = [
            Resource("clk12", 0, Pins(pinout["clk12"], dir="i"), Clock(self.clk_freq), io),
            *[Resource("led", i, Pins(pinout[f"led{i}"], dir="o"), io) for i in range(8)],
            Resource("uart", 0,
                     Subsignal("tx", Pins(pinout["uart_tx"], dir="o")),
                     Subsignal("rx", Pins(pinout["uart_rx"], dir="i")), io),
            *[Resource("pwm", i, Pins(pinout[f"pwm{i}"], dir="o"), io) for i in range(4)],
            Resource("arm", 0, Pins(pinout["arm"], dir="i"), io),
            Resource("imu_spi", 0,
                     Subsignal("cs", PinsN(pinout["imu_cs_n"], dir="o")),
                     Subsignal("clk", Pins(pinout["imu_sclk"], dir="o")),
                     Subsignal("copi", Pins(pinout["imu_copi"], dir="o")),
                     Subsignal("cipo", Pins(pinout["imu_cipo"], dir="i")),
                     Subsignal("int", Pins(pinout["imu_int"], dir="i")), io),
            Resource("imu_i2c", 0,
                     Subsignal("scl", Pins(pinout["imu_sclk"], dir="io")),
                     Subsignal("sda", Pins(pinout["imu_copi"], dir="io")),
                     Subsignal("ad0", Pins(pinout["imu_cipo"], dir="o")),
                     Subsignal("ncs", Pins(pinout["imu_cs_n"], dir="o")),
                     Subsignal("int", Pins(pinout["imu_int"], dir="i")), io),
        ]
        super().__init__(toolchain=toolchain)

    def system_pll(self, out_hz):
        """The PLL making ``out_hz`` from the oscillator (Quartus' ``altpll``; ``top.sdc``'s
        ``derive_pll_clocks`` constrains its output)."""
        return SystemPLL(in_hz=self.default_clk_frequency, out_hz=out_hz)

    @property
    def device_name(self):
        return f"{self.device}{self.package}{self.speed}{self.suffix}"
