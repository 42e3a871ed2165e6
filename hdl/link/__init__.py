"""The link to the host: telemetry (``telemetry_scheduler``, ``telemetry``, the framer;
``frame_arbiter``; ``frame_types``, the frame layouts), the UART (``uart_tx``, ``uart_rx``),
commands (``command_decoder``, its input ``rewindable_fifo``; the ``register_executor`` it
shares with the AXI slave, its ``event_counters``), the PWM
outputs (``pwm``, ``board_bus``). Imports the engine, the sensor side, the primitives and the
contract."""
