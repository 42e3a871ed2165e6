"""The contract: plain data both the gateware and the reference keep, and the host reads, with
no Amaranth in it: number formats and tables (``numeric_contract``), the sensors' register maps
(``mpu9250_regs``, ``ak8963_regs``), the filters' names and codes (``filter_registry``), the
command channel's tables (``commands``), the PWM block's registers and limits (``pwm_regs``),
the self-test's axes (``self_test_axes``) and the defaults the command line shares
(``defaults``). Imports nothing of the project."""
