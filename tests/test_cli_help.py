"""Every option and argument of every verb says what it is for (issue #29)."""

import argparse

from mpu9250_ahrs.cli import build_parser


def test_every_option_has_help():
    parser = build_parser()
    verbs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = [f"{verb} {a.option_strings or a.dest}"
               for verb, sub in verbs.choices.items() for a in sub._actions
               if not a.help and a.dest != "help"]
    assert not missing, missing


def test_config_help_names_every_filter():
    """``config``'s help lists the filters from the registry (it had one hard-coded list, and
    Madgwick, added since, was missing)."""
    from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_NAMES
    parser = build_parser()
    verbs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    action = next(a for a in verbs.choices["config"]._actions if a.dest == "action")
    assert all(name in action.help for name in FILTER_NAMES)
