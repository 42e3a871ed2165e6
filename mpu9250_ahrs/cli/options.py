"""What the command line's verbs share: argument types, the sensor and build options
declared once, the sensor configuration and the rate check they make of them."""

import argparse
import sys

from ..hdl.contract.defaults import DEFAULT_BAUD


__all__ = ["check_rates"]


def _int(text):
    return int(text, 0)


class BadNumber(argparse.ArgumentTypeError, ValueError):
    """A number ``_number``'s types refuse: argparse's usage error on the command line, and a
    ``ValueError`` (one error line from ``main``) where a verb parses an argument itself."""


def _number(kind, *, low=None, above=None, integer=False):
    """An argparse type: a finite number (an integer if ``integer``) at least ``low`` or
    greater than ``above``; anything else is one clear usage error (``BadNumber``)."""
    def parse(text):
        try:
            value = int(text, 0) if integer else float(text)
        except ValueError:
            raise BadNumber(f"{text!r} is not {kind}") from None
        if value != value or value in (float("inf"), float("-inf")):
            raise BadNumber(f"{text!r} is not a finite number")
        if low is not None and value < low:
            raise BadNumber(f"{text} is less than {low}")
        if above is not None and value <= above:
            raise BadNumber(f"{text} must be more than {above}")
        return value
    parse.__name__ = kind
    return parse


_positive = _number("a number", above=0)


_count = _number("an integer", low=1, integer=True)


def _pin(text):
    if "=" not in text:
        raise argparse.ArgumentTypeError(f"{text!r}: give NAME=BALL, e.g. imu_sclk=J1")
    name, ball = text.split("=", 1)
    return name.strip(), ball.strip().upper()


def _config(args):
    from ..hdl.sensor.mpu9250_driver import MPU9250Config
    common = dict(gyro_fs_dps=args.gyro_fs, accel_fs_g=args.accel_fs,
                  int_latched=not args.int_pulse, wiring=args.wiring,
                  i2c_address=args.i2c_address, magnetometer=not args.no_mag,
                  self_test=not args.no_self_test)
    if getattr(args, "odr", None) is not None:
        if args.dlpf is not None or args.smplrt_div is not None:
            raise ValueError("--odr sets DLPF_CFG and SMPLRT_DIV itself: leave out --dlpf and "
                             "--smplrt-div")
        return MPU9250Config.for_odr(args.odr, **common)
    return MPU9250Config(dlpf_cfg=1 if args.dlpf is None else args.dlpf,
                         smplrt_div=0 if args.smplrt_div is None else args.smplrt_div,
                         **common)


def _core_options(args):
    """``AHRSCore`` arguments from the command line (telemetry rate, Euler-rate prediction)."""
    out = {}
    if getattr(args, "telemetry_divider", None) is not None:
        out["telemetry_divider"] = args.telemetry_divider
    if getattr(args, "no_commands", False):
        out["commands"] = False
    if getattr(args, "no_pwm", False):
        out["pwm"] = False
    if getattr(args, "attitude_port", False):
        out["attitude_port"] = True
    if getattr(args, "axi_lite", False):
        out["axi_lite"] = True
    if getattr(args, "controller", None):
        if getattr(args, "no_pwm", False):
            raise ValueError("--controller balance drives the PWM outputs: leave out --no-pwm")
        out["controller"] = args.controller
    if getattr(args, "euler_rates", False):
        from ..hdl.engine.attitude_engine import default_filter_config
        from ..hdl.contract.numeric_contract import FilterRates
        out["filter_config"] = default_filter_config(_config(args),
                                                     FilterRates(euler_rates=True))
    return out


def check_rates(config, clk_freq, args, *, out=None):
    """Refuse (ValueError, one line) a sample rate the design cannot filter at ``clk_freq``;
    warn (one line on ``out``) when the telemetry cannot carry every result."""
    from ..hdl.board.top import rate_budget
    from ..hdl.link.uart_tx import UARTTransmitter
    # a baud the UART cannot make: one line here, not an error inside an elaboration
    UARTTransmitter.divisor_for(clk_freq, getattr(args, "baud", DEFAULT_BAUD))
    budget = rate_budget(config, clk_freq, getattr(args, "baud", DEFAULT_BAUD),
                         _core_options(args).get("telemetry_divider"))
    if budget["sample_rate_hz"] > budget["max_sample_rate_hz"]:
        raise ValueError(
            f"{budget['sample_rate_hz']:g} Hz is more than this design filters at "
            f"{clk_freq / 1e6:g} MHz with {config.wiring.upper()} wiring: a sample needs "
            f"{budget['cycles_per_sample']} cycles, the longer of its read "
            f"({budget['read_cycles']}) and the engine's update ({budget['update_cycles']}), "
            f"which overlap (the next sample is read while the last is filtered): at most "
            f"{budget['max_sample_rate_hz']:.0f} Hz")
    if budget["telemetry_divider"] > 1:
        print(f"mpu9250-ahrs: warning: telemetry sends one result in "
              f"{budget['telemetry_divider']} ({budget['frames_per_s']:.0f} of "
              f"{budget['sample_rate_hz']:g} per "
              f"second; a {budget['frame_bytes']}-byte frame takes "
              f"{budget['frame_us']:.0f} us at {budget['baud']} baud); every sample is "
              f"still filtered", file=out or sys.stderr)
    return budget


def _add_full_scale_options(p, *, gyro=True, whose=""):
    """``--gyro-fs`` (unless ``gyro`` is False) and ``--accel-fs``: the one declaration of
    the full scales every verb that needs them shares (``whose``: e.g. "the board's ")."""
    if gyro:
        p.add_argument("--gyro-fs", type=int, default=2000, metavar="DPS",
                       help=f"{whose}gyro full scale: 250, 500, 1000 or 2000 °/s (default 2000)")
    p.add_argument("--accel-fs", type=int, default=16, metavar="G",
                   help=f"{whose}accelerometer full scale: 2, 4, 8 or 16 g (default 16)")


def _add_sensor_options(p):
    _add_full_scale_options(p)
    p.add_argument("--odr", type=_positive, default=None, metavar="HZ",
                   help="output data rate: 8000, or 1000/n for n = 1..256; sets DLPF_CFG and "
                        "SMPLRT_DIV (default 1000)")
    p.add_argument("--dlpf", type=int, default=None, help="CONFIG.DLPF_CFG 0..7 (default 1)")
    p.add_argument("--smplrt-div", type=int, default=None,
                   help="SMPLRT_DIV: rate = 1 kHz / (1 + div) (default 0)")
    p.add_argument("--clk-freq", type=_positive, default=None, metavar="HZ",
                   help="system clock (default 48e6: the board's PLL output)")
    p.add_argument("--baud", type=_count, default=DEFAULT_BAUD,
                   help=f"telemetry UART ({DEFAULT_BAUD})")
    p.add_argument("--euler-rates", action="store_true",
                   help="the per-axis filters predict with Euler-angle rates (register "
                        "EULER_RATES) instead of the published body rates")
    p.add_argument("--telemetry-divider", type=_count, default=None, metavar="N",
                   help="frame every N-th result (default: the smallest N the baud rate "
                        "carries; simulate: at its shortened sample period); every sample is "
                        "filtered either way")
    p.add_argument("--int-pulse", action="store_true",
                   help="50 µs INT pulses instead of a latched INT")
    p.add_argument("--wiring", choices=("spi", "i2c"), default="spi",
                   help="how the MPU9250 board is wired: SPI (AK8963 through the MPU9250's I2C "
                        "master) or I2C (AK8963 through the bypass multiplexer); default spi")
    p.add_argument("--i2c-address", type=_int, default=0x68,
                   help="MPU9250 I2C address with --wiring i2c: 0x68 (AD0 low) or 0x69")
    p.add_argument("--no-mag", action="store_true",
                   help="leave the AK8963 magnetometer alone (six-axis samples)")
    p.add_argument("--no-self-test", action="store_true",
                   help="no self-test of the MPU9250 and AK8963 at bring-up (it takes about "
                        "0.3 s; the board register SELF_TEST then stays 0)")


def _add_left_out_options(p, *, which=""):
    """What a user who needs the room can leave out of a build (``build``, ``report``, and
    ``simulate``'s whole core: ``which`` says so in the help)."""
    p.add_argument("--no-pwm", action="store_true",
                   help=f"leave the four PWM outputs out{which} (the command channel then "
                        f"answers bad_address for the PWM registers)")
    p.add_argument("--no-commands", action="store_true",
                   help=f"leave the command channel (UART receiver, decoder, replies) out{which}, "
                        f"and with it the PWM outputs: telemetry only, the filters as built")
    p.add_argument("--attitude-port", action="store_true",
                   help=f"with the core's attitude and sample streams for logic on the same "
                        f"chip{which} (ports attitude__*, attitude_dropped, sample__*, "
                        f"sample_dropped; build/README.md); a board top leaves them "
                        f"unconnected")
    p.add_argument("--axi-lite", action="store_true",
                   help=f"with an AXI4-Lite slave for a soft CPU{which} (ports s_axi__*, irq; "
                        f"hdl/AXI_LITE.md): the last result, status, counters, the engine's "
                        f"registers")
    p.add_argument("--controller", choices=("balance",), default=None,
                   help=f"with the balance controller{which}: a self-balancing robot's loop on "
                        f"the chip driving the four PWM outputs as two H-bridges (the PWM block "
                        f"left out), its registers in space 0x03 (hdl/contract/balance_regs.py), "
                        f"an arming input (port arm; pin arm on the boards: Arduino D2 on the "
                        f"MAX10 board, GP11 on the ULX3S)")


def _clock(args):
    from ..hdl.primitives.clocking import SYSTEM_CLOCK_HZ
    if args.clk_freq is not None and args.clk_freq <= 0:
        raise ValueError(f"--clk-freq must be positive, not {args.clk_freq:g}")
    return args.clk_freq or SYSTEM_CLOCK_HZ
