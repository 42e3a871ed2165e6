"""The verbs that run the design or a filter without a board: ``simulate`` (co-simulation,
faults, waveforms) and ``replay`` (a recording through a filter, the engine or the whole
simulated board)."""

import json
import math
import os
import sys
import time

from ..hdl.contract.filter_registry import FILTER_NAMES, FLOAT_FILTERS
from .options import (_add_full_scale_options, _add_left_out_options, _add_sensor_options,
                      _clock, _config, _count, _core_options, _number, _positive, check_rates)


__all__ = ["add_simulate", "add_replay", "cmd_simulate", "cmd_replay", "attitude_json",
           "sample_read_time"]


def add_simulate(sub, quiet):
    """``simulate``: its options."""
    p = sub.add_parser("simulate", parents=[quiet],
                       help="co-simulate the gateware with the MPU9250 model",
                       description="Bring-up plus N samples, compiled (Verilator) or in "
                                   "Amaranth's simulator (--simulator), with real time scaled "
                                   "down (delays and sample period) to save cycles.")
    p.add_argument("--samples", type=_count, default=20, help="samples to read (default 20)")
    p.add_argument("--vcd", default=None, metavar="FILE",
                   help="write a waveform of every signal and a GTKWave .gtkw beside it: VCD, or "
                        "FST (GTKWave's compressed format, tens of times smaller) where FILE "
                        "ends in .fst; for long runs an FST and a window (--trace-from/-to)")
    p.add_argument("--trace-from", default=None, metavar="WHEN",
                   help="with --vcd: trace from WHEN on: a count of samples (5: once 5 samples "
                        "are out, so the read of the 6th is in) or a simulated time with its "
                        "unit (2ms, 150us, 0.01s); default the start")
    p.add_argument("--trace-to", default=None, metavar="WHEN",
                   help="with --vcd: trace until WHEN (as --trace-from); default the end")
    p.add_argument("--who-am-i", type=_number("a byte", low=0, integer=True), default=0x71,
                   help="WHO_AM_I of the modelled part (default 0x71; 0x73 is an MPU9255)")
    p.add_argument("--delay-scale", type=_positive, default=1e-3,
                   help="scale of start-up and reset delays (default 1e-3)")
    p.add_argument("--odr-scale", type=_positive, default=None,
                   help="scale of the sample period (default 0.2 where the shortened period holds "
                        "twice a sample's cycles, as with SPI up to 1 kHz at 48 MHz; else 1)")
    p.add_argument("--quiet-summary", action="store_true", help="summary to stderr")
    p.add_argument("--pose", default=None, metavar="ROLL,PITCH,YAW",
                   help="the models read a board held still at this attitude (degrees, with "
                        "sensor noise) instead of the counting test pattern")
    p.add_argument("--attitude", action="store_true",
                   help="also run the samples through the attitude engine and print its result "
                        "per sample (quaternion, roll/pitch/yaw, bias, flags)")
    p.add_argument("--filter", choices=FILTER_NAMES,
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
    _add_left_out_options(p, which=" of the core --attitude simulates")
    p.set_defaults(func=cmd_simulate)


def add_replay(sub, quiet):
    """``replay``: its options."""
    p = sub.add_parser("replay", parents=[quiet], help="score a reference filter on a recording",
                       description="Quantise a BROAD-format recording (imu_gyr rad/s, imu_acc "
                                   "m/s², imu_mag µT, opt_quat, movement, sampling_rate) to "
                                   "MPU9250/AK8963 counts, run a filter, and print one JSON line "
                                   "with total/heading/inclination RMSE (BROAD's metric, degrees, "
                                   "over the movement samples).")
    p.add_argument("file", help="HDF5 recording, e.g. ../shared/data/broad/02_*.hdf5")
    p.add_argument("--filter", choices=FLOAT_FILTERS,
                   default="flagship",
                   help="the filter to score (flagship)")
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
                        f"board: {', '.join(FILTER_NAMES)}")
    p.add_argument("--samples", type=_count, default=None, metavar="N",
                   help="only the recording's first N samples")
    p.add_argument("--fixed", action="store_true", help="the same as --engine fixed")
    p.add_argument("--out", help="write the estimated quaternions (t, w, x, y, z) as CSV")
    p.add_argument("--beta", type=_positive, default=None,
                   help="Madgwick's gain β (default 0.1; every engine: BETA_K in the gateware)")
    _add_full_scale_options(p, whose="the recording's ")
    p.set_defaults(func=cmd_replay)


def cmd_simulate(args):
    from .. import progress
    from ..sim.scenarios.setup import SimSetup
    from ..sim.scenarios.core import run_core
    from ..sim.scenarios.frontend import run_frontend
    from ..sim.bench.bench import simulator_name

    if args.fault == "list":
        from ..sim.scenarios.faults import FAULTS
        for name, fault in FAULTS.items():
            print(f"{name:24s} {'/'.join(fault.wirings):8s} {fault.description}")
        return 0
    config = _config(args)
    clk_freq = _clock(args)
    check_rates(config, clk_freq, args)
    odr_scale = args.odr_scale if args.odr_scale is not None else \
        SimSetup.default_odr_scale(config, clk_freq)
    # the self-tests as built (the fault tests choose their own: ``catalogue_setup``)
    setup = SimSetup(clk_freq=clk_freq, config=config, delay_scale=args.delay_scale,
                     odr_scale=odr_scale, self_test=config.self_test)
    compiled = _simulator_choice(args)
    wave = _waveform(args)
    if args.fault is not None:
        return _simulate_fault(args, setup, compiled, wave)
    sources = _pose_sources(args.pose, args.samples, config, setup) if args.pose else {}
    model = setup.model(who_am_i=args.who_am_i, magnetometer=not args.no_mag, **sources)
    summary = {"wiring": config.wiring, "clock_hz": clk_freq,
               "odr_hz": config.output_data_rate, "dlpf_cfg": config.dlpf_cfg,
               "smplrt_div": config.smplrt_div}
    if args.attitude:
        # without --telemetry-divider, the divider the frames fit at the simulated (shortened)
        # sample period, as the build's fits the real one
        core_options = {"filter": args.filter,
                        "telemetry_divider": setup.telemetry_divider(args.baud),
                        **_core_options(args)}
        with progress.bar(args.samples, "simulate (whole core)", "result") as shown:
            run = run_core(setup, n_results=args.samples, model=model, baud=args.baud,
                           core_kwargs=core_options,
                           vcd=wave, progress=shown, compiled=compiled,
                           keep_on_interrupt=True)
        for r in run.results:
            print(json.dumps(attitude_json(r, args.filter)))
        # after the first result (as ``report``): the first sample's data-ready may come
        # while the read levelling's scan holds the reader, once, as streaming begins
        latency = run.latencies_us(clk_freq)[1:]
        interrupted = run.interrupted
        summary.update({
            "samples_filtered": run.counters.get("filtered"),
            "samples_lost": run.counters.get("lost"),
            "saturated_results": sum(r["flags"]["saturated"] for r in run.results),
            "results_not_sent": run.counters.get("not_sent"),
            "frames_received": len(run.frames),
            "telemetry_divider": core_options["telemetry_divider"],
            "latency_us": {"drdy_to_attitude": round(max(latency), 2) if latency else None},
            "cycles": run.cycles, "wall_s": round(run.wall_s, 3),
            "cycles_per_s": round(run.cycles / run.wall_s) if run.wall_s else None,
            "simulator": simulator_name(run.compiled),
            "status": run.status, "asa": run.asa})
        violations = [str(v) for who in (model, *model.aux_devices.values())
                      for v in who.violations]
    else:
        with progress.bar(args.samples, "simulate (sensor front end)", "sample") as shown:
            result = run_frontend(setup, n_samples=args.samples, model=model, vcd=wave,
                                  progress=shown, compiled=compiled, keep_on_interrupt=True)
        for s in result.samples:
            print(json.dumps({"counter": s["counter"], "accel": s["accel"], "temp": s["temp"],
                              "gyro": s["gyro"], "mag": s["mag"], "flags": s["flags"],
                              "skipped": s["skipped"]}))
        interrupted = result.interrupted
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
            "asa": result.asa, "who_am_i": result.who_am_i, "self_test": result.self_test,
            # the board register SPI_TRAINING at the end (read levelling, issue #58)
            "spi_training": result.level})
    summary.update({"violations": violations,
                    "time_scale": {"delays": setup.delay_scale,
                                   "sample_period": setup.odr_scale}})
    if interrupted:
        summary["interrupted"] = True
    print(json.dumps(summary), file=sys.stderr if args.quiet_summary else sys.stdout)
    if wave and os.path.exists(wave.path):
        print(f"wrote {wave.path} and {wave.gtkw}")
    if interrupted:
        # what was simulated is printed above (and the waveform kept up to there)
        print(f"mpu9250-ahrs simulate: interrupted; kept what was simulated "
              f"({summary.get('samples', len(run.results) if args.attitude else 0)} "
              f"{'results' if args.attitude else 'samples'})", file=sys.stderr)
        return 130
    return 1 if violations else 0


def _waveform(args):
    """``--vcd``, ``--trace-from`` and ``--trace-to`` as a ``sim.bench.waveforms.Waveform`` (None
    without --vcd); one error line for a bad value or a window without a file."""
    from ..sim.bench.waveforms import Waveform, parse_bound
    bounds = [None if text is None else parse_bound(text, option)
              for text, option in ((args.trace_from, "--trace-from"),
                                   (args.trace_to, "--trace-to"))]
    if args.vcd is None:
        if any(bounds):
            raise ValueError("--trace-from and --trace-to choose a window of the waveform: "
                             "give --vcd FILE too")
        return None
    return Waveform(args.vcd, *bounds)


def _simulator_choice(args):
    """``--simulator`` as ``run_frontend``'s ``compiled``: True, False or "prefer" (auto:
    compiled, built once if need be, where the run allows it). Auto without Verilator and g++
    says so in one line and runs Amaranth's simulator."""
    from ..sim.bench.compiled_design import verilator_available
    if args.simulator == "compiled":
        return True
    if args.simulator == "python":
        return False
    if not verilator_available():
        print("mpu9250-ahrs: verilator or g++ not found: simulating in Amaranth's simulator "
              "(slower; apt-get install verilator g++ for the compiled path)", file=sys.stderr)
        return False
    return "prefer"


def _simulate_fault(args, setup, compiled=None, wave=None):
    """``simulate --fault NAME``: the front end with one fault of the catalogue."""
    from .. import progress
    from ..sim.scenarios.faults import run_fault
    if args.attitude or args.pose:
        raise ValueError("--fault runs the sensor front end with its test pattern: leave out "
                         "--attitude and --pose")
    with progress.bar(None, f"simulate --fault {args.fault}", "sample") as shown:
        summary = run_fault(args.fault, setup, at=args.fault_at, vcd=wave, progress=shown,
                            compiled=compiled)
    summary["time_scale"] = {"delays": setup.delay_scale, "sample_period": setup.odr_scale}
    print(json.dumps(summary), file=sys.stderr if args.quiet_summary else sys.stdout)
    ok = summary["detected_after_samples"] is not None and summary["recovered"] and \
        summary["stale_valid_samples"] == 0
    return 0 if ok else 1


def attitude_json(result, filter):
    """One engine result (an ``Attitude`` as dicts) for printing: quaternion, roll/pitch/yaw
    in degrees, bias in gyro counts, flags."""
    from ..reference.fixed_point import bam_to_deg
    from ..reference.flagship_fixed import q30_to_float
    return {"counter": result["counter"], "filter": filter,
            "quat": [round(float(v), 6) for v in q30_to_float(result["quat"])],
            "roll_pitch_yaw_deg": [round(float(v), 4) for v in bam_to_deg(result["angles"])],
            "bias_counts": [round(v / 65536, 4) for v in result["bias"]],
            **{k: bool(v) for k, v in result["flags"].items() if k != "filter"}}


def _pose_sources(pose, samples, config, setup):
    """Model sources for a board held still at ``pose`` ("roll,pitch,yaw" in degrees), with
    the sensor error model's noise: MPU9250 and AK8963 values in counts."""
    from ..hdl.contract import ak8963_regs as A
    from ..sim.models.motion import SensorModel, accel_gyro_source, mag_source, static
    from ..reference.recording import Scales
    try:
        euler = [float(v) for v in pose.split(",")]
    except ValueError:
        euler = []
    if len(euler) != 3 or not all(math.isfinite(v) for v in euler):
        raise ValueError(f"--pose: {pose!r} is not roll,pitch,yaw in degrees (three numbers, "
                         f"e.g. 30,-10,45)")
    # the results are printed in these ranges: a pose outside them would come back as
    # another triple of the same attitude (300,100,45 as roll 120, pitch 80) without a word
    roll, pitch, yaw = euler
    if not (-180 <= roll <= 180 and -90 <= pitch <= 90 and -180 <= yaw <= 180):
        raise ValueError(f"--pose: {pose!r} is outside roll and yaw ±180°, pitch ±90° (the "
                         f"ranges the results are printed in)")
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
    from ..sim.scenarios.frontend import sample_read_cycles
    cycles = sample_read_cycles(result, setup)
    return None if cycles is None else round(cycles / setup.clk_freq * 1e6, 2)


def cmd_replay(args):
    import numpy as np
    from ..reference.evaluate import FIXED_FILTERS, run_filter, run_fixed, score
    from ..reference.recording import Scales, load_broad, quantise, saturated, to_units

    engine = "fixed" if args.fixed else args.engine
    if engine != "float" and args.filter not in FIXED_FILTERS:
        raise ValueError(f"--engine {engine} runs {', '.join(FIXED_FILTERS)}, not "
                         f"{args.filter}")
    from ..hdl.contract import mpu9250_regs as R
    R.gyro_config(args.gyro_fs)             # the full scales the part has, as simulate checks
    R.accel_config(args.accel_fs)
    rec = load_broad(args.file, first=args.samples)
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
    at_limit = saturated(*counts)
    fs = {"gyro": f"±{args.gyro_fs} °/s (--gyro-fs)", "accel": f"±{args.accel_fs} g (--accel-fs)",
          "mag": "the AK8963's range"}
    for name, n in at_limit.items():
        if n:
            print(f"mpu9250-ahrs replay: warning: {n} samples have a {name} axis at the limit "
                  f"of {fs[name]}: clipped, the motion is beyond that full scale",
                  file=sys.stderr)
    params = {"beta": args.beta} if args.beta is not None else {}
    units = {"gyro_lsb_per_dps": scales.gyro_lsb_per_dps,
             "accel_lsb_per_ms2": scales.accel_lsb_per_ms2}
    extra = {}
    start = time.perf_counter()
    from ..progress import enabled
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
        from ..progress import bar
        from ..sim.scenarios.board_replay import replay_board
        with bar(len(truth), "replay --engine board", "result") as shown:
            board = replay_board(args.filter, *counts, rec.dt, gyro_fs_dps=args.gyro_fs,
                                 accel_fs_g=args.accel_fs, progress=shown, **units, **params)
        # scored on what the host decoded: the samples the telemetry framed
        quat, truth, movement = board.quat, truth[board.indices], movement[board.indices]
        t = board.indices * rec.dt
        extra = board.summary()
    elif engine == "gateware":
        from ..reference.flagship_fixed import q30_to_float
        from ..sim.scenarios.attitude_bench import first_mismatch
        from ..sim.scenarios.compiled_engine import replay_gateware
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
              "samples_held": rec.held, "truth_rejected": rec.truth_rejected,
              "samples_at_limit": at_limit, **extra}
    if args.out:
        np.savetxt(args.out, np.column_stack([t, quat]),
                   delimiter=",", header="t_s,w,x,y,z", comments="", fmt="%.9g")
    print(json.dumps(result, allow_nan=False))
    return 0 if extra.get("bit_exact", True) else 1
