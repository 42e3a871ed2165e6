"""The sensor side: the SPI and I2C controllers (``spi_controller``, ``i2c_controller``), the
register port (``register_port``, ``register_port_arbiter``), bring-up (``bring_up_sequencer``,
``self_test``, ``read_leveller``), the sample reader (``sample_reader``, ``data_ready_timer``,
``sample_offer``) and store (``sample_store``), the driver and front end (``mpu9250_driver``,
``sensor_frontend``) and their layouts (``sample``, ``driver_status``). Imports the primitives
and the contract."""
