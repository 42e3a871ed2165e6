"""The compiled whole-board path's speed against Amaranth's simulator, side by side:
``python -m mpu9250_ahrs.sim.scenarios.speed`` prints both paths' cycles per second on the same runs
(the SPI and I2C front ends, the whole core) and whether their results were the same, and the
compiled core's own speed clocked free (``compiled_free_cycles_per_s``): the most the core's
ratio could reach if the Python models and the loop around them cost nothing."""

import time


__all__ = ["speed", "compiled_core_free_speed"]


def compiled_core_free_speed(cycles=3_000_000):
    """Cycles per second of the compiled core (the build ``run_core`` uses at ``SimSetup``'s
    defaults, from the cache) clocked ``cycles`` edges in one call from reset, its pins idle:
    no Python in the loop, so the Verilated model's own speed."""
    from ..bench.compiled_bench import CompiledBench
    from ..bench.harness import PinModels
    from .core import core_harness, core_ports
    from .setup import SimSetup
    setup = SimSetup()
    core, harness, key = core_harness(setup)
    design = CompiledBench(harness, *core_ports(core), setup.clk_freq, name="core", key=key,
                           models=PinModels(setup.clk_freq, mpu=setup.model())).design
    start = time.perf_counter()
    design.run(cycles, 0)
    return round(cycles / (time.perf_counter() - start))


def speed(samples=20):
    """Both paths on the same stimulus (``SimSetup``'s defaults: 48 MHz, 1 kHz scaled 0.2,
    the I2C wiring in real time), each build cached first: cycles per second of each and
    their ratio, and whether the results were the same. A benchmark, not a test: the figures
    depend on the machine."""
    from ...hdl.primitives.clocking import SYSTEM_CLOCK_HZ
    from ...hdl.sensor.mpu9250_driver import MPU9250Config
    from .core import run_core
    from .frontend import run_frontend
    from .setup import SimSetup
    spi = SimSetup()
    i2c_config = MPU9250Config(wiring="i2c")
    i2c = SimSetup(config=i2c_config,
                   odr_scale=SimSetup.default_odr_scale(i2c_config, SYSTEM_CLOCK_HZ))
    runs = {
        "frontend_spi": (lambda c: run_frontend(spi, n_samples=samples, compiled=c),
                         ("samples", "sample_cycles")),
        "frontend_i2c": (lambda c: run_frontend(i2c, n_samples=max(2, samples // 4),
                                                compiled=c), ("samples", "sample_cycles")),
        "core_spi": (lambda c: run_core(spi, n_results=samples, compiled=c),
                     ("results", "result_cycles", "frames")),
    }
    out = {}
    for name, (run, fields) in runs.items():
        run(True)                   # the build, cached
        fast, slow = run(True), run(False)
        out[name] = {"cycles": fast.cycles,
                     "same": all(getattr(fast, f) == getattr(slow, f) for f in fields),
                     "python_cycles_per_s": round(slow.cycles / slow.wall_s),
                     "compiled_cycles_per_s": round(fast.cycles / fast.wall_s),
                     "ratio": round(slow.wall_s / fast.wall_s * fast.cycles / slow.cycles)}
    free = compiled_core_free_speed()
    out["core_spi"]["compiled_free_cycles_per_s"] = free
    out["core_spi"]["ratio_if_models_cost_nothing"] = round(
        free / out["core_spi"]["python_cycles_per_s"])
    return out


def main(argv=None):
    """``python -m mpu9250_ahrs.sim.scenarios.speed``: both paths' speeds as JSON."""
    import argparse
    import json
    argparse.ArgumentParser(prog="python -m mpu9250_ahrs.sim.scenarios.speed",
                            description="Both simulation paths' cycles per second on the same "
                                        "runs.").parse_args(argv)
    print(json.dumps(speed(), indent=1))
    return 0


if __name__ == "__main__":
    import sys
    from ...reference.entry_point import run_main
    sys.exit(run_main("python -m mpu9250_ahrs.sim.scenarios.speed", main))
