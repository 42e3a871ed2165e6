"""``plot``: a ``monitor`` log's attitude, rates and flags against time, as an image."""

import numpy as np

from .monitor import read_log


__all__ = ["plot_log"]


FLAG_COLUMNS = ["attitude.flags.acc_used", "attitude.flags.mag_used",
                "attitude.flags.mag_disturbed", "attitude.flags.at_rest",
                "attitude.flags.saturated", "sample.flags.overrun", "status.mag_stale",
                "status.bad_burst", "status.int_timeout"]


def plot_log(log_path, out_path):
    """Three panels: roll/pitch/yaw (degrees), gyro (counts), flags (one row each)."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RuntimeError("plot needs matplotlib (pip install matplotlib)") from None
    log = read_log(log_path, required=("host_time_s", "roll_deg", "pitch_deg", "yaw_deg",
                                        *(f"sample.gyro.{i}" for i in range(3))))
    t = np.asarray(log["host_time_s"], float)
    if len(t) == 0:
        raise ValueError(f"{log_path}: no frames in the log")
    for name in ("host_time_s", "roll_deg", "pitch_deg", "yaw_deg",
                 *(f"sample.gyro.{i}" for i in range(3))):
        # a span no axis can draw (±1e308: matplotlib's "arange: cannot compute length")
        values = np.asarray(log[name], float)
        values = values[np.isfinite(values)]
        with np.errstate(over="ignore"):
            span = float(np.ptp(values)) if len(values) else 0.0
        if not np.isfinite(span) or span > 1e15:
            raise ValueError(f"{log_path}: column {name} spans {span:g}: not a log's values")
    fig, (ax_att, ax_rate, ax_flags) = plt.subplots(3, 1, sharex=True, figsize=(10, 8))
    for name in ("roll_deg", "pitch_deg", "yaw_deg"):
        ax_att.plot(t, log[name], label=name.split("_")[0])
    ax_att.set_ylabel("attitude (°)")
    ax_att.legend(loc="upper right")
    for i, axis in enumerate("xyz"):
        ax_rate.plot(t, log[f"sample.gyro.{i}"], label=f"gyro {axis}")
    ax_rate.set_ylabel("gyro (counts)")
    ax_rate.legend(loc="upper right")
    for row, name in enumerate(FLAG_COLUMNS):
        values = np.nan_to_num(np.asarray(log.get(name, [0] * len(t)), float))
        ax_flags.fill_between(t, row, row + 0.8 * values, step="post")
    ax_flags.set_yticks(np.arange(len(FLAG_COLUMNS)) + 0.4)
    ax_flags.set_yticklabels([n.split(".")[-1] for n in FLAG_COLUMNS], fontsize=7)
    ax_flags.set_xlabel("host time (s)")
    fig.suptitle(f"{log_path}: {len(t)} frames")
    fig.tight_layout()
    fig.savefig(out_path, dpi=100)
    plt.close(fig)
    return {"frames": len(t), "out": str(out_path)}
