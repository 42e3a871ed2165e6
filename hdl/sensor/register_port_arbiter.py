"""Two clients of one register port, whole commands at a time."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import Out

from .register_port import RegisterPortSignature


__all__ = ["RegisterPortArbiter"]


class RegisterPortArbiter(wiring.Component):
    """Shares a register port (``RegisterPortSignature``) between two clients.

    Members
        ``first`` (a register port, as its client sees it): has priority.
        ``second`` (in, likewise): gets the port when ``first`` offers no command.
        ``port`` (out, to the register port).
        ``second_owns`` (out): the command on the port (taken, until its response is) is
            ``second``'s (the driver gives the SPI controller a client's own sample delay by it).

    A client owns the port from the cycle its command is taken until its response is taken
    (and no ``rx`` byte is offered beside it); its ``rx`` bytes and its response go to it
    alone. The choice is made combinationally when
    the port is free (no latency) and then held while the chosen command waits for the port's
    ``ready``: ``first`` can only overtake ``second`` before ``second``'s command is offered,
    never under it (that would change the payload under ``valid``).
    Throughput: back-to-back commands, as the port allows.
    """

    def __init__(self):
        super().__init__({
            "first": Out(RegisterPortSignature()),
            "second": Out(RegisterPortSignature()),
            "port": Out(RegisterPortSignature().flip()),
            "second_owns": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        busy = Signal()             # a command was taken and its response is not yet
        owner = Signal()            # 0 first, 1 second: whose command is offered or taken
        grant = Signal()            # whose command is offered now (when not busy)
        waiting = Signal()          # the command offered last cycle was not taken
        m.d.comb += grant.eq(Mux(waiting, owner, ~self.first.cmd.valid))
        m.d.sync += waiting.eq(~busy & self.port.cmd.valid & ~self.port.cmd.ready)
        m.d.comb += self.second_owns.eq(busy & owner)
        clients = (self.first, self.second)
        port = self.port

        # the payloads pass unconditionally (their ``valid`` says whose they are): gating them
        # would cost a LUT a bit
        m.d.comb += port.cmd.payload.eq(Mux(grant, self.second.cmd.payload,
                                            self.first.cmd.payload))
        with m.If(~busy):
            for index, client in enumerate(clients):
                with m.If(grant == index):
                    m.d.comb += [port.cmd.valid.eq(client.cmd.valid),
                                 client.cmd.ready.eq(port.cmd.ready)]
            m.d.sync += owner.eq(grant)
            with m.If(port.cmd.valid & port.cmd.ready):
                m.d.sync += busy.eq(1)
        for index, client in enumerate(clients):
            m.d.comb += [client.rx.payload.eq(port.rx.payload),
                         client.rsp.payload.eq(port.rsp.payload)]
            with m.If(busy & (owner == index)):
                m.d.comb += [client.rx.valid.eq(port.rx.valid),
                             port.rx.ready.eq(client.rx.ready),
                             client.rsp.valid.eq(port.rsp.valid),
                             port.rsp.ready.eq(client.rsp.ready)]
        # The response ends the ownership, unless an ``rx`` byte still waits beside it (a port
        # that broke its order): that byte goes to the owner, never to the next client.
        with m.If(port.rsp.valid & port.rsp.ready & ~port.rx.valid):
            m.d.sync += busy.eq(0)
        return m
