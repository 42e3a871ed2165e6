"""SampleReader against a register-port model: decoding, the burst checks, magnetometer
freshness (DRDY after a read without it, or new bytes), restarts and the stale time-out."""

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.sample_reader import (BAD_BURST_LIMIT, MPU_BYTES, SAMPLE_BYTES,
                                                   SampleReader)
from mpu9250_ahrs.hdl.sensor.sample_store import (OFFER_WRITES, SAMPLE_STORE_DEPTH, SLOT_WORDS,
                                                  STORE_WORDS)
from mpu9250_ahrs.sim.bench.streams import check_stream_rules

from .register_port_model import RegisterPortModel


PERIOD = 300


def burst(k, *, int_status=0x01, drdy=1, field=(100, -200, 300), data=None):
    """INT_STATUS, accel/temp/gyro (big-endian, distinct per k), ST1, HX..HZ (little-endian),
    ST2 (BITM)."""
    values = data if data is not None else [k * 10 + i for i in range(7)]
    mpu = b"".join((v & 0xFFFF).to_bytes(2, "big") for v in values) if data is None else data
    ak = bytes([drdy]) + b"".join((v & 0xFFFF).to_bytes(2, "little") for v in field) + b"\x10"
    return bytes([int_status]) + mpu + ak


def run(bursts, *, mag_ok=1, extra_periods=0, gyro_jump=None, wiring="spi", early=None):
    """One data-ready edge per entry of ``bursts`` (None: no edge that period), a period apart;
    returns the samples taken and, per period, the status and pulses seen. ``early`` (a
    list): gets, per rise of ``imu_ready``, (payload, ``sample_slot``, the burst's bytes the
    port model still has to send then)."""
    # the INT here is a pulse (high for half a period), not latched
    dut = SampleReader(wiring=wiring, int_latched=False, gyro_jump=gyro_jump,
                       period_cycles=PERIOD,
                       first_timeout_cycles=4 * PERIOD,
                       timeout_cycles=4 * PERIOD, mag_timeout_periods=3)
    queue = []
    model = RegisterPortModel(dut.port, lambda device, reg, length: queue.pop(0))
    samples, log = [], []
    rising = [0]

    async def testbench(ctx):
        ctx.set(dut.enable, 1)
        ctx.set(dut.mag_ok, mag_ok)
        ctx.set(dut.samples.ready, 1)
        ctx.set(dut.start, 1)
        await model.cycle(ctx)
        ctx.set(dut.start, 0)
        for b in list(bursts) + [None] * extra_periods:
            pulses = {"restart": 0, "mag_lost": 0}
            if b is not None:
                # I2C: the MPU9250's bytes, then the AK8963's, in a read each (none while
                # the magnetometer is down)
                queue.extend([b] if wiring == "spi" else
                             [b[:MPU_BYTES]] + [b[MPU_BYTES:]] * mag_ok)
                ctx.set(dut.int_pin, 1)
            for c in range(PERIOD):
                if c == PERIOD // 2:
                    ctx.set(dut.int_pin, 0)
                await model.cycle(ctx)
                for name in pulses:
                    pulses[name] |= ctx.get(getattr(dut, name))
                if ctx.get(dut.samples.valid):
                    samples.append(ctx.get(dut.samples.payload))
                if early is not None and ctx.get(dut.imu_ready) and not rising[0]:
                    early.append((ctx.get(dut.samples.payload), ctx.get(dut.sample_slot),
                                  len(model._queue)))
                    assert not ctx.get(dut.samples.valid)
                rising[0] = ctx.get(dut.imu_ready)
            log.append({"bad_burst": ctx.get(dut.bad_burst), "mag_stale": ctx.get(dut.mag_stale),
                        "int_timeout": ctx.get(dut.int_timeout), **pulses})
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.samples, "samples")
    check_stream_rules(sim, dut.port.cmd, "commands")
    stored = check_store(sim, dut)
    sim.add_testbench(testbench)
    sim.run()
    assert stored == [s.counter for s in samples]
    return samples, log


def check_store(sim, dut):
    """A model of the sample store fed by the reader's writes (byte lanes): once each offered
    sample's writes after the offer are in (four cycles from its ``valid``), its slot holds
    the payload (``hdl/sensor/sample_store.py``); a burst's bytes never go to the slot of the last
    sample offered (the engine may hold it). Returns the counters of the samples checked."""
    ram = [0] * SAMPLE_STORE_DEPTH
    checked = []

    async def process(ctx):
        held, since, due = None, 99, []     # due: (cycles to go, slot, payload bits, counter)
        async for _, _, en, addr, value, valid, slot, payload in ctx.tick().sample(
                dut.store.w_en, dut.store.w_addr, dut.store.w_data, dut.samples.valid,
                dut.sample_slot, dut.samples.payload):
            since += 1
            for lane in range(4):
                if en >> lane & 1:
                    mask = 0xFF << 8 * lane
                    ram[addr] = ram[addr] & ~mask | value & mask
            if en and since >= OFFER_WRITES:    # a burst's byte, not a write after an offer
                assert addr // SLOT_WORDS != held
            for go, s, bits, counter in due:
                if go == 0:
                    words = [bits >> 32 * k & 0xFFFF_FFFF for k in range(STORE_WORDS)]
                    assert ram[SLOT_WORDS * s:SLOT_WORDS * s + STORE_WORDS] == words
                    checked.append(counter)
            due = [(go - 1, s, b, c) for go, s, b, c in due if go > 0]
            if valid and (not checked and not due or
                          payload.counter != (due[-1][3] if due else checked[-1])):
                due.append((OFFER_WRITES - 1, slot, payload.as_value().value, payload.counter))
                held, since = slot, 0
    sim.add_process(process)
    return checked


def test_decoding_and_magnetometer_freshness():
    f1, f2 = (100, -200, 300), (101, -200, 300)
    samples, log = run([burst(0, field=f1), burst(1, field=f1), burst(2, drdy=0, field=f1),
                        burst(3, field=f1), burst(4, field=f2), burst(5, field=f2)])
    assert [s.counter for s in samples] == list(range(6))
    assert [list(s.accel) for s in samples[:2]] == [[0, 1, 2], [10, 11, 12]]
    assert samples[1].temp == 13 and list(samples[1].gyro) == [14, 15, 16]
    # DRDY with new bytes: new; DRDY again, same bytes: an old measurement read again; DRDY
    # after a read without it: new even with the same bytes
    assert [s.flags.mag_new for s in samples] == [1, 0, 0, 1, 1, 0]
    assert [s.flags.mag_valid for s in samples] == [1, 0, 0, 1, 1, 0]
    assert list(samples[4].mag) == list(f2)
    assert not any(entry["bad_burst"] or entry["restart"] for entry in log)


@pytest.mark.parametrize("wiring", ["spi", "i2c"])
def test_early_start_offers_the_gyro_and_accelerometer_first(wiring):
    """The early start (SPI): ``imu_ready`` rises once the fifteenth byte is in, with every
    field of the payload but the magnetometer's already the sample's and ``sample_slot`` its
    slot, before ``valid``; a burst that fails its checks gives none. I2C: never."""
    f = [(100 + k, -200, 300) for k in range(4)]
    bad = burst(2, data=b"\xff" * 14)
    early = []
    samples, _ = run([burst(0, field=f[0]), burst(1, field=f[1]), bad, burst(3, field=f[3])],
                     wiring=wiring, early=early)
    assert [s.counter for s in samples] == [0, 1, 3]
    if wiring == "i2c":
        assert early == []
        return
    assert len(early) == 3
    for (payload, slot, pending), sample in zip(early, samples):
        # a byte a cycle here: the AK8963's still coming
        assert 0 < pending < SAMPLE_BYTES - MPU_BYTES
        for name in ("counter", "skipped", "temp"):
            assert getattr(payload, name) == getattr(sample, name)
        assert list(payload.accel) == list(sample.accel)
        assert list(payload.gyro) == list(sample.gyro)
        for flag in ("data_ready", "overrun", "resumed"):
            assert getattr(payload.flags, flag) == getattr(sample.flags, flag)
    assert [slot for _, slot, _ in early] == [0, 1, 2]
    assert [list(s.mag) for s in samples] == [list(f[0]), list(f[1]), list(f[3])]


def test_bad_bursts_are_dropped_counted_and_restart():
    good = [burst(k) for k in range(2)]
    # a line stuck low (all zeros), stuck high (data all ones), INT_STATUS 0xFF
    bad = [burst(2, int_status=0x00, data=bytes(14)), burst(3, data=b"\xff" * 14),
           burst(4, int_status=0xFF)]
    samples, log = run(good + bad[:1] + [burst(5)] + bad + [burst(9, int_status=0)])
    # one bad burst: no sample, flagged, counted in the next sample's skipped (the sample
    # was made: the line lost it)
    assert [s.counter for s in samples] == [0, 1, 3]
    assert samples[2].skipped == 1
    assert [e["bad_burst"] for e in log[:4]] == [0, 0, 1, 0]
    # BAD_BURST_LIMIT in a row: a restart asked for
    assert BAD_BURST_LIMIT == 4
    assert [e["restart"] for e in log] == [0] * 7 + [1]


def test_magnetometer_time_out_and_no_data_ready():
    samples, log = run([burst(0, field=(1, 2, 3))] + [burst(k, drdy=0) for k in range(1, 6)],
                       extra_periods=5)
    lost = [e["mag_lost"] for e in log]
    # three sample-period ticks (mid-period) without a new field: stale, and the set-up asked
    # for, again every three periods
    assert lost[:6] == [0, 0, 1, 0, 0, 1] and log[2]["mag_stale"] == 1
    # no data-ready edge for four periods: a time-out and a restart asked for
    assert any(e["restart"] and e["int_timeout"] for e in log[6:])



def test_gyro_jump_on_each_axis():
    """A gyro word 2**14 or more above, or more than 2**14 below, the last sample passed on
    fails the burst, on any axis (``gyro_jumps``, the reference's rule); the edges pass; the
    base is the last sample passed on."""
    import numpy as np
    from mpu9250_ahrs.hdl.sensor.sample_reader import gyro_jumps

    def gyro(x, y, z):
        return burst(0, data=b"".join((v & 0xFFFF).to_bytes(2, "big")
                                      for v in (1, 2, 3, 4, x, y, z)))
    triples = [(-100, 200, 300),
               (-100 + 16384, 200, 300), (-100, 200 - 16385, 300), (-100, 200, 300 - 16385),
               (-100, 200, 300 + 16383), (-100, 200, 300 + 16383 + 16384),
               (-100 - 16384, 200, 300 + 16383), (-100 - 16384, 200 - 16384, 300 + 16383)]
    samples, log = run([gyro(*t) for t in triples], gyro_jump=16384)
    passed = [list(s.gyro) for s in samples]
    assert passed == [[-100, 200, 300], [-100, 200, 16683], [-16484, 200, 16683],
                      [-16484, -16184, 16683]]
    assert [e["bad_burst"] for e in log] == [0, 1, 1, 1, 0, 1, 0, 0]
    # the reference's rule gives the same verdicts from the same bases
    bases = [triples[0]] * 4 + [triples[4]] * 2 + [triples[6]] * 2
    assert list(gyro_jumps(np.array(bases[1:]), np.array(triples[1:]), 16384)) == \
        [bool(e["bad_burst"]) for e in log[1:]]


@pytest.mark.parametrize("wiring", ["spi", "i2c"])
def test_store_field_is_zero_while_the_magnetometer_is_down(wiring):
    """With the magnetometer not up, the payload's field is 0 and so is the store's (the reader
    writes zeros over the bytes the burst brought, or, I2C, left from an older burst, as it does
    not read the AK8963 then; ``check_store`` compares every sample). Up again, the field is
    stored."""
    bursts = [burst(k, field=(1000 + k, -2000, 3000)) for k in range(3)]
    samples, _ = run(bursts, mag_ok=0, wiring=wiring)
    assert len(samples) == 3 and all(list(s.mag) == [0, 0, 0] for s in samples)
    assert not any(s.flags.mag_new for s in samples)
    samples, _ = run(bursts, wiring=wiring)
    assert [list(s.mag) for s in samples] == [[1000 + k, -2000, 3000] for k in range(3)]


def test_reads_failing_back_to_back_are_each_counted():
    """I2C: reads of the MPU9250 that fail on the bus are checked (and counted) one after the
    other, each retried at once while INT is still high; the sample that finally comes counts
    them all (its ``counter`` is the checks before it), however close together they came (the
    count's update, a nibble a cycle, holds the next read back until it is done)."""
    dut = SampleReader(wiring="i2c", int_latched=False, period_cycles=PERIOD,
                       first_timeout_cycles=4 * PERIOD, timeout_cycles=4 * PERIOD,
                       mag_timeout_periods=3)
    good = burst(0)
    failing = BAD_BURST_LIMIT - 1           # one more would ask for a restart
    queue = [None] * failing + [good[:MPU_BYTES], good[MPU_BYTES:]]
    model = RegisterPortModel(dut.port, lambda device, reg, length: queue.pop(0))
    samples, starts = [], []

    async def testbench(ctx):
        ctx.set(dut.enable, 1)
        ctx.set(dut.mag_ok, 1)
        ctx.set(dut.samples.ready, 1)
        ctx.set(dut.start, 1)
        await model.cycle(ctx)
        ctx.set(dut.start, 0)
        ctx.set(dut.int_pin, 1)
        for c in range(PERIOD):
            reads = len(model.reads)
            await model.cycle(ctx)
            if len(model.reads) > reads:
                starts.append(c)
            if ctx.get(dut.samples.valid):
                samples.append(ctx.get(dut.samples.payload))
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.samples, "samples")
    sim.add_testbench(testbench)
    sim.run()
    assert len(samples) == 1 and samples[0].counter == failing
    assert samples[0].flags.mag_new and list(samples[0].mag) == [100, -200, 300]
    # the failed reads came as fast as the count lets them: ten cycles from a check to the
    # next read, two more for the read to fail
    gaps = [b - a for a, b in zip(starts, starts[1:failing + 1])]
    assert len(starts) == failing + 2 and gaps == [12] * failing, starts
