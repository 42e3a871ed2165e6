"""The balancing robot's plant (``sim/models/balance_plant.py``) and its twin
(``sim/scenarios/twin.py``): the physics' checks, the negative control, the loop closed around
the controller's fixed-point model, pushes, and the verb's one JSON line."""

import json
import math

import pytest

from mpu9250_ahrs.sim.models.balance_plant import G, BalancePlant, PlantParams
from mpu9250_ahrs.sim.scenarios.twin import Push, TwinTrace, parse_push, run_twin
from mpu9250_ahrs.sim.scenarios.twin_chip import TWIN_FAULTS_RIDE, TWIN_FAULTS_STOP


def test_upright_at_rest_stays_and_measures_gravity():
    plant = BalancePlant()
    for _ in range(1000):
        plant.step(1e-4, 0.0)
    rate, (fx, fz) = plant.imu()
    assert (plant.psi, plant.theta, rate) == (0.0, 0.0, 0.0)
    assert fx == pytest.approx(0.0) and fz == pytest.approx(G)


def test_a_small_tilt_grows_at_the_linearised_rate():
    """Unpowered (duty 0: the motors short through the bridge, their back-EMF brakes), a small
    tilt grows as exp(λt), λ the largest eigenvalue of the equations linearised at upright:
    the integration checked against the equations' own linearisation (numpy)."""
    import numpy as np
    p = PlantParams()
    plant = BalancePlant(p, tilt=1e-6)
    # linearised: A·[ddtheta, ddpsi] = f(state); state' = J·state, from finite differences
    eps, J = 1e-7, np.zeros((4, 4))
    for k in range(4):
        s = [0.0] * 4
        s[k] = eps
        ddtheta, ddpsi = plant.accelerations(s[1], s[2], s[3], 0.0, 0.0)
        J[:, k] = [s[2] / eps, s[3] / eps, ddtheta / eps, ddpsi / eps]
    growth = max(np.linalg.eigvals(J).real)
    tilts = []
    for k in range(10_000):                     # 1 s; the growing mode dominates by 0.5 s
        plant.step(1e-4, 0.0)
        if k in (4_999, 9_999):
            tilts.append(plant.psi)
    assert math.log(tilts[1] / tilts[0]) / 0.5 == pytest.approx(growth, rel=0.02)


def test_a_static_tilt_reads_gravity_in_the_body_frame():
    plant = BalancePlant(tilt=math.radians(10))
    plant.ddtheta = plant.ddpsi = 0.0
    _, (fx, fz) = plant.imu()
    assert fx == pytest.approx(-G * math.sin(math.radians(10)))
    assert fz == pytest.approx(G * math.cos(math.radians(10)))


def test_without_a_controller_it_falls_within_two_seconds():
    summary = run_twin(5, loop="off")
    assert not summary["upright"] and summary["fell_at_s"] < 2.0


@pytest.mark.parametrize("loop", ["model", "float"])
def test_the_controller_holds_it_through_two_pushes(loop):
    trace = TwinTrace()
    summary = run_twin(10, loop=loop, pushes=[Push(2, 3), Push(2, 6)], trace=trace)
    assert summary["upright"] and summary["pushes_recovered"] == 2, summary
    assert len(trace.t) == 10_000 and max(map(abs, trace.duty)) <= 1.0


def test_a_push_too_hard_is_not_recovered():
    summary = run_twin(4, loop="model", pushes=[Push(40, 1)])
    assert not summary["upright"] and summary["pushes_recovered"] == 0


def test_push_syntax():
    assert parse_push("2.5@3") == Push(2.5, 3.0)
    with pytest.raises(ValueError, match="F@T"):
        parse_push("2")
    with pytest.raises(ValueError, match="one of"):
        run_twin(1, loop="hosted")


def test_twin_verb_prints_one_json_line_last(capsys):
    from mpu9250_ahrs.cli import main
    assert main(["twin", "--seconds", "2", "--loop", "model", "--push", "1@1"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["upright"] and summary["fell_at_s"] is None
    assert main(["twin", "--loop", "model", "--host-latency-ms", "4"]) == 2   # one error line
    assert "needs --loop host" in capsys.readouterr().err
    assert main(["twin", "--loop", "model", "--vcd", "twin.vcd"]) == 2
    assert "--vcd needs --loop chip" in capsys.readouterr().err
    assert main(["twin", "--loop", "chip", "--trace-to", "10ms"]) == 2
    assert "give --vcd FILE too" in capsys.readouterr().err


@pytest.mark.slow
def test_the_gateware_holds_it_through_a_push():
    """The chip loop (the whole core co-simulated with the balance controller, its sensor
    models reading the plant, its PWM pins driving it): upright through a push, and the
    gateware's pitch within 1° RMS of the plant's. About a minute (a core build of its own)."""
    summary = run_twin(2, loop="chip", pushes=[Push(2, 0.5)])
    assert summary["upright"] and summary["pushes_recovered"] == 1, summary
    assert summary["estimate_rms_deg"] < 1.0 and summary["simulator"] == "compiled"


@pytest.mark.slow
def test_the_host_loop_runs_through_the_uart():
    """The host loop: the law on the PC, frames read off the co-simulated board's UART a
    millisecond late, the PWM block's registers written back: it balances, on fewer updates
    than the samples."""
    summary = run_twin(1, loop="host", host_latency_ms=1.0)
    assert summary["upright"] and 300 < summary["updates"] < 1000, summary


@pytest.mark.slow
@pytest.mark.parametrize("fault", TWIN_FAULTS_STOP)
def test_a_sensor_fault_stops_the_motors(fault):
    """The fault catalogue with the controller armed (issue #57): the sensor's data go bad or
    stop; no result comes, or one the driver flags, the controller trips (stale, or fault) and
    every PWM pin stays low from then on: within BAL_STALE's periods (5 ms) from the last
    result, which can come a period after the fault (7 ms); the robot then falls, motors
    off."""
    summary = run_twin(1.2, loop="chip", fault=fault, fault_at_s=0.5)
    assert summary["fault_injected"] and not summary["motors_ran_on"], summary
    assert summary["disarmed_after_ms"] <= 7.0, summary


@pytest.mark.slow
@pytest.mark.parametrize("fault", TWIN_FAULTS_RIDE)
def test_a_fault_the_attitude_survives_leaves_it_balancing(fault):
    """The magnetometer's faults (the tilt needs none of it), a sample dropped (a flipped bit,
    a spurious INT), a rate glitch the driver repairs: the controller rides through, upright,
    motors running, the gateware's pitch still within 1° RMS."""
    summary = run_twin(1.2, loop="chip", fault=fault, fault_at_s=0.5)
    assert summary["fault_injected"] and summary["motors_ran_on"], summary
    assert summary["upright"] and summary["estimate_rms_deg"] < 1.0, summary


def test_the_twin_refuses_a_fault_it_cannot_inject():
    with pytest.raises(ValueError, match="does not run the fault 'i2c_bus_stuck'"):
        run_twin(0.1, loop="chip", fault="i2c_bus_stuck")


@pytest.mark.slow
def test_the_chip_loop_waveform_opens_in_gtkwave(tmp_path):
    """``twin --loop chip --vcd``: the core's waveform from the arming (a window of 20 ms: a
    whole run would be gigabytes), with the controller's group, opens in GTKWave."""
    from mpu9250_ahrs.sim.bench.waveforms import GTKWAVE_HINT, Waveform, gtkwave_check
    from tests.conftest import require_tool
    require_tool("gtkwave", GTKWAVE_HINT)
    require_tool("xvfb-run", GTKWAVE_HINT)
    wave = Waveform(str(tmp_path / "twin.vcd"), stop=("s", 0.02))
    summary = run_twin(0.1, loop="chip", vcd=wave)
    assert summary["upright"] and summary["vcd"] == wave.path
    opened = gtkwave_check(wave.path, wave.gtkw)
    assert opened["returncode"] == 0 and opened["errors"] == [], opened
    assert {"cs_n", "sclk", "arm", "pwm", "armed", "duty"} <= set(opened["traces"]), opened
    armed_s = summary["armed_at_cycle"] / 4e6
    start, end = (t * 1e-12 for t in opened["window"])
    assert armed_s <= start < end <= armed_s + 0.02 + 1e-6, (opened["window"], armed_s)
