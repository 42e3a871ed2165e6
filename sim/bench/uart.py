"""UART receiver for simulations: turns a simulated TX line back into bytes (8N1)."""

__all__ = ["FramingError", "attach_uart_receiver"]


class FramingError(AssertionError):
    pass


def attach_uart_receiver(sim, tx, divisor, sink):
    """Append each byte received on ``tx`` (``divisor`` clock cycles per bit) to ``sink``.

    It wakes on the start bit's falling edge and then samples every bit in its middle, so it
    costs a few Python steps per bit rather than one per cycle. A low stop bit raises
    ``FramingError``.
    """
    async def level_after(ctx, cycles):
        # plain awaits rather than ``.repeat()``: an abandoned ``repeat`` (the simulation ends
        # mid-byte) raises when the coroutine is collected
        for _ in range(cycles - 1):
            await ctx.tick()
        *_, level = await ctx.tick().sample(tx)
        return level

    async def process(ctx):
        while True:
            await ctx.negedge(tx)
            if await level_after(ctx, divisor // 2):
                continue                      # a glitch, not a start bit
            byte = 0
            for bit in range(8):
                byte |= await level_after(ctx, divisor) << bit
            if not await level_after(ctx, divisor):
                raise FramingError(f"stop bit low after byte 0x{byte:02X}")
            sink.append(byte)
    sim.add_process(process)
