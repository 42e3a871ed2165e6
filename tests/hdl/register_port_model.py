"""A register port for testbenches: answers a client's commands cycle by cycle from Python."""


class RegisterPortModel:
    """Serves ``bus`` (the port side of a ``RegisterPortSignature``: ``cmd`` in, ``rx`` and
    ``rsp`` out). ``answer(device, reg, length)`` gives the bytes of a read (or None: the
    command fails with ``error``); writes are recorded in ``writes`` as (device, reg, data).
    Drive it with ``await model.cycles(ctx, n)`` or ``await model.until(ctx, cond)``: each
    cycle is one clock edge, with the handshake the design saw at that edge."""

    def __init__(self, bus, answer):
        self.bus, self.answer = bus, answer
        self.writes, self.reads = [], []
        self._queue, self._rsp, self._error = [], False, False
        self.ready = True

    def _drive(self, ctx):
        bus = self.bus
        ctx.set(bus.rx.valid, 0)
        ctx.set(bus.rsp.valid, 0)
        if self._queue:
            ctx.set(bus.rx.valid, 1)
            ctx.set(bus.rx.payload, self._queue.pop(0))
        elif self._rsp:
            ctx.set(bus.rsp.valid, 1)
            ctx.set(bus.rsp.payload.error, self._error)
            self._rsp = False
        else:
            self.ready = True
        ctx.set(bus.cmd.ready, self.ready and not self._queue and not self._rsp)

    async def cycle(self, ctx):
        self._drive(ctx)
        bus = self.bus
        *_, valid, ready, cmd = await ctx.tick().sample(bus.cmd.valid, bus.cmd.ready,
                                                        bus.cmd.payload)
        if valid and ready:
            self.ready = False
            if cmd.write:
                self.writes.append((cmd.device, cmd.reg, cmd.data))
                self._queue, self._error = [], False
            else:
                self.reads.append((cmd.device, cmd.reg, cmd.length))
                data = self.answer(cmd.device, cmd.reg, cmd.length)
                self._queue, self._error = ([], True) if data is None else (list(data), False)
            self._rsp = True

    async def cycles(self, ctx, n):
        for _ in range(n):
            await self.cycle(ctx)

    async def until(self, ctx, cond, limit=100_000):
        for _ in range(limit):
            if cond():
                return
            await self.cycle(ctx)
        raise TimeoutError("condition not met")
