"""The assembler's checks: scoped scratch registers, shifts, labels, field ranges."""

import pytest

from mpu9250_ahrs.hdl.engine.attitude_isa import Q30, Assembler, Cond


def asm_with_pool():
    return Assembler(scratch_pool=(10, 11, 12))


def test_scratch_value_read_inside_its_scope():
    asm = asm_with_pool()
    with asm.scratch(2) as (t0, t1):
        asm.add(t0, 1, 2)
        asm.mul(t1, t0, 3, Q30)
        asm.br("x", Cond.A_NEG, a=t1)
        asm.label("x")
    assert len(asm.code) == 3


def test_scratch_read_after_it_was_given_back():
    asm = asm_with_pool()
    with asm.scratch(1) as (t,):
        asm.add(t, 1, 2)
    with pytest.raises(ValueError, match="reads scratch register 0x0a, free"):
        asm.add(5, t, 1)


def test_scratch_read_of_what_another_scope_left():
    """Handed out again, a register's old value is someone else's: reading it before writing
    is the mistake the scopes exist for."""
    asm = asm_with_pool()
    with asm.scratch(1) as (t,):
        asm.add(t, 1, 2)
    with asm.scratch(1) as (u,):
        assert u == t
        with pytest.raises(ValueError, match="not written since it was handed out"):
            asm.sub(5, 1, u)


def test_scratch_write_while_free_and_pool_exhausted():
    asm = asm_with_pool()
    with pytest.raises(ValueError, match="which is free"):
        asm.add(11, 1, 2)
    with pytest.raises(ValueError, match="4 scratch registers asked for, 3 free"):
        with asm.scratch(4):
            pass


def test_vectoring_writes_its_pair_and_shifts_are_named():
    asm = asm_with_pool()
    with asm.scratch(2) as (t0, t1):
        asm.vec(t0, 1, 2)                       # writes t0 and t0 + 1
        asm.add(5, t0, t1)
    with pytest.raises(ValueError, match="shift 31 not one of"):
        asm.mul(5, 1, 2, 31)
    with pytest.raises(ValueError, match="undefined label"):
        asm.br("nowhere")
        asm.resolve()


def test_fixed_conditions_are_fetch_jumps():
    """A branch on a condition fixed for the run carries its index into the engine's vector of
    them (``FETCH_JUMPS``: the engine decides it as it leaves the ROM); a register test carries
    none, and only a register test can be inverted."""
    from amaranth.lib import data
    from mpu9250_ahrs.hdl.engine.attitude_isa import FETCH_JUMPS, Instr, Instruction, Op

    def jump(ins):
        return data.Const(data.Layout.cast(Instr), ins.encode()).jump

    assert jump(Instruction(Op.BR, cond=Cond.FILTER, sh=2)) == FETCH_JUMPS[(Cond.FILTER, 2)]
    assert jump(Instruction(Op.BR, cond=Cond.ALWAYS)) == FETCH_JUMPS[(Cond.ALWAYS, 0)]
    assert jump(Instruction(Op.BR, cond=Cond.A_ZERO, a=5, inv=True)) == 0
    assert jump(Instruction(Op.ADD, 1, 2, 3)) == 0
    assert len(set(FETCH_JUMPS.values())) == len(FETCH_JUMPS) and 0 not in FETCH_JUMPS.values()
    with pytest.raises(ValueError, match="only a register test"):
        Instruction(Op.BR, cond=Cond.FIRST, inv=True).encode()


def test_fixed_branches_fold_into_the_instruction_before():
    """A branch on a fixed condition is folded into the instruction before it (``then``), not
    into a branch or END, and not when a label names it; the labels after it move up."""
    from mpu9250_ahrs.hdl.engine.attitude_isa import Op
    asm = Assembler()
    asm.add(1, 2, 3)
    asm.br("out", Cond.FILTER, code=2)          # folded into the ADD
    asm.br("out", Cond.A_ZERO, a=4)
    asm.br("out", Cond.FIRST)                   # after a branch: kept
    asm.label("named")
    asm.br("out")                               # named: kept
    asm.end()
    asm.br("out")                               # after END: kept
    asm.label("out")
    asm.sub(1, 2, 3)
    code = asm.resolve()
    assert [i.op for i in code] == [Op.ADD, Op.BR, Op.BR, Op.BR, Op.END, Op.BR, Op.SUB]
    assert code[0].then == (Cond.FILTER, 2, 6) and asm.labels == {"named": 3, "out": 6}
    assert all(i.target == 6 for i in code if i.op == Op.BR)
    assert len(asm.resolve()) == len(code)      # nothing more to fold


def test_background_rules():
    """A VEC, ROT or DIV started in the background (``go_on``) and its collect: work between
    them resolves, the other unit's operations included; a branch, a label, a folded jump,
    another operation of the same unit, an access to what the collect writes or a missing
    collect between them is refused at ``resolve``."""
    from mpu9250_ahrs.hdl.engine.attitude_isa import COLLECT, GO_ON, Op

    def program(*between, start=lambda asm: asm.vec(20, 1, 2, go_on=True), collect=True):
        asm = Assembler()
        start(asm)
        for emit in between:
            emit(asm)
        if collect:
            asm.collect()
        asm.label("out")
        asm.end()
        return asm

    code = program(lambda asm: asm.add(5, 20 + 2, 1), lambda asm: asm.mul(6, 1, 2, Q30),
                   start=lambda asm: asm.rot(20, 3, go_on=True)).resolve()
    assert [i.op for i in code[:4]] == [Op.ROT, Op.ADD, Op.MUL, Op.ROT]
    assert (code[0].sh, code[3].sh, code[3].d) == (GO_ON, COLLECT, 20)
    touches = "which reads or writes its result's registers"
    refused = [
        (touches, lambda asm: asm.add(5, 21, 1)),           # reads d + 1
        (touches, lambda asm: asm.add(20, 1, 1)),           # writes d
        ("meets BR", lambda asm: asm.br("out", Cond.A_ZERO, a=5)),
        ("meets a label", lambda asm: asm.label("inside")),
        ("meets a jump folded into it", lambda asm: asm.br("out")),
    ]
    for why, between in refused:
        with pytest.raises(ValueError, match=why):
            program(between).resolve()
    with pytest.raises(ValueError, match="meets another ROT"):
        program(lambda asm: asm.rot(30, 1, go_on=True), lambda asm: asm.collect(),
                collect=False).resolve()
    asm = Assembler()
    asm.rot(20, 3, go_on=True)
    asm.end()
    with pytest.raises(ValueError, match="meets END"):
        asm.resolve()
    with pytest.raises(ValueError, match="a collect with no cordic operation started"):
        program(start=lambda asm: asm.vec(20, 1, 2))
    # the divider's: the CORDIC may work meanwhile (blocking or in the background), not
    # another division
    asm = Assembler()
    asm.div(20, 1, 2, go_on=True)
    asm.vec(30, 1, 2, go_on=True)
    asm.add(5, 1, 2)
    asm.collect("cordic")
    asm.collect("divider")
    asm.div(21, 1, 2, go_on=True)
    asm.vec(30, 1, 2)
    asm.collect("divider")
    asm.end()
    asm.resolve()
    asm = Assembler()
    asm.div(20, 1, 2, go_on=True)
    asm.div(22, 1, 2, go_on=True)
    asm.collect("divider")
    asm.end()
    with pytest.raises(ValueError, match="meets another DIV"):
        asm.resolve()


def test_muls_that_read_a_result_too_early():
    """The MUL timing the engine does not test: a NOP goes before a MUL that reads the result
    of the MUL just before it (after the word, or at a folded jump's target); a MUL reading
    the result of the MUL two before it is refused, on a path through a folded jump too, and
    taken with another instruction between."""
    from mpu9250_ahrs.hdl.engine.attitude_isa import Op
    def program(*emits):
        asm = Assembler()
        for emit in emits:
            emit(asm)
        asm.end()
        asm.label("x")
        asm.mul(7, 5, 1, Q30)
        asm.end()
        return asm

    first = lambda asm: asm.mul(5, 1, 2, Q30)
    between = lambda asm: asm.mul(6, 1, 2, Q30)
    reads = lambda asm: asm.mul(7, 5, 3, Q30)
    with pytest.raises(ValueError, match="reads the result of instruction 0, the MUL two"):
        program(first, between, reads).resolve()
    # the one between ends in a jump to a MUL that reads it
    with pytest.raises(ValueError, match="reads the result of instruction 0"):
        program(first, between, lambda asm: asm.br("x")).resolve()
    program(first, between, lambda asm: asm.add(8, 1, 2), reads).resolve()
    # the one between reads it: a NOP before it, and then the third is three after the first
    code = program(first, lambda asm: asm.mul(6, 5, 2, Q30), reads).resolve()
    assert [i.op for i in code[:4]] == [Op.MUL, Op.NOP, Op.MUL, Op.MUL]
    # through a folded jump: the NOP at its target, which the label names
    asm = program(first, lambda asm: asm.br("x"))
    code = asm.resolve()
    assert code[0].then[2] == asm.labels["x"] and code[asm.labels["x"]].op == Op.NOP
    assert code[asm.labels["x"] + 1].op == Op.MUL
