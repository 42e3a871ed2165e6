"""What is simulated, each scenario written once for both simulators (``sim.bench``)."""
