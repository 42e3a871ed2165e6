"""The attitude engine's filters, by name, in select-code order: the registry everything reads.

A name's position is its code (the CONTROL register's bits 1:0, ``AttitudeFlags.filter``); its
microcode is ``hdl/engine/filters/<name>.py``, its integer step the reference's engine model's
filter of that name (``reference/engine_model.py``). The command line's choices, the host's monitor,
the reference's engine model and the engine itself read the names from here. Plain data:
``reference/`` reads it too (``tests/test_imports.py``).
"""

__all__ = ["FILTER_NAMES", "FILTER_CODES", "FLOAT_FILTERS"]


FILTER_NAMES = ("kalman", "complementary", "flagship", "madgwick")
FILTER_CODES = {name: code for code, name in enumerate(FILTER_NAMES)}
# the reference's float filters (``reference/evaluate.py``, ``replay``): the engine's, the
# flagship last (the tables' order)
FLOAT_FILTERS = (*(name for name in FILTER_NAMES if name != "flagship"), "flagship")
