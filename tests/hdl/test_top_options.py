"""What a user may leave out of a build (issue #24): the PWM outputs, the command channel.
The default build keeps both; ``report --no-pwm`` / ``--no-commands`` count the others."""

import pytest
from amaranth.back import verilog

from mpu9250_ahrs.cli import main
from mpu9250_ahrs.hdl.board.top import AHRSCore


def test_left_out_blocks_and_their_ports_are_gone():
    full = AHRSCore(clk_freq=12e6)
    no_pwm = AHRSCore(clk_freq=12e6, pwm=False)
    no_commands = AHRSCore(clk_freq=12e6, commands=False)
    members = lambda core: set(core.signature.members)
    assert {"uart_rx", "pwm", "raw_mode"} <= members(full)
    assert "pwm" not in members(no_pwm) and "uart_rx" in members(no_pwm)
    assert not {"uart_rx", "pwm", "raw_mode"} & members(no_commands)
    assert {"cfg", "cfg_read", "cfg_read_data", "counters"} <= members(no_commands)
    # a build that leaves something out answers "who are you" with another build word
    assert len({full.version, no_pwm.version, no_commands.version}) == 3
    assert full.version == AHRSCore(clk_freq=12e6, commands=True, pwm=True).version
    with pytest.raises(ValueError, match="pwm=True needs commands=True"):
        AHRSCore(clk_freq=12e6, commands=False, pwm=True)


@pytest.mark.parametrize("flag, absent, present", [
    ("--no-pwm", ["mpu9250_ahrs_core.pwm"], ["mpu9250_ahrs_core.decoder"]),
    ("--no-commands", ["mpu9250_ahrs_core.pwm", "mpu9250_ahrs_core.decoder",
                       "mpu9250_ahrs_core.uart_rx"], ["mpu9250_ahrs_core.engine"]),
])
def test_build_leaves_them_out(tmp_path, flag, absent, present):
    assert main(["build", "--verilog-only", "--out", str(tmp_path), flag]) == 0
    text = (tmp_path / "mpu9250_ahrs_core.v").read_text()
    for name in absent:
        assert f"module \\{name} " not in text and f"module \\{name}$" not in text, name
    for name in present:
        assert f"module \\{name}" in text, name


def test_a_core_without_the_command_channel_still_streams_attitude():
    """The engine and the telemetry as in the default build: the same results, framed."""
    from mpu9250_ahrs.sim.scenarios.setup import QUICK_CORE_BAUD, quick_core_setup
    from mpu9250_ahrs.sim.scenarios.core import run_core
    setup = quick_core_setup()
    # the default build: the quick set-up's compiled build where it can run
    default = run_core(setup, n_frames=1, baud=QUICK_CORE_BAUD, compiled="prefer")
    bare = run_core(setup, n_frames=1, baud=QUICK_CORE_BAUD, core_kwargs={"commands": False})
    n = min(len(default.results), len(bare.results))
    assert n >= 1 and bare.results[:n] == default.results[:n]
    assert len(bare.frames) >= 1 and bare.frames[0] == default.frames[0]


def test_the_balance_controller_takes_the_pwm_blocks_place():
    """``controller="balance"`` (issue #57): the controller drives ``pwm``, an ``arm`` pin
    comes in, the PWM block is left out; a build with both is refused, and the build word
    says which it is."""
    core = AHRSCore(clk_freq=12e6, controller="balance")
    members = set(core.signature.members)
    assert {"pwm", "arm", "uart_rx"} <= members and not core.has_pwm
    assert core.version not in (AHRSCore(clk_freq=12e6).version,
                                AHRSCore(clk_freq=12e6, pwm=False).version)
    with pytest.raises(ValueError, match="leaves the PWM block out"):
        AHRSCore(clk_freq=12e6, controller="balance", pwm=True)
    with pytest.raises(ValueError, match="needs commands=True"):
        AHRSCore(clk_freq=12e6, controller="balance", commands=False)
    text = verilog.convert(core, name="core", emit_src=False)
    assert "module \\core.balance " in text and "module \\core.pwm " not in text
