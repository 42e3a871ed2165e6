"""Gateware: SPI controller, MPU9250 driver, platform and top level."""
