"""The command decoder's bus to the board's register blocks (the PWM outputs)."""

from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["BoardBusSignature"]


class BoardBusSignature(wiring.Signature):
    """A register bus with an 8-bit address, from the command decoder's side.

    - ``addr`` (out, 8), ``w_data`` (out, 32), ``w_en`` (out): a write lands in the cycle
      ``w_en`` is high, and only if ``ok`` is high in that cycle.
    - ``exists`` (in): ``addr`` is a register of the block (read or write).
    - ``ok`` (in): a write of ``w_data`` to ``addr`` is acceptable (the register is writable
      and the value in range); combinational from ``addr`` and ``w_data``, so the decoder
      can reply "refused" without writing anything.
    - ``r_data`` (in, 32): the register at ``addr``, from the cycle after ``addr`` (a block
      may register its reads, e.g. from a block RAM); the decoder holds ``addr`` from the
      command's payload until it is answered.
    """
    def __init__(self):
        super().__init__({
            "addr": Out(8), "w_data": Out(32), "w_en": Out(1),
            "exists": In(1), "ok": In(1), "r_data": In(32),
        })
