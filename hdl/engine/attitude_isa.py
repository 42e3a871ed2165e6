"""Instruction set of the attitude engine's shared datapath, and a small assembler.

The engine (``hdl/engine/attitude_engine.py``) runs microcode from a ROM over a register file of 256
32-bit words. One instruction names a destination ``d`` and two sources ``a`` and ``b``
(register addresses); every result is saturated to 32 bits (or wrapped, or saturated to 16
bits, as the instruction says) and a saturation sets the sample's ``saturated`` flag.

====  ===========================================================  ======================
op    effect                                                       cycles (engine)
====  ===========================================================  ======================
NOP   nothing (``nop``: the assembler's, between MULs, below)     1
ADD   d = a + b                                                    1
SUB   d = a − b                                                    1
MUL   acc = (acc if ``acc`` else 2^(s−1)) ± a·b, s = MUL_SHIFTS[sh]  3; 1 when a MUL
                                                                   follows (below)
      (exact, 66 bits: the rounding constant goes in first);
      if ``wb``: d = acc >> s  (= rshift_round of the sum)
DIV   d = div_q24(a, b): ⌊a·2²⁴/b⌋, 0 if b ≤ 0                     34
VEC   CORDIC vectoring of (x = a, y = b): d = atan2 (BAM32),       19; 11 if short
      d+1 = magnitude · K; ``sh`` bit 0 (``CORDIC_SHORT``): short
      (8 iterations: a length within 3·10⁻⁵, its angle coarse)
ROT   CORDIC rotation of the angle in a: d = cos, d+1 = sin (Q1.30)  18
BR    if condition (``cond``, inverted by ``inv``): go to target   1, or 3 when taken
                                                                   on A_ZERO / A_NEG; 0
                                                                   folded (below)
SETF  set result flag ``sh`` (``Flag``; ``d`` holds 1 << sh)       1
END   the sample is done: results out                              1
SYNC  wait for the sample's magnetometer words (the early start,     1 + the wait, + 4
      below), the loader writes MRAW0..2 meanwhile
====  ===========================================================  ======================

In the background: a VEC, ROT or DIV with ``sh`` bit 1 (``GO_ON``: the start) takes its
operands and starts its unit (the CORDIC, the divider), and the next instruction follows at
once; the same op with ``sh`` bit 2 (``COLLECT``: the collect, ``d`` the start's) waits for
the unit if it is still running, then writes its result (d and d + 1, or d) as the blocking
op does. Between the two the program does other work, under the assembler's rules
(``Assembler.resolve`` checks them): in the same basic block (no branch, label, folded jump or
END between them), no other operation of the same unit, and nothing reads or writes what the
collect writes (a read would find the old value, a write be overwritten). The other unit may
work meanwhile: a division in the background of CORDIC operations, or the other way round.
Cycles: the start takes 1 and the collect 2 (DIV: 1) once the unit is done; the work between
them is free up to 16 cycles after a VEC (8 after a short one), 15 after a ROT and 32 after a
DIV (the blocking op's time less those), and the collect waits out what is left of them.

MUL after MUL: a MUL followed by a MUL goes on at once (their products overlap in the MAC's
stages); one followed by anything else waits for its write-back. The engine tests no
operand: a MUL that read the result of the MUL just before it, or of the one two before it,
would read it too early. The assembler keeps them apart: ``Assembler.resolve`` puts a NOP
before a MUL that reads the result of the MUL that runs just before it (the first then waits
for its write-back, as before any other instruction), and refuses a MUL that reads the
result of the MUL two before it (put another instruction between them, or order the MULs
otherwise).

The early start (issue #58): the engine starts an update once the sample's gyro and
accelerometer bytes are in (the loader writes every ``LOAD_ORDER`` word but MRAW0..2), while the
AK8963's bytes are still on the bus; SYNC waits for the whole sample (``samples.valid``), the
loader writes MRAW0..2 and the sample's ``mag_valid`` is taken, then the program goes on. A
program reads MRAW and branches on ``MAG_INVALID`` only after a SYNC (the instruction-level
model, ``sim/models/attitude_isa_model.py``, poisons both before it; ``resolve`` refuses a
``MAG_INVALID`` decision within ``SYNC_SHADOW`` words after a SYNC, which the fetch would make
before the flag is taken). Nothing is pending at a SYNC (a MUL before it has written back: only a
MUL goes on before its write-back).

Conditions: ``ALWAYS``; ``A_ZERO`` (register a is 0); ``A_NEG`` (register a is negative: a
comparison is a SUB then this); ``MAG_INVALID`` (the sample's ``mag_valid`` flag is 0);
``FIRST`` (first sample since the filter was reset or another filter selected); ``FILTER``
(the filter whose code is the instruction's ``sh`` field is selected: the dispatch).

A branch on a condition fixed for the run (ALWAYS, MAG_INVALID, FIRST, FILTER) is decided as
its word leaves the ROM, and the assembler folds it into the instruction before it
(``Instruction.then``) unless that one is a branch or END or a label names the branch: then it
costs no cycle at all.

Operand b: the engine forwards a result into the next instruction's operand a only (a
forwarding of b cost about 30 LUTs, ``report``). An instruction that reads as b the register
written as it goes on to execute (the d of the instruction just before it, or, for a MUL after
two MULs, the write-back of the MUL three before it) would read the old value: the assembler
(``Assembler.resolve``) swaps an ADD's or MUL's operands where that clears it, and otherwise
puts a NOP before it (about a dozen cycles an update at most: ``report``'s
``cycles_per_update``).

The assembler (``Assembler``) gives registers names, resolves labels and checks ranges. The
engine has no other hazards but the background units': a result is visible to the very next
instruction (as its b, under the rule above), and the assembler checks the rules above for a
unit started in the background.
"""

import enum
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

from amaranth.hdl import unsigned
from amaranth.lib import data

from ..contract.filter_registry import FILTERS


__all__ = ["Op", "Cond", "Flag", "FETCH_JUMPS", "REGISTER_CONDS", "SYNC_SHADOW", "MUL_SHIFTS",
           "Q14", "Q24", "DOUBLED", "Q30", "CORDIC_SHORT", "GO_ON", "COLLECT", "UNITS",
           "REG_COUNT", "REG_BITS",
           "ROM_DEPTH", "ROM_BITS", "Instr", "Instruction", "Assembler"]

REG_COUNT = 256
ROM_DEPTH = 1024
REG_BITS = (REG_COUNT - 1).bit_length()
ROM_BITS = (ROM_DEPTH - 1).bit_length()
# The rounding shifts the programs use. Each one costs a 32-bit multiplexer input and an overflow
# test, so there are few: formats are chosen to share them (Q2.14 coefficients and ASA, Q8.24
# covariances, Q1.30 sines, RATE in Q14; 29 for the doubled products 2·a·b of a rotation
# matrix), and a left shift is a MUL by a power-of-two constant register with shift 14 (the ALU
# has no shifter).
Q14 = 14            # Q2.14 coefficients, ASA, RATE; by a power-of-two register: a left shift
Q24 = 24            # Q8.24 covariances, gains, T
DOUBLED = 29        # 2·a·b of Q2.30 values (a rotation matrix's products)
Q30 = 30            # products of Q1.30 / Q2.30 values, ½x as a MUL by 2²⁹
MUL_SHIFTS = (Q14, Q24, DOUBLED, Q30)
# VEC, ROT and DIV: the ``sh`` field's bits (the module docstring has the background units)
CORDIC_SHORT = 1            # VEC: 8 iterations (a length)
GO_ON = 2                   # the start: the next instruction follows at once
COLLECT = 4                 # the collect: wait for the unit, write its result


class Op(enum.IntEnum):
    NOP = 0
    ADD = 1
    SUB = 2
    # 3 was OR (the zero tests' until they became register tests: the ALU has no OR)
    MUL = 4
    DIV = 5
    VEC = 6
    ROT = 7
    BR = 8
    SETF = 9
    END = 10
    SYNC = 11


# the ops that can run in the background (``GO_ON``), by the unit they use
UNITS = {"VEC": "cordic", "ROT": "cordic", "DIV": "divider"}


class Cond(enum.IntEnum):
    ALWAYS = 0
    A_ZERO = 1
    MAG_INVALID = 2
    FIRST = 3
    FILTER = 4          # the selected filter's code equals the instruction's ``sh``
    A_NEG = 5


class Flag(enum.IntEnum):
    """Result flags a program sets with SETF (``AttitudeFlags`` fields of the same names)."""
    ACC_USED = 0
    MAG_USED = 1
    MAG_DISTURBED = 2
    MAG_NEW_REF = 3
    AT_REST = 4
    BIAS_UPDATED = 5


# the fetch-decided conditions' index: 3 bits for four filters, a bit more per doubling of them
# (a wider ROM word: the cost of a fifth filter's dispatch, beside its routine's words)
JUMP_BITS = (3 + len(FILTERS)).bit_length()


class Instr(data.Struct):
    op: unsigned(4)
    d: unsigned(REG_BITS)
    a: unsigned(REG_BITS)
    b: unsigned(REG_BITS)
    sh: unsigned(3)         # MUL: MUL_SHIFTS index; SETF: the flag; VEC, ROT, DIV: the
                            # CORDIC_SHORT, GO_ON and COLLECT bits
    wrap: unsigned(1)       # ADD/SUB: wrap to 32 bits (angles) instead of saturating
    sat16: unsigned(1)      # ADD/SUB: saturate to 16 bits (calibrated sensor values)
    acc: unsigned(1)        # MUL: add to the running accumulator
    neg: unsigned(1)        # MUL: subtract the product
    wb: unsigned(1)         # MUL: write the rounded accumulator to d
    cond: unsigned(3)
    inv: unsigned(1)
    target: unsigned(ROM_BITS)
    jump: unsigned(JUMP_BITS)   # BR on a fixed condition: ``FETCH_JUMPS`` (0: none)


# A branch on a condition that holds still for the whole run is decided as it leaves the
# ROM (``hdl/engine/attitude_engine.py``): its word carries the condition as an index into the
# engine's vector of them, so that the decision is one bit chosen by three ROM bits (the
# path from the ROM to its own address). 0: not such a branch (the register tests are
# decided in execute).
FETCH_JUMPS = {
    (Cond.ALWAYS, 0): 1, (Cond.MAG_INVALID, 0): 2, (Cond.FIRST, 0): 3,
    **{(Cond.FILTER, code): 4 + code for code in range(len(FILTERS))},
}
REGISTER_CONDS = (Cond.A_ZERO, Cond.A_NEG)


@dataclass(frozen=True)
class Instruction:
    op: Op
    d: int = 0
    a: int = 0
    b: int = 0
    sh: int = 0
    wrap: bool = False
    sat16: bool = False
    acc: bool = False
    neg: bool = False
    wb: bool = True
    cond: Cond = Cond.ALWAYS
    inv: bool = False
    target: object = 0          # label name until resolved
    # a branch on a fixed condition folded into this instruction by ``Assembler.resolve``:
    # (cond, code, target), taken after it as the branch would have been; costs no cycle
    then: object = None

    def encode(self):
        """The ROM word (an integer laid out as ``Instr``)."""
        layout = data.Layout.cast(Instr)
        jump, target = 0, self.target
        if self.op == Op.BR and self.cond not in REGISTER_CONDS:
            if self.inv:
                raise ValueError(f"{self}: only a register test (A_ZERO, A_NEG) is inverted")
            jump = _fetch_jump(self, self.cond, self.sh)
        if self.then is not None:
            if self.op in (Op.BR, Op.END):
                raise ValueError(f"{self}: a branch folded into a {self.op.name}")
            cond, code, target = self.then
            jump = _fetch_jump(self, cond, code)
        word = 0
        for name, value in (("op", int(self.op)), ("d", self.d), ("a", self.a), ("b", self.b),
                            ("sh", self.sh), ("wrap", self.wrap), ("sat16", self.sat16),
                            ("acc", self.acc), ("neg", self.neg), ("wb", self.wb),
                            ("cond", int(self.cond)), ("inv", self.inv),
                            ("target", target), ("jump", jump)):
            f = layout[name]
            value = int(value)
            if not 0 <= value < (1 << f.width):
                raise ValueError(f"{self}: field {name}={value} does not fit {f.width} bits")
            word |= value << f.offset
        return word


def _fetch_jump(ins, cond, code):
    key = (cond, code if cond == Cond.FILTER else 0)
    if key not in FETCH_JUMPS:
        raise ValueError(f"{ins}: {Cond(cond).name} is not decided at the fetch")
    return FETCH_JUMPS[key]


def _reads_writes(ins):
    """(registers read, registers written) by an instruction."""
    op = ins.op
    background = op.name in UNITS
    if background and ins.sh & COLLECT:
        reads = ()
    elif op in (Op.ADD, Op.SUB, Op.DIV, Op.VEC, Op.MUL):
        reads = (ins.a, ins.b)
    elif op == Op.ROT:
        reads = (ins.a,)
    elif op == Op.BR and ins.cond in (Cond.A_ZERO, Cond.A_NEG):
        reads = (ins.a,)
    else:
        reads = ()
    if background and ins.sh & GO_ON:
        writes = ()
    elif op in (Op.VEC, Op.ROT):
        writes = (ins.d, ins.d + 1)
    elif op in (Op.ADD, Op.SUB, Op.DIV) or (op == Op.MUL and ins.wb):
        writes = (ins.d,)
    else:
        writes = ()
    return reads, writes


@dataclass
class Assembler:
    """Collects instructions for one ROM. Registers are given by address (ints); ``mul`` takes
    its shift in bits (``Q14``, ``Q24``, ``DOUBLED``, ``Q30``) and looks up its code.

    ``scratch_pool``: addresses of working registers that routines borrow with ``scratch(n)``
    and give back at the end of the ``with`` block. Each instruction is checked as it is emitted: a
    scratch register it reads must be held by a live scope and written since it was handed out
    (otherwise it would read what another routine left there), one it writes must be held.
    The check follows the program text, so a value written on one side of a branch counts as
    written after the join."""
    code: list = field(default_factory=list)
    labels: dict = field(default_factory=dict)
    scratch_pool: tuple = ()

    def __post_init__(self):
        self._free = list(self.scratch_pool)
        self._written = set()               # held scratch registers written since handed out

    def label(self, name):
        if name in self.labels:
            raise ValueError(f"label {name!r} defined twice")
        self.labels[name] = len(self.code)

    @contextmanager
    def scratch(self, n):
        """``n`` scratch registers, held for the ``with`` block."""
        if n > len(self._free):
            raise ValueError(f"{n} scratch registers asked for, {len(self._free)} free")
        regs, self._free = self._free[:n], self._free[n:]
        try:
            yield regs
        finally:
            self._written -= set(regs)
            self._free = sorted(self._free + regs, key=self.scratch_pool.index)

    def _emit(self, ins):
        reads, writes = _reads_writes(ins)
        for reg in reads:
            if reg in self.scratch_pool and reg not in self._written:
                state = "free" if reg in self._free else "not written since it was handed out"
                raise ValueError(f"instruction {len(self.code)} ({ins.op.name}) reads scratch "
                                 f"register {reg:#04x}, {state}")
        for reg in writes:
            if reg in self.scratch_pool:
                if reg in self._free:
                    raise ValueError(f"instruction {len(self.code)} ({ins.op.name}) writes "
                                     f"scratch register {reg:#04x}, which is free")
                self._written.add(reg)
        self.code.append(ins)

    @staticmethod
    def _code(table, bits, what):
        if bits not in table:
            raise ValueError(f"{what} shift {bits} not one of {table}")
        return table.index(bits)

    def add(self, d, a, b, *, wrap=False, sat16=False):
        self._emit(Instruction(Op.ADD, d, a, b, wrap=wrap, sat16=sat16))

    def sub(self, d, a, b, *, wrap=False, sat16=False):
        self._emit(Instruction(Op.SUB, d, a, b, wrap=wrap, sat16=sat16))

    def mul(self, d, a, b, shr, *, acc=False, neg=False, wb=True):
        self._emit(Instruction(Op.MUL, d, a, b, self._code(MUL_SHIFTS, shr, "MUL"),
                               acc=acc, neg=neg, wb=wb))

    def nop(self):
        self._emit(Instruction(Op.NOP))

    def mac(self, d, terms, shr):
        """d = rshift_round(Σ ±a·b, shr); ``terms``: (a, b) or (a, b, -1)."""
        for i, t in enumerate(terms):
            last = i == len(terms) - 1
            self.mul(d if last else 0, t[0], t[1], shr, acc=i > 0,
                     neg=len(t) > 2 and t[2] < 0, wb=last)

    def div(self, d, a, b, *, go_on=False):
        """``go_on``: in the background (the start; ``collect("divider")`` writes d)."""
        self._emit(Instruction(Op.DIV, d, a, b, sh=GO_ON if go_on else 0))

    def vec(self, d, x, y, *, short=False, go_on=False):
        """``short``: a length only (``CORDIC_SHORT_ITERATIONS``: d's angle is coarse).
        ``go_on``: in the background (the start; ``collect`` writes d and d + 1)."""
        self._emit(Instruction(Op.VEC, d, x, y, sh=(CORDIC_SHORT if short else 0)
                               | (GO_ON if go_on else 0)))

    def rot(self, d, angle, *, go_on=False):
        """``go_on``: in the background, as ``vec``'s."""
        self._emit(Instruction(Op.ROT, d, angle, sh=GO_ON if go_on else 0))

    def collect(self, unit="cordic"):
        """The result of the operation started last with ``go_on`` on ``unit`` (``UNITS``: the
        CORDIC's VEC or ROT, the divider's DIV), into its d (and d + 1)."""
        start = next((i for i in reversed(self.code) if UNITS.get(i.op.name) == unit), None)
        if start is None or not start.sh & GO_ON:
            raise ValueError(f"instruction {len(self.code)}: a collect with no {unit} "
                             f"operation started in the background before it")
        self._emit(Instruction(start.op, start.d, sh=COLLECT))

    def br(self, target, cond=Cond.ALWAYS, *, a=0, inv=False, code=0):
        """``code``: the filter code a ``Cond.FILTER`` branch tests for."""
        self._emit(Instruction(Op.BR, a=a, sh=code, cond=cond, inv=inv, target=target))

    def setf(self, flag):
        # the flag's bit in ``d`` too: the engine ORs ``d`` into the flags (no decoder of sh)
        self._emit(Instruction(Op.SETF, sh=flag, d=1 << flag))

    def end(self):
        self._emit(Instruction(Op.END))

    def sync(self):
        """Wait for the sample's magnetometer words (the early start: the module docstring)."""
        self._emit(Instruction(Op.SYNC))

    def _fold(self):
        """Folds each branch on a fixed condition (``FETCH_JUMPS``) into the instruction
        before it (``Instruction.then``), where that one is neither a branch nor END and no
        label names the branch: the engine decides such a branch as the word leaves the ROM,
        so folded it costs no cycle (its own word would cost one). Labels after it move up."""
        code, i = self.code, 1
        while i < len(code):
            ins, prev = code[i], code[i - 1]
            if (ins.op == Op.BR and ins.cond not in REGISTER_CONDS and not ins.inv
                    and prev.op not in (Op.BR, Op.END) and prev.then is None
                    and i not in self.labels.values()):
                code[i - 1] = replace(prev, then=(ins.cond, ins.sh, ins.target))
                del code[i]
                self.labels = {k: v - 1 if v > i else v for k, v in self.labels.items()}
            else:
                i += 1

    def _separate_muls(self):
        """A NOP before a MUL that reads the result of the MUL that runs just before it (MUL
        after MUL, the module docstring): after the word before it, or at a folded jump's
        target (where every path to it takes the NOP). Labels after it move down."""
        code, i = self.code, 0
        while i < len(code):
            a = code[i]
            if a.op == Op.MUL and a.wb:
                for t in _successors(code, i, self.labels.get):
                    if code[t].op == Op.MUL and a.d in _reads_writes(code[t])[0]:
                        code.insert(t, Instruction(Op.NOP))
                        self.labels = {k: v + 1 if v > t else v for k, v in self.labels.items()}
                        i += t <= i
            i += 1

    def _separate_b_reads(self):
        """No instruction reads as ``b`` the register written as it goes on to execute
        (``_landing``; the engine forwards ``a`` only: the module docstring). An ADD's or
        MUL's operands are swapped where that clears it (``a`` is forwarded); otherwise a NOP
        goes before it (after the word before it, or at a folded jump's target: every path to
        it takes the NOP). Labels after it move down."""
        code, t = self.code, 0
        before = _predecessors(code, self.labels.get)
        # A NOP writes nothing and ends a chain of MULs, and a swap writes what it wrote: a
        # change only takes writes away from what follows, so the words before it stay clear
        # and the search goes on from it
        while t < len(code):
            ins = code[t]
            landing = _landing(code, before, t)
            if ins.b in landing and ins.b in _b_read(ins):
                if ins.op in (Op.ADD, Op.MUL) and ins.a not in landing:
                    code[t] = replace(ins, a=ins.b, b=ins.a)
                else:
                    code.insert(t, Instruction(Op.NOP))
                    self.labels = {k: v + 1 if v > t else v for k, v in self.labels.items()}
                    before = _predecessors(code, self.labels.get)
            t += 1

    def resolve(self):
        """Instructions with label targets replaced by addresses, the branches on fixed
        conditions folded where they can be (``_fold``), NOPs between MULs where one reads the
        result of the one just before (``_separate_muls``) and before a read of operand b the
        engine would make too early (``_separate_b_reads``; ``labels`` then gives the
        addresses of the final program), and the background units', MULs' and b's rules
        checked."""
        self._fold()
        self._separate_muls()
        self._separate_b_reads()

        def address(label):
            if label not in self.labels:
                raise ValueError(f"branch to undefined label {label!r}")
            return self.labels[label]

        out = []
        for ins in self.code:
            if ins.op == Op.BR:
                ins = replace(ins, target=address(ins.target))
            if ins.then is not None:
                cond, code, target = ins.then
                ins = replace(ins, then=(cond, code, address(target)))
            out.append(ins)
        if len(out) > ROM_DEPTH:
            raise ValueError(f"program of {len(out)} instructions exceeds the ROM ({ROM_DEPTH})")
        _check_background(out, set(self.labels.values()))
        _check_sync_shadow(out)
        _check_mul_chains(out)
        _check_b_reads(out)
        return out


# The words after a SYNC where a fetch-decided MAG_INVALID could be decided before the engine
# took the sample's ``mag_valid``: the next word left the ROM before SYNC ran, the one after
# leaves it as SYNC goes on, when the decision register (a cycle behind the flag) still
# holds the last sample's; two words more of margin
SYNC_SHADOW = 4


def _check_sync_shadow(code):
    for i, ins in enumerate(code):
        if ins.op != Op.SYNC:
            continue
        for k in range(i, min(i + 1 + SYNC_SHADOW, len(code))):
            after = code[k]
            if ((after.op == Op.BR and after.cond == Cond.MAG_INVALID) or
                    (after.then is not None and after.then[0] == Cond.MAG_INVALID)):
                raise ValueError(f"instruction {k}: MAG_INVALID decided {k - i} words after "
                                 f"the SYNC at {i} (at least {SYNC_SHADOW + 1})")


def _successors(code, i, address=None):
    """The instructions that may run right after instruction ``i``: the next word and a folded
    jump's target (only the target, for an ALWAYS one; not one past the last word); none after
    END or a branch (a branch is not a MUL: it ends a chain of them, all that the MUL rules
    follow). ``address``: a folded jump's target from its label (before ``resolve`` replaces
    them; None: undefined, left out, ``resolve`` refuses it)."""
    ins = code[i]
    if ins.op in (Op.END, Op.BR):
        return []
    after = []
    if ins.then is not None:
        cond, _, target = ins.then
        target = target if address is None else address(target)
        if target is not None and target < len(code):
            after.append(target)
        if cond == Cond.ALWAYS:
            return after
    return after + [i + 1] if i + 1 < len(code) else after


def _b_read(ins):
    """The register an instruction reads through the engine's ``b`` port (a tuple: empty when
    it reads none)."""
    reads = _reads_writes(ins)[0]
    return (ins.b,) if len(reads) == 2 else ()


def _predecessors(code, address=None):
    """For each word, the words that may run just before it (``_successors`` reversed)."""
    before = [set() for _ in code]
    for i in range(len(code)):
        for t in _successors(code, i, address):
            before[t].add(i)
    return before


def _landing(code, before, t):
    """The registers written as instruction ``t`` goes on to execute, on any path to it: the
    ``d`` of the instruction just before it (a VEC's or ROT's d + 1 is written a cycle before,
    while ``t`` waits and reads its operands again; a MUL that writes back waits for its
    write-back unless a MUL follows), or, for a MUL after a MUL (which goes on at once), the
    write-back of the MUL three before it when the two between are MULs (its write-back comes
    two cycles after its issue)."""
    out = set()
    for i in before[t]:
        if code[t].op != Op.MUL or code[i].op != Op.MUL:
            if _reads_writes(code[i])[1]:
                out.add(code[i].d)
            continue
        for j in before[i]:
            if code[j].op != Op.MUL:
                continue
            out.update(code[k].d for k in before[j] if code[k].op == Op.MUL and code[k].wb)
    return out


def _check_b_reads(code):
    """``_separate_b_reads``' rule, checked on the final program."""
    before = _predecessors(code)
    for t, ins in enumerate(code):
        if _landing(code, before, t) & set(_b_read(ins)):
            raise ValueError(f"instruction {t} reads as b the register written as it goes on "
                             f"to execute: the engine does not forward b")


def _check_mul_chains(code):
    """The MUL timing the engine does not test (the module docstring): on no path does a MUL
    read the result of the MUL just before it, or of the one two before it."""
    for i, a in enumerate(code):
        if a.op != Op.MUL or not a.wb:
            continue
        for j in _successors(code, i):
            if code[j].op != Op.MUL:
                continue
            for k, apart in [(j, "just before it")] + [(k, "two before it")
                                                       for k in _successors(code, j)]:
                if code[k].op == Op.MUL and a.d in _reads_writes(code[k])[0]:
                    raise ValueError(f"instruction {k}: a MUL reads the result of instruction "
                                     f"{i}, the MUL {apart}, which goes on at once: the engine "
                                     f"would read it too early (put another instruction "
                                     f"between them)")


def _check_background(code, labelled):
    """The background units' rules (the module docstring): each start (``GO_ON``) is followed
    in its basic block by its collect, with no other operation of its unit, and no access to
    what the collect writes, between them; every collect has its start. ``labelled``: the
    addresses labels name (a branch may land there)."""
    collected = set()
    for i, ins in enumerate(code):
        unit = UNITS.get(ins.op.name)
        if unit is None or not ins.sh & GO_ON:
            continue
        written = set(_reads_writes(replace(ins, sh=COLLECT))[1])
        j, why = i, None
        while why is None:
            if code[j].then is not None:
                why = "a jump folded into it"
            j += 1
            if j == len(code):
                why = "the end of the program"
                break
            nxt = code[j]
            if j in labelled:
                why = "a label"
            elif nxt.op in (Op.BR, Op.END):
                why = nxt.op.name
            elif UNITS.get(nxt.op.name) == unit:
                if nxt.sh & COLLECT and nxt.op == ins.op and nxt.d == ins.d:
                    collected.add(j)
                    break
                why = f"another {nxt.op.name}"
            elif written & set(sum(_reads_writes(nxt), ())):
                why = f"{nxt.op.name} at {j}, which reads or writes its result's registers"
        if why is not None:
            raise ValueError(f"instruction {i}: {ins.op.name} started in the background meets "
                             f"{why} before its collect")
    for j, ins in enumerate(code):
        if ins.op.name in UNITS and ins.sh & COLLECT and j not in collected:
            raise ValueError(f"instruction {j}: a collect with no start before it")
