"""A filter is one record (issue #59): everything that dispatches on a filter reads the registry
(``hdl/contract/filter_registry.py``). A fifth filter sketched here is its own modules and a
record: the engine's program takes its routine and dispatch, the select, the CONTROL code and
the results' ``filter`` field widen to three bits, the ISA's fetch-jump index to four, the
gateware elaborates, and the reference runs its float and integer steps by its record."""

import json
import subprocess
import sys

from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_NAMES, FILTERS, record
from mpu9250_ahrs.hdl.contract.numeric_contract import control_code_bits, control_fields


def test_the_records_are_the_registry():
    assert tuple(f.name for f in FILTERS) == FILTER_NAMES
    assert record("madgwick").microcode == "madgwick"
    assert control_code_bits(4) == 2 and control_code_bits(5) == 3 and control_code_bits(16) == 4


def test_control_code_above_four_filters():
    """Four filters: bits 5:4 are reserved (a word with them is refused, as before); five: bit 4
    is the code's third bit."""
    assert control_fields(1 << 4, 4) is None
    assert control_fields((1 << 4) | 1, 5) is None          # code 5 names no filter
    assert control_fields(1 << 4, 5) == (4, False)
    assert control_fields(1 << 5, 5) is None                # bit 5 still reserved
    assert control_fields(0b1011, 5) == (None, False)       # keep: the code ignored


# The sketch, in a process of its own: the registry is read as the modules are imported
SKETCH = r'''
import json, sys, types
import numpy as np
from mpu9250_ahrs.hdl.contract import filter_registry as fr
from mpu9250_ahrs.hdl.contract.numeric_contract import control_code_bits

# the fifth filter's own module: its microcode (hold the angles: the per-axis filters' tail
# makes the quaternion of them), its float step and its integer step
mod = types.ModuleType("sketch.fifth_filter")
mod.CONFIG_REGISTERS, mod.REGISTERS = [], []
def emit(asm, r):
    from mpu9250_ahrs.hdl.engine.filters.shared import magnetometer_in
    magnetometer_in(asm, "hold")        # every routine passes the early start's SYNC once
    asm.br("angles_out")
mod.emit = emit
mod.run_float = lambda gyr, acc, mag, dt, **params: np.tile([1.0, 0, 0, 0], (len(gyr), 1))
class Hold:
    first = True
    def __init__(self, kf):
        self.kf = kf
    def step(self, g, a, m, mag_valid, st, periods=1):
        from mpu9250_ahrs.reference.flagship_fixed import euler_quat_fixed
        return euler_quat_fixed(self.kf.theta, st), self.kf.theta, set()
mod.engine_step = lambda reg, kf: Hold(kf)
sys.modules["sketch"] = types.ModuleType("sketch")
sys.modules["sketch.fifth_filter"] = mod

# ... and its record: the one line a new filter adds outside its modules
fr.FILTERS += (fr.FilterRecord("hold", microcode="sketch.fifth_filter",
                               float_step="sketch.fifth_filter",
                               fixed_step="sketch.fifth_filter:engine_step"),)
fr.FILTER_NAMES = tuple(f.name for f in fr.FILTERS)
fr.FILTER_CODES = {n: c for c, n in enumerate(fr.FILTER_NAMES)}
fr.FILTER_CODE_BITS = control_code_bits(len(fr.FILTERS))
fr.FLOAT_FILTERS = fr.FILTER_NAMES

from amaranth.back import rtlil
from amaranth.lib import data
from mpu9250_ahrs.hdl.engine.attitude_engine import AttitudeEngine
from mpu9250_ahrs.hdl.engine.attitude_isa import JUMP_BITS
from mpu9250_ahrs.hdl.engine.attitude_program import build_program
from mpu9250_ahrs.hdl.engine.attitude_result import AttitudeFlags
from mpu9250_ahrs.hdl.engine.host_port import HostPort
from mpu9250_ahrs.reference.engine_model import EngineModel
from mpu9250_ahrs.reference.evaluate import run_filter
program, _ = build_program()
engine = AttitudeEngine(filter="hold")
rtlil.convert(engine)
model = EngineModel(filter="hold")
model.sample([0, 0, 0], [0, 0, 2048], [0, 0, 0])
print(json.dumps({
    "words": len(program), "jump_bits": JUMP_BITS,
    "select_bits": len(HostPort(4).select),
    "flag_bits": data.Layout.cast(AttitudeFlags)["filter"].width,
    "model_filter": model.filter, "model_switch": model.control(0b10),
    "float": run_filter("hold", np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3)), 0.01).tolist()}))
'''


def test_a_fifth_filter_is_its_modules_and_a_record():
    out = subprocess.run([sys.executable, "-c", SKETCH], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["words"] <= 1024                         # the ROM still holds the program
    assert got["jump_bits"] == 4 and got["flag_bits"] == 3
    assert got["select_bits"] == 3
    assert got["model_filter"] == 4 and got["model_switch"] is True
    assert got["float"] == [[1.0, 0, 0, 0]] * 2
