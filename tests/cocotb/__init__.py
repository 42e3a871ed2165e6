"""Tests of exported Verilog run by cocotb with bus models this project did not write."""
