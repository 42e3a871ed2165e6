"""This project's filters next to published libraries, on the same quantised recordings.

Every library gets the same inputs (quantised to MPU9250/AK8963 counts and back to units) and one
parameter set for all trials: its defaults, with only the sample rate (and, for imufusion, the
gyro range) set. Their outputs are turned into body->ENU quaternions; the conventions, found by
checking each library on a recording with optical truth:

- ``vqf`` (VQF 9D): ENU already.
- ``ahrs`` Madgwick: NWU-referenced output (North-West-Up) despite taking ENU-style inputs: rotated
  to ENU here (a −90° turn about up). Left as it is, it reads ~90° off.
- ``ahrs`` Mahony: ENU already.
- ``ahrs`` EKF: left out. With its defaults no frame/conjugation combination tried came within
  20° on the slowest trial; it needs its magnetic reference and noise settings chosen, which
  would be per-setup tuning.
- ``imufusion`` (x-io Fusion): ``CONVENTION_ENU``, gyro in °/s through its ``Bias`` (offset)
  corrector, accelerometer in g.
Libraries that are not installed are skipped (``pip install -e ".[bench]"``).
"""

import numpy as np

from .frames import matrix_to_quat, quat_mul


__all__ = ["external_filters", "missing_external_filters"]

_NWU_TO_ENU = matrix_to_quat(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]))


def _vqf(g, a, m, rate):
    from vqf import VQF
    out = VQF(1 / rate).updateBatch(np.ascontiguousarray(g), np.ascontiguousarray(a),
                                    np.ascontiguousarray(m))
    return out["quat9D"]


def _ahrs_madgwick(g, a, m, rate):
    import ahrs
    return quat_mul(_NWU_TO_ENU, ahrs.filters.Madgwick(gyr=g, acc=a, mag=m, frequency=rate).Q)


def _ahrs_mahony(g, a, m, rate):
    import ahrs
    return ahrs.filters.Mahony(gyr=g, acc=a, mag=m, frequency=rate).Q


def _imufusion(g, a, m, rate):
    import imufusion
    settings = imufusion.AhrsSettings()
    settings.convention = imufusion.CONVENTION_ENU
    settings.gyroscope_range = 2000
    settings.sample_rate = int(round(rate))
    fusion = imufusion.Ahrs()
    fusion.set_settings(settings)
    fusion.set_sample_period(1 / rate)
    bias = imufusion.Bias()
    gd, ag = np.degrees(g), a / 9.81
    out = np.empty((len(g), 4))
    for k in range(len(g)):
        fusion.update(bias.update(gd[k]), ag[k], m[k])
        out[k] = fusion.get_quaternion()
    return out


EXTERNAL = (("vqf", "vqf", _vqf), ("ahrs.Madgwick", "ahrs", _ahrs_madgwick),
            ("ahrs.Mahony", "ahrs", _ahrs_mahony), ("imufusion", "imufusion", _imufusion))


def _installed(module):
    try:
        __import__(module)
    except ImportError:
        return False
    return True


def external_filters():
    """name -> function(gyr rad/s, acc m/s², mag µT, rate Hz) -> body->ENU quaternions, for the
    libraries that are installed."""
    return {name: fn for name, module, fn in EXTERNAL if _installed(module)}


def missing_external_filters():
    """The rows ``external_filters`` leaves out: their libraries are not installed."""
    return [name for name, module, fn in EXTERNAL if not _installed(module)]
