"""Top levels and boards: ``top`` (the core and the board top), ``platform`` (the MAX10
board), ``ulx3s`` (the open ECP5 flow). Imports every other wing."""
