"""What the design talks to: behavioural models of the sensors, the bus and the motion."""
