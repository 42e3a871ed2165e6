"""The gateware's flows behind the command line's verbs: resource and timing ``report``, the open
ECP5 place-and-route's ``timing``, the ULX3S bitstream (``open_build``)."""
