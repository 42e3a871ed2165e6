"""Recorded data: BROAD-format HDF5 files, quantised to what an MPU9250 + AK8963 would output.

A BROAD file (``shared/data/broad/README.md``) holds ``imu_gyr`` (rad/s), ``imu_acc`` (m/s²),
``imu_mag`` (µT) in the sensor frame, ``opt_quat`` (sensor->ENU, w x y z, NaN where the cameras
lost the markers), ``movement`` (bool: the samples that are scored) and the ``sampling_rate``
attribute. The recording's sensor frame is taken as the MPU9250 body frame.

``quantise`` turns physical values into MPU9250 counts (gyro at the chosen full scale, accel at
the chosen full scale, both saturating at ±32767/−32768) and AK8963 16-bit counts (0.15 µT/LSB,
±32760), rounding to nearest. ``to_units`` turns counts back into rad/s, m/s² and µT, so the
float filters see exactly the quantised data the gateware would.
"""

from dataclasses import dataclass

import numpy as np


__all__ = ["Recording", "load_broad", "open_hdf5", "Scales", "quantise", "saturated",
           "COUNT_LIMITS", "to_units", "G"]

G = 9.81


@dataclass
class Recording:
    name: str
    rate: float
    gyr: np.ndarray      # rad/s
    acc: np.ndarray      # m/s²
    mag: np.ndarray      # µT
    quat: np.ndarray     # truth, sensor->ENU (w, x, y, z); NaN rows where unknown
    movement: np.ndarray
    held: int = 0        # samples whose sensor values were NaN or infinite: held (see below)
    truth_rejected: int = 0   # truth rows not of unit norm: set unknown (NaN), not scored

    @property
    def dt(self):
        return 1.0 / self.rate


def _hold_bad_rows(*arrays):
    """Rows where any sensor value is NaN or infinite take the values of the last good row
    (the first good row for those before it), as a sensor read that failed would be held.
    Returns the arrays and how many rows were held."""
    bad = np.zeros(len(arrays[0]), bool)
    for a in arrays:
        bad |= ~np.all(np.isfinite(a), axis=1)
    if bad.all():
        raise ValueError("no sample has finite gyro, accel and mag values")
    if not bad.any():
        return arrays, 0
    good = np.flatnonzero(~bad)
    source = good[np.clip(np.searchsorted(good, np.arange(len(bad)), side="right") - 1, 0, None)]
    return tuple(a[source] for a in arrays), int(bad.sum())


# A truth quaternion further than this from unit norm is no rotation: the optical system's
# output is normalised to ~1e-6, so 1 % only catches rows that are not quaternions at all
# (scaled, zero, garbage).
TRUTH_NORM_TOLERANCE = 0.01
# the N x width datasets beside ``movement`` (N)
_WIDTHS = {"imu_gyr": 3, "imu_acc": 3, "imu_mag": 3, "opt_quat": 4}


def open_hdf5(path):
    """The HDF5 file ``path`` open for reading, or a ValueError that says in a few words what
    is wrong with it (missing, a folder, unreadable, not HDF5) rather than HDF5's own
    message (a line of 300 characters with a buffer's address)."""
    import os
    import h5py
    problem = ("no such file" if not os.path.exists(path) else
               "a folder, not a file" if os.path.isdir(path) else
               "no permission to read it" if not os.access(path, os.R_OK) else
               "not an HDF5 file (no HDF5 signature)" if not h5py.is_hdf5(path) else None)
    if problem:
        raise ValueError(f"{path}: cannot be read as HDF5: {problem}")
    try:
        return h5py.File(path, "r")
    except OSError as e:
        # e.g. a truncated file: HDF5's reason is the part before its details in brackets
        reason = str(e).split("(", 1)[-1].split(")", 1)[0] if "(" in str(e) else str(e)
        raise ValueError(f"{path}: cannot be read as HDF5: {reason.strip()[:120]}") from None


# BROAD's trials are sampled at 286 Hz; the MPU9250 at up to 32 kHz. A rate outside these
# bounds is a file that is wrong, not a recording (1e-9 Hz scored 100° and broke the JSON)
RATE_BOUNDS_HZ = (0.1, 100_000.0)
# a recording's rows are read whole (16 floats a row) and copied a few times: refused where
# that would not fit in what the machine has free (a 2.6 KB file can declare 90 M sparse rows)
_BYTES_PER_ROW = 16 * 8 * 6


def _rate(path, attribute):
    """The ``sampling_rate`` attribute as one real rate in ``RATE_BOUNDS_HZ``, or a
    ValueError naming what it is instead (an array, a complex, a string, out of bounds)."""
    raw = np.asarray(attribute)
    if raw.size != 1 or raw.dtype.kind not in "iuf":
        what = (f"{raw.size} values" if raw.size != 1 else
                "complex" if raw.dtype.kind == "c" else f"of type {raw.dtype}")
        raise ValueError(f"{path}: sampling_rate must be one real number of Hz, not {what}")
    rate = float(raw.reshape(-1)[0])
    lo, hi = RATE_BOUNDS_HZ
    if not np.isfinite(rate) or rate <= 0:
        raise ValueError(f"{path}: sampling_rate {rate:g} is not a positive rate")
    if not lo <= rate <= hi:
        raise ValueError(f"{path}: sampling_rate {rate:g} Hz is not a recording's rate "
                         f"({lo:g} .. {hi:g} Hz)")
    return rate


def _available_bytes():
    """Memory free for a new allocation (``MemAvailable``), or None where it cannot be read."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _check_size(path, n):
    need, free = n * _BYTES_PER_ROW, _available_bytes()
    if free is not None and need > free:
        raise ValueError(f"{path}: {n:,} samples (about {need / 1e9:.1f} GB to read and "
                         f"process) do not fit in the {free / 1e9:.1f} GB this machine has "
                         f"free; read the first N (replay --samples N) or cut the file")


def load_broad(path, first=None):
    """A BROAD-format HDF5 file, checked: the datasets and the ``sampling_rate`` attribute
    there, N × 3 sensor arrays, N × 4 truth and N movement flags with N ≥ 2, a finite
    rate within ``RATE_BOUNDS_HZ``, each dataset's shape before its data is read, and that
    the rows fit in the memory free; ``first``: only the first rows (those alone are read).
    NaN or infinite sensor values are held (``Recording.held`` counts them; ``replay`` says
    so). Truth rows whose norm is not 1 within ``TRUTH_NORM_TOLERANCE`` are set unknown
    (``Recording.truth_rejected`` counts them; ``replay`` says so), the others normalised; a
    file with no known truth row, or whose known truth is all of that kind, is refused.
    Anything else is a ValueError with one line."""
    from pathlib import Path
    f = open_hdf5(path)
    with f:
        missing = sorted({"imu_gyr", "imu_acc", "imu_mag", "opt_quat", "movement"} - set(f))
        if "sampling_rate" not in f.attrs:
            missing.append("attribute sampling_rate")
        if missing:
            raise ValueError(f"{path}: not a BROAD-format file (missing {', '.join(missing)})")
        # shapes first, from the datasets' headers: a small file may declare huge datasets
        shapes = {}
        for name in ("movement", *_WIDTHS):
            shape = getattr(f[name], "shape", None)
            if shape is None:
                raise ValueError(f"{path}: {name} is a group, not a dataset")
            shapes[name] = shape
        if len(shapes["movement"]) != 1:
            raise ValueError(f"{path}: movement has shape {shapes['movement']}, expected (N,)")
        n = shapes["movement"][0]
        for name, width in _WIDTHS.items():
            if shapes[name] != (n, width):
                raise ValueError(f"{path}: {name} has shape {shapes[name]}, expected "
                                 f"({n}, {width}) like movement")
        rate = _rate(path, f.attrs["sampling_rate"])
        n = n if first is None else min(n, first)
        _check_size(path, n)
        try:
            # only the rows wanted are read (a slice of a dataset reads no more)
            arrays = {k: np.asarray(f[k][:n], float) for k in _WIDTHS}
            movement = np.asarray(f["movement"][:n]).astype(bool)
        except (TypeError, ValueError, IndexError) as e:
            raise ValueError(f"{path}: unreadable BROAD data ({e})") from None
    if n < 2:
        raise ValueError(f"{path}: {n} samples; a recording needs at least 2")
    (gyr, acc, mag), held = _hold_bad_rows(arrays["imu_gyr"], arrays["imu_acc"],
                                           arrays["imu_mag"])
    quat = arrays["opt_quat"].copy()
    known = np.all(np.isfinite(quat), axis=1)
    off = known & (np.abs(np.linalg.norm(np.where(known[:, None], quat, 0), axis=1) - 1)
                   > TRUTH_NORM_TOLERANCE)
    if not known.any():
        raise ValueError(f"{path}: opt_quat has no known row (all NaN or infinite): no truth "
                         f"to score against")
    if off[known].all():
        norms = np.linalg.norm(quat[known], axis=1)
        raise ValueError(f"{path}: opt_quat is not a unit quaternion in any row (norms "
                         f"{norms.min():.3g} .. {norms.max():.3g}): no truth to score against")
    quat[off] = np.nan
    # the rows kept are rotations stored to a few decimals: scored as the rotations they are
    kept = known & ~off
    quat[kept] /= np.linalg.norm(quat[kept], axis=1, keepdims=True)
    return Recording(Path(path).stem, rate, gyr, acc, mag, quat, movement.reshape(-1), held,
                     int(off.sum()))


@dataclass(frozen=True)
class Scales:
    gyro_fs_dps: int = 2000
    accel_fs_g: int = 16
    mag_ut_per_lsb: float = 0.15

    @property
    def gyro_lsb_per_dps(self):
        return 32768 / self.gyro_fs_dps                    # 16.4 LSB/(°/s) at ±2000 °/s

    @property
    def gyro_lsb_per_rad(self):
        return self.gyro_lsb_per_dps * 180 / np.pi

    @property
    def accel_lsb_per_ms2(self):
        return 32768 / self.accel_fs_g / G                 # 2048 LSB/g at ±16 g


# what ``quantise`` saturates at, as the parts do: the MPU9250's words, the AK8963's range
COUNT_LIMITS = {"gyro": (-32768, 32767), "accel": (-32768, 32767), "mag": (-32760, 32760)}


def _counts(x, scale, lo, hi):
    # a value beyond any full scale (1e308) overflows to inf and is clipped like the rest
    with np.errstate(over="ignore"):
        return np.clip(np.round(np.asarray(x, float) * scale), lo, hi).astype(np.int32)


def quantise(gyr, acc, mag, scales=Scales()):
    """Physical -> raw counts (int32 arrays), saturating like the parts do."""
    return (_counts(gyr, scales.gyro_lsb_per_rad, *COUNT_LIMITS["gyro"]),
            _counts(acc, scales.accel_lsb_per_ms2, *COUNT_LIMITS["accel"]),
            _counts(mag, 1 / scales.mag_ut_per_lsb, *COUNT_LIMITS["mag"]))


def saturated(gyr_counts, acc_counts, mag_counts):
    """Samples with an axis at its sensor's limit (``COUNT_LIMITS``: clipped by ``quantise``,
    or by the part), by sensor: a full scale too narrow for the motion."""
    out = {}
    for name, counts in zip(COUNT_LIMITS, (gyr_counts, acc_counts, mag_counts)):
        lo, hi = COUNT_LIMITS[name]
        counts = np.asarray(counts)
        out[name] = int(np.any((counts <= lo) | (counts >= hi), axis=-1).sum())
    return out


def to_units(gyr_counts, acc_counts, mag_counts, scales=Scales()):
    return (np.asarray(gyr_counts, float) / scales.gyro_lsb_per_rad,
            np.asarray(acc_counts, float) / scales.accel_lsb_per_ms2,
            np.asarray(mag_counts, float) * scales.mag_ut_per_lsb)
