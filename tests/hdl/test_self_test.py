"""SelfTest: the sums and verdicts against the rules of ``hdl/sensor/self_test.py``, at the
thresholds."""

import random

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.self_test import (ACCEL_CODE0, CODE_INDEX, GYRO_CODE0, MAG_INDEX,
                                               MAG_LIMITS, SelfTest, mag_axis_passes,
                                               mpu_axis_passes, otp)


def test_otp_table():
    assert otp(1) == 2620 and otp(2) == round(2620 * 1.01)
    assert otp(255) == round(2620 * 1.01 ** 254) < 1 << 16
    with pytest.raises(ValueError):
        otp(0)


def test_rules():
    # gyro: more than half the factory response; accel: between half and one and a half
    assert mpu_axis_passes(otp(10) // 2 + 1, 10, 1, gyro=True)
    assert not mpu_axis_passes(otp(10) // 2, 10, 1, gyro=True)
    assert not mpu_axis_passes(-otp(10), 10, 1, gyro=True)
    assert mpu_axis_passes(otp(10), 10, 4, gyro=False) is False      # N = 4: four times it
    assert mpu_axis_passes(4 * otp(10), 10, 4, gyro=False)
    # code 0: the absolute limits, either sign
    assert mpu_axis_passes(-7860, 0, 1, gyro=True) and not mpu_axis_passes(7859, 0, 1, True)
    assert mpu_axis_passes(3687, 0, 1, gyro=False) and not mpu_axis_passes(3686, 0, 1, False)
    assert mpu_axis_passes(-11059, 0, 1, False) and not mpu_axis_passes(11060, 0, 1, False)
    assert (GYRO_CODE0, ACCEL_CODE0) == (15719, 7373)
    # magnetometer, after ASA: floor(h * (asa + 128) / 256)
    assert mag_axis_passes(200, 128, 0) and not mag_axis_passes(201, 128, 0)
    assert mag_axis_passes(-800, 128, 2) and not mag_axis_passes(-799, 128, 2)
    assert mag_axis_passes(-3200, 128, 2) and not mag_axis_passes(-3201, 128, 2)
    assert mag_axis_passes(134, 255, 1)             # 134 * 383 / 256 = 200.5: 200
    assert not mag_axis_passes(135, 255, 1)         # 201.97: 201
    assert MAG_LIMITS[2] == (-3200, -800)


def _words_to_bytes(words):
    out = []
    for w in words:
        out += [(w >> 8) & 0xFF, w & 0xFF]
    return out


def run_cases(samples_log2, cases, mag_cases):
    """``cases``: (off bursts, on bursts, codes) with bursts as lists of seven 16-bit words
    (accel X, Y, Z, temperature, gyro X, Y, Z); ``mag_cases``: (h, asa) per axis. Returns the
    block's ``fail`` word after each case and ``done`` / ``mag_done``."""
    dut = SelfTest(samples_log2=samples_log2)
    results = []

    async def send(ctx, byte, index, subtract=0, first=0):
        ctx.set(dut.i, {"valid": 1, "byte": byte, "index": index, "subtract": subtract,
                        "first": first})
        await ctx.tick()
        ctx.set(dut.i.valid, 0)
        # bytes on a sensor bus come many cycles apart
        for _ in range(4):
            await ctx.tick()
        assert not ctx.get(dut.busy)

    async def tb(ctx):
        for off, on, codes in cases:
            for n, burst in enumerate(off):
                for i, b in enumerate(_words_to_bytes(burst)):
                    await send(ctx, b, i, subtract=1, first=n == 0)
            for burst in on:
                for i, b in enumerate(_words_to_bytes(burst)):
                    await send(ctx, b, i)
            for axis, code in enumerate(codes):
                await send(ctx, code, CODE_INDEX + axis)
            results.append((ctx.get(dut.status.fail) & 0x3F, ctx.get(dut.status.done)))
        for h, asa in mag_cases:
            ctx.set(dut.asa, [asa] * 3)
            for axis in range(3):
                await send(ctx, h[axis] & 0xFF, MAG_INDEX + 2 * axis)
                await send(ctx, (h[axis] >> 8) & 0xFF, MAG_INDEX + 2 * axis + 1)
            results.append((ctx.get(dut.status.fail) >> 6, ctx.get(dut.status.mag_done)))

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(tb)
    sim.run()
    return results


def _expected(off, on, codes, n):
    fails = 0
    for axis in range(6):
        word = axis if axis < 3 else axis + 1
        total = sum(b[word] for b in on) - sum(b[word] for b in off)
        if not mpu_axis_passes(total, codes[axis], n, gyro=axis >= 3):
            fails |= 1 << axis
    return fails


@pytest.mark.parametrize("samples_log2", [0, 2])
def test_against_rules(samples_log2):
    n = 1 << samples_log2
    rng = random.Random(samples_log2)
    cases = []
    for case in range(10):
        codes = [rng.choice([0, 1, rng.randrange(1, 256), 255]) for _ in range(6)]
        off = [[rng.randrange(-20000, 20000) for _ in range(7)] for _ in range(n)]
        on = []
        for _ in range(n):
            burst = []
            for word in range(7):
                axis = word if word < 3 else word - 1
                if word == 3:
                    burst.append(rng.randrange(-32768, 32768))
                    continue
                code = codes[axis]
                base = otp(code) if code else (GYRO_CODE0 if word > 3 else ACCEL_CODE0)
                # around each threshold: T / 2, 3 T / 2 (per sample), and anywhere
                target = rng.choice([base // 2, base // 2 + 1, (3 * base) // 2,
                                     (3 * base) // 2 + 1, base, -base,
                                     rng.randrange(-40000, 40000)])
                if code == 0:
                    target = rng.choice([1, -1]) * rng.choice([base // 2, base // 2 + 1,
                                                               (3 * base) // 2,
                                                               (3 * base) // 2 + 1])
                v = off[len(on)][word] + target
                burst.append(max(-32768, min(32767, v)))
            on.append(burst)
        cases.append(([[w & 0xFFFF for w in b] for b in off],
                      [[w & 0xFFFF for w in b] for b in on], codes))
    mag_cases = [((200, -200, -800), 128), ((201, 0, -799), 128), ((134, -134, -3200), 255),
                 ((0, 0, 0), 0), ((-32768, 32767, -1500), 176)]
    got = run_cases(samples_log2, cases, mag_cases)

    def signed(w):
        return w - 0x10000 if w & 0x8000 else w
    for (off, on, codes), (fails, done) in zip(cases, got):
        off = [[signed(w) for w in b] for b in off]
        on = [[signed(w) for w in b] for b in on]
        assert fails == _expected(off, on, codes, n) and done
    verdicts = [f >> a & 1 for f, _ in got[:len(cases)] for a in range(6)]
    assert 0 < sum(verdicts) < len(verdicts)        # both verdicts were exercised
    for (h, asa), (fails, done) in zip(mag_cases, got[len(cases):]):
        want = sum((not mag_axis_passes(h[a], asa, a)) << a for a in range(3))
        assert fails == want and done
