"""NumPy reference filters (float and bit-exact fixed point). Not yet written: see issue 4."""
