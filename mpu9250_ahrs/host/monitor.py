"""``monitor``: decode the board's frames, show a live line, log every frame (CSV or HDF5)."""

import csv
import sys
import time

from ..hdl.contract.filter_registry import FILTER_NAMES
from ..hdl.link.frame_types import ATTITUDE, SENSOR
from ..hdl.link.frame_types import AttitudeFrame
from ..hdl.contract.self_test_axes import AXES as SELF_TEST_AXES
from .protocol import unpack


__all__ = ["COLUMNS", "flatten", "monitor", "read_log"]


def flatten(fields, prefix=""):
    """Nested frame fields -> {"sample.accel.0": v, ...}."""
    out = {}
    items = enumerate(fields) if isinstance(fields, list) else fields.items()
    for key, value in items:
        name = f"{prefix}{key}"
        if isinstance(value, (dict, list)):
            out.update(flatten(value, name + "."))
        else:
            out[name] = value
    return out


# Every frame type's fields fit these columns (a sensor frame's are an attitude frame's first).
COLUMNS = ["host_time_s", "type", "seq", *flatten(unpack(AttitudeFrame, 0)),
           "roll_deg", "pitch_deg", "yaw_deg"]


def _row(ftype, seq, fields, t):
    row = {"host_time_s": round(t, 6), "type": ftype, "seq": seq, **flatten(fields)}
    if ftype == ATTITUDE:
        for name, bam in zip(("roll_deg", "pitch_deg", "yaw_deg"), fields["attitude"]["angles"]):
            row[name] = round(bam * 360 / 2 ** 32, 4)
    return row


class _HDF5Log:
    """Columns gathered in memory and written as one dataset each at the end."""
    def __init__(self, path):
        try:
            import h5py  # noqa: F401
        except ImportError:
            raise RuntimeError("--hdf5 needs h5py (pip install h5py)") from None
        self.path, self.rows = path, []

    def writerow(self, row):
        self.rows.append(row)

    def close(self):
        import h5py
        import numpy as np
        with h5py.File(self.path, "w") as f:
            for name in COLUMNS:
                values = [r.get(name, np.nan) for r in self.rows]
                f.create_dataset(name, data=np.asarray(values, float))


def monitor(link, *, frames=None, csv_path=None, hdf5_path=None, out=None,
            live_every_s=0.5):
    """Read frames until ``frames`` (None: until interrupted), log each; a live line on
    ``out`` (stderr). Returns the summary (dict)."""
    out = out or sys.stderr
    log = None
    handle = None
    if csv_path:
        handle = open(csv_path, "w", newline="")
        log = csv.DictWriter(handle, COLUMNS, extrasaction="ignore")
        log.writeheader()
    elif hdf5_path:
        log = _HDF5Log(hdf5_path)
    start = time.monotonic()
    first = None
    count, shown = 0, 0.0
    last = None
    try:
        for ftype, seq, fields in link.frames(frames, types=(SENSOR, ATTITUDE)):
            t = time.monotonic() - start
            first = t if first is None else first
            count += 1
            last = (ftype, fields)
            if log is not None:
                log.writerow(_row(ftype, seq, fields, t))
            if t - shown >= live_every_s or count == frames:
                shown = t
                out.write("\r" + _live_line(link, count, t - first, ftype, fields))
                out.flush()
    except KeyboardInterrupt:
        pass
    finally:
        if handle is not None:
            handle.close()
        elif log is not None:
            log.close()
    out.write("\n")
    elapsed = (time.monotonic() - start) - (first or 0)
    stats = link.stats
    return {"frames": count, "crc_errors": stats.crc_errors, "lost_frames": stats.lost,
            "noise_bytes": stats.skipped_bytes,
            "frame_rate_hz": round((count - 1) / elapsed, 3) if count > 1 and elapsed else None,
            "last_type": None if last is None else last[0],
            "log": csv_path or hdf5_path}


def _live_line(link, count, elapsed, ftype, fields):
    rate = (count - 1) / elapsed if elapsed > 0 else 0.0
    status = fields["status"]
    flags = [k for k, v in status.items() if v and k not in ("restarts", "self_test_fail",
                                                                "streaming", "mag_ok")]
    # the axes that failed their self-test, by name (hdl/contract/self_test_axes.py: AXES)
    flags += [f"self_test:{axis}" for i, axis in enumerate(SELF_TEST_AXES)
              if status.get("self_test_fail", 0) >> i & 1]
    text = f"{count} frames {rate:6.1f}/s"
    if ftype == ATTITUDE:
        roll, pitch, yaw = (v * 360 / 2 ** 32 for v in fields["attitude"]["angles"])
        filt = (*FILTER_NAMES, "?")[fields["attitude"]["flags"]["filter"]]
        text += f"  {filt} roll {roll:7.2f} pitch {pitch:7.2f} yaw {yaw:7.2f}"
    else:
        text += f"  raw accel {fields['sample']['accel']} gyro {fields['sample']['gyro']}"
    stats = link.stats
    return (text + f"  flags {','.join(flags) or '-'}  crc errors {stats.crc_errors}"
            f"  lost {stats.lost}   ")


def read_log(path, required=("type",)):
    """A ``monitor`` log (CSV or HDF5) -> {column: list of floats}. Checked before use: the
    ``required`` columns there, every column of one length (HDF5: one-dimensional datasets,
    their shapes read before their data), every CSV row as long as the header and numeric;
    anything else is a ValueError with one line."""
    required = tuple(required)
    if str(path).endswith((".h5", ".hdf5")):
        import h5py
        from ..reference.recording import open_hdf5
        with open_hdf5(path) as f:
            columns = {name: f[name] for name in f if isinstance(f[name], h5py.Dataset)}
            missing = [c for c in required if c not in columns]
            if not columns or missing:
                raise ValueError(f"{path}: not a monitor log (no column "
                                 f"{', '.join(missing or required)})")
            lengths = {name: d.shape for name, d in columns.items()}
            flat = [name for name, shape in lengths.items() if len(shape) != 1]
            if flat:
                # (the first required column's shape was the expected one: a 2-D one read
                # "shape (4, 4), expected (4, 4)")
                raise ValueError(f"{path}: column {flat[0]} has shape {lengths[flat[0]]}: a "
                                 f"log's columns are one-dimensional")
            n = lengths[required[0]]
            bad = [name for name, shape in lengths.items() if shape != n]
            if bad:
                raise ValueError(f"{path}: column {bad[0]} has shape {lengths[bad[0]]}, "
                                 f"expected {n} like {required[0]}")
            try:
                return {name: [float(v) for v in d[()]] for name, d in columns.items()}
            except (TypeError, ValueError) as e:
                raise ValueError(f"{path}: a column is not numbers ({e})") from None
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        rows = list(reader)
        header = reader.fieldnames or []
    missing = [c for c in required if c not in header]
    if not rows or missing:
        raise ValueError(f"{path}: not a monitor log (no "
                         f"{'rows' if not missing else 'column ' + ', '.join(missing)})")
    out = {name: [] for name in header}
    for line, r in enumerate(rows, start=2):
        if None in r:
            raise ValueError(f"{path}: line {line} has more fields than the header")
        for name in header:
            text = r[name]
            try:
                out[name].append(float(text) if text not in ("", None) else float("nan"))
            except ValueError:
                raise ValueError(f"{path}: line {line}, column {name}: {text!r} is not a "
                                 f"number") from None
    return out

