"""Bad input to every verb of the command line: one clear line on stderr and a non-zero exit,
never a traceback, a hang or silent nonsense. Each case runs ``main`` in-process (an uncaught
exception fails the test) and stops before any simulation or synthesis starts."""

import json

import numpy as np
import pytest

from mpu9250_ahrs.cli import main


def broad_file(path, n=50, rate=100.0, **override):
    """A small BROAD-format file; ``override`` replaces datasets or the rate."""
    import h5py
    rng = np.random.default_rng(0)
    data = {"imu_gyr": rng.normal(0, 0.01, (n, 3)),
            "imu_acc": np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.05, (n, 3)),
            "imu_mag": np.tile([20.0, 0.0, -40.0], (n, 1)) + rng.normal(0, 0.3, (n, 3)),
            "opt_quat": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
            "movement": np.ones(n, bool)}
    data.update({k: v for k, v in override.items() if k != "sampling_rate"})
    with h5py.File(path, "w") as f:
        for k, v in data.items():
            if isinstance(v, dict):             # a group in place of a dataset
                group = f.create_group(k)
                for kk, vv in v.items():
                    group[kk] = vv
            elif isinstance(v, str) and v == "huge":
                # declared 10^9 x 3 (24 GB), nothing written: its shape is checked first
                f.create_dataset(k, shape=(10 ** 9, 3), dtype=float)
            elif v is not None:
                f[k] = v
        f.attrs["sampling_rate"] = override.get("sampling_rate", rate)
    return str(path)


def sparse_broad_file(path, n):
    """A BROAD file of ``n`` rows declared, none written (a few KB on disk)."""
    import h5py
    with h5py.File(path, "w") as f:
        for name, width in (("imu_gyr", 3), ("imu_acc", 3), ("imu_mag", 3), ("opt_quat", 4)):
            f.create_dataset(name, shape=(n, width), dtype=float)
        f.create_dataset("movement", shape=(n,), dtype=bool)
        f.attrs["sampling_rate"] = 100.0
    return str(path)


def test_build_out_a_file_is_one_line_naming_the_option(capsys, tmp_path):
    """Issue #60: ``build --out afile`` said "File exists"."""
    afile = tmp_path / "afile"
    afile.write_text("")
    for extra in ([], ["--verilog-only"]):
        code, out, err = run(["build", "--out", str(afile), *extra], capsys)
        assert_one_error(code, err, "--out", "is a file; build writes a folder")


def test_replay_reads_only_the_samples_asked_for(capsys, tmp_path):
    """``replay --samples N`` reads the first N rows alone: a file declaring more rows than
    the machine could hold is replayed in its first part (its truth is 0 here: refused)."""
    path = sparse_broad_file(tmp_path / "sparse.hdf5", 90_000_000)
    code, out, err = run(["replay", path, "--samples", "100"], capsys)
    assert code == 2 and "not a unit quaternion" in err and "fit" not in err


def run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as e:             # argparse's usage errors
        code = e.code
    out = capsys.readouterr()
    return code, out.out, out.err


def assert_one_error(code, err, *words):
    assert code not in (0, None), err
    assert "Traceback" not in err
    lines = [l for l in err.splitlines() if "error" in l]
    assert len(lines) == 1, err
    for w in words:
        assert w.lower() in lines[0].lower(), lines[0]


SIMULATE = [
    (["--samples", "0"], "less than 1"),
    (["--samples", "-5"], "less than 1"),
    (["--samples", "many"], "not an integer"),
    (["--odr-scale", "0"], "more than 0"),
    (["--odr-scale", "nan"], "finite"),
    (["--delay-scale", "-1"], "more than 0"),
    (["--clk-freq", "0"], "more than 0"),
    (["--gyro-fs", "300"], "gyro full scale"),
    (["--accel-fs", "3"], "full scale"),
    (["--odr", "0"], "more than 0"),
    (["--odr", "7"], "1000/n"),
    (["--odr", "100", "--dlpf", "1"], "leave out"),
    (["--dlpf", "9"], "dlpf_cfg"),
    (["--baud", "0"], "less than 1"),
    # a ZeroDivisionError traceback, and a divider named where the baud was the matter
    (["--baud", "100000000"], "the UART needs at least 4"),
    (["--baud", "10"], "a faster baud"),
    (["--telemetry-divider", "0"], "less than 1"),
    (["--i2c-address", "0x50", "--wiring", "i2c"], "i2c_address"),
    (["--who-am-i", "-1"], "less than 0"),
    (["--fault", "nonsense"], "unknown fault"),
    (["--fault", "i2c_bus_stuck"], "i2c wiring"),
    (["--fault", "ak8963_lost", "--no-mag"], "magnetometer"),
    (["--fault", "ak8963_lost", "--attitude"], "leave out"),
    (["--fault", "ak8963_lost", "--fault-at", "0"], "less than 1"),
    (["--odr", "8000", "--wiring", "i2c"], "more than this design filters"),
    # issue #55: the option named, and the waveform's file and window checked before a run
    (["--pose", "30,x,2"], "--pose: '30,x,2'"),
    (["--pose", "30,2"], "--pose"),
    (["--pose", "30,nan,2", "--attitude"], "--pose"),
    # issue #60: accepted and shown as roll 120, pitch 80 without a word
    (["--pose", "300,100,45", "--attitude"], "outside roll and yaw ±180°"),
    (["--vcd", "out/sim.txt"], "ends in .vcd or .fst"),
    (["--trace-from", "3"], "give --vcd"),
    (["--vcd", "out/x.vcd", "--trace-from", "3q"], "--trace-from: '3q'"),
    (["--vcd", "out/x.vcd", "--trace-to", "-1ms"], "--trace-to"),
    (["--vcd", "out/x.fst", "--trace-from", "5", "--trace-to", "4"], "before it starts"),
]


BUILD = [
    (["--pin", "imu_sclk"], "NAME=BALL"),
    (["--pin", "imu_sclk=Z9"], "not a ball"),
    (["--pin", "imu_sclk=N14"], "not a ball"),
    (["--pin", "imu_sclk=H6"], "both on ball"),
    (["--pin", "nothing=A1"], "unknown pin names"),
    (["--clk-freq", "-4"], "more than 0"),
    (["--clk-freq", "7e6"], "baud"),
    (["--gyro-fs", "300"], "gyro full scale"),
    (["--baud", "20000000"], "the UART needs at least 4"),
]


# report counts the build its options make: it refuses what build refuses (--baud was ignored)
REPORT = [(["--clk-freq", "0"], "more than 0"), (["--accel-fs", "32"], "full scale"),
          (["--odr", "3"], "1000/n"), (["--baud", "100000000"], "the UART needs at least 4")]


CASES = [("simulate", a, w) for a, w in SIMULATE] + [("build", a, w) for a, w in BUILD] + \
    [("report", a, w) for a, w in REPORT]


@pytest.mark.parametrize("verb,args,words", CASES,
                         ids=[" ".join([v, *a]) for v, a, _ in CASES])
def test_bad_input(verb, args, words, capsys, tmp_path):
    """simulate, build and report: one error line each (build writes nothing)."""
    out_dir = ["--out", str(tmp_path / "q")] if verb == "build" else []
    code, out, err = run([verb, *out_dir, *args], capsys)
    assert_one_error(code, err, words)
    assert not (tmp_path / "q" / "top.v").exists()


def _replay_cases(tmp_path):
    n = 50
    text = tmp_path / "text.hdf5"
    text.write_text("not HDF5")
    return [
        (str(tmp_path / "missing.hdf5"), [], "cannot be read"),
        (str(text), [], "cannot be read"),
        # issue #55: a folder, in one line naming it (was h5py's 300 characters)
        (str(tmp_path), [], "a folder, not a file"),
        (broad_file(tmp_path / "shape.hdf5", imu_gyr=np.zeros((n, 2))), [], "shape"),
        (broad_file(tmp_path / "length.hdf5", imu_acc=np.zeros((n - 1, 3))), [], "shape"),
        (broad_file(tmp_path / "empty.hdf5", n=0), [], "at least 2"),
        (broad_file(tmp_path / "rate0.hdf5", sampling_rate=0.0), [], "sampling_rate"),
        (broad_file(tmp_path / "nomag.hdf5", imu_mag=None), [], "missing imu_mag"),
        # issue #60: a rate no recording has (scored 100°, or JSON's "out of range float"),
        # a complex or an array rate (used silently), no truth at all (null, exit 0, no line),
        # five consistent sparse datasets of 90 M rows (a MemoryError traceback after 15 s)
        (broad_file(tmp_path / "rate_tiny.hdf5", sampling_rate=1e-9), [],
         "not a recording's rate"),
        (broad_file(tmp_path / "rate_complex.hdf5", sampling_rate=100 + 1j), [], "complex"),
        (broad_file(tmp_path / "rate_array.hdf5", sampling_rate=np.array([100.0, 50.0])), [],
         "one real number"),
        (broad_file(tmp_path / "truth_nan.hdf5", opt_quat=np.full((n, 4), np.nan)), [],
         "no known row"),
        (sparse_broad_file(tmp_path / "sparse.hdf5", 90_000_000), [], "do not fit"),
        (broad_file(tmp_path / "allnan.hdf5", imu_gyr=np.full((n, 3), np.nan)), [],
         "no sample has finite"),
        (broad_file(tmp_path / "ok.hdf5"), ["--gyro-fs", "0"], "gyro full scale"),
        (broad_file(tmp_path / "ok2.hdf5"), ["--gyro-fs", "300"], "gyro full scale"),
        (broad_file(tmp_path / "ok3.hdf5"), ["--accel-fs", "5"], "full scale"),
        (broad_file(tmp_path / "ok5.hdf5"), ["--beta", "-1"], "more than 0"),
        # issue #25: truth that is no rotation (scaled x10^6, all zero) is refused, not
        # scored 0.0 or 180 degrees
        (broad_file(tmp_path / "scaled.hdf5", opt_quat=np.tile([1e6, 0, 0, 0], (n, 1))), [],
         "not a unit quaternion"),
        (broad_file(tmp_path / "zero.hdf5", opt_quat=np.zeros((n, 4))), [],
         "not a unit quaternion"),
        (broad_file(tmp_path / "group.hdf5", imu_gyr={"x": np.zeros(3)}), [], "group"),
        (broad_file(tmp_path / "huge.hdf5", imu_acc="huge"), [], "shape"),
    ]


def test_replay_bad_input(capsys, tmp_path):
    for path, args, words in _replay_cases(tmp_path):
        code, out, err = run(["replay", path, *args], capsys)
        assert_one_error(code, err, words)


def test_replay_nan_samples_are_held_and_counted(capsys, tmp_path):
    """NaN sensor values become neither −2³¹ counts nor a silent jump: held at the previous
    sample, counted in ``samples_held`` and announced on stderr."""
    n = 60
    gyr = np.zeros((n, 3))
    gyr[10:13] = np.nan
    path = broad_file(tmp_path / "nan.hdf5", n=n, imu_gyr=gyr)
    for engine in ("float", "fixed"):
        code, out, err = run(["replay", path, "--filter", "flagship", "--engine", engine],
                             capsys)
        assert code == 0, err
        result = json.loads(out)
        assert result["samples_held"] == 3
        assert "3 samples" in err and "held" in err
        assert result["inclination_rmse_deg"] < 5


def test_replay_counts_samples_at_a_full_scale_limit(capsys, tmp_path):
    """A full scale too narrow for the motion: the clipped samples are counted per sensor
    (``samples_at_limit``) and named on stderr, so a poor score has its reason."""
    n = 60
    gyr = np.zeros((n, 3))
    gyr[10:14, 2] = np.radians(300)             # beyond ±250 °/s, within ±500
    path = broad_file(tmp_path / "fast.hdf5", n=n, imu_gyr=gyr)
    code, out, err = run(["replay", path, "--gyro-fs", "250"], capsys)
    assert code == 0, err
    assert json.loads(out)["samples_at_limit"] == {"gyro": 4, "accel": 0, "mag": 0}
    assert "4 samples have a gyro axis at the limit of ±250 °/s" in err
    code, out, err = run(["replay", path, "--gyro-fs", "500"], capsys)
    assert json.loads(out)["samples_at_limit"]["gyro"] == 0 and "limit" not in err


def test_replay_leaves_out_truth_that_is_no_rotation(capsys, tmp_path):
    """Some truth rows not of unit norm: left out of the score, counted and announced."""
    n = 60
    truth = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    truth[5:9] *= 1e6
    truth[20] = 0
    path = broad_file(tmp_path / "partly.hdf5", n=n, opt_quat=truth)
    code, out, err = run(["replay", path, "--filter", "flagship"], capsys)
    assert code == 0, err
    result = json.loads(out)
    assert result["truth_rejected"] == 5 and result["samples"] == n - 5
    assert "5 truth quaternions" in err


def test_replay_score_is_the_same_for_a_truth_off_unit_norm(capsys, tmp_path):
    """Trial 02 with its truth scaled by 1 ± 1e-4 … 1e-2 (within the loader's tolerance):
    the same score to 0.01° (it scored 0.0° at × 1.001 and 11.5° at × 0.995, for 1.33°)."""
    import h5py
    from tests.conftest import broad_files
    trial = [f for f in broad_files() if "/02_" in f]
    if not trial:
        pytest.skip("the BROAD recordings are not in ../shared/data/broad/")

    def score(scale):
        path = tmp_path / f"scaled_{scale}.hdf5"
        with h5py.File(trial[0], "r") as src, h5py.File(path, "w") as dst:
            for name in ("imu_gyr", "imu_acc", "imu_mag", "movement"):
                dst[name] = src[name][()]
            dst["opt_quat"] = src["opt_quat"][()] * scale
            dst.attrs["sampling_rate"] = src.attrs["sampling_rate"]
        # its first 25,000 samples (half of it, 13,551 of them in motion, 1.03° total): the
        # default run's time
        code, out, err = run(["replay", str(path), "--samples", "25000"], capsys)
        assert code == 0, err
        result = json.loads(out)
        assert result["truth_rejected"] == 0 and result["samples"] > 10_000
        return [result[k] for k in ("total_rmse_deg", "heading_rmse_deg",
                                    "inclination_rmse_deg")]
    exact = score(1.0)
    assert 0.8 < exact[0] < 1.7
    for scale in (1 - 0.0099, 1 - 1e-3, 1 - 1e-4, 1 + 1e-4, 1 + 1e-3, 1 + 0.0099):
        assert score(scale) == pytest.approx(exact, abs=0.01), scale


def test_replay_without_scored_samples_prints_null(capsys, tmp_path):
    """No movement sample with a truth: RMSE is JSON null with a reason, not a bare NaN."""
    n = 40
    path = broad_file(tmp_path / "still.hdf5", n=n, movement=np.zeros(n, bool))
    code, out, err = run(["replay", path, "--filter", "madgwick"], capsys)
    assert code == 0, err
    result = json.loads(out)
    assert result["total_rmse_deg"] is None and result["rmse_note"]


def test_simulate_fault_list(capsys):
    from mpu9250_ahrs.sim.scenarios.faults import FAULTS
    code, out, err = run(["simulate", "--fault", "list"], capsys)
    assert code == 0
    assert [line.split()[0] for line in out.splitlines()] == list(FAULTS)


def test_host_verbs_bad_input(capsys, tmp_path):
    """The host verbs (monitor, config, calibrate, plot) and build --calibration: bad options
    and bad files, each one line (no port is opened for any of them but the missing one)."""
    bad_json = tmp_path / "bad.json"
    bad_json.write_text("{not json")
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"gyro_offset": [1, 2], "accel_offset": [0, 0, 0],
                                 "accel_scale": [1, 1, 1], "hard_iron": [0, 0, 0],
                                 "soft_iron": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}))
    huge = tmp_path / "huge.json"
    huge.write_text(json.dumps({"gyro_offset": [1e9, 0, 0], "accel_offset": [0, 0, 0],
                                "accel_scale": [1, 1, 1], "hard_iron": [0, 0, 0],
                                "soft_iron": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}))
    not_a_log = tmp_path / "x.csv"
    not_a_log.write_text("a,b\n1,2\n")
    # issue #25: each of these gave a traceback
    cal = {"gyro_offset": [0, 0, 0], "accel_offset": [0, 0, 0], "accel_scale": [1, 1, 1],
           "hard_iron": [0, 0, 0], "soft_iron": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}
    strings = tmp_path / "strings.json"
    strings.write_text(json.dumps({**cal, "gyro_offset": ["1", "2", "3"]}))
    singular = tmp_path / "singular.json"
    singular.write_text(json.dumps({**cal, "soft_iron": [[1, 0, 0], [0, 1, 0], [0, 0, 0]]}))
    mirrored = tmp_path / "mirrored.json"
    mirrored.write_text(json.dumps({**cal, "soft_iron": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}))
    # issue #60: tracebacks (OverflowError), every result saturated, the field zeroed
    hostile = {}
    for name, key, value in (
            ("digits", "gyro_offset", [int("9" * 401), 0, 0]),
            ("soft_e308", "soft_iron", [[1e308, 0, 0], [0, 1e308, 0], [0, 0, 1e308]]),
            ("soft_1000", "soft_iron", [[1000, 0, 0], [0, 1000, 0], [0, 0, 1000]]),
            ("soft_tiny", "soft_iron", [[1e-5, 0, 0], [0, 1e-5, 0], [0, 0, 1e-5]]),
            ("turn_180", "soft_iron", [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]),
            ("rotation", "soft_iron", [[0, -1, 0], [1, 0, 0], [0, 0, 1]]),
            ("hard_big", "hard_iron", [40000, 0, 0])):
        hostile[name] = tmp_path / f"{name}.json"
        hostile[name].write_text(json.dumps({**cal, key: value}))
    header = "type,host_time_s,roll_deg,pitch_deg,yaw_deg,sample.gyro.0,sample.gyro.1"
    no_column = tmp_path / "nocol.csv"
    no_column.write_text(header + "\n2,0.1,1,2,3,4,5\n")
    extra = tmp_path / "extra.csv"
    extra.write_text(header + ",sample.gyro.2\n2,0.1,1,2,3,4,5,6,7\n")
    import h5py
    empty_h5 = tmp_path / "empty.h5"
    with h5py.File(empty_h5, "w"):
        pass
    groups_h5 = tmp_path / "groups.h5"
    with h5py.File(groups_h5, "w") as f:
        f.create_group("type")
    png = str(tmp_path / "p.png")
    cases = [
        (["monitor", "/dev/no-such-tty"], "no such serial port"),
        (["monitor", "sim", "--frames", "0"], "less than 1"),
        (["monitor", "sim", "--timeout", "-1"], "more than 0"),
        (["config", "sim", "frobnicate"], "invalid choice"),
        (["config", "sim", "set", "R"], "takes 2 argument"),
        # a traceback (argparse's error type, raised outside argparse) before
        (["config", "sim", "rate", "0"], "more than 0"),
        (["config", "sim", "rate", "fast"], "not a number"),
        (["plot", str(tmp_path / "none.csv"), "--out", str(tmp_path / "p.png")],
         "none.csv: no such file"),        # the path first, not "[Errno 2] ...: '...'"
        (["plot", str(not_a_log), "--out", str(tmp_path / "p.png")], "not a monitor log"),
        (["build", "--calibration", str(tmp_path / "none.json")], "no such file"),
        (["build", "--calibration", str(bad_json)], "not json"),
        (["build", "--calibration", str(wrong)], "gyro_offset"),
        (["build", "--calibration", str(huge)], "out of range"),
        (["build", "--calibration", str(strings)], "not numbers"),
        (["build", "--calibration", str(singular)], "singular"),
        (["build", "--calibration", str(mirrored)], "mirrored"),
        (["build", "--calibration", str(hostile["digits"])], "finite numbers"),
        (["build", "--calibration", str(hostile["soft_e308"])], "out of range"),
        (["build", "--calibration", str(hostile["soft_1000"])], "-2 .. 2 (Q2.14)"),
        (["build", "--calibration", str(hostile["soft_tiny"])], "quantised to Q2.14"),
        (["build", "--calibration", str(hostile["turn_180"])], "not positive definite"),
        (["build", "--calibration", str(hostile["rotation"])], "not symmetric"),
        (["build", "--calibration", str(hostile["hard_big"])], "hard_iron"),
        (["plot", str(no_column), "--out", png], "sample.gyro.2"),
        (["plot", str(extra), "--out", png], "more fields"),
        (["plot", str(empty_h5), "--out", png], "not a monitor log"),
        (["plot", str(groups_h5), "--out", png], "not a monitor log"),
    ]
    for argv, words in cases:
        code, out, err = run(argv, capsys)
        assert_one_error(code, err, words)


def test_benchmark_bad_recording(tmp_path, capsys):
    from mpu9250_ahrs.sim.scenarios.benchmark import main as benchmark
    bad = tmp_path / "bad.hdf5"
    bad.write_text("not HDF5")
    for path in (str(tmp_path / "missing.hdf5"), str(bad)):
        code = benchmark([path, "--no-fixed"])
        assert_one_error(code, capsys.readouterr().err, "HDF5")


def test_benchmark_checks_its_output_paths_first(tmp_path, capsys):
    """Issue #29: the benchmark's --json/--figure folders are made before the trials run, and
    a folder given for a file is one error line before any work (a missing recording would
    otherwise be the first error)."""
    from mpu9250_ahrs.sim.scenarios.benchmark import main as benchmark
    missing = str(tmp_path / "missing.hdf5")
    code = benchmark([missing, "--no-fixed", "--json", str(tmp_path)])
    assert_one_error(code, capsys.readouterr().err, "not a writable file path")
    code = benchmark([missing, "--no-fixed", "--json", str(tmp_path / "new" / "b.json")])
    assert (tmp_path / "new").is_dir()
    assert_one_error(code, capsys.readouterr().err, "HDF5")


def test_output_folders_are_made_before_the_work(capsys, tmp_path):
    """Issue #29: a file a verb writes into a folder that is not there yet: the folder is made
    before any work starts (calibrate lost its fitted result at the very end this way); a
    folder given for a file is one error line; ``--version`` answers."""
    n = 40
    path = broad_file(tmp_path / "rec.hdf5", n=n)
    out = tmp_path / "new" / "deeper" / "q.csv"
    code, _, err = run(["replay", path, "--filter", "madgwick", "--out", str(out)], capsys)
    assert code == 0, err
    assert out.is_file()
    code, _, err = run(["replay", path, "--out", str(tmp_path)], capsys)
    assert_one_error(code, err, "is a folder")
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and "mpu9250-ahrs" in capsys.readouterr().out


def test_an_interrupted_verb_says_what_it_kept(monkeypatch, tmp_path, capsys):
    """Issue #29: Ctrl-C gives one line saying what was kept, no traceback, exit 130."""
    import mpu9250_ahrs.cli as cli
    from mpu9250_ahrs.cli import gateware, host_verbs

    def interrupted(args):
        (tmp_path / "partial.csv").write_text("host_time_s\n")
        raise KeyboardInterrupt
    monkeypatch.setattr(host_verbs, "cmd_monitor", interrupted)
    assert cli.main(["monitor", "sim", "--csv", str(tmp_path / "partial.csv")]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"mpu9250-ahrs monitor: interrupted; kept as far as it got: "
                   f"{tmp_path / 'partial.csv'}"]
    monkeypatch.setattr(gateware, "cmd_report",
                        lambda args: (_ for _ in ()).throw(KeyboardInterrupt))
    assert cli.main(["report"]) == 130
    assert capsys.readouterr().err.strip() == \
        "mpu9250-ahrs report: interrupted; nothing was written"


ENTRY_POINTS = [
    # issue #60: tracebacks, or exit 0 with "trials": -5
    (["reference.soak", "--rate", "0"], "--rate: 0 is not a finite number above 0"),
    (["reference.soak", "--samples", "-1"], "--samples: -1 is less than 1"),
    (["host.protocol", "abc"], "'abc' is not a whole number"),
    (["host.protocol", "-5"], "-5 is less than 1"),
    (["sim.scenarios.benchmark", "x.hdf5", "--jobs", "0"], "--jobs: 0 is less than 1"),
    (["sim.scenarios.faults", "--wiring", "usb"], "invalid choice"),
]


def _entry(args, **kw):
    import subprocess
    import sys
    import signal
    module = "mpu9250_ahrs" + (f".{args[0]}" if args[0] else "")     # "": the verbs
    # SIGINT as a terminal delivers it, whoever started the tests (a process started by one
    # that ignores SIGINT, a script's background job, inherits that and ignores Ctrl-C)
    return subprocess.Popen([sys.executable, "-m", module, *args[1:]],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            **kw)


def test_python_m_entry_points_bad_arguments():
    """The README's ``python -m`` tools hold to the verbs' rules: one error line, no
    traceback, a non-zero exit."""
    runs = [(_entry(args), words) for args, words in ENTRY_POINTS]
    for proc, words in runs:
        out, err = proc.communicate(timeout=120)
        assert_one_error(proc.returncode, err, words)


@pytest.mark.slow
def test_python_m_entry_points_ctrl_c_is_one_line():
    """Ctrl-C in a long ``python -m`` tool: one line, exit 130 (was a 23-40 line traceback;
    the benchmark's workers each printed theirs too)."""
    import signal
    import time
    from tests.conftest import broad_files
    long_runs = [["reference.soak", "--samples", "100000000"], ["sim.scenarios.faults"]]
    if broad_files():
        long_runs.append(["sim.scenarios.benchmark", broad_files()[0], "--jobs", "2"])
    procs = [_entry(args) for args in long_runs]
    time.sleep(6)                                   # imported and working
    for proc in procs:
        proc.send_signal(signal.SIGINT)
    for args, proc in zip(long_runs, procs):
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, (args, err)
        assert "Traceback" not in err and err.strip().splitlines()[-1].endswith(
            "interrupted"), (args, err)


def test_plot_of_columns_no_axis_can_draw(capsys, tmp_path):
    """Issue #60: a 2-D column read "shape (4, 4), expected (4, 4)"; values of ±1e308 ended in
    matplotlib's "arange: cannot compute length"."""
    import h5py
    columns = ["type", "host_time_s", "roll_deg", "pitch_deg", "yaw_deg",
               *(f"sample.gyro.{i}" for i in range(3))]
    two_d, huge = tmp_path / "twod.h5", tmp_path / "huge.h5"
    with h5py.File(two_d, "w") as f:
        for c in columns:
            f[c] = np.zeros((4, 4))
    with h5py.File(huge, "w") as f:
        for c in columns:
            f[c] = np.array([-1e308, 1e308, 0.0, 0.0]) if c == "roll_deg" else np.arange(4.0)
    png = str(tmp_path / "p.png")
    for path, words in ((two_d, "one-dimensional"), (huge, "column roll_deg spans inf")):
        code, out, err = run(["plot", str(path), "--out", png], capsys)
        assert_one_error(code, err, words)


@pytest.mark.slow
def test_simulate_ctrl_c_keeps_what_was_simulated(tmp_path):
    """Issue #60: Ctrl-C on a long ``simulate`` kept nothing ("interrupted; nothing was
    written"; the samples are printed at the end). Now the samples simulated so far, the
    summary (``interrupted``: true) and the waveform up to there are kept; exit 130."""
    import signal
    import time
    vcd = tmp_path / "cut.vcd"
    proc = _entry(["", "simulate", "--simulator", "python", "--clk-freq", "4e6", "--baud",
                   "1000000", "--no-self-test", "--samples", "1000000", "--vcd", str(vcd)])
    # the VCD is opened as the simulation starts: interrupted a moment after (bring-up is
    # about a second of this simulation; under load fewer samples, or none, are kept)
    for _ in range(600):
        if vcd.exists():
            break
        time.sleep(0.1)
    time.sleep(3)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "Traceback" not in err, err
    lines = out.strip().splitlines()
    samples = [json.loads(line) for line in lines if line.startswith('{"counter"')]
    summary = json.loads(next(line for line in lines if '"interrupted"' in line))
    # (how many depends on the machine's load: tests/sim/test_compiled_bench.py counts them)
    assert summary["interrupted"] is True and summary["samples"] == len(samples)
    assert err.strip().splitlines()[-1] == (f"mpu9250-ahrs simulate: interrupted; kept what "
                                            f"was simulated ({len(samples)} samples)")
    assert vcd.stat().st_size > 0 and (tmp_path / "cut.gtkw").is_file()
