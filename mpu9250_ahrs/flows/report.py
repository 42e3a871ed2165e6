"""``report``: what the design costs on a 10M08, from Yosys, and how many cycles an update takes.

Synthesis is Debian's Yosys 0.23 (``apt-get install yosys``), ``synth_intel -family max10``.
It cannot map multipliers or initialised RAM onto the MAX10's hard blocks, so before
synthesis ``report`` swaps those blocks for empty modules (``hard_blocks_as_blackboxes``: the
gateware has no option for it) and counts them from their sizes:

- ``multipliers_18x18``: the engine's 32×32 multiplier is built from four 18×18 blocks (empty
  modules here) and the adders that combine their products, in logic as on a MAX10 (its blocks
  have no adders), so those adders are in ``logic_elements``; any other non-constant ``$mul``
  in the netlist is counted as ⌈a/18⌉·⌈b/18⌉ blocks.
- ``memory_bits``: the register file (twice: one copy per read port, as Quartus builds a RAM
  with two read addresses), the microcode ROM and (whole design) the other ``FrameRAM``s: the
  telemetry framer's frame buffer, the sample store, the sequencer's program, the command
  decoder's FIFO and counters, the PWM block's read-back, the self-test's sums and table, the
  CORDIC's arctangents. Small constant tables Yosys turns into ROMs stay in logic here:
  ``rom_bits_in_logic``. ``m9k_blocks``: each memory in the M9K mode that takes the fewest
  (``hdl.memories.m9k_blocks``; the register file twice), an estimate of Quartus' packing.
- ``logic_elements``: ``fiftyfivenm_lcell_comb`` cells, or registers where those are more (a
  MAX10 LE holds one LUT and one register). Yosys 0.23 maps adders without the LE's carry chain,
  so this is pessimistic; ``logic_elements_carry_chain`` is the same design through
  ``synth_ice40`` (LUT4 + carry chain + register: the same LE structure) for comparison.
- ``logic_elements_spread`` (``report --spread K``): ``logic_elements`` of K equivalent
  netlists (``reordered``: the same Verilog, its assignments in other orders), mean, least and
  most. Yosys and ABC map equivalent netlists to counts about 1.5 % apart, so one count is one
  draw; a change smaller than that is judged by the means.
- ``logic_levels``: the longest path in LUTs between registers, memories and multipliers
  (``ltp``), a stand-in for Fmax, which needs Quartus. The multiplier's own delay is not in it.
"""

import json
import math
import os
import re
import shutil
import subprocess
import tempfile

from amaranth.back import verilog


__all__ = ["DEVICE", "hard_blocks_as_blackboxes", "synthesize", "reordered",
           "logic_element_spread", "cycles_per_update", "report"]

# Intel MAX10 10M08SCU169: the budget the figures are read against.
DEVICE = {"name": "10M08SCU169C8G", "logic_elements": 8064, "multipliers_18x18": 24,
          "memory_bits": 387072, "m9k_blocks": 42}

YOSYS_HINT = "install it with: apt-get install yosys (Debian's 0.23 has synth_intel)"


def hard_blocks_as_blackboxes(engine, rams=(), others=()):
    """Mark the engine's multiplier, register file and ROM, the ``FrameRAM``s ``rams`` and the
    blocks ``others`` (whose own multipliers then are ``BLACKBOX_NAME`` blocks; the engine's
    CORDIC is one) to elaborate as empty modules (with the logic Quartus adds around them), for
    Yosys 0.23."""
    for block in (engine.multiplier, engine.regfile, engine.rom, engine.cordic, *rams,
                  *others):
        block.blackbox = True


def _stubs(engine, rams):
    from ..hdl.primitives.memories import blackbox_stub
    from ..hdl.primitives.multiplier import BLACKBOX_STUB
    return blackbox_stub(engine.regfile, engine.rom) + BLACKBOX_STUB + \
        "".join(ram.stub() for ram in rams)


def _yosys(script, cwd):
    yosys = shutil.which("yosys")
    if yosys is None:
        raise RuntimeError(f"report needs yosys; {YOSYS_HINT}")
    result = subprocess.run([yosys, "-q", "-p", script], cwd=cwd, capture_output=True,
                            text=True)
    if result.returncode:
        raise RuntimeError(f"yosys failed:\n{result.stderr[-2000:]}")
    return result


def _count(stat_text, cell):
    found = re.search(rf"^\s+{re.escape(cell)}\s+(\d+)\s*$", stat_text, re.M)
    return int(found.group(1)) if found else 0


def _logic_elements(stat_text):
    """``logic_elements`` of a ``synth_intel`` ``stat``: LUTs, or registers where those are
    more (a MAX10 LE holds one of each)."""
    return max(_count(stat_text, "fiftyfivenm_lcell_comb"), _count(stat_text, "dffeas"))


def reordered(verilog_text, seed):
    """The same netlist written otherwise: in each module, the single-line ``assign``
    statements after its last declaration, in an order drawn from ``seed`` (0: as they are).
    Yosys and ABC map equivalent netlists to counts that differ by about ±1.5 % (the order of
    the statements is enough), so one count is one draw: ``logic_element_spread`` makes
    several."""
    import random
    if seed == 0:
        return verilog_text
    rng = random.Random(seed)
    declaration = re.compile(r"^\s*(wire|reg|input|output|inout)\b")
    assign = re.compile(r"^\s+assign [^;]*;\s*$")
    lines = verilog_text.split("\n")
    out, module = [], []

    def flush():
        declared = [i for i, line in enumerate(module) if declaration.match(line)]
        first = declared[-1] + 1 if declared else 0
        places = [i for i in range(first, len(module)) if assign.match(module[i])]
        moved = [module[i] for i in places]
        rng.shuffle(moved)
        for i, line in zip(places, moved):
            module[i] = line
        out.extend(module)
        module.clear()

    for line in lines:
        module.append(line)
        if line.strip() == "endmodule":
            flush()
    flush()
    return "\n".join(out)


def logic_element_spread(verilog_text, stubs, name, draws, first=None):
    """``logic_elements`` of ``draws`` equivalent netlists (``reordered``, seeds 0 ..
    ``draws`` − 1; seed 0 is the count ``synthesize`` gives: ``first``, when it has been made
    already), two syntheses at a time: ``{"mean", "min", "max", "counts"}``. The mean is the
    figure to compare two designs by when they differ by less than the spread."""
    import concurrent.futures
    import statistics

    def count(seed):
        with tempfile.TemporaryDirectory() as tmp:
            with open(os.path.join(tmp, "design.v"), "w") as f:
                f.write(reordered(verilog_text, seed))
            with open(os.path.join(tmp, "stubs.v"), "w") as f:
                f.write(stubs)
            _yosys(f"read_verilog stubs.v; read_verilog design.v; synth_intel -family max10 "
                   f"-top {name} -nobram; tee -q -o intel.txt stat", tmp)
            return _logic_elements(open(os.path.join(tmp, "intel.txt")).read())

    known = [] if first is None else [first]
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        counts = known + list(pool.map(count, range(len(known), draws)))
    return {"mean": round(statistics.mean(counts), 1), "min": min(counts), "max": max(counts),
            "counts": counts}


def synthesize(top, name, engine, rams=(), others=(), *, blocks=False, ports=None,
                spread=0):
    """Figures for one elaboratable (``engine``: the AttitudeEngine inside it; ``rams``: other
    ``FrameRAM``s in it); their hard blocks are synthesised as empty modules. With ``blocks``,
    also ``blocks``: the same synthesis without flattening, per block (``block_figures``).
    ``ports``: the top's ports, for an elaboratable that is not a component. ``spread``: also
    ``logic_elements_spread``, the count of that many equivalent netlists
    (``logic_element_spread``)."""
    from ..hdl.primitives.memories import m9k_blocks
    from ..hdl.primitives.multiplier import BLACKBOX_NAME
    rams = [*rams, engine.cordic.atan_rom]        # the CORDIC's arctangents: a ROM
    hard_blocks_as_blackboxes(engine, rams, others)
    with tempfile.TemporaryDirectory() as tmp:
        text, stubs = verilog.convert(top, name=name, ports=ports), _stubs(engine, rams)
        with open(os.path.join(tmp, "design.v"), "w") as f:
            f.write(text)
        with open(os.path.join(tmp, "stubs.v"), "w") as f:
            f.write(stubs)
        read = "read_verilog stubs.v; read_verilog design.v"
        # netlist before mapping: multiplies and memories Yosys found itself
        _yosys(f"{read}; hierarchy -top {name}; proc; flatten; opt; memory -nomap; opt; "
               f"write_json pre.json", tmp)
        with open(os.path.join(tmp, "pre.json")) as f:
            pre = json.load(f)["modules"][name]
        _yosys(f"{read}; synth_intel -family max10 -top {name} -nobram; tee -q -o intel.txt "
               f"stat; delete t:dffeas t:mpu9250_ahrs_*; tee -q -o ltp.txt ltp", tmp)
        _yosys(f"{read}; synth_ice40 -top {name} -nobram; tee -q -o ice40.txt stat", tmp)
        if blocks:
            _yosys(f"{read}; synth_intel -family max10 -top {name} -nobram -noflatten; "
                   f"write_json hier.json", tmp)
            with open(os.path.join(tmp, "hier.json")) as f:
                hier = json.load(f)["modules"]
        intel = open(os.path.join(tmp, "intel.txt")).read()
        ice40 = open(os.path.join(tmp, "ice40.txt")).read()
        ltp = open(os.path.join(tmp, "ltp.txt")).read()

    multipliers = _count(intel, BLACKBOX_NAME)
    other_muls = []
    rom_bits = 0
    for cell in pre["cells"].values():
        p = cell["parameters"]
        if cell["type"] == "$mul":
            a, b = int(p["A_WIDTH"], 2), int(p["B_WIDTH"], 2)
            other_muls.append(f"{a}x{b}")
            multipliers += math.ceil(a / 18) * math.ceil(b / 18)
        elif cell["type"] == "$mem_v2":
            rom_bits += int(p["SIZE"], 2) * int(p["WIDTH"], 2)
    ffs = _count(intel, "dffeas")
    ice_ffs = sum(int(n) for n in re.findall(r"^\s+SB_DFF\w*\s+(\d+)\s*$", ice40, re.M))
    levels = re.search(r"length=(\d+)", ltp)
    figures = {
        "logic_elements": _logic_elements(intel),
        "logic_elements_carry_chain": max(_count(ice40, "SB_LUT4"), ice_ffs),
        "registers": ffs,
        "memory_bits": engine.regfile.bits + engine.rom.bits + sum(r.bits for r in rams),
        "rom_bits_in_logic": rom_bits,
        # the register file twice (a copy per read port), the ROM and RAMs in their best modes
        "m9k_blocks": 2 * m9k_blocks(engine.regfile.depth, 32) + engine.rom.m9k_blocks
        + sum(ram.m9k_blocks for ram in rams),
        "multipliers_18x18": multipliers,
        "other_multiplies": other_muls,
        "logic_levels": int(levels.group(1)) if levels else None,
    }
    if blocks:
        memories = {ram.name: ram.bits for ram in rams}
        memories[f"mpu9250_ahrs_regfile{engine.regfile.depth}x32"] = engine.regfile.bits
        memories[f"mpu9250_ahrs_rom{len(engine.rom.words)}x{engine.rom.width}"] = engine.rom.bits
        figures["blocks"] = block_figures(hier, name, memories, BLACKBOX_NAME)
    if spread:
        figures["logic_elements_spread"] = logic_element_spread(
            text, stubs, name, spread, first=figures["logic_elements"])
    return figures


def block_figures(modules, top, memories, multiplier):
    """Per block (each submodule of ``top`` and, one level down, of its engine and sensor
    front end), from a netlist synthesised without flattening (``modules``: Yosys' JSON):
    ``logic_elements`` (as the flat count: LUTs or registers, the more), ``luts``,
    ``registers``, ``memory_bits`` (the blackbox RAMs and ROMs in it, ``memories``: module
    name: bits) and ``multipliers_18x18`` (``multiplier`` blackboxes). Each module's own
    cells plus its submodules'; ``top`` itself is the logic between the blocks. Synthesis
    across a block's boundary is not optimised, so the blocks add up to more than the flat
    count (``logic_elements``)."""
    def own(module):
        cells = modules[module]["cells"].values()
        kinds = [c["type"] for c in cells]
        return {"luts": kinds.count("fiftyfivenm_lcell_comb"),
                "registers": kinds.count("dffeas"),
                "memory_bits": sum(memories.get(k, 0) for k in kinds),
                "multipliers_18x18": kinds.count(multiplier)}

    def total(prefix):
        names = [n for n in modules if n == prefix or n.startswith(prefix + ".")]
        sums = {"luts": 0, "registers": 0, "memory_bits": 0, "multipliers_18x18": 0}
        for n in names:
            for k, v in own(n).items():
                sums[k] += v
        return {"logic_elements": max(sums["luts"], sums["registers"]), **sums}

    out = {"(between blocks)": {"logic_elements": max(own(top)["luts"], own(top)["registers"]),
                                **own(top)}}
    children = sorted({n[len(top) + 1:].split(".")[0] for n in modules
                       if n.startswith(top + ".")})
    def label(name):
        return re.sub(r"\$\d+$", "", name)      # Amaranth's suffix for a name used twice

    for child in children:
        out[label(child)] = total(f"{top}.{child}")
        if label(child) in ("engine", "frontend"):
            inside = f"{top}.{child}."
            for sub in sorted({n[len(inside):].split(".")[0] for n in modules
                               if n.startswith(inside)}):
                out[f"{label(child)}.{label(sub)}"] = total(f"{top}.{child}.{sub}")
    return out


def cycles_per_update(samples=6):
    """Cycles from a sample offered to its result, per filter: the most over a short static
    pose with every update taken (accelerometer and magnetometer valid each sample; the
    sensor's noise as the engine's tests have it, so that Madgwick takes its gradient step,
    which it leaves out for an error within the noise of a noiseless one), leaving out the
    first sample after a reset (returned apart: it also starts the filter). The flagship's
    longest path, at rest while its magnetic reference is still learnt, is longer by the bias
    update (``replay --engine gateware`` prints the most over a recording)."""
    from ..hdl.engine.attitude_engine import AttitudeEngine
    from ..hdl.engine.register_map import CONTROL_ADDR, control_word
    from ..hdl.contract.filter_registry import FILTER_CODES
    from ..reference.frames import body_to_mag
    from ..sim.scenarios.attitude_bench import run_engine
    from ..sim.models.motion import SensorModel, static

    sensor = SensorModel(seed=1, gyro_noise=math.radians(0.05), accel_noise=0.02, mag_noise=0.3)
    gc, ac, mc = sensor.counts(static((30, -20, 100), samples / 100))
    mag_ak = body_to_mag(mc)
    out, first = {}, {}
    for name in FILTER_CODES:
        run = run_engine(AttitudeEngine(), gc, ac, mag_ak,
                         writes={0: [(CONTROL_ADDR, control_word(name, reset=True))]})
        assert run.mag_used.all() and run.acc_used.all()
        out[name] = max(run.cycles[1:])
        first[name] = run.cycles[0]
    return out, first


def drdy_to_attitude_us(clk_freq, config, results=21, part=None):
    """Data-ready (INT at the pin) to the attitude leaving the engine, µs, with the reset
    default filter (the flagship): measured in a co-simulation of the whole core against the
    MPU9250 and AK8963 models (SDO output delay 100 ns), over ``results`` samples after the
    first. ``with_mag_correction``: the most over the updates that took a new magnetometer
    field (the AK8963 measures at 100 Hz, one sample in ten at the default 1 kHz), else
    None; ``without_mag_correction``: the most over the others; ``drdy_to_attitude``: the
    worst of all. Real bus and engine timing; only the waits of bring-up and the sample
    period are compressed, which the latency does not depend on. ``part``: ``MPU9250Timing``
    fields the model's part has instead (its SDO timing: whether the read levelling trains,
    issue #58)."""
    from ..hdl.contract.defaults import DEFAULT_BAUD
    from ..sim.scenarios.setup import SimSetup
    from ..sim.scenarios.core import run_core
    setup = SimSetup(clk_freq=clk_freq, config=config,
                     odr_scale=SimSetup.default_odr_scale(config, clk_freq))
    # the telemetry divider for the shortened sample period, as ``simulate`` has it: the same
    # core, so one compiled build serves both
    model = setup.model(magnetometer=config.magnetometer, part=part)
    run = run_core(setup, n_results=results + 1, compiled=None,   # compiled when it can be
                   model=model,
                   core_kwargs={"telemetry_divider": setup.telemetry_divider(DEFAULT_BAUD)})
    pairs = list(zip(run.latencies_us(clk_freq), run.results))[1:]

    def most(mag):
        found = [t for t, r in pairs if bool(r["flags"]["mag_used"]) == mag]
        return round(max(found), 2) if found else None
    return {"drdy_to_attitude": round(max(t for t, _ in pairs), 2),
            "with_mag_correction": most(True), "without_mag_correction": most(False)}


def untrainable_part():
    """A part the read levelling cannot train on: the fault catalogue's ``sdo_slow`` (its
    bursts stay at the safe rate), as ``MPU9250Timing`` fields."""
    from ..sim.scenarios.faults import FAULTS
    return dict(FAULTS["sdo_slow"].part)


def spi_training(clk_freq, config, latency_us=None, untrained_us=None):
    """The read levelling (issue #58) of the build at ``clk_freq``: its trained rate
    (``sensor_frontend.spi_timing_for``; None where it is no faster than the safe rate, or
    with I2C), the burst's ``read_cycles`` at each rate (``sample_read_cycles``: a bound), the
    sample delays it scans, the eye it needs (2·margin + a cycle: the chosen delay keeps a
    cycle from both ends of the run), and the data-ready-to-attitude latency measured in
    co-simulation trained (``latency_us``: the model's part, 100 ns, trains) and untrained
    (``untrained_us``: ``untrainable_part``, the safe rate)."""
    from dataclasses import replace
    from ..hdl.sensor.sensor_frontend import sample_read_cycles, spi_timing_for
    from ..hdl.sensor.spi_controller import IO_BUDGET, SPITiming
    if config.wiring != "spi":
        return None
    safe = SPITiming.for_clock(clk_freq)
    timing = spi_timing_for(clk_freq)
    out = {"built": timing.has_trained, "safe_sclk_hz": round(safe.sclk_hz(clk_freq, True)),
           "safe_read_cycles": sample_read_cycles(config, clk_freq, safe)}
    if not timing.has_trained:
        return out
    period = timing.trained_period()
    trained = replace(safe, fast_half=timing.trained_low, fast_high=timing.trained_high)
    step_ns = 1e9 / clk_freq
    eye_needed = 2 * IO_BUDGET.margin_ns + step_ns
    out.update({
        "trained_sclk_hz": round(clk_freq / period),
        "trained_read_cycles": sample_read_cycles(config, clk_freq, trained),
        "sample_delays": [0, timing.max_sample_delay],
        "eye_needed_ns": round(eye_needed, 1),
        "jitter_and_drift_allowed_ns": round(period * step_ns - eye_needed, 1),
        "latency_trained_us": latency_us, "latency_untrained_us": untrained_us})
    return out


def report(*, clk_freq=None, config=None, latency=True, core_options=None, spread=0,
           baud=None):
    """The figures (``report``'s JSON). ``core_options``: ``AHRSCore`` options of the build
    counted (``commands=False``, ``pwm=False``: what a user may leave out; the telemetry
    divider, the filters' configuration), ``baud`` its UART's (``DEFAULT_BAUD``); the
    datapath, cycles and latency are those of the default build either way. ``spread``: the whole
    design's ``logic_elements`` also over that many equivalent netlists
    (``design.logic_elements_spread``)."""
    from ..hdl.engine.attitude_engine import AttitudeEngine
    from ..hdl.primitives.clocking import SYSTEM_CLOCK_HZ
    from ..hdl.sensor.mpu9250_driver import MPU9250Config
    from ..hdl.contract.defaults import DEFAULT_BAUD
    from ..hdl.board.top import AHRSCore, AsyncResetCore, rate_budget

    baud = DEFAULT_BAUD if baud is None else baud
    config = MPU9250Config() if config is None else config
    clk_freq = SYSTEM_CLOCK_HZ if clk_freq is None else clk_freq
    engine = AttitudeEngine()
    from ..progress import steps
    shown = steps(["datapath", "design", "cycles", "latency"], "report")
    shown.next("synthesis of the datapath (Yosys)")
    datapath = synthesize(engine, "attitude_engine", engine)
    shown.next("synthesis of the whole design: flat, carry chain, per block (Yosys)")
    core_options = dict(core_options or {})
    core = AHRSCore(clk_freq=clk_freq, config=config, baud=baud, **core_options)
    self_test = core.frontend.driver.self_test_block
    # as a board builds it: the reset asynchronous (``AsyncResetCore`` says why)
    wrapped = AsyncResetCore(core)
    design = synthesize(wrapped, "mpu9250_ahrs_core", core.engine,
                        rams=[core.framer.ram, core.sample_store,
                              core.frontend.driver.sequencer.rom,
                              *([core.decoder.fifo.ram, core.decoder.counters.ram]
                                if core.commands else []),
                              *([core.pwm_block.shadow] if core.has_pwm else []),
                              *([core.balance.shadow, core.balance.gains]
                                if core.controller else []),
                              *([self_test.sums, self_test.table] if self_test else [])],
                        others=[*([self_test] if self_test else []),
                                *([core.balance] if core.controller else [])], blocks=True,
                        ports=wrapped.ports(), spread=spread)
    design["room_left_les"] = DEVICE["logic_elements"] - design["logic_elements"]
    shown.next("cycles per update (simulated, every filter)")
    cycles, first = cycles_per_update()
    shown.next("data-ready to attitude (co-simulation of the core)")
    latency_us = drdy_to_attitude_us(clk_freq, config) if latency else {"drdy_to_attitude": None}
    untrained_us = (drdy_to_attitude_us(clk_freq, config, part=untrainable_part())
                    if latency and config.wiring == "spi" else None)
    shown.close()
    mhz = clk_freq / 1e6
    budget = rate_budget(config, clk_freq, baud, core_options.get("telemetry_divider"))
    return {
        "build": {"commands": core.commands, "pwm": core.has_pwm,
                  "attitude_port": core.attitude_port, "axi_lite": core.axi_lite,
                  "controller": core.controller},
        "clock_hz": clk_freq,
        "latency_us": latency_us,
        "max_sample_rate_hz": round(budget["max_sample_rate_hz"]),
        "sample_budget_cycles": {k: budget[k] for k in ("read_cycles", "update_cycles",
                                                         "cycles_per_sample")},
        "spi_training": spi_training(clk_freq, config, latency_us, untrained_us),
        "device": DEVICE,
        "design": design,
        "datapath": datapath,
        "cycles_per_update": cycles,
        "cycles_first_update_after_reset": first,
        "update_us": {k: round(v / mhz, 2) for k, v in cycles.items()},
        "design_percent_of_device": {
            "logic_elements": round(100 * design["logic_elements"] / DEVICE["logic_elements"], 1),
            "logic_elements_carry_chain": round(
                100 * design["logic_elements_carry_chain"] / DEVICE["logic_elements"], 1),
            "multipliers_18x18": round(
                100 * design["multipliers_18x18"] / DEVICE["multipliers_18x18"], 1),
            "memory_bits": round(100 * design["memory_bits"] / DEVICE["memory_bits"], 1),
        },
        "link": link_figures(config, budget["baud"], budget["telemetry_divider"]),
        "tool": "Yosys 0.23 synth_intel -family max10 (see mpu9250_ahrs/flows/report.py for method)",
    }


def link_figures(config, baud, divider=None):
    """The UART's frames: bytes per frame type, the most frames a second the link carries
    (10 bits a byte), and the telemetry divider (``divider``, or the default for ``config``)
    and frame rate."""
    from ..hdl.link.frame_types import FRAME_TYPES
    from ..hdl.link.frame_types import frame_bytes
    from ..hdl.board.top import telemetry_divider_for
    names = {0x01: "sensor", 0x02: "attitude", 0x81: "reply"}
    sizes = {names[t]: frame_bytes(layout) for t, layout in FRAME_TYPES.items()}
    divider = telemetry_divider_for(config, baud, divider)
    return {"baud": baud, "frame_bytes": sizes,
            "max_frames_per_s": {k: round(baud / 10 / v, 1) for k, v in sizes.items()},
            "telemetry_divider": divider,
            "attitude_frames_per_s": round(config.output_data_rate / divider, 1)}
