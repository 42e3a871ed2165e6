"""Primitives the other wings build on: block RAMs (``memories``), the multiplier and its
black box (``multiplier``), clock arithmetic and the PLLs (``clocking``). Import only the
contract."""
