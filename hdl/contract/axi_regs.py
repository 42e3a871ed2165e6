"""The AXI4-Lite slave's register map (``AHRSCore(axi_lite=True)``, ``build --verilog-only
--axi-lite``): byte addresses of 32-bit words, what each holds, and the engine's register window.
Plain data: the gateware (``hdl/link/axi_lite_slave.py``), the documentation
(``hdl/AXI_LITE.md``, generated from ``markdown_table``) and the tests read it.

Reads of an address outside the map answer DECERR; a write to a read-only word, or an engine
write the engine refuses (a read-only or state register, a CONTROL word it does not take, the
same rule as the command channel's), answers SLVERR (the engine counts its refusals in
``cfg_refused``). Byte strobes are ignored: every write is a whole word.
"""

__all__ = ["AXI_REGS", "AXI_RESULT_WORDS", "AXI_ENGINE_BASE", "AXI_ENGINE_WORDS",
           "AXI_ADDR_BITS", "AXI_IRQ_RESULT", "markdown_table"]


# the result block: the ``Attitude`` of the last result in its order, one word each
AXI_RESULT_WORDS = ("QUAT0", "QUAT1", "QUAT2", "QUAT3", "ROLL", "PITCH", "YAW", "BIAS0", "BIAS1",
                    "BIAS2", "COUNTER", "FLAGS")
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
    "DROPPED": (0x18, "r", "results not shown in the result block because it was held for a "
                           "read (16 bits, saturating)"),
    "REFUSED": (0x1C, "r", "engine writes refused (16 bits, saturating; both ports')"),
    **{name: (0x40 + 4 * k, "r",
              "the last result's " + ("word " + name.lower() if k < 10 else name.lower()) +
              (" (reading it holds the block: QUAT0 to FLAGS come from one result)"
               if k == 0 else " (reading it lets the block follow the results again)"
               if name == "FLAGS" else ""))
       for k, name in enumerate(AXI_RESULT_WORDS)},
}
AXI_ENGINE_BASE = 0x400            # the engine's register ``a`` at AXI_ENGINE_BASE + 4·a
AXI_ENGINE_WORDS = 256
AXI_ADDR_BITS = 11                 # 0x000 .. 0x7FF
AXI_IRQ_RESULT = 1 << 0


def markdown_table():
    """The map as a Markdown table (``hdl/AXI_LITE.md`` holds it; a test compares)."""
    lines = ["| Address | Name | Access | Holds |", "|---|---|---|---|"]
    for name, (address, access, text) in AXI_REGS.items():
        lines.append(f"| 0x{address:03X} | {name} | {access} | {text} |")
    lines.append(f"| 0x{AXI_ENGINE_BASE:03X} + 4·a | engine register a (0..255) | r/w | the "
                 f"engine's register map (``hdl/engine/register_map.py``): CONTROL at a = "
                 f"0xFF |")
    return "\n".join(lines)
