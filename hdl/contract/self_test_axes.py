"""The self-test's axes, in the order of their fail bits (``SelfTest.fail``,
``DriverStatus.self_test_fail``, the board register SELF_TEST's bits 2-10): plain data the
host names them by."""

__all__ = ["AXES"]


AXES = ("accel_x", "accel_y", "accel_z", "gyro_x", "gyro_y", "gyro_z", "mag_x", "mag_y", "mag_z")
