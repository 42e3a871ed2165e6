"""Attitude engine: calibration and attitude filters on one shared fixed-point datapath.

A microcoded sequencer (program in ``hdl/engine/attitude_program.py``, each filter's routine in
``hdl/engine/filters/``, register map in ``hdl/engine/register_map.py``, instruction set in
``hdl/engine/attitude_isa.py``) drives one
datapath: a 32×32 multiplier with a 66-bit accumulator (rounding and saturation on write-back),
a saturating/wrapping adder, an iterative CORDIC (``hdl/engine/cordic.py``) and a divider
(``hdl/engine/divider.py``). Results equal ``reference.engine_model.EngineModel`` bit for bit. Four
filters, selected at run time (``hdl/contract/filter_registry.py``): the flagship quaternion filter
(the reset default), the per-axis Kalman filter, the complementary filter and Madgwick's gradient
descent.

Pipeline: fetch (instruction ROM, synchronous) → read (register file, two synchronous read
ports, transparent to the write port; while an instruction waits they read its operands again
each cycle) → operands registered → execute, which writes the register file in its own cycle.
The operand registers keep the block RAM's clock-to-output time out of the execute stage's
adders (the routed critical path of ``report --timing`` ran through it once); the MAC adds and
saturates in separate cycles (``hdl/engine/multiply_accumulate.py``). The write is not registered
first: that stage, and a held copy of each operand for a write it delayed past the operands'
read, cost registers and LUTs (``report``) for Fmax margin that the CORDIC's path, the routed
critical one, does not leave (``report --timing``).
A result is visible to the next instruction without stalls as its ``a`` operand (forwarded
into the operand register); as ``b`` it is read from the register file, so the assembler keeps
an instruction from reading as ``b`` the register written as it goes on (it swaps an ADD's or
MUL's operands, else puts a NOP before it: ``attitude_isa``); multi-cycle operations (MUL 3,
or 1 when the next is a MUL, which the assembler keeps from reading its result:
``attitude_isa``; DIV 34, VEC 19, ROT 18 cycles) hold the pipeline, except a VEC, ROT or
DIV started in the background (``attitude_isa``: its collect waits for its unit); a taken
branch on a register (A_ZERO, A_NEG) costs two bubbles (decided in execute, the ROM reads its
target at once), one on a condition fixed for the run (ALWAYS, MAG_INVALID, FIRST, FILTER)
none: it is decided as it leaves the ROM (from the word's ``jump`` field, which any
instruction may carry: the assembler folds most such branches into the instruction before
them).
"""

import math
import operator
from functools import reduce
from types import SimpleNamespace

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .alu import ALU
from .attitude_isa import (COLLECT, CORDIC_SHORT, FETCH_JUMPS, GO_ON, REG_BITS, REG_COUNT, ROM_BITS,
                           ROM_DEPTH, Cond, Flag, Instr, Op, _reads_writes)
from .register_map import (CONTROL_ADDR, HOST_WRITABLE, LOAD_BASE, LOAD_EARLY, LOAD_ORDER, REGS,
                           config_init, load_words)
from ..contract.filter_registry import FILTER_CODES
from .attitude_program import build_program
from .host_port import HostPort
from .multiply_accumulate import MultiplyAccumulate
from .cordic import CORDIC, cordic_word
from .divider import Divider, divider_word
from ..primitives.memories import MicrocodeROM, RegisterFile
from ..primitives.multiplier import Multiplier
from ..contract.numeric_contract import (INV_GAIN_Q30, CalibrationFixed, FilterRates,
                                         FlagshipFixedConfig, KalmanFixedConfig,
                                         calibration_registers, mag_period)
from ..contract.filter_registry import filter_registers
from .attitude_result import Attitude
from .config_write import ConfigWrite
from ..sensor.sample import Sample
from ..sensor.sample_store import OFFER_WRITES, SAMPLE_STORE_DEPTH, SLOT_WORDS, SLOTS, STORE_WORDS


__all__ = ["AttitudeEngine", "PEEKED", "default_filter_config", "default_flagship_config"]


# The result's words ``peek_data`` reads, in ``Attitude``'s order: the registers its
# quaternion, angles and bias are snooped from
PEEKED = (*(f"QOUT{i}" for i in range(4)), *(f"THETA{i}" for i in range(3)),
          *(f"BIAS{i}" for i in range(3)))
# the register map puts them in that order from a multiple of 16: a word's address is its
# index with the base's high bits above it, no table
PEEK_BASE = REGS[PEEKED[0]]
assert PEEK_BASE % 16 == 0 and len(PEEKED) <= 16
assert [REGS[name] for name in PEEKED] == list(range(PEEK_BASE, PEEK_BASE + len(PEEKED)))


# An upper bound of the cycles of one update (sample taken to result out), whatever the filter
# and input: the longest measured are the first updates after a reset
# (``test_longest_updates_within_the_bound``: the Kalman filter's with Euler-angle rates and
# every measurement taken, the flagship's and Madgwick's; ``report`` prints each filter's). It
# was set when the Kalman filter's divisions held the pipeline and its Euler-rate updates were
# the longest; kept, so the rates it allows are those the design was checked at. The rate checks
# of ``build`` and ``report`` rely on it; tests check it on whole recordings, resets and the
# Euler-rate option.
WORST_UPDATE_CYCLES = 720


def _field_halves():
    """Where the loader finds the sample's sensor fields (raw gyro, accelerometer,
    magnetometer: ``load_words``' arguments; ``LOAD_ORDER`` puts the magnetometer's last):
    each field's 16-bit half of the sample's words, as 2·word + half."""
    sample = data.Layout.cast(Sample)
    places = []
    for field in ("gyro", "accel", "mag"):
        for i in range(3):
            offset = sample[field].offset + 16 * i
            assert offset % 16 == 0, "a sensor field off a 16-bit boundary"
            places.append(offset // 16)
    return places


SENSOR_FIELD_HALVES = _field_halves()
# which ``LOAD_ORDER`` words are the sample's sensor fields (the rest: the ASA bytes, the periods)
LOADED_FIELDS = [name[:4] in ("GRAW", "ARAW", "MRAW") for name in LOAD_ORDER]
assert [n for n, field in zip(LOAD_ORDER, LOADED_FIELDS) if field] == [
    f"{reg}{i}" for reg in ("GRAW", "ARAW", "MRAW") for i in range(3)]
assert LOAD_ORDER[LOAD_EARLY:] == [f"MRAW{i}" for i in range(3)]


def default_filter_config(sensor, rates=None):
    """The per-axis filters' registers for an ``MPU9250Config``: T = 1/ODR, the gyro's LSB per
    °/s from its full scale, and ``rates`` (``FilterRates``: Q densities, R, P₀, τ; the
    published preset's by default) converted to per-step values at that rate."""
    rates = FilterRates() if rates is None else rates
    return rates.at(1 / sensor.output_data_rate, 32768 / sensor.gyro_fs_dps)


def default_flagship_config(sensor):
    """The flagship's registers for an ``MPU9250Config``: T = 1/ODR, the LSBs of its full
    scales (rad/s and m/s²) and the magnetometer's gains for its own period (``mag_period``:
    a new field every 10 ms at any rate of 100 Hz or more), the published parameters
    otherwise."""
    dt = 1 / sensor.output_data_rate
    return FlagshipFixedConfig(dt=dt,
                               gyro_lsb_per_rad=32768 / sensor.gyro_fs_dps * 180 / math.pi,
                               accel_lsb_per_ms2=32768 / sensor.accel_fs_g / 9.80665,
                               mag_dt=mag_period(dt, sensor.magnetometer))


class AttitudeEngine(wiring.Component):
    """Calibration and the three attitude filters, one sample at a time, on one microcoded
    fixed-point datapath (the module's docstring has the pipeline).

    Parameters
        ``config`` (``KalmanFixedConfig``), ``cal`` (``CalibrationFixed``) and ``flagship``
            (``FlagshipFixedConfig``): the register file's reset values. ``filter``: the filter
            selected at reset (a ``FILTER_CODES`` name: the flagship unless told).
            ``extra_registers`` (name: value): more reset values of the register map, e.g.
            ``TELEMETRY_DIV``. ``program``: (instructions, entries ``init`` and ``sample``)
            to run instead of ``build_program()``'s (a test's own).
    Members
        ``samples`` (in, stream of ``Sample``): one update per sample. Taken when the engine is
            idle and the previous result has been taken; the sample is held (``sample``) as
            its load starts, loaded from there (one cycle per ``LOAD_ORDER`` word: 10 before
            the program starts, the AK8963's 3 at its SYNC), and acknowledged at the SYNC
            (``attitude_isa``: the early start), which also takes its ``mag_valid``. With
            ``sample_store``, the sensor fields are loaded
            from the sample store instead (below), and only ``skipped`` is held.
        ``imu_ready`` (in; with ``sample_store``): the early start (``SampleReader``'s): the
            payload's fields but the field's (``counter``, ``skipped``, ``overrun``: taken
            with it) are the next sample's and its gyro and
            accelerometer are in its slot; ``valid`` follows. The engine, idle, starts the
            update on it as on ``valid``; its SYNC waits for ``valid`` (and ``OFFER_WRITES``
            cycles of it: the reader's zeros over a field it does not have).
        ``asa`` (in, 3 × 8 bits): the AK8963's fuse-ROM sensitivity bytes (from the driver).
        ``cfg`` (in, stream of ``ConfigWrite``): register writes (``register_map`` has the
            map); accepted while the engine is idle. Only ``HOST_WRITABLE`` addresses are written:
            a write to a constant or to the filter state is taken, ignored and counted in
            ``cfg_refused`` (out, 16, saturating). ``CONTROL_ADDR`` (0xFF) is the control
            register: bits 1:0 select the filter (0 Kalman, 1 complementary, 2 flagship,
            3 Madgwick: ``filter_registry``), bit 2
            resets the filter state; selecting another filter makes the next sample a first one.
        ``cfg_read`` (in, stream of 8-bit addresses) / ``cfg_read_data`` (out, stream of signed
            32): register read-back, accepted while idle, the word one cycle later (0xFF reads the
            filter select; any other address reads the register file, state included).
        ``results`` (out, stream of ``Attitude``): one per sample — quaternion, angles, bias,
            counter, flags — valid (and unchanging) until taken.
        ``busy`` (out): an update or a filter reset is running.
        ``sample`` (out, ``Sample``): the sample of the present (or last) update, held from
            the start of its load to the next load.
        ``sample_store`` (parameter, False): the sample is read from the sample store
            (``hdl/sensor/sample_store.py``, the core's; the engine's own tests feed it in the
            payload): ``sample_slot`` (in), beside ``samples``: the sample's slot;
            ``store_addr`` (out) / ``store_data`` (in, 32): the store's read port (a word the
            cycle after its address). The loader reads the sensor fields from the sample's
            slot (at LOAD and SYNC); outside them the port reads word ``sample_index`` (in,
            0..``STORE_WORDS``) of the slot of the sample held, on ``sample_word`` (out, 32)
            a cycle later: the framer copies the sample from there (word ``STORE_WORDS``,
            which no sample fills, reads 0). ``sample`` then holds ``skipped`` only.
        ``peek_en``, ``peek_index`` (in, 0..9) / ``peek_data`` (out, signed 32): the offered
            result's words read from the register file (``PEEKED``: the quaternion, angles and
            bias, in ``Attitude``'s order; the word the cycle after ``peek_en``), equal to
            ``results.payload``'s while ``results`` is valid: the framer copies them from here
            rather than through a multiplexer of the result's bits. Only while ``results``
            is valid (the engine is idle then). While the engine is idle ``peek_data`` is 0
            the cycle after one without ``peek_en`` (the port reads ZERO): the framer ORs the
            words in, with no gate of its own.
    Latency (sample valid, or ``imu_ready``, to result valid) and throughput (one sample per
    update): ``report``'s ``cycles_per_update`` per filter, with the sample whole at the start
    (SYNC waits ``OFFER_WRITES`` + 1 cycles from ``valid`` with the store, then loads 3 words);
    every instruction has a fixed time, so only the branches taken (measurements skipped or
    rejected) and SYNC's wait make an update shorter or longer.
    """

    def __init__(self, config=KalmanFixedConfig(), cal=None, flagship=None, *,
                 filter="flagship", extra_registers=None, sample_store=False, program=None):
        self.config = config
        self.sample_store = sample_store
        self.cal = CalibrationFixed() if cal is None else cal
        self.flagship = FlagshipFixedConfig.matching(config) if flagship is None else flagship
        self.filter_at_reset = FILTER_CODES[filter]
        self.program, self.entry = build_program() if program is None else program
        # the hard blocks, kept as attributes: ``report`` substitutes them for its synthesis
        self.multiplier = Multiplier()
        self.cordic = CORDIC()                  # three of its own 18 x 18 blocks (its shifts)
        # Madgwick's β: the float filter's default at this sample period (a host writes BETA_K)
        registers = {**filter_registers(config, self.flagship),
                     **calibration_registers(self.cal), **(extra_registers or {})}
        self.regfile = RegisterFile(REG_COUNT, config_init(registers, INV_GAIN_Q30))
        # the host port reads CONTROL as the register file's word at its address with the
        # select ORed in (``HostPort``): that word reads 0 for ever (neither the program, the
        # loader nor the host writes it; the host's CONTROL writes go to the select)
        assert self.regfile.init[CONTROL_ADDR] == 0
        assert not any(CONTROL_ADDR in _reads_writes(i)[1] for i in self.program)
        assert CONTROL_ADDR not in range(LOAD_BASE, LOAD_BASE + len(LOAD_ORDER))
        self.rom = MicrocodeROM([i.encode() for i in self.program],
                                data.Layout.cast(Instr).size)
        super().__init__({
            "samples": In(stream.Signature(Sample)),
            "imu_ready": In(1),
            "asa": In(data.ArrayLayout(8, 3)),
            "cfg": In(stream.Signature(ConfigWrite)),
            "cfg_read": In(stream.Signature(REG_BITS)),
            "cfg_read_data": Out(stream.Signature(signed(32))),
            "results": Out(stream.Signature(Attitude)),
            "busy": Out(1),
            "cfg_refused": Out(16),
            "sample": Out(Sample),
            **({"sample_slot": In(range(SLOTS)), "store_addr": Out(range(SAMPLE_STORE_DEPTH)),
                "store_data": In(32), "sample_index": In(range(STORE_WORDS + 1)),
                "sample_word": Out(32)} if sample_store else {}),
            "peek_en": In(1), "peek_index": In(range(len(PEEKED))),
            "peek_data": Out(signed(32)),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.cordic = cordic = self.cordic
        m.submodules.divider = divider = Divider()
        m.submodules.alu = alu = ALU()
        m.submodules.mac = mac = MultiplyAccumulate(self.multiplier)
        m.submodules.host = host = HostPort(self.filter_at_reset, writable=HOST_WRITABLE)
        m.submodules.regfile = rf = self.regfile
        m.submodules.rom = rom = self.rom
        wiring.connect(m, wiring.flipped(self.cfg), host.cfg)
        wiring.connect(m, wiring.flipped(self.cfg_read), host.cfg_read)
        wiring.connect(m, host.cfg_read_data, wiring.flipped(self.cfg_read_data))
        m.d.comb += self.cfg_refused.eq(host.refused)

        # the parts below share the units (``u``) and the pipeline's signals (``p``)
        u = SimpleNamespace(cordic=cordic, divider=divider, alu=alu, mac=mac, host=host, rf=rf,
                            rom=rom)
        p = self._state(rom)
        self._operands(m, u, p)
        self._write_port(m, u, p)
        # ``xa``/``xb`` are loaded every cycle, not only with ``x``: every unit reads them in
        # the first cycle of ``x``'s instruction only (the ALU and the branch test then; the
        # MAC, divider and CORDIC take them at their issue or start, in that cycle), and at an
        # ``advance`` they take ``o``'s operands as ``x`` takes ``o``. Without an enable, the
        # stall logic (``advance``) is not in the operands' path
        m.d.sync += [p.xa.eq(p.o_a), p.xb.eq(p.o_b)]
        self._control(m, u, p)
        return m

    def _state(self, rom):
        """The sequencer's and the pipeline's signals (the module docstring has the pipeline),
        as a namespace for the parts of ``elaborate``."""
        # -- sequencer state ------------------------------------------------------------------
        # the address the ROM read last (the next is the one after it, a branch's target or,
        # after ``start``, the entry: ``start`` leaves the address before it here)
        fetch_pc = Signal(ROM_BITS)
        rvalid = Signal()                                 # rom.data is a real instruction
        rinstr = data.View(Instr, rom.data)
        # datapath registers are reset-less: whatever they hold is qualified by a valid bit
        # or overwritten before use, and a reset costs a LUT (or the LE's clear) per bit
        o = Signal(Instr, reset_less=True)                # instruction with its operands read
        ovalid = Signal()
        x = Signal(Instr, reset_less=True)                # instruction in execute
        xvalid = Signal()
        xa = Signal(signed(32), reset_less=True)          # its operands, registered
        xb = Signal(signed(32), reset_less=True)
        # ``x``'s adder controls, decoded as ``x`` is loaded (not from its opcode in the cycle:
        # the adder's carry chain starts at flip-flops, report --timing). Like ``x``, they
        # matter only while ``xvalid``, which rises only at an ``advance`` that loads them
        x_sub = Signal(reset_less=True)
        phase = Signal(2)
        advance = Signal()
        flush = Signal()

        first = Signal(init=1)
        init_pending = Signal(init=1)                     # run the INIT program after reset
        running_init = Signal()
        mag_valid = Signal()
        flags_set = Signal(len(Flag))                     # SETF flags of this update
        flag_sat = Signal()
        out = Signal(Attitude, reset_less=True)
        result_valid = Signal()
        return SimpleNamespace(fetch_pc=fetch_pc, rvalid=rvalid, rinstr=rinstr, o=o, ovalid=ovalid,
                               x=x, xvalid=xvalid, xa=xa, xb=xb, x_sub=x_sub,
                               phase=phase, advance=advance, flush=flush,
                               first=first, init_pending=init_pending,
                               running_init=running_init, mag_valid=mag_valid, flags_set=flags_set,
                               flag_sat=flag_sat, out=out, result_valid=result_valid)

    def _operands(self, m, u, p):
        """The read ports' addresses, the units' operands (``xa``, ``xb``) and the branch
        condition of ``x`` (``p.cond``)."""
        (xa, xb, fetch_pc, advance, out, x_sub, x, rinstr, rf, first, rom, host, alu, mac,
         cordic, divider, mag_valid) = (
            p.xa, p.xb, p.fetch_pc, p.advance, p.out, p.x_sub, p.x, p.rinstr, u.rf,
            p.first, u.rom, u.host, u.alu, u.mac, u.cordic, u.divider, p.mag_valid)
        # A branch on a condition that holds still for the whole run (ALWAYS, MAG_INVALID,
        # FIRST, FILTER: set before it starts) is decided as it leaves the ROM: when taken, the
        # ROM reads its target next rather than the word after it, so it costs its own word's
        # cycle (it goes on as a no-op), or none where the assembler folded it into the
        # instruction before (any word may carry ``jump``: ``Instruction.then``). Only the
        # register tests (A_ZERO, A_NEG) are decided in execute (``flush``, which overrides
        # this). The word's ``jump`` field indexes a vector of those conditions
        # (``FETCH_JUMPS``), registered (they hold still in RUN), so the ROM's output goes
        # through one bit's choice to its own address
        held = {(Cond.ALWAYS, 0): C(1, 1), (Cond.MAG_INVALID, 0): ~mag_valid,
                (Cond.FIRST, 0): first,
                **{(Cond.FILTER, code): host.select == code
                   for code in range(1 << len(host.select))}}
        bits = [C(0, 1)] * (1 << len(rinstr.jump))
        for key, index in FETCH_JUMPS.items():
            bits[index] = held[key]
        fixed = Signal(len(bits), reset_less=True)
        m.d.sync += fixed.eq(Cat(*bits))
        jump = Signal()
        m.d.comb += jump.eq(p.rvalid & fixed.bit_select(rinstr.jump, 1))
        # the address read at this advance, which ``fetch_pc`` then keeps: one incrementer,
        # of a register, before the choices (the ROM's output through a decision and a carry
        # chain was the routed critical path once, report --timing)
        p.fetch_addr = Signal(ROM_BITS)
        m.d.comb += p.fetch_addr.eq(Mux(p.flush, x.target,
                                        Mux(jump, rinstr.target, fetch_pc + 1)))
        # read port A: the instruction being fetched, or the host's read-back while idle
        m.d.comb += [
            # a register test taken in execute (``flush``) reads its target at once
            rom.addr.eq(p.fetch_addr), rom.en.eq(advance),
            rf.ra_addr.eq(Mux(host.r_en, host.r_addr, Mux(advance, rinstr.a, p.o.a))),
            rf.rb_addr.eq(Mux(self.peek_en,
                              Cat(self.peek_index, C(PEEK_BASE >> 4, REG_BITS - 4)),
                              Mux(self.busy, Mux(advance, rinstr.b, p.o.b), REGS["ZERO"]))),
            # the ports read every cycle: the instruction fetched at an advance, else ``o``'s
            # operands again (so a write while ``o`` waits reaches it through the register
            # file), or the host's or the framer's word (each taken the cycle after)
            rf.r_en.eq(1), host.r_data.eq(rf.ra_data),
            self.peek_data.eq(rf.rb_data),
            self.results.payload.eq(out),
        ]
        opa, opb = xa, xb
        m.d.comb += [
            alu.a.eq(opa), alu.b.eq(opb), alu.sub.eq(x_sub),
            alu.wrap.eq(x.wrap), alu.sat16.eq(x.sat16),
            mac.a.eq(opa), mac.b.eq(opb), mac.ins.eq(x),
            cordic.x_in.eq(opa), cordic.y_in.eq(opb), cordic.angle_in.eq(opa),
            cordic.mode.eq(x.op == Op.ROT), cordic.short.eq((x.sh & CORDIC_SHORT).any()),
            divider.num.eq(opa), divider.den.eq(opb),
        ]

        # the register tests, in execute (the other conditions were taken at the fetch): a
        # branch is taken when ``cond`` differs from its ``inv``
        cond = Signal()
        with m.Switch(x.cond):
            with m.Case(Cond.A_ZERO):
                m.d.comb += cond.eq(opa == 0)
            with m.Case(Cond.A_NEG):
                m.d.comb += cond.eq(opa[-1])
            with m.Default():
                m.d.comb += cond.eq(x.inv)
        p.cond = cond

    def _write_port(self, m, u, p):
        """The register file's write port (loader, host or the execute stage), the result
        snooped from it, and ``o``'s operands (``p.o_a``, with the forwarding of a write into
        it, and ``p.o_b``)."""
        (mac, o, rinstr, alu, host, flag_sat, advance, rf, out, x) = (
            u.mac, p.o, p.rinstr, u.alu, u.host, p.flag_sat, p.advance, u.rf, p.out, p.x)
        # -- the write port: loader, host, or the execute stage (MAC write-back, then ALU,
        # DIV, CORDIC: never two in one cycle, the sequencer sees to it) -----------------------
        w_en, w_addr, w_data, w_sat = Signal(), Signal(REG_BITS), Signal(signed(32)), Signal()
        # the ALU's result joins the write data last (``alu_w``: the ALU writes now), after the
        # other sources' multiplexer (``w_other``), and the forwarding below takes the write
        # data: the adder's path to the operand registers is one choice longer than from the
        # adder itself, and each operand chooses between two sources, the write data and the
        # register file (report --timing still finds its critical path elsewhere)
        w_other, w_sat_other, alu_w = Signal(signed(32)), Signal(), Signal()
        m.d.comb += [w_data.eq(Mux(alu_w, alu.result, w_other)),
                     w_sat.eq(Mux(alu_w, alu.saturated, w_sat_other))]
        # the register file is written in the execute stage's cycle (a read at the same edge
        # sees the write: the register file is transparent); ``wr_*``, the write registered,
        # is what the result is snooped from
        wr_en = Signal()
        wr_addr = Signal(REG_BITS, reset_less=True)
        wr_data = Signal(signed(32), reset_less=True)
        m.d.sync += [wr_en.eq(w_en), wr_addr.eq(w_addr), wr_data.eq(w_data)]
        m.d.comb += [rf.w_en.eq(w_en), rf.w_addr.eq(w_addr), rf.w_data.eq(w_data)]
        # the MAC's write-back is the address and data when no other writer chooses them
        # (ungated: whatever they are without ``w_en``, nothing reads them then). The other
        # writers' words each an AND with its select (``w_from``, set where that writer
        # writes: never two in one cycle), OR-ed: the selects are decided once for all the
        # bits, not in a chain of choices per bit
        w_from = {name: Signal(name=f"w_from_{name}")
                  for name in ("host", "divider", "mag_sin", "angle_cos", "load")}
        load_word = Signal(signed(32))          # the loader's (``_control``)
        words = {"host": host.w_data, "load": load_word}
        # the CORDIC's two results, its registers chosen with the mode, and the divider's
        # quotient, its register or a limit, in the same AND-OR (``cordic_word``,
        # ``divider_word``): neither has an output multiplexer of its own
        m.d.comb += [w_addr.eq(mac.wb_addr),
                     w_other.eq(reduce(operator.or_, (
                         Mux(w_from[name], word, 0) for name, word in words.items()),
                         Mux(Cat(*w_from.values()).any(), 0, mac.wb_data)) |
                         cordic_word(u.cordic, w_from["mag_sin"], w_from["angle_cos"]) |
                         divider_word(u.divider, w_from["divider"]))]
        with m.If(host.w_en):
            m.d.comb += [w_en.eq(1), w_addr.eq(host.w_addr), w_from["host"].eq(1)]
        # the result is snooped from the register writes (no copy at the end of an update)
        fields = [*(out.quat[i] for i in range(4)), *(out.angles[i] for i in range(3)),
                  *(out.bias[i] for i in range(3))]
        snooped = list(zip(fields, PEEKED))
        # Whether this cycle's write is to ``o``'s ``a``: ``w_en & (w_addr == o.a)``, made
        # from registered facts (does ``o`` read what ``x`` writes, what the MAC writes back),
        # kept with the registers they compare, so that no address comparison is between the
        # write-back's multiplexers and the operands' forwarding (that path limited the routed
        # Fmax, report --timing). ``x_wd``: the execute stage writes ``x.d`` now (it takes the
        # write port over the MAC's, as below). A VEC's or ROT's write of d + 1 is never the
        # last of its instruction (d follows a cycle later), so ``o``, waiting, reads it from
        # the register file: no fact for d + 1. Outside RUN only ``xa``/``xb`` see them, and
        # those are not read there.
        x_wd = Signal()
        # the MAC's d next cycle: the pending MUL's (``eq_wb`` matters only in a cycle after
        # one with a MUL pending: the MAC writes back only then)
        wb_next_d = mac.wb_next_addr
        eq_x = Signal(reset_less=True, init=1, name="eq_xd_a")
        eq_wb = Signal(reset_less=True, init=1, name="eq_wb_a")
        m.d.sync += [
            eq_x.eq(Mux(advance, o.d == rinstr.a, eq_x)),
            eq_wb.eq(Mux(advance, wb_next_d == rinstr.a, wb_next_d == o.a)),
        ]
        hit_a = (x_wd & eq_x) | (~x_wd & mac.wb_en & eq_wb)
        # the operands of ``o``, as they are now: ``a``, this cycle's write forwarded from the
        # write data (the ALU's result or another's: an ALU instruction writes ``x.d`` whatever
        # else is pending, so ``hit_a`` is then its write), else the register file's read of the
        # cycle before (which saw every write up to then: the ports read ``o``'s operands again
        # each cycle it waits). ``b`` is not forwarded (its 32-bit choice and facts cost about
        # 30 LUTs, ``report``; the assembler's NOPs a few cycles an update): no program reads as
        # ``b`` the register written as it goes on (``Assembler.resolve`` swaps an ADD's or
        # MUL's operands, else puts a NOP before it)
        o_a = Mux(hit_a, w_data, rf.ra_data)
        o_b = rf.rb_data
        # snooped from the registered write (a cycle after the execute stage's): the ALU's and
        # the write multiplexer's paths end at ``wr_data``, not at the result's 320 flip-flops
        # as well. The last write of an update is at the latest in the cycle before END
        # executes, so its result is in ``out`` when ``result_valid`` rises
        with m.If(wr_en):
            for field, name in snooped:
                with m.If(wr_addr == REGS[name]):
                    m.d.sync += field.eq(wr_data)
        with m.If(w_en & w_sat):
            m.d.sync += flag_sat.eq(1)

        (p.w_en, p.w_addr, p.w_data, p.w_other, p.w_sat_other, p.alu_w, p.x_wd,
         p.hit_a, p.o_a, p.o_b, p.w_from, p.load_word) = (
            w_en, w_addr, w_data, w_other, w_sat_other, alu_w, x_wd, hit_a, o_a, o_b,
            w_from, load_word)

    def _execute(self, m, u, p):
        """The execute stage for ``x`` (an FSM state body)."""
        (advance, xvalid, mac, o, w_en, w_addr, w_sat_other, x, ovalid, x_sub,
         rom, rvalid, fetch_pc, flush, x_wd, alu_w, phase, cond, divider, cordic,
         flags_set) = (
            p.advance, p.xvalid, u.mac, p.o, p.w_en, p.w_addr, p.w_sat_other, p.x,
            p.ovalid, p.x_sub, u.rom, p.rvalid, p.fetch_pc, p.flush, p.x_wd, p.alu_w,
            p.phase, p.cond, u.divider, u.cordic, p.flags_set)
        m.d.comb += advance.eq(1)                       # overridden below by stalls
        # a VEC's, ROT's or DIV's background start or collect (``attitude_isa``)
        go_on, collect = (x.sh & GO_ON).any(), (x.sh & COLLECT).any()
        with m.If(mac.wb_en):
            m.d.comb += [w_en.eq(1), w_sat_other.eq(mac.wb_saturated)]
        with m.If(xvalid):
            with m.Switch(x.op):
                with m.Case(Op.ADD, Op.SUB):
                    m.d.comb += [w_en.eq(1), w_addr.eq(x.d), x_wd.eq(1), alu_w.eq(1)]
                with m.Case(Op.MUL):
                    # the write-back comes two cycles after the issue: the MUL stays
                    # until then, unless the next instruction is a MUL (it writes nothing
                    # in its issue cycle; its operands are taken as it goes on). That MUL
                    # reads neither this one's result nor the one's before: the assembler
                    # sees to it (``attitude_isa``: MUL after MUL), the engine tests nothing
                    overlap = ovalid & (o.op == Op.MUL)
                    with m.If(phase == 0):
                        m.d.comb += mac.issue.eq(1)
                        with m.If(~overlap):
                            m.d.comb += advance.eq(0)
                            m.d.sync += phase.eq(1)
                    with m.Elif((phase == 1) & ~overlap):
                        m.d.comb += advance.eq(0)
                        m.d.sync += phase.eq(2)
                    with m.Else():
                        m.d.sync += phase.eq(0)
                with m.Case(Op.DIV):
                    # in the background as the CORDIC's operations are (below)
                    with m.If((phase == 0) & ~collect):
                        m.d.comb += divider.start.eq(1)
                        with m.If(~go_on):
                            m.d.comb += advance.eq(0)
                            m.d.sync += phase.eq(1)
                    with m.Elif(Mux(phase == 1, ~divider.done, divider.busy)):
                        # a blocking DIV waits for ``done`` as before; a collect while the
                        # divider is busy (equivalent; this form maps smaller, report)
                        m.d.comb += advance.eq(0)
                    with m.Else():
                        m.d.sync += phase.eq(0)
                        m.d.comb += [w_en.eq(1), w_addr.eq(x.d), x_wd.eq(1),
                                     p.w_from["divider"].eq(1),
                                     w_sat_other.eq(divider.saturated)]
                with m.Case(Op.VEC, Op.ROT):
                    # the CORDIC's ``mag_sin`` into d + 1 first (VEC's magnitude, ROT's sin),
                    # then its ``angle_cos`` into d (the angle, cos): one source and one
                    # address a write, the mode chosen inside the CORDIC, and d, the one
                    # forwarded (``x_wd``), last
                    # In the background (``attitude_isa``): a start (GO_ON) goes on at once;
                    # its collect (COLLECT) skips the start and waits, as phase 1 does, for
                    # the CORDIC to be idle (its results hold until the next start)
                    with m.If((phase == 0) & ~collect):
                        m.d.comb += cordic.start.eq(1)
                        with m.If(~go_on):
                            m.d.comb += advance.eq(0)
                            m.d.sync += phase.eq(1)
                    with m.Elif(phase != 2):
                        m.d.comb += advance.eq(0)
                        with m.If(~cordic.busy):
                            m.d.comb += [w_en.eq(1), w_addr.eq(x.d + 1),
                                         p.w_from["mag_sin"].eq(1),
                                         w_sat_other.eq(cordic.saturated)]
                            m.d.sync += phase.eq(2)
                    with m.Else():
                        m.d.sync += phase.eq(0)
                        m.d.comb += [w_en.eq(1), w_addr.eq(x.d), x_wd.eq(1),
                                     p.w_from["angle_cos"].eq(1)]
                with m.Case(Op.BR):
                    with m.If(cond ^ x.inv):
                        m.d.comb += flush.eq(1)
                with m.Case(Op.SYNC):
                    # the early start (``attitude_isa``): wait for the sample (``mag_ready``;
                    # its first field word's store word is read meanwhile), load the
                    # AK8963's words (a cycle each), take the sample and its ``mag_valid``,
                    # then a cycle more, so that ``o``, which read its operands while this
                    # waited, reads the last loaded word again before it goes on. Nothing else
                    # writes meanwhile: only a MUL goes on before its write-back, and only
                    # into a MUL
                    with m.If(phase == 0):
                        m.d.comb += [advance.eq(0), p.sync_wait.eq(1)]
                        with m.If(p.mag_ready):
                            m.d.sync += phase.eq(1)
                    with m.Elif(phase == 1):
                        m.d.comb += [advance.eq(0), p.in_load.eq(1), w_en.eq(1),
                                     w_addr.eq(LOAD_BASE | p.load_index),
                                     p.w_from["load"].eq(1)]
                        m.d.sync += p.load_index.eq(p.load_index + 1)
                        with m.If(p.load_index == len(LOAD_ORDER) - 1):
                            payload = self.samples.payload
                            m.d.comb += self.samples.ready.eq(1)
                            m.d.sync += [phase.eq(2),
                                         p.mag_valid.eq(payload.flags.mag_valid)]
                    with m.Else():
                        m.d.sync += phase.eq(0)
                with m.Case(Op.SETF):
                    # ``d`` is the flag one-hot (``Assembler.setf``): no decoder of ``sh``
                    m.d.sync += flags_set.eq(flags_set | x.d[:len(Flag)])
        with m.If(advance):
            m.d.sync += [
                x.eq(o), xvalid.eq(ovalid & ~flush),
                x_sub.eq(o.op == Op.SUB),
                o.eq(rom.data), ovalid.eq(rvalid & ~flush),
                fetch_pc.eq(p.fetch_addr), rvalid.eq(1),
            ]

    def _load_data(self, m, load_index, taking, in_load, sync_wait):
        """The loader's word ``load_index`` (16 bits; the write sign-extends it), in
        ``LOAD_ORDER``: a sensor field of the sample (``SENSOR_FIELD_HALVES``) or the ASA bytes
        and the periods (``load_words``). ``taking``: IDLE takes a sample now; ``in_load``: a
        word is written now (LOAD, or SYNC's loads); ``sync_wait``: SYNC waits for the
        sample (its first word's store word is read meanwhile)."""
        held = self.sample
        sensor = LOADED_FIELDS
        if not self.sample_store:
            # the held sample's halves, through one multiplexer with the ASA and the periods
            bits = held.as_value()
            halves = [bits[16 * h:16 * h + 16] for h in SENSOR_FIELD_HALVES]
            words = load_words(halves[0:3], halves[3:6], halves[6:9],
                               [self.asa[i] for i in range(3)], held.skipped)
            return Array(Value.cast(v)[:16] for v in words)[load_index]
        # From the store: a load word's store word is read the cycle before (in the cycle
        # that takes the sample, the first), from the sample's slot; outside the loads the
        # port reads the framer's word of the held sample's slot. A block RAM's read port is
        # the multiplexer: only the half of the word and the ASA and periods are chosen here.
        held_slot = Signal(range(SLOTS))
        with m.If(taking):
            m.d.sync += held_slot.eq(self.sample_slot)
        places = load_words(*(SENSOR_FIELD_HALVES[3 * k:3 * k + 3] for k in range(3)),
                            [0] * 3, 0)
        tail = [Value.cast(v)[:16] for v in
                load_words([0] * 3, [0] * 3, [0] * 3, [self.asa[i] for i in range(3)],
                           held.skipped)]
        # a slot's word STORE_WORDS is never written: it reads 0 (``sample_index``)
        assert max(h // 2 for h in SENSOR_FIELD_HALVES) < STORE_WORDS < SLOT_WORDS
        word_bits = (SLOT_WORDS - 1).bit_length()
        words = [C(h // 2 if is_sensor else 0, word_bits) for h, is_sensor in zip(places, sensor)]
        ahead = Array(words + [C(0, word_bits)])[
            Mux(taking, 0, Mux(in_load, load_index + 1, load_index))]
        m.d.comb += [
            self.store_addr.eq(Mux(taking | in_load | sync_wait, Cat(ahead, self.sample_slot),
                                   Cat(self.sample_index, held_slot))),
            self.sample_word.eq(self.store_data),
        ]
        half = Array(C(h % 2 if is_sensor else 0, 1) for h, is_sensor in zip(places, sensor))[
            load_index]
        from_tail = Array(C(0, 16) if is_sensor else v for v, is_sensor in zip(tail, sensor))[
            load_index]
        is_sensor = Array(C(int(x), 1) for x in sensor)[load_index]
        return Mux(is_sensor, self.store_data.word_select(half, 16), from_tail)

    def _control(self, m, u, p):
        """The engine's states: IDLE (a result offered, the host's port open), LOAD (the
        sample into the register file), RUN (the program, ``_execute``)."""
        (result_valid, host, first, init_pending, fetch_pc, rvalid, ovalid, xvalid, phase, w_en,
         w_addr, running_init, flags_set, flag_sat, out, x) = (
            p.result_valid, u.host, p.first, p.init_pending, p.fetch_pc, p.rvalid, p.ovalid,
            p.xvalid, p.phase, p.w_en, p.w_addr, p.running_init, p.flags_set,
            p.flag_sat, p.out, p.x)
        def start(entry):
            m.d.sync += [fetch_pc.eq((entry - 1) % ROM_DEPTH), rvalid.eq(0), ovalid.eq(0),
                         xvalid.eq(0), phase.eq(0)]

        load_index = Signal(range(len(LOAD_ORDER)), reset_less=True)
        held = self.sample
        taking = Signal()                   # IDLE takes a sample now
        in_load = Signal()                  # the loader writes a word now
        sync_wait = Signal()                # SYNC waits for the sample
        load_data = self._load_data(m, load_index, taking, in_load, sync_wait)
        m.d.comb += p.load_word.eq(load_data.as_signed())
        # SYNC's loads may start: the sample is offered, and, from the store, has been for
        # ``OFFER_WRITES`` cycles, so that the reader's zeros over a field it does not have
        # (``hdl/sensor/sample_store.py``) are in before the first read of the field's words
        mag_ready = Signal()
        if self.sample_store:
            offered_for = Signal(range(OFFER_WRITES + 1))
            m.d.sync += offered_for.eq(Mux(self.samples.valid,
                                           Mux(mag_ready, offered_for, offered_for + 1), 0))
            m.d.comb += mag_ready.eq(offered_for == OFFER_WRITES)
        else:
            m.d.comb += mag_ready.eq(self.samples.valid)
        (p.load_index, p.in_load, p.sync_wait, p.mag_ready) = (
            load_index, in_load, sync_wait, mag_ready)

        with m.If(self.results.valid & self.results.ready):
            m.d.sync += result_valid.eq(0)
        # the host's CONTROL writes: another filter starts with its next sample; a reset runs
        # the INIT program
        with m.If(host.switched):
            m.d.sync += first.eq(1)
        with m.If(host.reset):
            m.d.sync += init_pending.eq(1)

        with m.FSM() as fsm:
            # A result is offered only in IDLE, which is left only once it was taken, so the
            # registers it is snooped from hold still. (It is never pending elsewhere; gating
            # it costs a gate and lets the stream contract be proven by induction.)
            m.d.comb += self.results.valid.eq(result_valid & fsm.ongoing("IDLE"))
            with m.State("IDLE"):
                # a reset waits until the last result is taken: the result is snooped from the
                # state registers the reset writes, and must hold still while it is valid
                with m.If(init_pending & ~result_valid):
                    start(self.entry["init"])
                    m.d.sync += [init_pending.eq(0), running_init.eq(1)]
                    m.next = "RUN"
                with m.Elif((self.samples.valid | self.imu_ready) & ~result_valid):
                    # the sample, or (the early start) its gyro and accelerometer words, in
                    # the store already while the AK8963's bytes are still coming
                    sample = self.samples.payload
                    m.d.comb += taking.eq(1)
                    if self.sample_store:           # the sample stays in the store
                        m.d.sync += held.skipped.eq(sample.skipped)
                    else:
                        m.d.sync += held.eq(sample)
                    # the result's counter and overrun now (``imu_ready``: the payload has
                    # them already): the result's words change as an update starts, which
                    # the AXI slave's SEQUENCE relies on (``hdl/AXI_LITE.md``)
                    m.d.sync += [load_index.eq(0), flags_set.eq(0),
                                 flag_sat.eq(0), out.counter.eq(sample.counter),
                                 out.flags.overrun.eq(sample.flags.overrun),
                                 out.flags.filter.eq(host.select)]
                    m.next = "LOAD"
                with m.Else():
                    m.d.comb += host.open.eq(1)
            with m.State("LOAD"):
                # the words before the AK8963's (``LOAD_EARLY``); SYNC loads the rest
                m.d.comb += [self.busy.eq(1), w_en.eq(1), w_addr.eq(LOAD_BASE | load_index),
                             p.w_from["load"].eq(1), in_load.eq(1)]
                m.d.sync += load_index.eq(load_index + 1)
                with m.If(load_index == LOAD_EARLY - 1):
                    start(self.entry["sample"])
                    m.next = "RUN"
            with m.State("RUN"):
                m.d.comb += self.busy.eq(1)
                with m.If(xvalid & (x.op == Op.END)):
                    m.d.sync += running_init.eq(0)
                    with m.If(running_init):
                        m.d.sync += first.eq(1)
                    with m.Else():
                        m.d.sync += [first.eq(0), result_valid.eq(1),
                                     out.flags.saturated.eq(flag_sat)]
                        for flag in Flag:
                            m.d.sync += out.flags[flag.name.lower()].eq(flags_set[flag])
                    m.next = "IDLE"
                with m.Else():
                    self._execute(m, u, p)
