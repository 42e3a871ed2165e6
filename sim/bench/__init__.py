"""How a design is simulated: its harness, one bench interface and the two simulators behind it."""
