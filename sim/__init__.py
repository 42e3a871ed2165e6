"""Behavioural models of the sensors, motion sources and the co-simulation harness."""
