"""Logic that uses the attitude on the chip: the balance controller (``balance_controller``),
built the way a user's own logic would be, from the core's result and sample. Imports the
link (its register bus), the engine, the sensor side, the primitives and the contract."""
