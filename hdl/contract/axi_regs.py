"""The AXI4-Lite slave's register map (``AHRSCore(axi_lite=True)``, ``build --verilog-only
--axi-lite``): byte addresses of 32-bit words, what each holds, and the engine's register window.
Plain data: the gateware (``hdl/link/axi_lite_slave.py``), the documentation
(``hdl/AXI_LITE.md``, generated from ``markdown_table``) and the tests read it.

Reads of an address outside the map answer DECERR; a write to a read-only word answers SLVERR.
The host's registers (engine, board, PWM) are reached through the command channel's
``RegisterExecutor``, by its rules: a request it refuses (a read-only or state register, a
CONTROL word the engine does not take) answers SLVERR, one to no register DECERR; CMD_OK and
CMD_REFUSED count them with the UART's. Byte strobes are ignored: every write is a whole word.
"""

from .commands import SPACES

__all__ = ["AXI_REGS", "AXI_RESULT_WORDS", "AXI_ENGINE_RESULT_WORDS", "AXI_REGISTER_BASE",
           "AXI_ADDR_BITS", "AXI_IRQ_RESULT", "axi_register_address", "markdown_table"]


# the result block: the ``Attitude`` of the last result in its order, one word each. The
# first ten (quaternion, angles, bias) are the engine's registers that hold them (its
# ``PEEKED``, read through its register port); COUNTER and FLAGS its result's own
AXI_RESULT_WORDS = ("QUAT0", "QUAT1", "QUAT2", "QUAT3", "ROLL", "PITCH", "YAW", "BIAS0", "BIAS1",
                    "BIAS2", "COUNTER", "FLAGS")
AXI_ENGINE_RESULT_WORDS = 10
_WORD_TEXT = {"COUNTER": "the last result's sample counter",
              "FLAGS": "the last result's flags (``AttitudeFlags``, bit 0 ``acc_used``)"}
# name: (byte address, access, what it holds)
AXI_REGS = {
    "VERSION": (0x00, "r", "the register map's version (``commands.REGMAP_VERSION``) in bits "
                           "15:0, 0xA71 in bits 31:20"),
    "STATUS": (0x04, "r", "the driver's status (``DriverStatus``, bit 0 ``streaming``)"),
    "IRQ": (0x08, "r/w1c", "bit 0: a result came since it was last cleared (write 1 to "
                           "clear); ``irq`` is high while it and IRQ_ENABLE bit 0 are"),
    "IRQ_ENABLE": (0x0C, "r/w", "bit 0: ``irq`` follows IRQ bit 0"),
    "FILTERED": (0x10, "r", "results the engine produced (``TelemetryCounters.filtered``)"),
    "LOST": (0x14, "r", "sensor samples never filtered (``TelemetryCounters.lost``)"),
    "SEQUENCE": (0x18, "r", "the engine's updates' starts and ends, its reset program's too "
                            "(two an update; 16 bits, wrapping): the same before and after a "
                            "read of the result block, the block's words are one result's"),
    **{name: (0x40 + 4 * k, "r",
              _WORD_TEXT.get(name, f"the last result's {name.lower()} (the engine's register; "
                                   f"answers between updates)"))
       for k, name in enumerate(AXI_RESULT_WORDS)},
}
# The host's registers, as the command channel names them (``commands.SPACES``: a space and an
# address): register ``a`` of space ``s`` at AXI_REGISTER_BASE + 0x400·s + 4·a
AXI_REGISTER_BASE = 0x400
AXI_ADDR_BITS = 13                 # 0x0000 .. 0x1FFF
AXI_IRQ_RESULT = 1 << 0


def axi_register_address(space, addr):
    """The byte address of the host's register ``addr`` in ``space`` (``SPACES``' value)."""
    return AXI_REGISTER_BASE + 0x400 * space + 4 * addr


assert axi_register_address(max(SPACES.values()), 0xFF) < 1 << AXI_ADDR_BITS


def markdown_table():
    """The map as a Markdown table (``hdl/AXI_LITE.md`` holds it; a test compares)."""
    lines = ["| Address | Name | Access | Holds |", "|---|---|---|---|"]
    for name, (address, access, text) in AXI_REGS.items():
        lines.append(f"| 0x{address:04X} | {name} | {access} | {text} |")
    held = {"engine": "the engine's register map (``hdl/engine/register_map.py``): CONTROL "
                      "at a = 0xFF",
            "board": "the board's registers (``commands.BOARD_REGS``: RAW_MODE, VERSION, the "
                     "counters, FRAMES_SENT, WHO_AM_I, SELF_TEST, SPI_TRAINING)",
            "pwm": "the PWM block's registers (``pwm_regs.PWM_REGS``; DECERR in a build "
                   "without it)",
            "control": "the balance controller's registers (``balance_regs.BALANCE_REGS``; "
                       "DECERR in a build without it)"}
    for space, code in SPACES.items():
        lines.append(f"| 0x{axi_register_address(code, 0):04X} + 4·a | {space} register a "
                     f"(0..255) | r/w | {held[space]} |")
    return "\n".join(lines)
