"""Defaults of the design that the command line, the simulations and the host tool share,
in plain Python (the command line reads them without loading Amaranth)."""

__all__ = ["DEFAULT_BAUD"]


# The link's rate unless told otherwise (``build``/``simulate --baud``, ``AHRSCore(baud=)``,
# the host tool's ``--baud``): 921,600 baud, 8N1.
DEFAULT_BAUD = 921_600
