"""Testbench helpers for ``lib.stream`` interfaces."""

__all__ = ["stream_put"]


async def stream_put(ctx, stream, payload):
    """Offer one transfer on ``stream`` (an input of the design) and wait until it is taken."""
    ctx.set(stream.payload, payload)
    ctx.set(stream.valid, 1)
    await ctx.tick().until(stream.ready)
    ctx.set(stream.valid, 0)
