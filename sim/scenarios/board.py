"""A simulated board on a real serial device: the whole ``AHRSCore`` (models, driver, engine,
telemetry, command channel, PWM) co-simulated, its UART pins bridged to a pseudo-terminal.

``SimulatedBoard.start()`` runs the simulation in a thread and gives ``port``: the path of the
pseudo-terminal's far end (``/dev/pts/N``), which any program opens like a USB serial adapter
(``monitor``, ``config`` ... with ``PORT`` = that path, or ``sim``, which starts a board in the
same process). Bytes the design sends on ``uart_tx`` appear there; bytes written there are
sent bit by bit into ``uart_rx``.

Time is scaled (``board_setup``): a 4 MHz clock, a UART at a quarter of it (four cycles a bit:
the receiver's minimum), sample periods of ``sample_cycles`` cycles. The pseudo-terminal has no
baud rate of its own, so the bridge plays one: if the host sets its end to a baud other than
``baud`` (the board's nominal 921,600; any other, 1,843,200 too), it gets what a UART at that
rate would make of the board's bytes (garbage, framing errors as 0x00 bytes, as Linux delivers
them), and the design's receiver gets the host's bytes as the line they make at the host's
baud (``line_segments``): it finds the wrong bits and the low stop bits itself, and counts
them (``RX_FRAMING_ERRORS``).

The sensor is held at a pose the caller sets (``set_pose``; ``tumble`` turns the field
through every direction, as a user turning the board for the magnetometer calibration), with
offsets the caller chooses (``SensorErrors``): what ``calibrate`` must find.
"""

import os
import termios
import threading
import time
from dataclasses import dataclass

import numpy as np

from ...hdl.contract import ak8963_regs as A
from ...hdl.contract.defaults import DEFAULT_BAUD
from ...hdl.sensor.mpu9250_driver import MPU9250Config
from ...reference.frames import body_to_mag, euler_to_quat, quat_to_matrix
from ..bench.open_bench import compiled_wanted, open_bench
from ..bench.harness import CosimHarness, PinModels
from ..models.sources import SensorSample
from .core import core_key
from .setup import SimSetup


__all__ = ["SensorErrors", "SimulatedBoard", "board_setup", "garble", "line_segments",
           "pty_baud", "SIM_CLOCK_HZ"]


SIM_CLOCK_HZ = 4e6
NOMINAL_BAUD = DEFAULT_BAUD


@dataclass(frozen=True)
class SensorErrors:
    """The simulated sensor's errors, in counts: what a calibration should recover.
    ``hard_iron``: body axes, after the AK8963's sensitivity adjustment (the engine's HARD)."""
    gyro_offset: tuple = (35, -20, 12)
    accel_offset: tuple = (120, -80, 200)
    accel_scale: tuple = (1.02, 0.98, 1.01)
    hard_iron: tuple = (150, -90, 60)
    gyro_noise: float = 2.0
    accel_noise: float = 6.0
    mag_noise: float = 1.5
    field_ut: float = 50.0
    inclination_deg: float = 60.0


def board_setup(config=None, sample_cycles=1600):
    """The ``SimSetup`` of a simulated board: 4 MHz, 200 Hz nominal, one sample every
    ``sample_cycles`` cycles (the period scaled to fit), delays scaled by 10⁻³. The AK8963's
    clock runs at 2.2 times its 100 Hz here (a little faster than the samples), so that every
    sample carries a new field and a magnetometer calibration needs fewer simulated samples."""
    config = config or MPU9250Config(smplrt_div=4)                  # 200 Hz
    odr_scale = sample_cycles / SIM_CLOCK_HZ * config.output_data_rate
    return SimSetup(clk_freq=SIM_CLOCK_HZ, config=config, odr_scale=odr_scale,
                    ak_clock_error=-0.55)


def _uart_bits(byte):
    """A byte on a UART line (8N1): start bit, data LSB first, stop bit."""
    return [0] + [(byte >> k) & 1 for k in range(8)] + [1]


def garble(data, ratio):
    """The bytes a UART receiver at ``ratio`` × the sender's baud makes of ``data`` sent
    back to back (8N1): wrong ones, and a 0x00 for each framing error (what Linux delivers
    for a character with a low stop bit unless IGNPAR or PARMRK is set)."""
    if abs(ratio - 1) < 0.03:
        return bytes(data)
    over = 16                                       # samples per sender bit
    line = []
    for byte in data:
        for b in _uart_bits(byte):
            line += [b] * over
    line += [1] * (over * 20)
    step = over / ratio                             # samples per receiver bit
    out = bytearray()
    i = 0
    while i < len(line):
        if line[i]:
            i += 1
            continue
        mid = i + step / 2
        value, ok = 0, True
        for k in range(1, 10):
            pos = min(int(mid + k * step), len(line) - 1)
            if k <= 8:
                value |= line[pos] << (k - 1)
            elif not line[pos]:
                ok = False                          # framing error
        out.append(value if ok else 0)
        i = int(mid + 9.5 * step)
    return bytes(out)


def line_segments(data, cycles_per_bit):
    """``data`` sent back to back (8N1) by a UART whose bit lasts ``cycles_per_bit`` cycles of
    the board (its baud against the board's: ``divisor`` / ratio), as the line the design's
    receiver sees: (level, cycles) runs, the bit edges rounded to whole cycles from the first
    one on (no error builds up), at least a cycle each. At another baud than the board's the
    receiver samples the wrong bits and finds low stop bits itself (``RX_FRAMING_ERRORS``),
    as it would on a real line."""
    segments, edge = [], 0
    bits = [b for byte in data for b in _uart_bits(byte)]
    for k, level in enumerate(bits):
        end = max(edge + 1, round((k + 1) * cycles_per_bit))
        if segments and segments[-1][0] == level:
            segments[-1] = (level, segments[-1][1] + end - edge)
        else:
            segments.append((level, end - edge))
        edge = end
    return segments


class SimulatedBoard:
    """The co-simulated board behind a pseudo-terminal (see the module's docstring).

    Parameters
        ``errors`` (``SensorErrors``): the sensor's offsets, scales, noise.
        ``sample_cycles``: cycles per sample period (1,600: a raw frame, 36 bytes at four
            cycles a bit, fits one).
        ``core_kwargs``: more ``AHRSCore`` options.
        ``seed``: the noise's.
    Members
        ``port``: the pseudo-terminal's path, once started. ``core``, ``model``: the design
        and the MPU9250 model. ``cycles``: simulated so far.
    """
    def __init__(self, *, errors=SensorErrors(), sample_cycles=1600, core_kwargs=None, seed=1,
                 setup=None, compiled=None):
        from ...hdl.board.top import AHRSCore
        # a board runs for as long as it is used: worth a build whenever one can be had
        self.compiled = compiled_wanted("prefer" if compiled is None else compiled)
        self.errors = errors
        self.setup = setup or board_setup(sample_cycles=sample_cycles)
        config = self.setup.config
        self.rng = np.random.default_rng(seed)
        self.pose = np.radians([0.0, 0.0, 0.0])
        self.tumbling = False
        core_kwargs = dict(clk_freq=self.setup.clk_freq, config=config,
                           timing=self.setup.driver_timing(), baud=self.setup.clk_freq / 4,
                           command_timeout_s=2e-3, telemetry_divider=1, **(core_kwargs or {}))
        self._key = core_key("board", **core_kwargs)
        self.core = AHRSCore(**core_kwargs)
        self.lsb_g = 32768 / config.accel_fs_g
        ak = self.setup.ak8963(source=self._field)
        self.model = self.setup.model(source=self._sample, aux_devices={A.I2C_ADDRESS: ak})
        self.asa_factor = np.array([(a + 128) / 256 for a in ak.asa])
        self.port = None
        self.cycles = 0
        self.error = None
        self._stop = threading.Event()
        self._thread = None
        self._fields = 0

    # -- what the simulated user does -------------------------------------------------------
    def set_pose(self, roll_deg, pitch_deg, yaw_deg):
        """Hold the board still at this attitude (ZYX Euler angles, degrees)."""
        self.tumbling = False
        self.pose = np.radians([roll_deg, pitch_deg, yaw_deg])

    def tumble(self):
        """Turn the board through all orientations (each new AK8963 field in another
        direction, spread over the sphere)."""
        self.tumbling = True

    def _rotation(self):
        return quat_to_matrix(euler_to_quat(self.pose))             # body -> earth

    def _sample(self, index, t):
        e = self.errors
        up_body = self._rotation().T @ np.array([0.0, 0.0, 1.0])
        accel = np.array(e.accel_scale) * up_body * self.lsb_g + e.accel_offset + \
            self.rng.normal(0, e.accel_noise, 3)
        gyro = np.array(e.gyro_offset) + self.rng.normal(0, e.gyro_noise, 3)
        clip = lambda v: tuple(int(np.clip(round(x), -32768, 32767)) for x in v)
        return SensorSample(accel=clip(accel), temp=0, gyro=clip(gyro))

    def _field(self, index, t):
        e = self.errors
        counts = e.field_ut / 0.15
        inc = np.radians(e.inclination_deg)
        if self.tumbling:
            # the R2 low-discrepancy sequence mapped onto the sphere: the field's direction
            # in body axes, spread evenly whatever the number of fields read
            k = self._fields
            self._fields += 1
            z = 1 - 2 * ((0.5 + k * 0.7548776662) % 1)
            phi = 2 * np.pi * ((0.5 + k * 0.5698402910) % 1)
            body = counts * np.array([np.sqrt(1 - z * z) * np.cos(phi),
                                      np.sqrt(1 - z * z) * np.sin(phi), z])
        else:
            earth = counts * np.array([0.0, np.cos(inc), -np.sin(inc)])
            body = self._rotation().T @ earth
        body = body + e.hard_iron + self.rng.normal(0, e.mag_noise, 3)
        raw = body_to_mag(body) / self.asa_factor
        return tuple(int(round(v)) for v in raw)

    # -- the simulation ---------------------------------------------------------------------
    def start(self):
        """Start the simulation thread; returns once the pseudo-terminal exists. A board
        already started is returned as it is (``with SimulatedBoard().start()`` starts one
        thread, not two on one model)."""
        if self._thread is not None:
            if self._stop.is_set():
                raise RuntimeError("this simulated board was stopped: make a new one")
            return self
        master, slave = os.openpty()
        attrs = termios.tcgetattr(slave)
        attrs[0] = attrs[1] = attrs[3] = 0                        # raw: no echo, no mapping
        attrs[2] = termios.CS8 | termios.CREAD | termios.CLOCAL
        attrs[4] = attrs[5] = termios.B921600
        termios.tcsetattr(slave, termios.TCSANOW, attrs)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.port = os.ttyname(slave)
        core = self.core
        harness = CosimHarness(core, spi=core.imu, int_pin=core.imu_int)
        sent = []
        bench = open_bench(harness, {"uart_rx": core.uart_rx}, {"uart_tx": core.uart_tx},
                           self.setup.clk_freq, compiled=self.compiled, name="board",
                           key=self._key, models=PinModels(self.setup.clk_freq, mpu=self.model),
                           uart=("uart_tx", core.uart.divisor, sent))
        return self._run_in_thread(lambda: bench.run(lambda b: self._bridge(b, sent)))

    async def _bridge(self, bench, sent):
        """The scenario: every byte time a look at the pseudo-terminal; the design's bytes
        (``sent``) to the host, the host's played into ``uart_rx`` at the host's baud."""
        divisor = self.core.uart.divisor
        poll = 10 * divisor                         # a byte time
        bench.set("uart_rx", 1)
        while not self._stop.is_set():
            await bench.tick(poll)
            self.cycles = bench.cycle
            ratio = pty_baud(self._master) / NOMINAL_BAUD
            self._flush(sent, ratio)
            for level, cycles in self._from_host(divisor):
                if self._stop.is_set():
                    break
                bench.set("uart_rx", level)
                await bench.tick(cycles)
            self._flush(sent, ratio)

    def _run_in_thread(self, run):
        def guarded():
            try:
                run()
            except BaseException as e:                # reported by stop()
                self.error = e
        self._thread = threading.Thread(target=guarded, name="simulated-board", daemon=True)
        self._thread.start()
        return self

    def _from_host(self, divisor):
        """The bytes the host wrote since the last look as the line they make at the host's
        baud (``divisor``: the board's cycles a bit): ``line_segments``, (level, cycles)
        runs, ending high. The baud is read after the bytes: a host sets it, then writes."""
        try:
            data = os.read(self._master, 4096)
        except OSError:                              # nothing written
            return []
        return line_segments(data, divisor * NOMINAL_BAUD / pty_baud(self._master))

    def _flush(self, sent, ratio):
        """The design's bytes so far to the host, as a UART at its baud sees them."""
        if sent:
            out = garble(bytes(sent), ratio)
            sent.clear()
            try:
                os.write(self._master, out)
            except OSError:                          # nobody reading: the bytes are lost
                pass

    def wait_cycles(self, cycles, timeout=600):
        """Block until the simulation has run ``cycles`` more cycles."""
        end = self.cycles + cycles
        start = time.monotonic()
        while self.cycles < end:
            if self.error is not None:
                raise RuntimeError(f"simulated board stopped: {self.error!r}")
            if time.monotonic() - start > timeout:
                raise RuntimeError(f"simulated board: {cycles} cycles took over {timeout} s")
            time.sleep(0.05)

    def stop(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=30)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        if self.error is not None:
            raise RuntimeError("the simulated board failed") from self.error

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


_SPEEDS = {getattr(termios, f"B{b}"): b for b in
           (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600,
            1000000, 1152000, 1500000, 2000000) if hasattr(termios, f"B{b}")}


# Linux: a speed outside the table is set (pyserial: any baud) with BOTHER and the number in
# struct termios2's c_ospeed, read with TCGETS2
_BOTHER = 0o010000
_TCGETS2 = 0x802C542A


def pty_baud(fd):
    """The baud the host set on its end of a pseudo-terminal (``fd``: either end; they share
    the setting): a speed of the table, or any other (1,843,200) as its number."""
    code = termios.tcgetattr(fd)[5]
    if code in _SPEEDS:
        return _SPEEDS[code]
    if code == _BOTHER:
        import array
        import fcntl
        buf = array.array("I", [0] * 11)            # struct termios2: 44 bytes
        try:
            fcntl.ioctl(fd, _TCGETS2, buf)
            if buf[10] > 0:
                return int(buf[10])                 # c_ospeed
        except OSError:
            pass
    raise RuntimeError(f"the host set a baud the simulated board cannot read (speed code "
                       f"{code:#o}): set a baud in bits per second")
