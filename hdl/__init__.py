"""Gateware of the MPU9250 attitude and heading reference, one block per module, in wings by
subsystem. A wing imports only itself and the wings below it, in the data's direction
(``tests/test_imports.py`` keeps the order):

- ``board``: top levels and boards (``top``, ``platform`` the MAX10, ``ulx3s`` the open ECP5
  flow);
- ``control``: logic that uses the attitude on the chip, built as a user's would be: the
  balance controller (``balance_controller``);
- ``link``: telemetry (``telemetry_scheduler``, ``telemetry`` the framer, ``frame_arbiter``,
  ``frame_types``), the UART (``uart_tx``, ``uart_rx``), commands (``command_decoder``, its
  ``rewindable_fifo``; the ``register_executor`` it shares with the AXI slave, its
  ``event_counters``), the PWM outputs (``pwm``, ``board_bus``), the
  doors for logic on the same chip (``stream_tap`` for the attitude and sample streams,
  ``axi_lite_slave``);
- ``engine``: ``attitude_engine`` on ``alu``, ``multiply_accumulate``, ``cordic``, ``divider``,
  ``host_port``; its instruction set ``attitude_isa`` and program ``attitude_program``, the
  filters' microcode ``filters`` (one module each), the ``register_map``, ``config_port_arbiter``
  and the layouts ``attitude_result``, ``config_write``;
- ``sensor``: ``spi_controller``, ``i2c_controller``, ``register_port`` (and its arbiter),
  ``bring_up_sequencer``, ``self_test``, ``read_leveller``, ``sample_reader`` (and its
  ``data_ready_timer``, ``sample_offer``), ``sample_store``, ``mpu9250_driver``, ``sensor_frontend`` and the
  layouts ``sample``, ``driver_status``;
- ``primitives``: ``memories``, ``multiplier``, ``clocking``;
- ``contract``: plain data shared with ``reference/`` and the host, no Amaranth: the numeric
  contract ``numeric_contract``, the register maps ``mpu9250_regs``, ``ak8963_regs``, the
  filters' names and codes ``filter_registry``, the command channel's tables ``commands``, the
  PWM block's registers ``pwm_regs``, the self-test's axes ``self_test_axes``, the AXI
  slave's map ``axi_regs``, the balance controller's registers ``balance_regs``, the defaults
  the command line shares (``defaults``).

Nothing here imports ``sim/`` or ``reference/`` (``tests/test_imports.py``).
"""
