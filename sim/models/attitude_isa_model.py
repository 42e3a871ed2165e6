"""Instruction-level model of the attitude engine: runs the microcode ROM in Python.

Not a reference (``reference.engine_model.EngineModel`` is, written independently of the
microcode): a fast way to check the microcode against the reference on thousands of samples
before the slower gateware simulation, and to debug a program one instruction at a time
(``trace=True``). The datapath primitives are the reference's, so only the program's logic is
under test here.
"""

from ...hdl.engine.attitude_isa import (COLLECT, CORDIC_SHORT, GO_ON, MUL_SHIFTS, UNITS, Cond, Flag,
    Op)
from ...hdl.engine.register_map import (CONFIG_REGS, LOAD_EARLY, LOAD_ORDER, REGS, config_init,
                                        load_words)
from ...hdl.contract.filter_registry import FILTER_CODES
from ...hdl.engine.attitude_program import build_program
from ...reference.fixed_point import (CORDIC_ITERATIONS, CORDIC_SHORT_ITERATIONS, INV_GAIN_Q30,
    Status, cordic_rotate, cordic_vector, div_q24, sat, sat16, sat32, wrap32)


__all__ = ["AttitudeISAModel"]


class AttitudeISAModel:
    """``registers``: the register file's reset values by name (``EngineModel(...).reg``)."""

    def __init__(self, registers, filter="flagship"):
        self.program, self.entry = build_program()
        self.regs = config_init({k: v for k, v in registers.items() if k in CONFIG_REGS},
                                INV_GAIN_Q30)
        self.filter = FILTER_CODES[filter]
        self.first = True
        self.run(self.entry["init"])

    def write(self, addr, value):
        self.regs[addr] = sat(value, 32)

    def select(self, filter):
        code = FILTER_CODES[filter]
        self.first |= code != self.filter
        self.filter = code

    def _holds(self, cond, a, code, mag_valid):
        """A branch's condition (``Cond``) on register a's value and the FILTER code.
        ``mag_valid`` None: not yet known (before the run's SYNC); a register None: the field's
        before the SYNC. Either tested is a program's error."""
        if a is None and cond in (Cond.A_ZERO, Cond.A_NEG):
            raise RuntimeError("a register test of the field before the SYNC")
        if mag_valid is None and cond == Cond.MAG_INVALID:
            raise RuntimeError("MAG_INVALID before the SYNC")
        return {Cond.ALWAYS: True, Cond.A_ZERO: a == 0, Cond.A_NEG: a < 0,
                Cond.MAG_INVALID: not mag_valid, Cond.FIRST: self.first,
                Cond.FILTER: self.filter == code}[Cond(cond)]

    def run(self, pc, mag_valid=True, trace=False, mag_words=None):
        """Run from ``pc`` to END; returns (flags set, saturated, instructions executed).
        ``mag_words`` (name: value): what SYNC loads (the early start, ``attitude_isa``);
        until then the field's registers (MRAW, M, MAG_OK) hold None, which no arithmetic
        takes, and MAG_INVALID is not decided: a program that reads the field before its SYNC
        fails here. A sample's run passes exactly one SYNC; the reset program's none."""
        r = self.regs
        synced = mag_words is None
        valid = mag_valid if synced else None   # the sample's flag, as the engine has it
        if not synced:
            for name in (*mag_words, *(f"M{i}" for i in range(3)), "MAG_OK"):
                r[REGS[name]] = None
        acc = 0
        flags = set()
        st = Status()
        steps = 0
        pending = {}            # a background start's results by unit, until its collect
        while True:
            ins = self.program[pc]
            steps += 1
            pc += 1
            a, b = r[ins.a], r[ins.b]
            op = ins.op

            def put(d, value, *, wrap=False):
                if wrap:
                    r[d] = wrap32(value)
                else:
                    value = sat32(value, st)
                    r[d] = sat16(value, st) if ins.sat16 else value
                if trace:
                    print(f"{pc - 1:3d} {op.name:4s} r{d:02x} <- {r[d]}")

            if op == Op.ADD:
                put(ins.d, a + b, wrap=ins.wrap)
            elif op == Op.SUB:
                put(ins.d, a - b, wrap=ins.wrap)
            elif op == Op.MUL:
                p = -a * b if ins.neg else a * b
                s = MUL_SHIFTS[ins.sh]
                acc = (acc if ins.acc else (1 << s >> 1)) + p     # rounding constant first
                if ins.wb:
                    put(ins.d, acc >> s)
            elif op.name in UNITS:
                # a background start (GO_ON) keeps its results for its collect (COLLECT): the
                # assembler has checked that nothing between them touches what it writes, so
                # computing them at the start is the same
                unit = UNITS[op.name]
                if ins.sh & COLLECT:
                    results = pending.pop(unit)
                elif op == Op.DIV:
                    results = (div_q24(a, b, st),)
                elif op == Op.VEC:
                    results = cordic_vector(a, b, st, CORDIC_SHORT_ITERATIONS
                                            if ins.sh & CORDIC_SHORT else CORDIC_ITERATIONS)
                else:
                    results = cordic_rotate(a)
                if ins.sh & GO_ON:
                    pending[unit] = results
                else:
                    for k, value in enumerate(results):
                        put(ins.d + k, value)
            elif op == Op.BR:
                if self._holds(ins.cond, a, ins.sh, valid) != bool(ins.inv):
                    pc = ins.target
            elif op == Op.SETF:
                flags.add(Flag(ins.sh))
            elif op == Op.SYNC:
                if synced:
                    raise RuntimeError(f"SYNC at {pc - 1}: a second one, or one outside a sample")
                for name, value in mag_words.items():
                    r[REGS[name]] = value
                synced, valid = True, mag_valid
            elif op == Op.END:
                if not synced:
                    raise RuntimeError(f"END at {pc - 1}: the sample's run passed no SYNC")
                return flags, st.saturated, steps
            if ins.then is not None:                # a branch folded into it (the assembler)
                cond, code, target = ins.then
                if self._holds(cond, a, code, valid):
                    pc = target

    def sample(self, gyro, accel, mag_ak, mag_valid=True, asa=(128, 128, 128), skipped=0):
        values = load_words(*([int(v) for v in x] for x in (gyro, accel, mag_ak, asa)),
                            int(skipped))
        words = dict(zip(LOAD_ORDER, (int(v) for v in values)))
        mag_words = {name: words.pop(name) for name in LOAD_ORDER[LOAD_EARLY:]}
        for name, value in words.items():
            self.regs[REGS[name]] = value
        result = self.run(self.entry["sample"], mag_valid, mag_words=mag_words)
        self.first = False
        return result

    def outputs(self):
        """(quaternion, angles, bias) as the engine reports them."""
        r = self.regs
        return ([r[REGS[f"QOUT{i}"]] for i in range(4)], [r[REGS[f"THETA{i}"]] for i in range(3)],
                [r[REGS[f"BIAS{i}"]] for i in range(3)])
