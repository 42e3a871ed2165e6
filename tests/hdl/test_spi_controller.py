"""SPI controller against a small mode-3 device model, at several divisors and burst lengths."""

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.spi_controller import SYNC_STAGES, SPIController, SPITiming
from mpu9250_ahrs.sim.bench.streams import check_stream_rules, stream_put


def response_byte(index):
    return (0x5A + 37 * index) & 0xFF


def run(timing, transactions, *, consumer_stall=0, vcd=None):
    """Send ``transactions`` (list of (bytes, fast)); return what the device and the controller
    received and the pin events the device saw as (cycle, name, value)."""
    dut = SPIController(timing)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.o_stream, "received bytes")
    dev = {"rx": [], "events": [], "byte_in": 0, "bits": 0, "sent": 0, "done": False}
    got = []
    total = sum(len(b) for b, _ in transactions)

    async def device(ctx):
        # A mode-3 device with a one-cycle output delay: it samples the pins as flip-flops do,
        # changes CIPO after a falling edge and latches COPI on a rising edge.
        cycle = 0
        prev_cs, prev_sclk = 1, 1
        out = 0
        async for _, _, cs_n, sclk, copi in ctx.tick().sample(dut.pins.cs_n, dut.pins.sclk,
                                                               dut.pins.copi):
            cycle += 1
            if cs_n != prev_cs:
                dev["events"].append((cycle, "cs_n", cs_n))
                if not cs_n:
                    dev["bits"] = 0
            if sclk != prev_sclk:
                dev["events"].append((cycle, "sclk", sclk))
                if not cs_n and not sclk:
                    if dev["bits"] % 8 == 0:
                        out = response_byte(dev["sent"])
                        dev["sent"] += 1
                    ctx.set(dut.pins.cipo, (out >> (7 - dev["bits"] % 8)) & 1)
                elif not cs_n and sclk:
                    dev["byte_in"] = ((dev["byte_in"] << 1) | copi) & 0xFF
                    dev["bits"] += 1
                    if dev["bits"] % 8 == 0:
                        dev["rx"].append(dev["byte_in"])
            if cs_n and sclk == 0:
                dev["events"].append((cycle, "error", "SCLK low while CS is high"))
            prev_cs, prev_sclk = cs_n, sclk

    async def producer(ctx):
        for data, fast in transactions:
            for i, byte in enumerate(data):
                await stream_put(ctx, dut.i_stream, {"data": byte, "fast": fast,
                                                     "last": i == len(data) - 1})

    async def consumer(ctx):
        # Ready for one cycle after every ``consumer_stall`` cycles (always, if 0).
        ctx.set(dut.o_stream.ready, 1)
        while len(got) < total:
            if consumer_stall:
                ctx.set(dut.o_stream.ready, 0)
                await ctx.tick().repeat(consumer_stall)
                ctx.set(dut.o_stream.ready, 1)
            await ctx.tick()
        await ctx.tick().until(dut.pins.cs_n)       # let CS rise and the gap pass
        await ctx.tick().repeat(timing.cs_gap + 4)

    async def collector(ctx):
        async for _, _, valid, ready, payload in ctx.tick().sample(
                dut.o_stream.valid, dut.o_stream.ready, dut.o_stream.payload):
            if valid and ready:
                got.append(payload)

    sim.add_process(device)
    sim.add_process(collector)
    sim.add_testbench(producer)
    sim.add_testbench(consumer)
    if vcd:
        with sim.write_vcd(vcd, vcd.replace(".vcd", ".gtkw"),
                           traces=[dut.pins.cs_n, dut.pins.sclk, dut.pins.copi, dut.pins.cipo]):
            sim.run()
    else:
        sim.run()
    return dev, got


def levels(events):
    """Durations in cycles of each SCLK level inside transactions, and CS framing figures."""
    out = {"low": [], "high": [], "setup": [], "hold": [], "gap": []}
    last_sclk = last_cs = None
    prev_cs_rise = None
    for cycle, name, value in events:
        if name == "error":
            raise AssertionError(value)
        if name == "cs_n" and value == 0:
            if prev_cs_rise is not None:
                out["gap"].append(cycle - prev_cs_rise)
            last_cs, last_sclk = cycle, None
        elif name == "cs_n" and value == 1:
            out["hold"].append(cycle - last_sclk[0])
            prev_cs_rise = cycle
        elif name == "sclk":
            if last_sclk is None:
                out["setup"].append(cycle - last_cs)
            else:
                out["high" if value == 0 else "low"].append(cycle - last_sclk[0])
            last_sclk = (cycle, value)
    return out


TIMINGS = [
    SPITiming(slow_half=3, fast_half=1, cs_hold=2, cs_gap=3),
    SPITiming(slow_half=6, fast_half=2, cs_hold=6, cs_gap=6),
    SPITiming(slow_half=5, fast_half=3, cs_hold=1, cs_gap=1, fast_high=2),   # an odd period
    SPITiming(slow_half=7, fast_half=4, cs_hold=9, cs_gap=2, cipo_delay=1),
]


@pytest.mark.parametrize("timing", TIMINGS, ids=lambda t: f"slow{t.slow_half}_fast{t.fast_half}_{t.fast_high}")
@pytest.mark.parametrize("length", [1, 2, 16])
def test_transfers(timing, length, vcd):
    transactions = [(bytes((0xA5 ^ (i * 29)) & 0xFF for i in range(length)), fast)
                    for fast in (0, 1)]
    dev, got = run(timing, transactions, vcd=vcd())
    sent = [b for data, _ in transactions for b in data]
    assert dev["rx"] == sent
    assert got == [response_byte(i) for i in range(len(sent))]

    lv = levels(dev["events"])
    # SCLK levels: exactly the rate's inside a byte; a high level between bytes may be longer.
    assert set(lv["low"]) <= {timing.slow_half, timing.fast_half}
    assert min(lv["high"]) in {timing.slow_half, timing.fast_high}
    assert lv["setup"] == [timing.slow_half, timing.fast_half]
    assert min(lv["hold"]) >= timing.cs_hold
    assert min(lv["gap"]) >= timing.cs_gap


@pytest.mark.parametrize("timing", TIMINGS, ids=lambda t: f"slow{t.slow_half}_fast{t.fast_half}_{t.fast_high}")
def test_a_burst_clocks_without_a_pause(timing):
    """Bytes offered in time and results taken at once: SCLK keeps its rhythm across the
    bytes of a transaction (every level the rate's), so a burst takes 8 periods a byte."""
    dev, got = run(timing, [(bytes(range(1, 17)), 1), (bytes(range(1, 5)), 0)])
    assert got == [response_byte(i) for i in range(20)]
    lv = levels(dev["events"])
    assert set(lv["low"]) == {timing.fast_half, timing.slow_half}
    assert set(lv["high"]) == {timing.fast_high, timing.slow_half}
    assert lv["high"].count(timing.fast_high) == 16 * 8 - 1


@pytest.mark.parametrize("timing", TIMINGS[:2], ids=lambda t: f"slow{t.slow_half}")
def test_consumer_backpressure(timing):
    transactions = [(bytes(range(1, 9)), 1)]
    dev, got = run(timing, transactions, consumer_stall=40)
    assert dev["rx"] == list(range(1, 9))
    assert got == [response_byte(i) for i in range(8)]


@pytest.mark.parametrize("clk_freq", [12e6, 25e6, 50e6, 100e6])
def test_timing_for_clock_meets_datasheet(clk_freq):
    t = SPITiming.for_clock(clk_freq)
    assert t.sclk_hz(clk_freq, fast=False) <= 1e6 + 1e-6
    assert t.slow_half / clk_freq >= 400e-9              # SCLK high/low at the slow rate
    assert t.sclk_hz(clk_freq, fast=True) <= 20e6 + 1e-6
    assert t.cs_hold / clk_freq >= 500e-9 - 1e-12
    assert t.fast_half >= 2 and t.fast_high >= 2


def test_timing_rejects_zero():
    with pytest.raises(ValueError, match="fast_half"):
        SPITiming(slow_half=2, fast_half=0, cs_hold=1, cs_gap=1)


def test_the_sample_point_leaves_the_io_budget_its_margin():
    """Issue #23: at the default 48 MHz the round trip of a CIPO bit (``IOBudget``: SDO's
    100 ns, the FPGA's output and input, the board both ways: 114 ns) leaves at least 10 ns
    before the sampling edge (125 ns); the fast SCLK is 48/7 MHz for it (a period of 7 cycles,
    low 4 and high 3, with the sample 2 cycles into the high level; 8 MHz left 4 ns)."""
    from mpu9250_ahrs.hdl.sensor.spi_controller import IO_BUDGET
    timing = SPITiming.for_clock(48e6)
    assert IO_BUDGET.arrival_ns == 114
    assert timing.setup_margin_ns(48e6) >= IO_BUDGET.margin_ns == 10
    for clk in (12e6, 25e6, 50e6, 100e6):
        assert SPITiming.for_clock(clk).setup_margin_ns(clk) >= 10


# the whole budget (114 ns) reads right; a bit later than the sampling edge (125 ns) does not
@pytest.mark.parametrize("sdo_ns,board_ns,reads_right", [(5, 0, True), (100, 14, True),
                                                         (100, 26, False)])
def test_cipo_sampling_point_against_the_output_delay(sdo_ns, board_ns, reads_right):
    """Co-simulation at the default 48 MHz, the model driving each SDO bit its part's delay
    (the fastest part's 5 ns, the datasheet's 100 ns) plus the round trip outside it (the
    FPGA's output and input and the board's, ``board_delay_s``: the cycle model has none of
    its own) after the falling edge: up to the I/O budget's 114 ns the fast sample burst
    reads right; beyond the sampling edge (126 ns: the bit arrives after the edge at 125 ns)
    it does not, so the sampling point is where the timing analysis says."""
    from dataclasses import replace
    from mpu9250_ahrs.hdl.primitives.clocking import SYSTEM_CLOCK_HZ
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    from mpu9250_ahrs.sim.scenarios.setup import SimSetup
    from mpu9250_ahrs.sim.scenarios.frontend import run_frontend, sample_matches
    from mpu9250_ahrs.sim.models.mpu9250_model import MPU9250Model
    from mpu9250_ahrs.sim.models.sources import counting_source
    # the safe rate's sampling edge: the read levelling off (it would train on these parts)
    setup = SimSetup(config=MPU9250Config(magnetometer=False), odr_scale=0.1, levelling=False)
    assert setup.clk_freq == SYSTEM_CLOCK_HZ
    timing = SPITiming.for_clock(setup.clk_freq)
    assert timing.sample_window(fast=True) == (6, 6) and timing.sclk_hz(48e6, True) == 48e6 / 7
    model = MPU9250Model(timing=replace(setup.model_timing(), sdo_delay_s=sdo_ns * 1e-9,
                                        board_delay_s=board_ns * 1e-9),
                         source=counting_source())
    # read wrongly, the bursts fail the driver's checks (bad_burst, then a restart) or, if one
    # passed them, carry the wrong values
    result = run_frontend(setup, n_samples=2, model=model,
                          until=None if reads_right else (lambda st: st["restarts"] >= 1))
    assert model.violations == []
    matches = [sample_matches(s, model.samples[k])
               for s, k in zip(result.samples, model.sample_reads)]
    if reads_right:
        assert len(matches) == 2 and all(matches)
    else:
        assert not any(matches) and result.status["bad_burst"]


def test_the_sample_burst_runs_without_a_pause():
    """Issue #23 (latency): at the default 48 MHz the whole sample burst (INT_STATUS to the
    AK8963's ST2, ``SAMPLE_BYTES`` + 1 bytes) is clocked without a pause between its bytes: CS
    low for the CS setup, 8 SCLK periods a byte, and the CS hold; and within
    ``sample_read_cycles``' bound, which ``build`` and ``report`` use for the rate check. At
    the trained rate (issue #58: the model's part trains) and at the safe rate."""
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    from mpu9250_ahrs.hdl.sensor.sample_reader import SAMPLE_BYTES
    from mpu9250_ahrs.hdl.sensor.sensor_frontend import sample_read_cycles as bound
    from mpu9250_ahrs.sim.scenarios.setup import SimSetup
    from mpu9250_ahrs.sim.scenarios.frontend import run_frontend, sample_read_cycles
    from mpu9250_ahrs.hdl.sensor.sensor_frontend import spi_timing_for
    for levelling in (True, False):
        setup = SimSetup(config=MPU9250Config(), odr_scale=0.1, levelling=levelling)
        t = spi_timing_for(setup.clk_freq, levelling)
        result = run_frontend(setup, n_samples=2)
        assert result.level["trained"] == levelling
        low, period = ((t.trained_low, t.trained_period()) if levelling else
                       (t.fast_half, t.period(fast=True)))
        gap_free = low + (SAMPLE_BYTES + 1) * 8 * period + t.cs_hold
        # CS rises a hold after the last bit is captured, which may come after the last high
        # level: trained, at its sample delay (``SPIController._capture``'s tap)
        late = (lambda tap, high: max(0, tap - high))
        later = (late(SYNC_STAGES - 1 + result.level["sample_delay"], t.trained_high) -
                 late(t.capture_delay - 1, t.fast_high)) if levelling else 0
        assert gap_free <= sample_read_cycles(result, setup) <= gap_free + 2 + later, levelling
        assert sample_read_cycles(result, setup) < bound(setup.config, setup.clk_freq)


@pytest.mark.slow
@pytest.mark.parametrize("board_ns", [0, 7, 14])
@pytest.mark.parametrize("sdo_ns", [5, 15, 50, 100, "noisy"])
def test_every_part_the_budget_allows_reads_right_trained_or_not(sdo_ns, board_ns):
    """Issue #58's sweep: parts from the fastest SDO delay the model gives (5 ns) to the
    datasheet's 100 ns, those between jittering ±2 ns, and a noisy one (65 ± 35 ns), on
    boards whose round trip outside the part is up to the I/O budget's (14 ns: the FPGA's
    output and input and the traces): every sample exact (compiled co-simulation), every part
    either trained (each but the noisy one) or left at the safe rate, and no fall back."""
    from dataclasses import replace
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    from mpu9250_ahrs.sim.scenarios.setup import SimSetup
    from mpu9250_ahrs.sim.scenarios.frontend import run_frontend, sample_matches
    from mpu9250_ahrs.sim.models.mpu9250_model import MPU9250Model
    from mpu9250_ahrs.sim.models.sources import counting_source
    setup = SimSetup(config=MPU9250Config(magnetometer=False), odr_scale=0.1)
    noisy = sdo_ns == "noisy"
    # ±2 ns, within the model's range (the fastest part and the datasheet's bound: none)
    jitter = 35e-9 if noisy else 2e-9 if 5 < sdo_ns < 100 else 0.0
    sdo_ns = 65 if noisy else sdo_ns
    model = MPU9250Model(timing=replace(setup.model_timing(), sdo_delay_s=sdo_ns * 1e-9,
                                        board_delay_s=board_ns * 1e-9, sdo_jitter_s=jitter),
                         source=counting_source(), sdo_seed=sdo_ns + board_ns)
    result = run_frontend(setup, n_samples=20, model=model, compiled=True)
    assert model.violations == [] and len(result.samples) == 20
    assert all(sample_matches(s, model.samples[k])
               for s, k in zip(result.samples, model.sample_reads))
    level = result.level
    assert level["scanned"] and level["trained"] != noisy and level["fallbacks"] == 0, level


PATTERN = [0x71, 0xA5, 0x3C, 0x96, 0x0F, 0xE1]      # varied bits: a shifted read differs


def _trained_scan(part_timing, clk_freq=48e6):
    """The SPI controller with a trained rate (``SPITiming.with_trained``) reading six known
    bytes from the MPU9250 model's sensor registers at every sample delay it offers: the
    delays that read them right (issue #58's eye, as a read levelling would scan it)."""
    from mpu9250_ahrs.hdl.contract import mpu9250_regs as R
    from mpu9250_ahrs.sim.models.mpu9250_model import MPU9250Model
    from mpu9250_ahrs.sim.bench.harness import CosimHarness, attach_mpu9250
    from mpu9250_ahrs.sim.bench.streams import stream_put
    timing = SPITiming.for_clock(clk_freq).with_trained(clk_freq)
    dut = SPIController(timing)
    model = MPU9250Model(timing=part_timing)
    model.regs[R.ACCEL_XOUT_H:R.ACCEL_XOUT_H + len(PATTERN)] = bytes(PATTERN)
    passing = []

    got = []

    async def collector(ctx):
        async for _, _, valid, payload in ctx.tick().sample(dut.o_stream.valid,
                                                           dut.o_stream.payload):
            if valid:                           # always ready: every valid cycle a transfer
                got.append(payload)

    async def bench(ctx):
        ctx.set(dut.o_stream.ready, 1)
        await ctx.tick().repeat(200)                    # past the model's start-up
        frame = [R.SPI_READ | R.ACCEL_XOUT_H] + [0] * len(PATTERN)
        for delay in range(timing.max_sample_delay + 1):
            ctx.set(dut.sample_delay, delay)
            got.clear()
            for i, byte in enumerate(frame):
                await stream_put(ctx, dut.i_stream, {"data": byte, "fast": 1, "trained": 1,
                                                     "last": i == len(frame) - 1})
            await ctx.tick().until(dut.pins.cs_n)
            await ctx.tick().repeat(timing.cs_gap + 4)
            assert len(got) == len(frame), (delay, got)
            if got[1:] == PATTERN:
                passing.append(delay)

    harness = CosimHarness(dut, spi=dut.pins)     # the model on the pins as in co-simulation
    sim = Simulator(harness)
    sim.add_clock(1 / clk_freq)
    attach_mpu9250(sim, model, harness, clk_freq)
    sim.add_process(collector)
    sim.add_testbench(bench)
    sim.run()
    assert model.violations == [], model.violations
    return timing, passing


@pytest.mark.parametrize("sdo_ns,board_ns,window", [(5, 0, (0, 2)), (15, 14, (0, 3)),
                                                    (50, 14, (2, 5)), (100, 14, (4, 7))])
def test_a_trained_read_finds_the_eye_where_the_round_trip_puts_it(sdo_ns, board_ns, window):
    """At 12 MHz (48 MHz / 4) the eye is an SCLK period wide wherever the part's delay and
    the board's put it: the passing sample delays are one run of a period's cycles, starting
    later the longer the round trip; a 100 ns part's too (beyond the safe rate's own sample
    point: the scan reaches a period past it). A part faster than a low level has its eye cut
    by the earliest delay (a rising edge's): three delays."""
    from mpu9250_ahrs.sim.models.mpu9250_model import MPU9250Timing
    part = MPU9250Timing(startup_s=1e-6, reset_s=1e-6, sdo_delay_s=sdo_ns * 1e-9,
                         board_delay_s=board_ns * 1e-9)
    timing, passing = _trained_scan(part)
    assert timing.trained_period() == 4 and timing.max_sample_delay == 9
    assert passing == list(range(window[0], window[1] + 1)), passing


def test_a_slow_noisy_part_leaves_no_eye_to_train_on():
    """A part at the datasheet's 100 ns whose edges spread ±35 ns: at 12 MHz no sample delay
    reads the bytes right every time (training must stay at the safe rate)."""
    from mpu9250_ahrs.sim.models.mpu9250_model import MPU9250Timing
    part = MPU9250Timing(startup_s=1e-6, reset_s=1e-6, sdo_delay_s=65e-9, sdo_jitter_s=35e-9,
                         board_delay_s=14e-9)
    _, passing = _trained_scan(part)
    assert len(passing) <= 1, passing
