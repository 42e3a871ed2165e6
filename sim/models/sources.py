"""Sensor value sources for the MPU9250 model.

A source is any callable ``source(index, t) -> SensorSample`` giving the raw counts the part
would convert for sample number ``index`` at time ``t`` (seconds). The model calls it once per
output sample, in order.
"""

from dataclasses import dataclass
from typing import Callable, Iterable, Iterator, Sequence, Tuple


__all__ = ["SensorSample", "constant_source", "table_source", "generator_source",
           "counting_source", "counting_field"]


def _s16(v):
    v = int(v)
    if not -0x8000 <= v <= 0x7FFF:
        raise ValueError(f"sensor count {v} does not fit a signed 16-bit register")
    return v


@dataclass(frozen=True)
class SensorSample:
    """One accel/temperature/gyro sample in raw signed 16-bit counts (MPU9250 body axes)."""
    accel: Tuple[int, int, int] = (0, 0, 0)
    temp: int = 0
    gyro: Tuple[int, int, int] = (0, 0, 0)

    def __post_init__(self):
        object.__setattr__(self, "accel", tuple(_s16(v) for v in self.accel))
        object.__setattr__(self, "gyro", tuple(_s16(v) for v in self.gyro))
        object.__setattr__(self, "temp", _s16(self.temp))

    def to_bytes(self):
        """Register image from ACCEL_XOUT_H to GYRO_ZOUT_L: big-endian, _H first."""
        out = bytearray()
        for v in (*self.accel, self.temp, *self.gyro):
            out += (v & 0xFFFF).to_bytes(2, "big")
        return bytes(out)


def constant_source(sample: SensorSample) -> Callable[[int, float], SensorSample]:
    return lambda index, t: sample


def table_source(samples: Sequence[SensorSample], *, repeat=False):
    """Samples in order; after the end, the last one again (or from the start if ``repeat``)."""
    if not samples:
        raise ValueError("table_source needs at least one sample")

    def source(index, t):
        if repeat:
            return samples[index % len(samples)]
        return samples[min(index, len(samples) - 1)]
    return source


def generator_source(iterable: Iterable[SensorSample]):
    """Samples drawn from an iterator; it must not run out while the model produces samples."""
    it: Iterator[SensorSample] = iter(iterable)

    def source(index, t):
        try:
            return next(it)
        except StopIteration:
            raise RuntimeError(f"generator_source ran out at sample {index}") from None
    return source


def counting_source(seed=0):
    """Distinct, recognisable values per sample and field: good for catching swapped bytes.
    Accel and gyro words move by 61 counts a sample, each on its own triangle wave between
    -4096 and 4095 (no wrap: steps stay under the driver's gyro jump check,
    ``sample_reader.GYRO_JUMP_DPS``, and a still part's self-test still passes across a few
    samples); the temperature steps by 7,919 across the whole range."""
    def triangle(n):
        n %= 16382
        return (n if n < 8191 else 16382 - n) - 4096

    def source(index, t):
        temp = (seed + index * 7919 + 3 * 4099) & 0xFFFF
        accel = tuple(triangle(seed + index * 61 + k * 4099 + 2048) for k in range(3))
        gyro = tuple(triangle(seed + index * 61 + k * 4099) for k in range(3))
        return SensorSample(accel=accel, temp=temp - 0x10000 if temp & 0x8000 else temp,
                            gyro=gyro)
    return source


def counting_field(seed=0):
    """AK8963 fields (16-bit counts) that change every measurement and stay clear of overflow."""
    def source(index, t):
        base = seed + index * 97
        return tuple(((base + k * 2731) % 16001) - 8000 for k in range(3))
    return source
