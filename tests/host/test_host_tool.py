"""The host tool against the co-simulated board through a real serial device (a
pseudo-terminal): every verb, bad input on the port, and the errors a user meets."""

import csv
import json
import os
import random
import threading
import time

import pytest
import serial

from mpu9250_ahrs.cli import main
from mpu9250_ahrs.hdl.link.frame_types import ATTITUDE, FRAME_TYPES
from mpu9250_ahrs.hdl.link.frame_types import payload_bytes
from mpu9250_ahrs.host.link import SIM_BOARDS, open_link
from mpu9250_ahrs.host.protocol import encode_frame
from mpu9250_ahrs.sim.scenarios.board import SensorErrors, SimulatedBoard, garble, pty_baud


def run_cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def board():
    """One simulated board for the configuration tests, served on a pseudo-terminal; the
    tool opens its path like any serial device."""
    b = SimulatedBoard().start()
    SIM_BOARDS[b.port] = b                 # time-outs in the board's time (it is slow)
    yield b
    SIM_BOARDS.pop(b.port, None)
    b.stop()


def test_monitor_sim_logs_frames_without_crc_errors(capsys, tmp_path):
    log = tmp_path / "x.csv"
    rc, out, err = run_cli(capsys, "monitor", "sim", "--frames", 20, "--csv", log)
    assert rc == 0, err
    summary = json.loads(out)
    assert summary["frames"] == 20 and summary["crc_errors"] == 0 and summary["lost_frames"] == 0
    with open(log) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 20 and {r["type"] for r in rows} == {str(ATTITUDE)}
    assert "crc errors 0" in err and "lost 0" in err                    # the live line
    counters = [int(r["sample.counter"]) for r in rows]
    assert counters == sorted(counters)
    rc, out, err = run_cli(capsys, "plot", log, "--out", tmp_path / "x.png")
    assert rc == 0 and (tmp_path / "x.png").stat().st_size > 10_000


def frames_after(board, n=3):
    with open_link(board.port) as link:
        return [f for _, _, f in link.frames(n, types=(ATTITUDE,))]


def test_config_filter_select_shows_in_the_frames(board, capsys):
    rc, out, err = run_cli(capsys, "config", board.port, "filter", "complementary")
    assert rc == 0, err
    assert all(f["attitude"]["flags"]["filter"] == 1 for f in frames_after(board))
    rc, out, err = run_cli(capsys, "config", board.port, "filter", "flagship")
    assert rc == 0 and json.loads(out) == {"filter": "flagship"}
    assert all(f["attitude"]["flags"]["filter"] == 2 for f in frames_after(board))


def test_config_set_reads_back_and_refuses_what_it_must(board, capsys):
    rc, out, err = run_cli(capsys, "config", board.port, "set", "R", "3.5")
    assert rc == 0, err
    assert json.loads(out)["value"] == 3.5
    rc, out, err = run_cli(capsys, "config", board.port, "get", "R")
    assert rc == 0 and json.loads(out) == {"name": "R", "value": 3.5, "unit": "deg²",
                                           "word": 3.5 * 2 ** 24, "format": "Q8.24"}
    rc, out, err = run_cli(capsys, "config", board.port, "set", "GATE_DIP", "12.5")
    assert rc == 0 and abs(json.loads(out)["value"] - 12.5) < 1e-6
    for args, message in [(("set", "ZERO", "1"), "read-only"),
                          (("set", "NOPE", "1"), "no register"),
                          # a PWM refusal says which rule, with the registers it reads
                          (("set", "PWM_SERVO_PERIOD", "100"), "is 2,500 .. 20,000 µs"),
                          (("set", "PWM_HIGH0", "30000"),
                           "more than channel 0's period (servo mode: PWM_SERVO_PERIOD = "
                           "20,000 µs)"),
                          (("set", "PWM_ENABLE", "16"), "16 is not bits 3:0"),
                          (("set", "R", "1e12"), "out of range 0 .. 128"),
                          # issue #25: 200 s wrapped to -56 s and its read-back passed
                          (("set", "T", "200"), "out of range 3.125e-05 .. 1 s"),
                          (("get",), "takes 1 argument")]:
        rc, out, err = run_cli(capsys, "config", board.port, *args)
        assert rc != 0 and message in err and len(err.strip().splitlines()) == 1, err


def test_config_rate_and_reset(board, capsys):
    rc, out, err = run_cli(capsys, "config", board.port, "rate", "50")
    assert rc == 0, err
    result = json.loads(out)
    assert result["divider"] == 4 and result["sample_rate_hz"] == pytest.approx(200, rel=1e-6)
    filtered = [f["counters"]["filtered"] for f in frames_after(board, 3)]
    assert [b - a for a, b in zip(filtered, filtered[1:])] == [4, 4]
    # beyond the divider's range: the nearest rate set, and a warning says so
    rc, out, err = run_cli(capsys, "config", board.port, "rate", "100000")
    assert rc == 0 and json.loads(out)["divider"] == 1, err
    assert "warning: 100000 Hz is beyond the telemetry's range" in err
    rc, out, err = run_cli(capsys, "config", board.port, "rate", "200")
    assert rc == 0 and "warning" not in err
    rc, out, err = run_cli(capsys, "config", board.port, "reset")
    assert rc == 0 and json.loads(out) == {"reset": True}


def test_garbage_on_the_port_is_counted_and_changes_nothing(board):
    from mpu9250_ahrs.host.config import get
    names = ("CMD_DISCARDED", "CMD_CRC_ERRORS", "R", "CONTROL")
    rng = random.Random(7)
    junk = rng.randbytes(300).replace(b"\xa5", b"\x00")            # noise ...
    bad = bytearray(encode_frame(0x10, 1, bytes(6)))
    bad[7] ^= 0x10                                                   # ... and a corrupt write
    with open_link(board.port) as link:
        before = {n: get(link, n)["value"] for n in names}
        link.serial.write(junk + bytes(bad))
        link.serial.flush()
        board.wait_cycles(320 * 40 * 2)                              # the bytes' time on the line
        after = {n: get(link, n)["value"] for n in names}
        assert len(list(link.frames(2, types=(ATTITUDE,)))) == 2    # and it goes on
    assert after["CMD_DISCARDED"] >= before["CMD_DISCARDED"] + 300
    assert after["CMD_CRC_ERRORS"] == before["CMD_CRC_ERRORS"] + 1
    assert after["R"] == before["R"] and after["CONTROL"] == before["CONTROL"]


def test_calibrate_recovers_the_offsets_the_model_was_given(board, capsys, tmp_path):
    """On the simulated board (its path: the tool finds the board in this process and plays
    the user who turns it; ``calibrate sim`` does the same with a board of its own)."""
    out_json = tmp_path / "cal.json"
    rc, out, err = run_cli(capsys, "calibrate", board.port, "--quick", "--out", out_json)
    assert rc == 0, err
    result = json.loads(out_json.read_text())
    truth = SensorErrors()
    # the bias is the mean of --quick's 12 rest samples, wherever the board's (seeded) noise
    # is when the step starts (the module's board has run the tests before): within four
    # standard errors of that noise. 1.5 counts was 2.6 of them, and the noise has 12-sample
    # windows off by 1.92 (the samples from counter 121: a flaky failure, 33.08 for 35)
    rest = 12
    assert result["gyro_offset"] == pytest.approx(truth.gyro_offset,
                                                  abs=4 * truth.gyro_noise / rest ** 0.5)
    assert result["accel_offset"] == pytest.approx(truth.accel_offset, abs=8)
    assert [1 / s for s in result["accel_scale"]] == pytest.approx(truth.accel_scale, abs=0.01)
    assert result["hard_iron"] == pytest.approx(truth.hard_iron, abs=4)
    assert result["checks"]["mag_spread_percent"] < 3
    # baked in by build: the calibration's registers become reset values
    rc, _, err = run_cli(capsys, "build", "--verilog-only", "--out", tmp_path / "v",
                         "--calibration", out_json)
    assert rc == 0, err


def test_calibrate_names_a_full_scale_that_is_not_the_boards(board, capsys, tmp_path):
    """The board reads ±16 g; told ±2 g, the tool said the z axis "was not pointing up" (a
    reading of 0.14 g): now it says which full scale the readings look like."""
    rc, out, err = run_cli(capsys, "calibrate", board.port, "--quick", "--accel-fs", 2,
                           "--out", tmp_path / "cal.json")
    assert rc == 2 and "full scale looks like ±16 g, not the ±2 g given" in err, err
    assert not (tmp_path / "cal.json").exists()


# -- errors a user meets --------------------------------------------------------------------

class FakeBoard:
    """A pseudo-terminal with a thread writing attitude frames at 921,600 baud's pace (the
    bytes garbled as a UART at the host's baud would see them), and no command channel."""
    def __init__(self, send=True):
        self.master, slave = os.openpty()
        self.port = os.ttyname(slave)
        self.slave = slave
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run if send else lambda: None, daemon=True)
        self.thread.start()

    def run(self):
        seq = 0
        n = payload_bytes(FRAME_TYPES[ATTITUDE])
        while not self.stop.is_set():
            baud = pty_baud(self.master)
            frame = encode_frame(ATTITUDE, seq, random.randbytes(n))
            try:
                os.write(self.master, garble(frame, baud / 921_600))
            except OSError:
                pass
            seq += 1
            time.sleep(0.01)

    def close(self):
        self.stop.set()
        self.thread.join()
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture
def fake():
    boards = []

    def make(**kw):
        boards.append(FakeBoard(**kw))
        return boards[-1]
    yield make
    for b in boards:
        b.close()


def one_line_error(capsys, *argv):
    rc, out, err = run_cli(capsys, *argv)
    assert rc != 0 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_missing_port(capsys):
    assert "no such serial port" in one_line_error(capsys, "monitor", "/dev/no-such-tty")


def test_busy_port(capsys, fake):
    b = fake()
    holder = serial.Serial(b.port, exclusive=True)
    try:
        assert "busy" in one_line_error(capsys, "monitor", b.port, "--frames", "1")
    finally:
        holder.close()


def test_wrong_baud_and_silent_board(capsys, fake):
    b = fake()
    rc, out, err = run_cli(capsys, "monitor", b.port, "--frames", 5)          # right baud
    assert rc == 0 and json.loads(out)["frames"] == 5, err
    err = one_line_error(capsys, "monitor", b.port, "--baud", 115200, "--frames", 5)
    assert "wrong baud rate" in err
    silent = fake(send=False)
    assert "nothing received" in one_line_error(capsys, "monitor", silent.port, "--frames", 1)
    assert "did not answer" in one_line_error(capsys, "config", silent.port, "get", "R",
                                              "--timeout", "0.4")


def test_pty_baud_reads_any_baud_the_host_sets():
    """Issue #60: a baud outside termios' table (1,843,200) read as 921,600, the board's own."""
    master, slave = os.openpty()
    try:
        port = serial.Serial(os.ttyname(slave), 1_843_200)
        assert pty_baud(master) == 1_843_200
        port.baudrate = 460_800
        assert pty_baud(master) == 460_800
        port.close()
    finally:
        os.close(master)
        os.close(slave)


def test_a_host_at_another_baud_reaches_the_receiver_as_framing_errors(board, capsys):
    """Issue #60: the bridge turned the host's bytes at a wrong baud into bytes (a framing
    error into 0x00) before the design's receiver, so RX_FRAMING_ERRORS never counted; the
    line itself now reaches it. At half the board's baud a 0x55's stop bit falls on a low
    data bit: counted. The board answers at the right baud afterwards."""
    def framing_errors():
        rc, out, err = run_cli(capsys, "config", board.port, "get", "RX_FRAMING_ERRORS")
        assert rc == 0, err
        return json.loads(out)["value"]
    before = framing_errors()
    wrong = serial.Serial(board.port, 460_800)
    wrong.write(b"\x55" * 8)
    wrong.flush()
    # the bytes take 640 cycles; the port stays at 460,800 until well after (the next
    # command sets the shared pseudo-terminal back to 921,600)
    board.wait_cycles(60_000)
    wrong.close()
    assert framing_errors() >= before + 4


def test_a_board_started_twice_runs_one_simulation():
    """Issue #60: ``with SimulatedBoard().start() as b`` (start() returns the board) ran two
    simulation threads on one model, which died in the model's 'SCLK too fast' message."""
    def boards():
        return {t for t in threading.enumerate() if t.name == "simulated-board" and t.is_alive()}
    before = boards()
    with SimulatedBoard().start() as b:
        assert b.start() is b
        assert len(boards() - before) == 1
        b.wait_cycles(20_000)
    assert b.error is None
    with pytest.raises(RuntimeError, match="was stopped: make a new one"):
        b.start()


def _burst(board, link, n, first_seq):
    """``n`` commands written at once (reads and writes of T, alternately) while telemetry
    streams; returns {seq: reply fields} of the replies that came."""
    from mpu9250_ahrs.hdl.link.frame_types import REPLY
    from mpu9250_ahrs.host.protocol import encode_command, reply_of
    seqs = [(first_seq + k) % 256 for k in range(n)]
    data = b"".join(encode_command("write", s, addr=0x08, value=100 + k) if k % 2 else
                    encode_command("read", s, addr=0x08) for k, s in enumerate(seqs))
    link.serial.write(data)
    link.serial.flush()
    got, start = {}, board.cycles
    # a reply every 108 byte times at worst (each behind a telemetry frame), 40 cycles a byte
    while board.cycles - start < 200_000 + 108 * 40 * n and len(got) < n:
        for ftype, _seq, fields in link._read():
            if ftype == REPLY and fields["cmd_seq"] in seqs:
                got[fields["cmd_seq"]] = reply_of(fields)
        time.sleep(0.01)
    return seqs, got


def test_commands_sent_back_to_back_are_all_answered_or_the_loss_is_said(board):
    """#60: four commands written at once while telemetry streams lost the fourth (the
    decoder's 32-byte FIFO overflowed while a reply waited behind a 92-byte frame). Bursts of
    four, and one of ``MAX_BURST_COMMANDS``, are answered whole; a longer burst at full line
    rate cannot be (a reply is longer than a command): the bytes dropped are counted and the
    reply after them says so (``input_lost``)."""
    from mpu9250_ahrs.hdl.contract.commands import MAX_BURST_COMMANDS
    from mpu9250_ahrs.host.config import get
    with open_link(board.port) as link:
        overruns = get(link, "RX_OVERRUNS")["value"]
        seq = 100
        for _ in range(5):
            seqs, got = _burst(board, link, 4, seq)
            seq += 4
            assert sorted(got) == sorted(seqs)
            assert all(r["result_name"] == "ok" and not r["input_lost"] for r in got.values())
        seqs, got = _burst(board, link, MAX_BURST_COMMANDS, seq)
        seq += MAX_BURST_COMMANDS
        assert len(got) == MAX_BURST_COMMANDS and get(link, "RX_OVERRUNS")["value"] == overruns
        seqs, got = _burst(board, link, 2 * MAX_BURST_COMMANDS, seq)
        assert len(got) < len(seqs) and any(r["input_lost"] for r in got.values())
        assert get(link, "RX_OVERRUNS")["value"] > overruns
