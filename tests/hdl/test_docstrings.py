"""Every component of the gateware is documented the way ``amaranth.lib`` documents its own: a
class docstring (``help(Block)`` says what it does, its parameters and ports) that states its
latency in cycles (the word "Latency", or "latency" in a sentence)."""

import importlib
import inspect
import pkgutil

import pytest
from amaranth.lib import wiring

import mpu9250_ahrs.hdl as hdl


def _components():
    found = []
    # every module of every wing (sub-packages included)
    for info in pkgutil.walk_packages(hdl.__path__, f"{hdl.__name__}."):
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if inspect.isclass(obj) and issubclass(obj, wiring.Component) and \
                    obj.__module__ == module.__name__:
                found.append(obj)
    return found


COMPONENTS = _components()


def test_components_found():
    assert len(COMPONENTS) > 20


@pytest.mark.parametrize("component", COMPONENTS, ids=lambda c: c.__name__)
def test_component_has_docstring_with_latency(component):
    doc = component.__doc__
    assert doc, f"{component.__module__}.{component.__name__} has no class docstring"
    assert "latency" in doc.lower(), \
        f"{component.__module__}.{component.__name__}: the docstring does not state the latency"
