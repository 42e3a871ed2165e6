"""The attitude engine: ``attitude_engine`` on ``alu``, ``multiply_accumulate``, ``cordic``,
``divider`` and ``host_port``; its instruction set ``attitude_isa`` and program
``attitude_program``, the filters' microcode ``filters`` (one module each, named in the
contract's ``filter_registry``), the ``register_map``, its layouts (``attitude_result``,
``config_write``) and ``config_port_arbiter``. Imports the sensor side's layouts, the
primitives and the contract."""
