"""Two clients of one register port, whole commands at a time."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .register_port import RegisterPortSignature


__all__ = ["RegisterPortArbiter"]


class RegisterPortArbiter(wiring.Component):
    """Shares a register port (``RegisterPortSignature``) between two clients.

    Members
        ``first`` (a register port, as its client sees it): has priority.
        ``second`` (in, likewise): gets the port when ``first`` offers no command.
        ``port`` (out, to the register port).

    A client owns the port from the cycle its command is taken until its response is taken;
    its ``rx`` bytes and its response go to it alone. The choice is made combinationally when
    the port is free (no latency); a client whose command is waiting keeps it valid and still
    (a stream's rule), so ``first`` can only overtake ``second`` between commands.
    Throughput: back-to-back commands, as the port allows.
    """

    def __init__(self):
        super().__init__({
            "first": Out(RegisterPortSignature()),
            "second": Out(RegisterPortSignature()),
            "port": Out(RegisterPortSignature().flip()),
        })

    def elaborate(self, platform):
        m = Module()
        busy = Signal()             # a command was taken and its response is not yet
        owner = Signal()            # 0 first, 1 second: whose command it was
        grant = Signal()            # whose command is offered now (when not busy)
        m.d.comb += grant.eq(~self.first.cmd.valid)
        clients = (self.first, self.second)
        port = self.port

        with m.If(~busy):
            for index, client in enumerate(clients):
                with m.If(grant == index):
                    m.d.comb += [port.cmd.valid.eq(client.cmd.valid),
                                 port.cmd.payload.eq(client.cmd.payload),
                                 client.cmd.ready.eq(port.cmd.ready)]
            with m.If(port.cmd.valid & port.cmd.ready):
                m.d.sync += [busy.eq(1), owner.eq(grant)]
        for index, client in enumerate(clients):
            with m.If(busy & (owner == index)):
                m.d.comb += [client.rx.valid.eq(port.rx.valid),
                             client.rx.payload.eq(port.rx.payload),
                             port.rx.ready.eq(client.rx.ready),
                             client.rsp.valid.eq(port.rsp.valid),
                             client.rsp.payload.eq(port.rsp.payload),
                             port.rsp.ready.eq(client.rsp.ready)]
        with m.If(port.rsp.valid & port.rsp.ready):
            m.d.sync += busy.eq(0)
        return m
