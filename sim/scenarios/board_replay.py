"""A recording through the whole board: ``replay FILE --engine board``.

The recording's samples are what the MPU9250 model measures (accelerometer and gyro, body axes)
and what the AK8963 model measures (the magnetometer, turned into its own axes); the core
(driver, SPI bus, attitude engine, telemetry scheduler, framer, UART) runs against them in the
co-simulation (compiled when Verilator is there), and the host's frame decoder reads the UART.
What the host decodes is scored against the recording's truth, and each frame's attitude is
checked bit for bit against the fixed-point model run over the samples the board read (the
same reference ``replay --engine fixed`` and ``--engine gateware`` use, on the bytes the bus
carried: ``model_reference``).

Time is compressed as in every co-simulation (``SimSetup``): the system clock is
``REPLAY_CLOCK_HZ``, a sample period a little longer than the sample's read and update, and the
UART at ``REPLAY_BAUD`` with the telemetry divider set (a register write, as a host would) so
that every ``divider``-th result is framed: the host gets that share of the recording's
samples, and the engine filters every one. The engine is set up for the recording's sample
period by register writes (``configuration_writes``), so the build is the core's own.
The AK8963 model measures at 100 Hz of the recording's time, as a real one would: a new field
in one sample of 1/(100 dt) (2.9 at the shared recordings' 286 Hz), where ``--engine fixed``
takes the recording's field at every sample; the frames equal to ``--engine fixed``'s results
are counted (``frames_as_engine_fixed``), and every frame equals the fixed-point model run over
the samples the board read, with the flags the driver gave them.
"""

import math
from dataclasses import dataclass, replace

import numpy as np

from ...hdl.sensor.mpu9250_driver import DriverTiming, MPU9250Config
from ...hdl.contract.numeric_contract import mag_period
from ..models.ak8963_model import AK8963Model, AK8963Timing
from .setup import SimSetup
from .core import run_core
from .frontend import sample_matches
from ..bench.bench import simulator_name
from ..models.sources import SensorSample


__all__ = ["REPLAY_CLOCK_HZ", "REPLAY_BAUD", "BoardReplay", "replay_board"]


REPLAY_CLOCK_HZ = 12e6          # fewer cycles per sample than 48 MHz; the same logic
REPLAY_BAUD = 3_000_000         # four cycles a bit at 12 MHz
# the sample rate the MPU9250 is set to (its period is then compressed; the engine's own
# period is the recording's, by register writes)
REPLAY_ODR_HZ = 100


@dataclass
class _RecordingTime(SimSetup):
    """``SimSetup`` whose driver times the magnetometer out in the recording's time
    (``time_per_s``: simulated seconds a recorded second), as the AK8963 model measures."""
    time_per_s: float = 1.0

    def driver_timing(self):
        return replace(super().driver_timing(),
                       mag_timeout_s=DriverTiming.mag_timeout_s * self.time_per_s)


@dataclass
class BoardReplay:
    """What ``replay_board`` saw: the frames the host decoded (their recording indices,
    quaternions as floats), whether each frame's attitude equals the fixed-point model's for
    its sample (and the first difference), whether every engine result does, and the run's
    figures."""
    indices: np.ndarray             # recording index of each frame's sample
    quat: np.ndarray                # each frame's quaternion (w, x, y, z)
    bit_exact: bool                 # every frame the host decoded
    first_mismatch: object
    results_bit_exact: bool         # every result the engine produced (framed or not)
    frames_as_engine_fixed: int     # frames equal to ``replay --engine fixed``'s result
    mag_not_valid: int              # samples read whose field the driver did not pass as valid
    samples_read: int
    frames: int
    divider: int
    cycles: int
    wall_s: float
    compiled: bool
    counters: dict

    def summary(self):
        return {"bit_exact": self.bit_exact, "first_mismatch": self.first_mismatch,
                "results_bit_exact": self.results_bit_exact,
                "frames_as_engine_fixed": self.frames_as_engine_fixed,
                "mag_not_valid": self.mag_not_valid,
                "board_samples_read": self.samples_read, "board_frames": self.frames,
                "telemetry_divider": self.divider, "board_cycles": self.cycles,
                "board_sim_s": round(self.wall_s, 1),
                "board_cycles_per_s": round(self.cycles / max(self.wall_s, 1e-9)),
                "simulator": simulator_name(self.compiled),
                "counters": self.counters}



def _recording_model(setup, gyr, acc, mag_ak, period_s, dt):
    """The MPU9250 model that plays the recording (body-axis counts ``gyr``, ``acc``; the
    field ``mag_ak`` in the AK8963's axes) from the first sample the driver reads, and
    ``first``: ``{"read": index}`` of that sample once it is read."""
    total = len(gyr)
    table = [SensorSample(accel=tuple(int(v) for v in a), gyro=tuple(int(v) for v in g))
             for a, g in zip(acc, gyr)]
    # the recording starts with the first sample the driver reads: the samples the model
    # makes during bring-up (never read) are the recording's first
    first = {}

    def source(index, t):
        if model.sample_reads and "read" not in first:
            first["read"] = model.sample_reads[0]
        return table[min(max(index - first.get("read", index), 0), total - 1)]
    model = setup.model(source=source, aux_devices={})
    # the AK8963 measures at its own 100 Hz against the recording's rate (``dt``), as on a
    # real board: the field of the sample the MPU9250 made last, in one sample of 1/(100 dt)
    ak = AK8963Model(timing=AK8963Timing().scaled(odr=period_s / (100 * dt) / 0.01),
                     source=lambda k, t: mag_ak[min(max(len(model.samples) - 1 -
                                                        first.get("read", 10 ** 9), 0),
                                                    total - 1)])
    model.aux_devices[0x0C] = ak
    return model, first


def replay_board(filter, gyr_counts, acc_counts, mag_counts, dt, *, gyro_fs_dps=2000,
                 accel_fs_g=16, samples=None, compiled="prefer", progress=None,
                 period_cycles=None, divider=None, **units_and_params):
    """The recording's first ``samples`` (default: all; body-axis counts, period ``dt``)
    through the co-simulated board, the engine set up for ``filter``: a ``BoardReplay``.
    ``period_cycles`` (the simulated sample period) and ``divider`` (frame every n-th result)
    default to the shortest that work."""
    from ...hdl.engine.register_map import TELEMETRY_DIV_ADDR
    from ...hdl.link.frame_types import AttitudeFrame, frame_bytes
    from ...hdl.board.top import rate_budget
    from ...reference.evaluate import engine_configs
    from ...reference.engine_model import attitude_fixed
    from ...reference.flagship_fixed import q30_to_float
    from ...reference.frames import body_to_mag
    from .attitude_bench import EngineRun, first_mismatch
    from .compiled_engine import configuration_writes
    from ...hdl.link.uart_tx import UARTTransmitter

    total = len(gyr_counts) if samples is None else min(samples, len(gyr_counts))
    if total < 1:
        raise ValueError("replay_board needs at least one sample")
    config = MPU9250Config.for_odr(REPLAY_ODR_HZ, gyro_fs_dps=gyro_fs_dps,
                                   accel_fs_g=accel_fs_g, self_test=False)
    # the sample period: the read and the update with a quarter to spare (the engine updates
    # while the next sample is read)
    budget = rate_budget(config, REPLAY_CLOCK_HZ, REPLAY_BAUD)
    if period_cycles is None:
        period_cycles = 1.25 * budget["cycles_per_sample"]
    odr_scale = period_cycles / REPLAY_CLOCK_HZ * config.output_data_rate
    # the driver's magnetometer time-out in the recording's time, as the AK8963's period is
    setup = _RecordingTime(clk_freq=REPLAY_CLOCK_HZ, config=config, odr_scale=odr_scale,
                           time_per_s=period_cycles / REPLAY_CLOCK_HZ / dt)
    # a frame on the wire: each byte ten bits and the cycle the UART takes the next one
    divisor = UARTTransmitter.divisor_for(REPLAY_CLOCK_HZ, REPLAY_BAUD)
    frame_cycles = frame_bytes(AttitudeFrame) * (10 * divisor + 1)
    if divider is None:
        # 15 % to spare: the first frames start later against their samples than the rest
        # (the first update after a reset is the longest), and a due result that finds the
        # framer still busy is not framed (the 5 % it had was too little once the SPI burst
        # lost its pauses, and the sample period with it)
        divider = math.ceil(frame_cycles * 1.15 / period_cycles)

    gyr = np.asarray(gyr_counts)[:total]
    acc = np.asarray(acc_counts)[:total]
    mag_ak = body_to_mag(np.asarray(mag_counts)[:total])
    model, first = _recording_model(setup, gyr, acc, mag_ak, period_cycles / REPLAY_CLOCK_HZ,
                                    dt)

    # the flagship's magnetometer gains for the AK8963's period, as the board sets them
    # (``attitude_engine.default_flagship_config``)
    units_and_params.setdefault("mag_dt", mag_period(dt))
    configs = engine_configs(filter, dt, **units_and_params)
    writes = configuration_writes(filter, configs=configs) + [
        (TELEMETRY_DIV_ADDR, divider)]
    # samples made during bring-up are never read: the run ends once the model made the
    # recording's last sample and the periods a frame takes after it (its result is out and
    # a frame of it on the wire by then), within a budget of every sample's period and
    # bring-up
    tail = 2 + math.ceil(frame_cycles / period_cycles)
    run = run_core(setup, baud=REPLAY_BAUD, model=model, writes=writes, compiled=compiled,
                   progress=progress,
                   until=lambda: len(model.samples) > first.get("read", 10 ** 9) + total + tail,
                   max_cycles=int(setup.bring_up_budget_cycles() + 40_000 +
                                  (total + tail + 3) * period_cycles * 1.5))
    offset = first.get("read", 0)
    # the reference: the fixed-point model over the samples the engine was given (the
    # driver's flags with them: a field it judged old or stale is not valid), which are the
    # model's own (``SensorSample``s and AK8963 bytes: checked per frame below)
    n = sum(1 for i in model.sample_reads[:len(run.samples)] if i - offset < total)
    n = min(n, len(run.results))
    given = run.samples[:n]
    ref = attitude_fixed([s["gyro"] for s in given], [s["accel"] for s in given],
                         [s["mag"] for s in given],
                         [s["flags"]["mag_valid"] for s in given], asa=run.asa,
                         configs=configs, select=filter,
                         skipped=[s["skipped"] for s in given])
    frames = [f for f in run.frames if f["sample"]["counter"] < n]
    sent = [f["sample"]["counter"] for f in frames]
    got = EngineRun.from_results([{**f["attitude"], "counter": f["sample"]["counter"]}
                                  for f in frames])
    mismatch = first_mismatch(got, ref.take(sent)) if frames else "no frame"
    # the frames' samples are what the model made (the bus and the driver changed nothing)
    reads = [model.samples[k] for k in model.sample_reads[:n]]
    wrong = next((k for k in sent if not sample_matches(frames[sent.index(k)]["sample"],
                                                         reads[k])), None)
    if mismatch is None and wrong is not None:
        mismatch = f"sample {wrong}: the frame's sample is not the one the model made"
    every = EngineRun.from_results(run.results[:n])
    all_mismatch = first_mismatch(every, ref)
    # against ``replay --engine fixed`` (the field valid at every sample): the frames equal
    # to it; they differ only after a field the driver did not take as new (the same bytes
    # as the read before, both with ST1.DRDY: a read again, by its rule)
    plain = attitude_fixed(gyr[:n], acc[:n], mag_ak[:n], None, asa=run.asa,
                           configs=configs, select=filter)
    as_fixed = sum(np.array_equal(q, plain.quat[k]) for q, k in
                   zip(got.quat, [model.sample_reads[c] - offset for c in sent]))
    not_new = sum(1 for s in given if not s["flags"]["mag_valid"])
    quat = q30_to_float(np.array([f["attitude"]["quat"] for f in frames], dtype=np.int64)
                        .reshape(-1, 4))
    return BoardReplay(indices=np.array([model.sample_reads[k] - offset for k in sent],
                                        dtype=int),
                       quat=quat, bit_exact=mismatch is None, first_mismatch=mismatch,
                       results_bit_exact=all_mismatch is None,
                       frames_as_engine_fixed=int(as_fixed), mag_not_valid=not_new,
                       samples_read=n,
                       frames=len(frames), divider=divider, cycles=run.cycles,
                       wall_s=run.wall_s, compiled=run.compiled, counters=run.counters)
