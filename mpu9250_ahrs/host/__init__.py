"""The host side: the link's frames and commands (``protocol``), a board on a serial port or
in co-simulation (``link``), and the command-line verbs ``monitor``, ``config``, ``calibrate``
and ``plot``."""
