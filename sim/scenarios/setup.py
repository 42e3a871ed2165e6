"""A simulation's set-up: scaled real time (``SimSetup``: the clock, the sensor's
configuration, the delays and sample period shortened alike in the driver and the models), the
models it makes, and the whole core's quick set-up the tests share."""

from dataclasses import dataclass, field, replace
from typing import Optional

from ...hdl.contract import ak8963_regs as A
from ...hdl.primitives.clocking import SYSTEM_CLOCK_HZ
from ...hdl.sensor.mpu9250_driver import DriverTiming, MPU9250Config
from ...hdl.sensor.sensor_frontend import SensorFrontEnd, spi_timing_for
from ..models.ak8963_model import AK8963Model, AK8963Timing
from ..models.i2c_bus import I2CBusModel
from ..models.mpu9250_model import MPU9250Model, MPU9250Timing
from ..models.sources import counting_field, counting_source


__all__ = ["SimSetup", "QUICK_CORE_BAUD", "quick_core_setup", "primary_bus"]


@dataclass
class SimSetup:
    """Scaled real time for simulation: same behaviour, fewer cycles.

    Start-up and reset delays are multiplied by ``delay_scale`` in both the driver and the
    model; the sample period and INT pulse by ``odr_scale`` in the model (the driver's
    interrupt timeout and self-test waits follow); the self-test runs only with
    ``self_test`` and then sums ``self_test_samples``.
    """
    clk_freq: float = SYSTEM_CLOCK_HZ
    config: MPU9250Config = field(default_factory=MPU9250Config)
    delay_scale: float = 1e-3
    odr_scale: float = 0.2
    mag_power_down_s: float = 100e-6       # the driver's AK8963 power-down wait
    # The AK8963 runs on its own oscillator: a period this much longer than nominal keeps its
    # measurements from locking to an exact multiple of the sample period (in which a
    # measurement can land in every read's data protection and be skipped, for ever).
    ak_clock_error: float = 0.0
    # The self-tests at bring-up (``MPU9250Config.self_test``) add their waits to every
    # bring-up (with SPI about 3 times the cycles, with I2C 7 times): simulations leave them
    # out unless they ask (``self_test=True``, as ``simulate`` does), and then sum
    # ``self_test_samples`` samples (None: the config's 128, 2 x 128 reads at 1 kHz)
    self_test: bool = False
    self_test_samples: Optional[int] = 2
    # the SPI controller's trained rate and the read levelling where the clock makes it faster
    # (``sensor_frontend.spi_timing_for``, issue #58); False: the safe rate only
    levelling: bool = True
    # the wait before the read levelling scans again (``DriverTiming.retrain_s``), in the
    # simulation's time; None: the driver's, scaled as the sample period is
    retrain_s: Optional[float] = None

    def __post_init__(self):
        if not self.self_test:
            self.config = replace(self.config, self_test=False)
        elif not self.config.self_test:
            # e.g. ``dataclasses.replace(setup, self_test=True)`` of a set-up made without
            # them: its config has lost them, and would run none, silently
            raise ValueError("SimSetup(self_test=True) needs a config with self_test")
        elif self.self_test_samples is not None:
            self.config = replace(self.config, self_test_samples=self.self_test_samples)

    @staticmethod
    def default_odr_scale(config, clk_freq):
        """The sample-period scale ``simulate`` and ``report`` use for ``config`` at
        ``clk_freq``: 0.2 where the shortened period still gives the design twice the cycles
        a sample needs (``rate_budget``: its read, or the engine's update), else 1 (real
        time). So 0.2 with SPI up to 1 kHz at the board's clock; 1 with I2C at 1 kHz (its
        400 kHz bus takes ~0.7 ms per nine-axis read), at 8 kHz (its period is short
        already), and at a clock too slow for the shortened period (a period shorter than
        the read would lose samples the design keeps at the real rate)."""
        from ...hdl.board.top import rate_budget
        scale = 0.2
        period_cycles = scale * clk_freq / config.output_data_rate
        fits = period_cycles >= 2 * rate_budget(config, clk_freq)["cycles_per_sample"]
        return scale if fits else 1.0

    @property
    def sample_period_s(self):
        return self.odr_scale / self.config.output_data_rate

    def telemetry_divider(self, baud):
        """The telemetry divider a build would have if the sample period were this set-up's
        (``telemetry_divider_for`` at ``1 / sample_period_s``): a build's default fits the
        real period, and a shortened one would leave most results no time on the UART."""
        from ...hdl.board.top import telemetry_divider_for
        return telemetry_divider_for(self.config, baud, rate=1 / self.sample_period_s)

    def driver_timing(self):
        return DriverTiming(time_scale=self.delay_scale, mag_power_down_s=self.mag_power_down_s,
                            sample_period_s=self.sample_period_s,
                            # the AK8963's period is scaled like the MPU9250's
                            mag_timeout_s=DriverTiming.mag_timeout_s * self.odr_scale,
                            retrain_s=(DriverTiming.retrain_s * self.odr_scale
                                       if self.retrain_s is None else self.retrain_s))

    def bring_up_budget_cycles(self):
        """Cycles that cover three bring-up attempts' waits plus the magnetometer's SLV4
        transfers (each waits for a sample tick of the MPU9250's I2C master): the start of
        every simulation's cycle budget."""
        timing = self.driver_timing()
        power_up, reset, _ = timing.cycles(self.clk_freq, self.config)
        return 3 * (power_up + reset + self.self_test_cycles()) + \
            40 * self.sample_period_s * self.clk_freq

    def self_test_cycles(self):
        """A bound on the cycles the self-tests add to a bring-up: their waits, and their reads
        at 400 kHz (the slowest bus: 9 bits a byte)."""
        cfg = self.config
        if not cfg.self_test:
            return 0
        waits = self.driver_timing().self_test_waits(self.clk_freq, cfg)
        reads = 2 * cfg.self_test_samples
        byte = 9 / 400e3 * self.clk_freq
        return (3 * waits.settle + reads * (waits.interval + 16 * byte) + 20 * byte +
                (waits.mag + 10 * byte if cfg.magnetometer else 0))

    def model_timing(self):
        return MPU9250Timing().scaled(delays=self.delay_scale, odr=self.odr_scale)

    def frontend(self, **kwargs):
        if self.config.wiring == "spi":
            kwargs.setdefault("spi_timing", spi_timing_for(self.clk_freq, self.levelling))
        return SensorFrontEnd(clk_freq=self.clk_freq, config=self.config,
                              timing=self.driver_timing(), **kwargs)

    def ak8963(self, **kwargs):
        kwargs.setdefault("source", counting_field())
        return AK8963Model(timing=AK8963Timing().scaled(
            odr=self.odr_scale * (1 + self.ak_clock_error)), **kwargs)

    def model(self, *, magnetometer=True, part=None, **kwargs):
        """An MPU9250 model (counting sensor values) with an AK8963 on its auxiliary bus
        (``model.aux_devices[0x0C]``) unless ``magnetometer`` is False. ``part``: its
        ``MPU9250Timing`` fields other than this set-up's (a dict: its SDO timing, issue #58)."""
        kwargs.setdefault("source", counting_source())
        if magnetometer:
            kwargs.setdefault("aux_devices", {A.I2C_ADDRESS: self.ak8963()})
        return MPU9250Model(timing=replace(self.model_timing(), **(part or {})), **kwargs)


# The whole core's quick set-up (``quick_core_setup``) and its UART's baud (a quarter of its
# clock, so that frames come quickly)
QUICK_CORE_BAUD = 3_000_000


def quick_core_setup():
    """The whole core's quick set-up: the default configuration (SPI, the magnetometer, 1 kHz)
    at a 12 MHz clock (a quarter of the board's cycles for the same bring-up and samples),
    the sample period scaled by 0.4 (a frame at ``QUICK_CORE_BAUD``, 3,680 cycles, fits in
    one). One set-up for the tests that run the whole core and the fault catalogue's
    ``host_garbage``, so that they share one compiled build (keyed by the set-up, the core's
    parameters and the baud); ``tests/sim/test_compiled_board.py`` checks it against
    Amaranth's simulator on this set-up."""
    return SimSetup(clk_freq=12e6, odr_scale=0.4)


def primary_bus(setup, model, *, injector=None, bus_kw=None):
    """I2C wiring: the ``I2CBusModel`` of the board's bus, ``model`` (an ``MPU9250Model``, or
    None: nothing answers) at ``setup``'s address with what its bypass exposes; nobody while
    ``injector`` (a fault) has the MPU9250 absent. ``bus_kw``: ``I2CBusModel``'s other
    arguments (clock stretching, a stuck bus)."""
    address = setup.config.i2c_address

    def lookup(a):
        if model is None or (injector is not None and injector.mpu_absent):
            return None
        return model.primary_bus_device(a, address)
    return I2CBusModel(lookup, **(bus_kw or {}))
