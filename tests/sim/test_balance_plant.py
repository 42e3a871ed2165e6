"""The balancing robot's plant (``sim/models/balance_plant.py``) and its twin
(``sim/scenarios/twin.py``): the physics' checks, the negative control, the loop closed around
the controller's fixed-point model, pushes, and the verb's one JSON line."""

import json
import math

import pytest

from mpu9250_ahrs.sim.models.balance_plant import G, BalancePlant, PlantParams
from mpu9250_ahrs.sim.scenarios.twin import Push, TwinTrace, parse_push, run_twin


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
@pytest.mark.parametrize("fault", ["cipo_stuck_high", "int_stuck_low"])
def test_a_sensor_fault_stops_the_motors(fault):
    """The fault catalogue with the controller armed (issue #57): the sensor's data go bad or
    stop; no result comes, the controller trips (stale) and every PWM pin stays low from then
    on, within BAL_STALE's periods (5 ms); the robot then falls, motors off."""
    summary = run_twin(1.2, loop="chip", fault=fault, fault_at_s=0.5)
    assert summary["fault_injected"] and summary["disarmed_after_ms"] <= 6.0, summary
