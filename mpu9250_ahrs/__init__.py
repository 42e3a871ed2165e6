"""mpu9250-ahrs: gateware, models and reference filters for an MPU9250 attitude reference."""
