"""The sample reader's hand-over: a burst's bytes into the sample offered (``samples``), into the
sample store's slot (``store``, ``sample_slot``), and, with the early start (issue #58), the
gyro and accelerometer before the magnetometer's bytes are in (``imu_ready``)."""

import operator
from functools import reduce

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..contract import ak8963_regs as A
from ..contract import mpu9250_regs as R
from .sample import Sample
from .sample_store import (FIELD_LANES, OFFER_WRITES, SENSOR_BITS, SLOT_WORDS, SLOTS, STORE_BITS,
                           STORE_WORDS, SampleStoreWriteSignature, store_places)


__all__ = ["SAMPLE_BYTES", "MPU_BYTES", "SampleOffer"]


SAMPLE_BYTES = 1 + R.SENSOR_BYTES + A.SAMPLE_BYTES   # INT_STATUS, accel/temp/gyro, ST1..ST2
MPU_BYTES = 1 + R.SENSOR_BYTES


class SampleOffer(wiring.Component):
    """Makes a burst that passed its checks the sample offered, and its slot of the store.

    The burst capture (``SampleReader``) judges the bytes; this block only places them: in the
    store as they arrive, in the payload at the offer (or, early, at the MPU9250's fifteenth
    byte), and the payload's other words in the store after the offer.

    Members
        ``burst`` (in, ``SAMPLE_BYTES`` bytes, the first in the low bits): the burst's bytes,
            INT_STATUS, the MPU9250's fourteen (big-endian words), ST1, HX..HZ
            (little-endian), ST2; each holds still from its arrival to the burst's end.
        ``arriving``, ``index``, ``data`` (in): a byte of the burst arrives this cycle, its
            place in the burst (0 .. ``SAMPLE_BYTES`` − 1) and its value: written into the
            slot being written, if it is a sensor byte (``store_places``).
        ``reading`` (in): a burst is in flight, before its check.
        ``early`` (in, pulse; at most once per burst): the burst's first ``MPU_BYTES`` are in
            and passed its checks. If no sample is offered, the payload takes every field but
            the magnetometer's (``mag`` and the ``mag_*`` flags), ``sample_slot`` the slot
            being written, and ``imu_ready`` rises, until the burst's end (``reading`` low).
        ``offer`` (in, pulse): the burst passed its checks. With no sample offered it becomes
            the sample (``valid``; its fields but the magnetometer's as at ``early`` if that
            took them), its slot ``sample_slot``, and the next slot is written; with one
            offered it is dropped (the next one carries ``flags.overrun`` and counts it in
            ``skipped``).
        ``mag_up`` (in, with ``offer``): the burst's field was read (the magnetometer is up
            and its read did not fail): else ``mag`` is 0, and so are its store words.
            ``mag_new`` (in, with ``offer``): the field is a new measurement (else the
            ``mag_*`` flags are 0).
        ``counter`` (in, 32 bits), ``skipped`` (in, 4 bits): the sample's count and the
            samples skipped before it (the data-ready timer's), taken with its fields.
        ``restarted`` (in, pulse): the next sample carries ``flags.resumed`` (and ``skipped``
            0). ``lost`` (in, pulse): a sample was made and lost (it failed its checks):
            counted in the next sample's ``skipped``.
        ``samples`` (out, stream of ``Sample``): valid never waits for ready.
        ``sample_slot`` (out): the store's slot of the sample offered (it changes only as a
            sample is offered or ``imu_ready`` rises, and holds while either is high).
        ``imu_ready`` (out): the early start's offer (above); it falls as the burst ends, the
            cycle ``valid`` rises.
        ``store`` (out, ``SampleStoreWriteSignature``): the sensor bytes as they arrive, then,
            in the cycles after ``valid`` rose (two, four if ``mag_up`` was 0), the payload's
            other words and zeros over the field: the slot holds the payload from the fifth
            cycle of ``valid``.

    Latency: ``valid`` and ``imu_ready`` the cycle after ``offer`` and ``early``. Throughput: a
    sample per ``offer``; the store's words after an offer take four cycles, and a burst's
    first byte must not come within them (the reader's next command and bus transfer take
    sixteen cycles at the least).
    """

    def __init__(self):
        super().__init__({
            "burst": In(8 * SAMPLE_BYTES),
            "arriving": In(1), "index": In(range(SAMPLE_BYTES + 1)), "data": In(8),
            "reading": In(1), "early": In(1), "offer": In(1),
            "mag_up": In(1), "mag_new": In(1),
            "counter": In(32), "skipped": In(4), "restarted": In(1), "lost": In(1),
            "samples": Out(stream.Signature(Sample)),
            "sample_slot": Out(range(SLOTS), init=SLOTS - 1),
            "imu_ready": Out(1),
            "store": Out(SampleStoreWriteSignature()),
        })

    def elaborate(self, platform):
        m = Module()
        buf = [self.burst[8 * k:8 * k + 8] for k in range(SAMPLE_BYTES)]
        # the sample offered: written whole before it is offered, so no reset (on a MAX10 a
        # synchronous reset costs logic per bit)
        sample = Signal.like(self.samples.payload, reset_less=True)
        m.d.comb += self.samples.payload.eq(sample)
        written = Signal(range(SLOTS))          # the slot the burst's bytes go to
        overrun, resumed = Signal(), Signal()
        dropped = Signal(4)                     # read but not passed on (consumer busy, checks)
        early_sent = Signal()                   # the sample is started (the payload has it)
        after, zero_field = self._store(m, written)

        with m.If(self.restarted):
            m.d.sync += resumed.eq(1)
        # the payload's fields but the field's are written now: early, or at an offer of a
        # sample not started early. One enable for both, so that each flip-flop of the
        # payload has one (two cost a LUT a bit: 180 of the reader's, standalone)
        imu_emit = Signal()
        with m.If(imu_emit):
            self._emit_imu(m, sample, buf, overrun, dropped, resumed)
        with m.If(~self.reading):               # between bursts (and at the check: after it)
            m.d.sync += [early_sent.eq(0), self.imu_ready.eq(0)]
        with m.Elif(self.early & ~self.samples.valid):
            m.d.comb += imu_emit.eq(1)
            m.d.sync += [early_sent.eq(1), self.imu_ready.eq(1), self.sample_slot.eq(written)]

        with m.If(self.samples.valid & self.samples.ready):
            m.d.sync += self.samples.valid.eq(0)
        # a sample lost to its checks, or offered while the last still is: one more dropped
        with m.If(self.lost | (self.offer & self.samples.valid)):
            m.d.sync += dropped.eq(Mux(dropped == 15, 15, dropped + 1))
        with m.If(self.offer):
            with m.If(self.samples.valid):
                m.d.sync += overrun.eq(1)
            with m.Else():
                self._emit_field(m, sample, buf)
                m.d.comb += imu_emit.eq(~early_sent)
                # this one is the payload now: its slot offered, the next written
                m.d.sync += [self.samples.valid.eq(1), self.sample_slot.eq(written),
                             written.eq(Mux(written == SLOTS - 1, 0, written + 1)),
                             after.eq(1), zero_field.eq(~self.mag_up)]
        return m

    def _store(self, m, written):
        """The sample store's writes: each sensor byte of the burst into the slot being
        ``written`` as it arrives; then, once a sample is offered (the returned ``after`` set
        to 1 by the offer), a word a cycle into its slot: the payload's words after the sensor
        fields (``counter``, ``flags``, ``skipped``), and, if its field was not read (the
        returned ``zero_field`` set by the offer), zeros over its field. Bytes and these writes
        never meet (the class docstring's throughput)."""
        store = self.store
        places = store_places(SAMPLE_BYTES, MPU_BYTES)
        word, lane, placed = Signal(range(SLOT_WORDS)), Signal(2), Signal()
        with m.Switch(self.index):
            for index, (w, k) in places.items():
                with m.Case(index):
                    m.d.comb += [word.eq(w), lane.eq(k), placed.eq(1)]
        # the writes after an offer: (word, lanes, data); the field's zeros last
        bits = Cat(self.samples.payload.as_value(), C(0, 32 * STORE_WORDS - STORE_BITS))
        writes = [(k, 0xF, bits[32 * k:32 * k + 32])
                  for k in range(SENSOR_BITS // 32, STORE_WORDS)]
        tail = len(writes)
        writes += [(w, lanes, C(0, 32)) for w, lanes in FIELD_LANES]
        assert len(writes) == OFFER_WRITES
        # the writes after an offer, one-hot (``after``'s bit k: write k now), so that each
        # write's address, lanes and word are chosen by a bit of a register, an AND-OR, not
        # by a decoder of a count in front of every bit of the data
        after, zero_field = Signal(len(writes)), Signal()
        # a byte's write is the address and data unless an offer's write chooses them (the
        # byte is gated by ``after`` being 0: an offer's writes and the bytes never meet, but
        # the capture's byte holds its last value)
        busy = after.any()
        m.d.comb += [
            store.w_addr.eq(Cat(reduce(operator.or_, (Mux(after[k], w, 0)
                                                      for k, (w, _, _) in enumerate(writes)),
                                       Mux(busy, 0, word)),
                                Mux(busy, self.sample_slot, written))),
            store.w_data.eq(reduce(operator.or_, (Mux(after[k], value, 0)
                                                  for k, (_, _, value) in enumerate(writes)),
                                   Mux(busy, 0, self.data.replicate(4)))),
            store.w_en.eq(reduce(operator.or_, (Mux(after[k], lanes, 0)
                                                for k, (_, lanes, _) in enumerate(writes)),
                                 Mux(self.arriving & placed & ~busy, 1 << lane, 0))),
        ]
        # the next write, or none after the last (after the payload's words if the field
        # needs no zeros)
        m.d.sync += after.eq(Cat(C(0, 1), after[:-1]) &
                             Mux(zero_field, C(-1, len(writes)), C((1 << tail) - 1, len(writes))))
        return after, zero_field

    def _emit_field(self, m, p, buf):
        """The magnetometer's part of the payload ``p``, at the offer."""
        st1, st2 = buf[MPU_BYTES], buf[MPU_BYTES + 7]
        mag_new, hofl = self.mag_new, st2[3]
        m.d.sync += [p.flags.mag_new.eq(mag_new),
                     p.flags.mag_dor.eq(mag_new & st1[1]),
                     p.flags.mag_overflow.eq(mag_new & hofl),
                     p.flags.mag_valid.eq(mag_new & ~hofl)]
        for axis in range(3):
            k = MPU_BYTES + 1 + 2 * axis
            m.d.sync += p.mag[axis].eq(Mux(self.mag_up, Cat(buf[k], buf[k + 1]).as_signed(), 0))

    def _emit_imu(self, m, p, buf, overrun, dropped, resumed):
        """The sample's fields but the magnetometer's, into the payload ``p`` (which is not
        offered now): at the offer, or at the early start's once the MPU9250's bytes are in."""
        def be16(k):
            return Cat(buf[k + 1], buf[k]).as_signed()

        skipped = self.skipped
        m.d.sync += [overrun.eq(0), resumed.eq(0),
                     p.counter.eq(self.counter), dropped.eq(0),
                     # after a restart the time since the last sample is unknown
                     p.skipped.eq(Mux(resumed, 0, Mux(skipped + dropped > 15, 15,
                                                      skipped + dropped))),
                     p.flags.data_ready.eq(buf[0][0]),
                     p.flags.overrun.eq(overrun),
                     p.flags.resumed.eq(resumed),
                     p.temp.eq(be16(1 + 6))]
        for axis in range(3):
            m.d.sync += [p.accel[axis].eq(be16(1 + 2 * axis)),
                         p.gyro[axis].eq(be16(1 + 8 + 2 * axis))]
