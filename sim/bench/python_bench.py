"""The bench (``sim.bench.bench.Bench``) on Amaranth's simulator: the scenario is its testbench."""

from amaranth.hdl import Value
from amaranth.sim import Simulator

from .bench import Bench, run_interruptible
from .harness import attach_models, attach_stuck_miso
from .uart import attach_uart_receiver


__all__ = ["PythonBench"]


class PythonBench(Bench):
    """``Bench`` on Amaranth's simulator. The models run as a process that wakes on pin
    changes and their own events (``attach_models``), the UART receiver as another
    (``attach_uart_receiver``); the scenario is the testbench, so its ``get`` sees settled
    values and its waits are the simulator's (``changed``: ``ctx.changed`` with a delay to
    ``until``). ``last_cycle``: the cycle the scenario last read (an interrupted run's
    end). ``sim``: the ``Simulator``."""

    compiled = False

    def __init__(self, harness, inputs, outputs, clk_freq, *, models=None, uart=None,
                 stuck_miso=None):
        super().__init__(harness, inputs, outputs, clk_freq)
        self._values = {n: Value.cast(p) for n, p in self.ports.items()}
        self.sim = Simulator(harness)
        self.sim.add_clock(1 / clk_freq)
        if models is not None:
            attach_models(self.sim, harness, clk_freq, mpu=models.mpu, bus=models.bus,
                          injector=models.injector)
        elif stuck_miso is not None:
            attach_stuck_miso(self.sim, harness, stuck_miso)
        if uart is not None:
            name, divisor, sink = uart
            attach_uart_receiver(self.sim, self._values[name], divisor, sink)
        self._ctx = None
        self.last_cycle = 0

    @property
    def cycle(self):
        self.last_cycle = self._ctx.get(self.harness.cycle)
        return self.last_cycle

    def get(self, name):
        return self._decode(name, self._ctx.get(self._values[name]))

    def set(self, name, value):
        self._ctx.set(self._values[name], self._encode(name, value))

    async def changed(self, *names, until):
        period = 1 / self.clk_freq
        await self._ctx.changed(*(self._values[n] for n in names)).delay(
            (until - self.cycle) * period)

    async def tick(self, cycles=1):
        if cycles == 1:
            await self._ctx.tick()
        else:
            await self._ctx.tick().repeat(cycles)

    def check(self):
        self.harness.check(self._ctx)

    def run(self, scenario, *, keep_on_interrupt=False, trace=None):
        async def testbench(ctx):
            self._ctx = ctx
            await scenario(self)
        self.sim.add_testbench(testbench)
        if trace:
            with trace.python_writer(self.sim):
                return run_interruptible(self.sim.run, keep_on_interrupt)
        return run_interruptible(self.sim.run, keep_on_interrupt)
