"""NumPy reference: float filters, calibration, the bit-exact fixed-point model, scoring."""
