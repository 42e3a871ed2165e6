"""The reader's hand-over (``SampleOffer``) on its own: a burst's bytes into the payload and the
store's slot, the early start's offer before the field, a sample dropped while the last is
offered (overrun, skipped), a lost one counted, a field not read written as zeros."""

from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.sample_offer import MPU_BYTES, SAMPLE_BYTES, SampleOffer
from mpu9250_ahrs.sim.bench.streams import check_stream_rules

from .test_sample_reader import check_store, burst


def run(script):
    """Runs ``script``, a list of steps, against a ``SampleOffer``: ("burst", bytes, early)
    sends a burst's bytes a cycle each while ``reading`` (pulsing ``early`` after the fifteenth
    if ``early``), ("offer", mag_up, mag_new), ("lost",), ("restarted",), ("take",): ``ready``
    for a cycle, ("wait", n). Returns the samples taken, and, per ``imu_ready`` rise, (payload,
    slot)."""
    dut = SampleOffer()
    taken, early_seen = [], []

    async def bench(ctx):
        counter, was_ready = 0, [0]

        async def cycle():
            await ctx.tick()
            if ctx.get(dut.imu_ready) and not was_ready[0]:
                assert not ctx.get(dut.samples.valid)
                early_seen.append((ctx.get(dut.samples.payload), ctx.get(dut.sample_slot)))
            was_ready[0] = ctx.get(dut.imu_ready)
            ctx.set(dut.samples.ready, 0)

        for step in script:
            kind = step[0]
            if kind == "burst":
                _, data, early = step
                ctx.set(dut.burst, int.from_bytes(data, "little"))
                ctx.set(dut.reading, 1)
                ctx.set(dut.counter, counter)
                counter += 1
                for k, byte in enumerate(data):
                    ctx.set(dut.arriving, 1)
                    ctx.set(dut.index, k)
                    ctx.set(dut.data, byte)
                    await cycle()
                    ctx.set(dut.arriving, 0)
                    if k == MPU_BYTES - 1 and early:
                        ctx.set(dut.early, 1)
                        await cycle()
                        ctx.set(dut.early, 0)
                ctx.set(dut.index, SAMPLE_BYTES)
                ctx.set(dut.reading, 0)
            elif kind == "offer":
                ctx.set(dut.offer, 1)
                ctx.set(dut.mag_up, step[1])
                ctx.set(dut.mag_new, step[2])
                await cycle()
                ctx.set(dut.offer, 0)
                for _ in range(6):          # the writes after the offer
                    await cycle()
            elif kind in ("lost", "restarted"):
                ctx.set(getattr(dut, kind), 1)
                await cycle()
                ctx.set(getattr(dut, kind), 0)
            elif kind == "take":
                assert ctx.get(dut.samples.valid)
                taken.append(ctx.get(dut.samples.payload))
                ctx.set(dut.samples.ready, 1)
                await cycle()
            elif kind == "wait":
                for _ in range(step[1]):
                    await cycle()

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.samples, "samples")
    stored = check_store(sim, dut)
    sim.add_testbench(bench)
    sim.run()
    assert stored == [s.counter for s in taken]
    return taken, early_seen


def test_a_burst_becomes_the_sample_and_its_slot():
    taken, early = run([("burst", burst(0, field=(7, -8, 9)), False), ("offer", 1, 1),
                        ("take",), ("burst", burst(1, field=(7, -8, 9)), False),
                        ("offer", 1, 0), ("take",)])
    assert early == []
    assert [list(s.accel) for s in taken] == [[0, 1, 2], [10, 11, 12]]
    assert taken[1].temp == 13 and list(taken[1].gyro) == [14, 15, 16]
    assert [list(s.mag) for s in taken] == [[7, -8, 9]] * 2
    assert [(s.flags.mag_new, s.flags.mag_valid) for s in taken] == [(1, 1), (0, 0)]
    assert [s.counter for s in taken] == [0, 1] and not any(s.skipped for s in taken)


def test_early_start_then_the_field():
    """``early`` puts every field but the magnetometer's in the payload and raises
    ``imu_ready`` with the slot being written; the offer adds the field and ``valid``."""
    taken, early = run([("burst", burst(0), True), ("offer", 1, 1), ("take",),
                        ("burst", burst(1), True), ("offer", 1, 1), ("take",)])
    assert [slot for _, slot in early] == [0, 1]
    for (payload, _), sample in zip(early, taken):
        assert list(payload.gyro) == list(sample.gyro)
        assert list(payload.accel) == list(sample.accel)
        assert payload.counter == sample.counter
    assert [list(s.mag) for s in taken] == [[100, -200, 300]] * 2


def test_a_sample_offered_while_the_last_waits_is_dropped():
    """No ready: the second burst's offer is dropped; the third sample carries ``overrun``
    and counts it (and a lost one) in ``skipped``; ``early`` while a sample is offered gives
    no early start."""
    taken, early = run([("burst", burst(0), False), ("offer", 1, 1),
                        ("burst", burst(1), True), ("offer", 1, 1), ("take",),
                        ("lost",), ("burst", burst(2), False), ("offer", 1, 1), ("take",)])
    assert early == []
    assert [s.counter for s in taken] == [0, 2]
    assert taken[1].flags.overrun and taken[1].skipped == 2


def test_resumed_and_a_field_not_read():
    """After ``restarted`` the next sample is ``resumed`` with ``skipped`` 0; a field not read
    (``mag_up`` 0) is 0 in the payload and, written as zeros, in the store (``check_store``)."""
    taken, _ = run([("burst", burst(0), False), ("offer", 1, 1), ("take",), ("lost",),
                    ("restarted",), ("burst", burst(1), True), ("offer", 0, 0), ("take",)])
    assert taken[1].flags.resumed and taken[1].skipped == 0
    assert list(taken[1].mag) == [0, 0, 0] and not taken[1].flags.mag_new
