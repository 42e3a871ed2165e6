"""``calibrate``: the guided calibration, as the well-known tools do it.

1. Gyro bias: the board still.
2. Accelerometer: six poses, each axis pointing up and then down.
3. Magnetometer: the board turned through all orientations.

The board sends raw sample frames meanwhile (raw-sample mode); the fits are
``reference/calibration.py``'s; every step is checked (the board still, the pose the one
asked for, the magnetometer's sphere fit good enough and the rotation wide enough) and a bad
one is refused with the reason. The result is written to the board's calibration registers,
read back, and saved as JSON that ``build --calibration FILE`` bakes in as reset values.
"""

import json
import os
import sys
from dataclasses import dataclass

import numpy as np

from ..hdl.engine.register_map import REGS
from ..hdl.link.frame_types import SENSOR
from ..hdl.contract.mpu9250_regs import ACCEL_FS_G
from ..reference.calibration import accel_six_pose, gyro_bias, mag_ellipsoid
from ..hdl.contract.numeric_contract import CalibrationFixed, calibration_registers
from .link import BoardError


__all__ = ["POSES", "Amounts", "calibrate", "load_calibration", "human_operator"]


# The axis pointing up -> the attitude (roll, pitch, yaw in degrees) that puts it there.
POSES = {"+z": (0, 0, 0), "-z": (180, 0, 0), "+x": (0, -90, 0), "-x": (0, 90, 0),
         "+y": (90, 0, 0), "-y": (-90, 0, 0)}


@dataclass
class Amounts:
    """How much to collect (raw frames) and the limits the checks use."""
    rest: int = 400
    pose: int = 200
    fields: int = 120              # new magnetometer fields while turning
    settle: int = 20               # frames dropped after each instruction
    still_counts: float = 60.0     # gyro standard deviation above this: the board moved
    max_spread_percent: float = 3.0
    min_fields: int = 24
    pose_tolerance: float = 0.25   # |reading| within this share of 1 g, on the right axis
    read_back: bool = True         # read every written register back (each write's reply
                                   # already says it landed; this checks the word)


def human_operator(step, text):
    """Asks the person at the board, and waits for Enter."""
    sys.stderr.write(f"\n{text} Press Enter when ready.")
    sys.stderr.flush()
    input()


def _collect(link, n, settle, progress, what):
    samples = []
    for k, (_, _, fields) in enumerate(link.frames(n + settle, types=(SENSOR,))):
        if k >= settle:
            samples.append(fields["sample"])
        progress(what, k + 1, n + settle)
    return samples


def _collect_fields(link, n, settle, progress, limit_frames):
    fields_seen = []
    for k, (_, _, fields) in enumerate(link.frames(limit_frames, types=(SENSOR,))):
        s = fields["sample"]
        if k >= settle and s["flags"]["mag_valid"]:
            fields_seen.append(s["mag"])
            progress("magnetometer", len(fields_seen), n)
            if len(fields_seen) >= n:
                break
    return fields_seen


def calibrate(link, *, operator=human_operator, amounts=Amounts(), accel_fs_g=16,
              progress=None, out_json=None):
    """Runs the procedure on ``link``; returns the result (dict, also saved to ``out_json``).
    Raises ``BoardError`` with the reason when a step fails its check."""
    a = amounts
    progress = progress or (lambda what, k, n: None)
    lsb_g = 32768 / accel_fs_g
    link.identify()
    link.check(link.command("raw", value=1), "raw-sample mode")
    try:
        # 1. gyro bias
        operator("rest", "Put the board down and keep it still.")
        link.discard()
        rest = _collect(link, a.rest, a.settle, progress, "gyro at rest")
        gyr = np.array([s["gyro"] for s in rest], float)
        if gyr.std(0).max() > a.still_counts:
            raise BoardError(f"gyro bias: the board moved (gyro spread {gyr.std(0).max():.0f} "
                             f"counts, limit {a.still_counts:g}); keep it still")
        bias, bias_se = gyro_bias(gyr)

        # 2. accelerometer, six poses
        means = {}
        for axis, _ in POSES.items():
            operator(axis, f"Turn the board so that its {axis[1]} axis points "
                           f"{'up' if axis[0] == '+' else 'down'} ({axis} up), and hold it still.")
            link.discard()
            got = _collect(link, a.pose, a.settle, progress, f"accelerometer {axis}")
            acc = np.array([s["accel"] for s in got], float)
            g = np.array([s["gyro"] for s in got], float)
            if g.std(0).max() > a.still_counts:
                raise BoardError(f"pose {axis}: the board moved; hold it still")
            mean = acc.mean(0)
            # at rest the accelerometer reads 1 g, whatever the pose: far from it, the full
            # scale given is not the board's (a pose error would only mislead)
            norm = np.linalg.norm(mean)
            if not 0.5 < norm / lsb_g < 2:
                fits = min(ACCEL_FS_G, key=lambda fs: abs(np.log(norm * fs / 32768)))
                raise BoardError(f"pose {axis}: the accelerometer reads {norm / lsb_g:.2f} g at "
                                 f"rest, not 1 g: the board's full scale looks like ±{fits} g, "
                                 f"not the ±{accel_fs_g:g} g given (--accel-fs)")
            i = "xyz".index(axis[1])
            sign = 1 if axis[0] == "+" else -1
            if abs(sign * mean[i] / lsb_g - 1) > a.pose_tolerance or \
                    np.abs(np.delete(mean, i)).max() / lsb_g > a.pose_tolerance:
                raise BoardError(f"pose {axis}: the {axis[1]} axis was not pointing "
                                 f"{'up' if sign > 0 else 'down'} (mean reading "
                                 f"{np.round(mean / lsb_g, 2).tolist()} g)")
            means[axis] = mean
        offset, scale = accel_six_pose(means, g=lsb_g)
        residual = [np.linalg.norm((means[k] - offset) / scale) / lsb_g - 1 for k in POSES]

        # 3. magnetometer
        asa = [link.check(link.command("read", addr=REGS[f"ASA{j}"]), "read ASA")["value"]
               / 2 ** 14 for j in range(3)]
        operator("tumble", "Turn the board slowly through all orientations (every face up, "
                           "every direction), away from iron and magnets.")
        link.discard()
        raw = _collect_fields(link, a.fields, a.settle, progress, 40 * a.fields + 400)
        if len(raw) < a.min_fields:
            raise BoardError(f"magnetometer: only {len(raw)} new fields (need {a.min_fields}); "
                             f"is the AK8963 up?")
        adj = np.array(raw, float) * asa
        body = np.stack([adj[:, 1], adj[:, 0], -adj[:, 2]], axis=1)
        try:
            fit = mag_ellipsoid(body)
        except ValueError as e:
            raise BoardError(f"magnetometer: {e}") from None
        directions = fit.apply(body)
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        coverage = float(np.linalg.eigvalsh(directions.T @ directions / len(directions)).min())
        if coverage < 0.1:
            raise BoardError(f"magnetometer: the board was not turned about every axis "
                             f"(coverage {coverage:.2f}, need 0.10)")
        if fit.spread_percent > a.max_spread_percent:
            raise BoardError(f"magnetometer: sphere fit too poor (spread "
                             f"{fit.spread_percent:.1f} %, limit {a.max_spread_percent:g} %): "
                             f"turn it away from iron and magnets, more slowly")
        # the fit keeps the ellipsoid's volume (det = 1): the field stays in counts
        soft = fit.matrix
        result = {
            "format": "mpu9250-ahrs calibration 1",
            "accel_fs_g": accel_fs_g,
            "gyro_offset": [float(v) for v in bias],
            "accel_offset": [float(v) for v in offset],
            "accel_scale": [float(1 / s) for s in scale],
            "hard_iron": [float(v) for v in fit.offset],
            "soft_iron": soft.tolist(),
            "checks": {"gyro_bias_standard_error_counts": [float(v) for v in bias_se],
                       "accel_pose_residual_percent": [round(100 * r, 3) for r in residual],
                       "mag_spread_percent": round(fit.spread_percent, 3),
                       "mag_fields": len(raw), "mag_coverage": round(coverage, 3)},
        }
        # the fit is kept before the board is touched: a write that fails loses nothing
        if out_json:
            _save(result, out_json)
        # written (and read back) while the short raw frames still go out: a reply then waits
        # behind a 36-byte frame at most, not a 92-byte one
        registers = calibration_registers(_fixed(result))
        for name, word in registers.items():
            link.check(link.command("write", addr=REGS[name], value=word), f"write {name}")
        for k, (name, word) in enumerate(registers.items() if a.read_back else ()):
            back = link.check(link.command("read", addr=REGS[name]), f"read {name}")["value"]
            if back & 0xFFFFFFFF != word & 0xFFFFFFFF:
                raise BoardError(f"{name}: wrote {word}, read back {back}")
            progress("written and read back", k + 1, len(registers))
    finally:
        link.command("raw", value=0)
    result["registers"] = registers
    if out_json:
        _save(result, out_json)
    return result


def _save(result, path):
    """``result`` as JSON at ``path``, atomically: a temporary file beside it, then renamed
    (an interrupted run leaves the old file or the new one, never half of one)."""
    tmp = f"{path}.tmp"
    with open(tmp, "w") as f:
        json.dump(result, f, indent=2)
    os.replace(tmp, path)


def _fixed(result):
    return CalibrationFixed.from_units(
        gyro_offset=result["gyro_offset"], accel_offset=result["accel_offset"],
        accel_scale=result["accel_scale"], hard_iron=result["hard_iron"],
        soft_iron=np.array(result["soft_iron"], float))


def _check_soft_iron(path, soft, how):
    """A soft-iron correction maps the measured ellipsoid onto a sphere: a symmetric,
    positive definite matrix (``reference.calibration.mag_ellipsoid``'s), not near singular
    (it would blow one axis up). A rotation, a mirror or a 180° turn is none. ValueError
    naming the file; ``how``: what was done to the matrix first, in words."""
    scale = float(np.max(np.abs(soft)))
    if scale == 0 or not np.all(np.isfinite(soft)):
        raise ValueError(f"{path}: 'soft_iron'{how} is all zero: not a soft-iron correction")
    sign, log_det = np.linalg.slogdet(soft)
    det = 0.0 if sign == 0 else float(sign * np.exp(min(log_det, 700.0)))
    if det <= 0:
        raise ValueError(f"{path}: 'soft_iron'{how} is {'singular' if det == 0 else 'mirrored'} "
                         f"(determinant {det:.3g}): not a soft-iron correction")
    if np.max(np.abs(soft - soft.T)) > 1e-3 * scale:
        raise ValueError(f"{path}: 'soft_iron'{how} is not symmetric (a rotation?): not a "
                         f"soft-iron correction")
    eigen = np.linalg.eigvalsh((soft + soft.T) / 2)
    if eigen.min() <= 0:
        raise ValueError(f"{path}: 'soft_iron'{how} is not positive definite (eigenvalues "
                         f"{', '.join(f'{e:.3g}' for e in eigen)}: a turn, 180° about an "
                         f"axis?): not a soft-iron correction")
    if eigen.max() / eigen.min() > 100:
        raise ValueError(f"{path}: 'soft_iron'{how} is near singular (condition number "
                         f"{eigen.max() / eigen.min():.3g} > 100): not a soft-iron correction")


def load_calibration(path):
    """A saved calibration (JSON) -> ``CalibrationFixed``; ValueError with one line if the
    file is not one."""
    try:
        with open(path) as f:
            result = json.load(f)
    except OSError as e:
        raise ValueError(f"{path}: {e.strerror}") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not JSON ({e.msg}, line {e.lineno})") from None
    shapes = {"gyro_offset": (3,), "accel_offset": (3,), "accel_scale": (3,),
              "hard_iron": (3,), "soft_iron": (3, 3)}
    if not isinstance(result, dict):
        raise ValueError(f"{path}: not a calibration (a JSON object expected)")
    def numbers(x):
        """JSON numbers only (a string such as "1.0" is refused, not converted)."""
        if isinstance(x, list):
            return all(numbers(v) for v in x)
        return isinstance(x, (int, float)) and not isinstance(x, bool)

    for key, shape in shapes.items():
        if key not in result:
            raise ValueError(f"{path}: no '{key}'")
        if not numbers(result[key]):
            raise ValueError(f"{path}: '{key}' is not numbers (JSON numbers, not strings)")
        try:
            value = np.array(result[key], float)
        except (TypeError, ValueError, OverflowError):
            # OverflowError: an integer too large for a float (400 digits)
            raise ValueError(f"{path}: '{key}' must be {shape} finite numbers") from None
        if value.shape != shape or not np.all(np.isfinite(value)):
            raise ValueError(f"{path}: '{key}' must be {shape} finite numbers")
    # the registers' ranges before any rounding: offsets are counts of 16-bit readings, the
    # scales and the soft-iron matrix Q2.14 (-2 .. 2)
    for key, limit, what in (("gyro_offset", 2 ** 15, "counts"),
                             ("accel_offset", 2 ** 15, "counts"),
                             ("hard_iron", 2 ** 15, "counts"),
                             ("accel_scale", 2.0, "(Q2.14)"), ("soft_iron", 2.0, "(Q2.14)")):
        value = np.array(result[key], float)
        if np.any(np.abs(value) >= limit):
            raise ValueError(f"{path}: '{key}' has {value.flat[np.argmax(np.abs(value))]:g}: "
                             f"out of range -{limit:g} .. {limit:g} {what}, its register's")
    _check_soft_iron(path, np.array(result["soft_iron"], float), "")
    cal = _fixed(result)
    registers = calibration_registers(cal)
    # quantised to Q2.14 a tiny matrix can become all zeros (the field lost): checked again
    _check_soft_iron(path, np.reshape(cal.soft_iron, (3, 3)) / 2 ** 14, " quantised to Q2.14")
    for name in ("ACC_SCALE0", "ACC_SCALE1", "ACC_SCALE2"):
        word = registers[name]
        if not 0 < word < 2 ** 15:
            raise ValueError(f"{path}: {name} = {word / 2 ** 14:g} is not a scale in (0, 2)")
    return cal
