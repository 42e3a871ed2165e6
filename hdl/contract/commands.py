"""The command channel's contract (``hdl/FRAMES.md``): the commands, the reply's results, the
register spaces, the board's registers, the register map's version and the bound on commands
sent back to back. Plain data: the gateware's ``link.command_decoder`` and the host's
``host.protocol`` read the same tables."""

__all__ = ["COMMANDS", "MAX_COMMAND_PAYLOAD", "MAX_COMMAND_BYTES", "COMMAND_FIFO_BYTES",
           "MAX_BURST_COMMANDS", "RESULTS", "RESULT_INPUT_LOST", "SPACES", "BOARD_REGS",
           "REGMAP_VERSION"]


# name: (type byte, payload bytes)
COMMANDS = {
    "write": (0x10, 6),        # address (2 bytes), value (4, signed)
    "read": (0x11, 2),         # address
    "filter": (0x12, 1),       # filter code (FILTER_CODES)
    "reset": (0x13, 0),        # reset the filter state, keep the filter
    "rate": (0x14, 2),         # telemetry divider: frame every n-th result
    "raw": (0x15, 1),          # bit 0: raw-sample mode (sensor frames instead of attitude)
    "who": (0x16, 0),          # who are you: version/build word and register-map version
}
MAX_COMMAND_PAYLOAD = max(n for _, n in COMMANDS.values())
# the bytes of a command, at most (sync 2, type, seq, length, payload, CRC 2)
MAX_COMMAND_BYTES = 5 + MAX_COMMAND_PAYLOAD + 2
# The decoder's input FIFO: the bytes of the commands that arrive while a reply waits for the
# link. A reply may wait behind a telemetry frame (92 bytes), and while telemetry fills the
# link each command's reply may wait behind one: a command (9 to 13 bytes) is then answered
# every 108 byte times at worst. 32 bytes lost the fourth of four commands sent back to back;
# 1,024 (the whole M9K the FIFO had anyway, as 1,024 x 8) hold ``MAX_BURST_COMMANDS`` of the
# longest whatever the link does, all answered
COMMAND_FIFO_BYTES = 1024
MAX_BURST_COMMANDS = COMMAND_FIFO_BYTES // MAX_COMMAND_BYTES
RESULTS = {"ok": 0, "refused": 1, "bad_address": 2, "bad_command": 3}
# OR-ed into a reply's result: bytes from the host were dropped (the input FIFO full) since
# the last reply was made; commands sent since then may have had no reply (send them again)
RESULT_INPUT_LOST = 0x80
# The high byte of a register address: which block it is in ("control": the balance
# controller's, ``balance_regs``, in a build with it).
SPACES = {"engine": 0x00, "board": 0x01, "pwm": 0x02, "control": 0x03}
# The board's own registers (space 0x01): all read-only but RAW_MODE.
BOARD_REGS = {
    "RAW_MODE": 0x00, "VERSION": 0x01, "REGMAP_VERSION": 0x02,
    "RX_FRAMING_ERRORS": 0x03, "RX_OVERRUNS": 0x04, "CMD_DISCARDED": 0x05,
    "CMD_CRC_ERRORS": 0x06, "CMD_MALFORMED": 0x07, "CMD_OK": 0x08, "CMD_REFUSED": 0x09,
    "FRAMES_SENT": 0x0A, "RATE_ERRORS": 0x0B, "WHO_AM_I": 0x0C, "SELF_TEST": 0x0D,
    "SPI_TRAINING": 0x0E,
}
# Bumped whenever an address, a format or a meaning in the register map changes (engine,
# board, PWM); the host tool refuses to configure a board whose map it does not know.
# 7: Madgwick (filter code 3, BETA_K at 0x80); 8: the result words at 0x30-0x39; 9: the
# flagship's REST_BIAS2 at 0x80, BETA_K at 0x81; 10: a reply's result bit 7
# (``RESULT_INPUT_LOST``); 11: SPI_TRAINING (board 0x0E, ``ReadLevelStatus``); 12: the
# frames' status: ``restarts`` 6 bits, ``spi_trained`` in its seventh (``DriverStatus``)
REGMAP_VERSION = 12
