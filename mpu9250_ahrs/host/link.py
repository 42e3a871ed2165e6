"""A board on a serial port: frames in, commands out, with time-outs and one-line errors.

``open_link(port, baud)`` opens a serial device with pyserial (``exclusive``: a port another
program holds is "busy"); given a ``board`` (a ``sim.scenarios.board.SimulatedBoard`` the caller started
in this process: the command line does for ``--port sim``) it opens that board's
pseudo-terminal and stops the board when the link closes. Against a simulated board in this
process (``board``, or the path of one registered in ``SIM_BOARDS``) time-outs count the
board's own time, not the wall clock's: the co-simulation runs slower than the hardware. This
module imports nothing of the simulation: the caller hands the board over.
"""

import errno
import time

from ..hdl.contract.commands import REGMAP_VERSION
from ..hdl.link.frame_types import REPLY
from ..hdl.contract.defaults import DEFAULT_BAUD
from .protocol import FrameDecoder, answers, encode_command, reply_of


__all__ = ["BoardError", "Link", "open_link", "SIM_BOARDS"]


# Simulated boards running in this process, by port path (``open_link`` registers the ones it
# starts; a test may register its own).
SIM_BOARDS = {}


class BoardError(RuntimeError):
    """A failure worth one line to the user (the command line prints it and exits 2)."""


class Link:
    """Frames from and commands to a board on ``serial`` (a pyserial ``Serial``).

    ``frames(n=None, timeout=...)`` yields ``(type, seq, fields)``; ``command(name, ...)``
    sends a command and returns its reply's fields, retrying a lost one. ``stats`` (the
    decoder's ``LinkStats``): frames, CRC errors, lost frames, noise bytes.
    """
    def __init__(self, serial, *, board=None, own_board=False, timeout=1.0):
        self.serial = serial
        self.board = board
        self.own_board = own_board    # started for this link: stopped when it closes
        self.timeout = timeout
        self.decoder = FrameDecoder()
        self.seq = 0
        self.backlog = []            # frames read while waiting for a reply
        self.port = serial.port
        self._noise_at_frame = 0     # noise bytes counted when the last frame came

    @property
    def stats(self):
        return self.decoder.stats

    def clock(self):
        """Seconds: the wall clock's, or the simulated board's (scaled to the real sensor's
        sample periods)."""
        if self.board is None:
            return time.monotonic()
        setup = self.board.setup
        return self.board.cycles / setup.clk_freq / setup.odr_scale

    def _read(self):
        try:
            chunk = self.serial.read(4096)
        except OSError as e:
            raise BoardError(f"{self.port}: read failed: {e}") from None
        return self.decoder.feed(chunk) if chunk else []

    def frames(self, n=None, *, timeout=None, types=None):
        """Frames as they come (``types``: only these), until ``n``; a silence of
        ``timeout`` seconds (default: the link's) raises ``BoardError``."""
        timeout = self.timeout if timeout is None else timeout
        count = 0
        last = self.clock()
        while n is None or count < n:
            got = self.backlog + self._read()
            self.backlog = []
            for k, frame in enumerate(got):
                if types is None or frame[0] in types:
                    count += 1
                    last = self.clock()
                    self._noise_at_frame = self.stats.skipped_bytes
                    if n is not None and count >= n:
                        self.backlog += got[k + 1:]
                        yield frame
                        return
                    yield frame
            if self.clock() - last > timeout:
                raise BoardError(self._silence(timeout))

    def _silence(self, timeout):
        noise = self.stats.skipped_bytes - self._noise_at_frame
        if self.stats.frames and noise:
            # a frame or two at first (bytes sent before the baud rate changed), noise since
            return (f"{self.port}: no valid frame for {timeout:g} s but {noise} bytes of "
                    f"noise since the last: wrong baud rate ({self.serial.baudrate})?")
        if self.stats.frames:
            return f"{self.port}: no frame for {timeout:g} s: the board stopped sending"
        if self.stats.skipped_bytes or self.stats.crc_errors:
            return (f"{self.port}: no valid frame within {timeout:g} s but "
                    f"{self.stats.skipped_bytes} bytes of noise: wrong baud rate "
                    f"({self.serial.baudrate})?")
        return (f"{self.port}: nothing received within {timeout:g} s: no board, not powered, "
                f"or not configured")

    def discard(self):
        """Drop what the board sent before now (the port's input buffer, frames kept while
        waiting for replies): after the user was told to move the board, what was measured
        before is not of the new pose, however long the host took to read it."""
        try:
            self.serial.reset_input_buffer()
        except OSError as e:
            raise BoardError(f"{self.port}: read failed: {e}") from None
        self.backlog = []
        self.decoder.drop()

    def wait_for_frame(self, timeout=None):
        return next(self.frames(1, timeout=timeout))

    def command(self, name, *, retries=3, timeout=None, **kwargs):
        """Send command ``name`` (``protocol.encode_command``'s arguments) and return its
        reply (``Reply`` fields plus ``result_name``). A reply that does not come within
        ``timeout`` (default: half the link's) is asked for again, ``retries`` times (a
        command repeated is harmless: every command sets, none toggles). A reply is this
        command's when its sequence number, its command and (a read's, a write's) address are
        this command's (``answers``): a CRC-good reply to another command with the same
        sequence number is not read as the value asked for."""
        timeout = self.timeout / 2 if timeout is None else timeout
        for _ in range(retries):
            self.seq = (self.seq + 1) % 256
            frame = encode_command(name, self.seq, **kwargs)
            try:
                self.serial.write(frame)
                self.serial.flush()
            except OSError as e:
                raise BoardError(f"{self.port}: write failed: {e}") from None
            start = self.clock()
            while self.clock() - start < timeout:
                got = self._read()
                for k, (ftype, seq, fields) in enumerate(got):
                    if ftype == REPLY and answers(fields, name, self.seq, **kwargs):
                        self.backlog += got[:k] + got[k + 1:]
                        return reply_of(fields)
                self.backlog += got
                del self.backlog[:-1000]
        raise BoardError(f"{self.port}: the board did not answer '{name}' ({retries} tries, "
                         f"{timeout:g} s each)")

    def check(self, reply, what):
        if reply["result_name"] != "ok":
            raise BoardError(f"{what}: the board refused it ({reply['result_name']})")
        return reply

    def identify(self):
        """The board's (version word, register-map version); refuses a map this tool does
        not know."""
        reply = self.check(self.command("who"), "who are you")
        if reply["addr"] != REGMAP_VERSION:
            raise BoardError(f"{self.port}: register map version {reply['addr']}, this tool "
                             f"knows {REGMAP_VERSION}: update one or the other")
        return reply["value"], reply["addr"]

    def close(self):
        try:
            self.serial.close()
        finally:
            if self.own_board:
                SIM_BOARDS.pop(self.board.port, None)
                self.board.stop()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def open_link(port, baud=DEFAULT_BAUD, *, timeout=1.0, board=None):
    """A ``Link`` on ``port``, or on ``board``'s port (a started simulated board, which the
    link then owns: it stops it on close). Raises ``BoardError`` for a missing or busy port."""
    import serial
    own = board is not None
    if own:
        SIM_BOARDS[board.port] = board
        port = board.port
    board = SIM_BOARDS.get(port)
    try:
        ser = serial.Serial(port, baud, timeout=0.02, exclusive=True)
    except serial.SerialException as e:
        code = getattr(e, "errno", None)
        text = str(e)
        if code == errno.ENOENT or "No such file" in text:
            raise BoardError(f"{port}: no such serial port") from None
        if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or "lock" in text.lower() \
                or "busy" in text.lower():
            raise BoardError(f"{port}: busy (another program has it open)") from None
        raise BoardError(f"{port}: cannot open: {text}") from None
    except ValueError as e:
        raise BoardError(f"{port}: {e}") from None
    try:
        ser.reset_input_buffer()        # bytes from before this link (another baud rate, say)
    except (OSError, serial.SerialException):
        pass
    return Link(ser, board=board, own_board=own, timeout=timeout)
