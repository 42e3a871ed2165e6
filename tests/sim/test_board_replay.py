"""A shared recording through the whole co-simulated board (``replay --engine board``): the
frames the host decodes are bit for bit the fixed-point model's results for the samples the
board read, those samples are the recording's, and nothing is lost on the way."""

import json

import numpy as np
import pytest

from mpu9250_ahrs.cli import main
from mpu9250_ahrs.reference.recording import Scales, load_broad, quantise
from mpu9250_ahrs.sim.scenarios.board_replay import replay_board
from mpu9250_ahrs.sim.bench.compiled_design import verilator_available

from tests.conftest import broad_files

RECORDINGS = broad_files()
pytestmark = [pytest.mark.skipif(not RECORDINGS, reason="shared/data/broad not beside the "
                                                        "checkout"),
              pytest.mark.skipif(not verilator_available(), reason="needs verilator and g++")]


@pytest.mark.slow          # its core's build (14 s) is most of it; the whole trial is slow too
def test_first_samples_of_a_shared_trial_bit_exact():
    rec = load_broad(RECORDINGS[0])
    scales = Scales()
    counts = quantise(rec.gyr, rec.acc, rec.mag, scales)
    n = 400
    run = replay_board("flagship", *counts, rec.dt, samples=n,
                       gyro_lsb_per_dps=scales.gyro_lsb_per_dps,
                       accel_lsb_per_ms2=scales.accel_lsb_per_ms2)
    assert run.compiled and run.bit_exact and run.results_bit_exact, run.first_mismatch
    # every sample read and filtered, every divider-th framed, in order, from the first
    assert run.samples_read == n and run.counters["lost"] == 0
    assert list(run.indices) == list(range(0, n, run.divider))
    assert run.frames == len(run.indices) and run.quat.shape == (run.frames, 4)
    assert np.allclose(np.linalg.norm(run.quat, axis=1), 1, atol=1e-6)
    # the AK8963 at 100 Hz of the recording's time: about one sample in 1/(100 dt) has a field
    assert abs((n - run.mag_not_valid) - n * 100 * rec.dt) <= 3


@pytest.mark.slow
def test_a_whole_shared_trial_through_the_board(capsys):
    """The issue's figure: a whole recording, every frame bit-exact (about 4 minutes)."""
    assert main(["replay", RECORDINGS[0], "--engine", "board", "--quiet"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["bit_exact"] and result["results_bit_exact"]
    assert result["board_samples_read"] == len(load_broad(RECORDINGS[0]).quat)
    assert result["counters"]["lost"] == 0 and result["total_rmse_deg"] is not None
