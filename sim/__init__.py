"""The simulation side, in three wings, imported downward only (``tests/test_imports.py``):

- ``scenarios``: what is simulated, each written once for both simulators: a front end's
  samples (``frontend``), the whole core's results and frames (``core``), the simulated board
  behind a pseudo-terminal (``board``), a recording through the board (``board_replay``), the
  fault catalogue (``faults``), the engine alone (``attitude_bench``, ``compiled_engine``),
  the comparison with published filters (``benchmark``), the simulators' speeds (``speed``),
  and the set-up they share (``setup``: scaled real time).
- ``bench``: how it is simulated: the harness around a design (``harness``), one bench
  interface (``bench``) with its two simulators (``python_bench``: Amaranth's;
  ``compiled_bench``: Verilator through ``compiled_design`` and ``verilator``), stream helpers
  and monitors (``streams``), the UART receiver (``uart``), waveforms (``waveforms``).
- ``models``: what the design talks to: the MPU9250 and AK8963 (``mpu9250_model``,
  ``ak8963_model``), the I2C bus (``i2c_bus``), sensor values (``sources``, ``motion``), the
  attitude engine's instruction set (``attitude_isa_model``).
"""
