"""Platform for the Radiona ULX3S (Lattice ECP5 LFE5U-25F, CABGA381), the open build flow.

Why this board: it is the most common ECP5 board with an FTDI UART, eight LEDs and a 2.54 mm
GPIO header, its 25F is the part ``report --timing`` places the core on (ECP5-25k, the open
proxy for the MAX10 C8), and ``amaranth-boards`` describes it. Its ECP5 speed grade is 6 (the
slowest), as the proxy's. Everything it needs comes from PyPI: YoWASP's Yosys, nextpnr-ecp5 and
ecppack (``build --board ulx3s`` points Amaranth at them).

The system clock comes from an ``ECP5PLL`` (25 MHz oscillator → 48 MHz by default); the MPU9250
goes on the GPIO header J1, the top row (``GP`` pins, as printed on the board's silk screen):

========================  ======  ===========  =========================================
name                      header  ball         what
========================  ======  ===========  =========================================
imu_cs_n                  GP0     B11          MPU9250 NCS (I2C wiring: held high)
imu_sclk                  GP1     A10          SCLK (I2C wiring: SCL, open drain)
imu_copi                  GP2     A9           SDI (I2C wiring: SDA, open drain)
imu_cipo                  GP3     B9           SDO (I2C wiring: AD0, driven)
imu_int                   GP4     A7           INT
pwm0 .. pwm3              GP7-10  A6 A4 A2 C4  PWM outputs (low until enabled)
arm                       GP11    F4           the balance controller's arming input
                                               (``--controller balance``; pulled down)
uart_tx / uart_rx         (FTDI)  L4 / M1      the USB serial port (``/dev/ttyUSB0``)
led0 .. led7              (LEDs)  B2 ... H3    status LEDs, as on the MAX10 board
========================  ======  ===========  =========================================

The header's pins are 3.3 V LVCMOS; the I2C lines get the ECP5's pull-ups (weak: the sensor
board's own pull-ups are still needed).
"""

from amaranth.build import Attrs, Pins, PinsN, Resource, Subsignal
from amaranth_boards.ulx3s import ULX3S_25F_Platform

from ..primitives.clocking import ECP5PLL


__all__ = ["ULX3SPlatform", "ULX3S_PINS"]


# name: the GPIO header's connector pin (``gpio 0``: "n+" is GPn)
ULX3S_PINS = {"imu_cs_n": "0+", "imu_sclk": "1+", "imu_copi": "2+", "imu_cipo": "3+",
              "imu_int": "4+", "pwm0": "7+", "pwm1": "8+", "pwm2": "9+", "pwm3": "10+",
              "arm": "11+"}


class ULX3SPlatform(ULX3S_25F_Platform):
    """The ULX3S 25F with the resources ``BoardTop`` requests (``imu_spi``, ``imu_i2c``,
    ``pwm``) on its GPIO header, and the ECP5 PLL as the system clock's source
    (``system_pll``). Programming the board (``openFPGALoader``) is the user's step: it is not
    among the tools a build requires."""

    def __init__(self):
        conn = ("gpio", 0)
        io = Attrs(IO_TYPE="LVCMOS33")
        pull = Attrs(IO_TYPE="LVCMOS33", PULLMODE="UP")
        pins = ULX3S_PINS

        def pin(name, direction, inverted=False):
            return (PinsN if inverted else Pins)(pins[name], dir=direction, conn=conn)

        self.resources = [*self.resources,
            *[Resource("pwm", i, pin(f"pwm{i}", "o"), io) for i in range(4)],
            # the balance controller's arming input: pulled down, so a header left open
            # never arms it
            Resource("arm", 0, pin("arm", "i"), Attrs(IO_TYPE="LVCMOS33", PULLMODE="DOWN")),
            Resource("imu_spi", 0,
                     Subsignal("cs", pin("imu_cs_n", "o", inverted=True)),
                     Subsignal("clk", pin("imu_sclk", "o")),
                     Subsignal("copi", pin("imu_copi", "o")),
                     Subsignal("cipo", pin("imu_cipo", "i")),
                     Subsignal("int", pin("imu_int", "i")), io),
            Resource("imu_i2c", 0,
                     Subsignal("scl", pin("imu_sclk", "io"), pull),
                     Subsignal("sda", pin("imu_copi", "io"), pull),
                     Subsignal("ad0", pin("imu_cipo", "o"), io),
                     Subsignal("ncs", pin("imu_cs_n", "o"), io),
                     Subsignal("int", pin("imu_int", "i"), io)),
        ]
        super().__init__(toolchain="Trellis")

    @property
    def required_tools(self):
        return ["yosys", "nextpnr-ecp5", "ecppack"]

    def system_pll(self, out_hz):
        """The PLL making ``out_hz`` from the 25 MHz oscillator. nextpnr derives its output's
        frequency from the dividers and the oscillator's constraint, and times the design
        against it."""
        return ECP5PLL(in_hz=self.default_clk_frequency, out_hz=out_hz)
