"""The compiled whole-board path's speed against Amaranth's simulator, side by side:
``python -m mpu9250_ahrs.sim.speed`` prints both paths' cycles per second on the same runs
(the SPI and I2C front ends, the whole core) and whether their results were the same."""


__all__ = ["speed"]


def speed(samples=20):
    """Both paths on the same stimulus (``SimSetup``'s defaults: 48 MHz, 1 kHz scaled 0.2,
    the I2C wiring in real time), each build cached first: cycles per second of each and
    their ratio, and whether the results were the same. A benchmark, not a test: the figures
    depend on the machine."""
    from ..hdl.mpu9250_driver import MPU9250Config
    from .cosim import SimSetup, run_core, run_frontend
    spi = SimSetup()
    i2c_config = MPU9250Config(wiring="i2c")
    i2c = SimSetup(config=i2c_config, odr_scale=SimSetup.default_odr_scale(i2c_config))
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
    return out


if __name__ == "__main__":
    import json
    print(json.dumps(speed(), indent=1))
