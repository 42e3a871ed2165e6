"""Gateware of the MPU9250 attitude and heading reference, one block per module.

Sensor side: ``spi_controller``, ``i2c_controller``, ``register_port`` (and its arbiter),
``bring_up_sequencer``, ``self_test``, ``sample_reader``, ``mpu9250_driver``,
``sensor_frontend``.
Attitude engine: ``attitude_engine`` on ``alu``, ``multiplier``, ``multiply_accumulate``,
``cordic``, ``divider``, ``memories``, ``host_port``; its instruction set ``attitude_isa`` and
program ``attitude_program``, the filters' microcode ``filters`` (one module each, named in
``filter_registry``) and the ``register_map``. Link: ``telemetry_scheduler``,
``telemetry`` (the framer), ``frame_arbiter``, ``uart_tx``, ``uart_rx``, ``command_decoder``
(its input ``rewindable_fifo``), ``pwm``, ``board_bus``. Top levels and boards: ``top``,
``platform`` (the MAX10), ``ulx3s`` (the open ECP5 flow), ``clocking``.
Layouts: ``sample``, ``driver_status``, ``attitude_result``, ``config_write``, ``frame_types``;
the numeric contract with ``reference/``: ``numeric_contract``; register maps:
``mpu9250_regs``, ``ak8963_regs``; defaults the command line shares (the baud rate):
``defaults``.

Nothing here imports ``sim/`` or ``reference/`` (``tests/test_imports.py``).
"""
