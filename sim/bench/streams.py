"""Testbench helpers for ``lib.stream`` interfaces: a producer, a consumer, and checkers of
the stream rules that any testbench can put on any stream of the design: ``check_stream_rules``
(a Python process, for short unit benches) and ``StreamMonitor`` (the same rules as logic in the
simulated design: no Python per cycle, for long co-simulations that wake only on events)."""

from amaranth.hdl import Const, Elaboratable, Module, Signal, Value


__all__ = ["stream_put", "stream_get", "check_stream_rules", "StreamMonitor", "Monitored"]


async def stream_put(ctx, stream, payload):
    """Offer one transfer on ``stream`` (an input of the design) and wait until it is taken."""
    ctx.set(stream.payload, payload)
    ctx.set(stream.valid, 1)
    await ctx.tick().until(stream.ready)
    ctx.set(stream.valid, 0)


async def stream_get(ctx, stream, *, timeout=None):
    """Take one transfer from ``stream`` (an output of the design): ``ready`` until ``valid``;
    returns the payload transferred. ``timeout``: cycles to wait at most (then
    ``AssertionError``); None waits for ever."""
    ctx.set(stream.ready, 1)
    waited = 0
    while True:
        _, _, valid, payload = await ctx.tick().sample(stream.valid, stream.payload)
        if valid:
            break
        waited += 1
        if timeout is not None and waited >= timeout:
            raise AssertionError(f"no transfer within {timeout} cycles")
    ctx.set(stream.ready, 0)
    return payload


def _bits(payload):
    return Const.cast(payload).value if hasattr(payload, "shape") else payload


def check_stream_rules(sim, stream, name="stream"):
    """Watch ``stream`` for the whole simulation (a background testbench): once ``valid`` is
    up it stays up until a cycle with ``ready``, and the payload holds still meanwhile. A
    violation raises ``AssertionError`` naming the stream and the cycle."""
    async def checker(ctx):
        waiting, held, cycle = False, None, 0
        async for _, _, valid, ready, payload in ctx.tick().sample(
                stream.valid, stream.ready, stream.payload):
            payload = _bits(payload)
            if waiting:
                assert valid, f"{name}: valid withdrawn before a transfer (cycle {cycle})"
                assert payload == held, \
                    f"{name}: payload changed under valid, {held:#x} -> {payload:#x} (cycle {cycle})"
            waiting, held, cycle = bool(valid and not ready), payload, cycle + 1
    sim.add_testbench(checker, background=True)


class StreamMonitor(Elaboratable):
    """The stream rules as simulation-only logic beside the design: ``withdrawn`` and
    ``changed`` are set (and stay set) at the first cycle where ``valid`` fell, or the payload
    changed, while a transfer waited. ``check(ctx)`` raises ``AssertionError`` if either is."""

    def __init__(self, stream, name):
        self.stream, self.name = stream, name
        tag = "".join(c if c.isalnum() else "_" for c in name)   # an identifier: the
        self.withdrawn = Signal(name=f"{tag}_withdrawn")          # compiled path exports
        self.changed = Signal(name=f"{tag}_changed")              # these to Verilog

    def elaborate(self, platform):
        m = Module()
        s = self.stream
        payload = Value.cast(s.payload)
        waiting, held = Signal(), Signal.like(payload)
        m.d.sync += [waiting.eq(s.valid & ~s.ready), held.eq(payload)]
        with m.If(waiting & ~s.valid):
            m.d.sync += self.withdrawn.eq(1)
        with m.If(waiting & (payload != held)):
            m.d.sync += self.changed.eq(1)
        return m

    def check(self, ctx):
        assert not ctx.get(self.withdrawn), f"{self.name}: valid withdrawn before a transfer"
        assert not ctx.get(self.changed), f"{self.name}: payload changed under valid"


class Monitored(Elaboratable):
    """``dut`` with a ``StreamMonitor`` on each of its ``streams`` (name: stream; ``monitor``
    adds more before the simulator is made); ``check(ctx)`` at the end of the testbench."""

    def __init__(self, dut, streams=None):
        self.dut = dut
        self.monitors = [StreamMonitor(s, name) for name, s in (streams or {}).items()]

    def monitor(self, stream, name):
        self.monitors.append(StreamMonitor(stream, name))

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = self.dut
        for index, monitor in enumerate(self.monitors):
            m.submodules[f"monitor{index}"] = monitor
        return m

    def check(self, ctx):
        for monitor in self.monitors:
            monitor.check(ctx)
