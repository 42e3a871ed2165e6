"""The ``lib.stream`` rules as properties, one call per stream.

The rules (Amaranth RFC 61, and this project's FRAMES.md and block docstrings):

1. ``valid`` is not withdrawn before a transfer: once raised, it stays up until a cycle with
   ``ready`` (the transfer).
2. The payload holds still while ``valid & ~ready``: what the consumer sees when it finally
   takes it is what was offered.

On a stream the block under test drives (an output) the rules are asserted; on a stream it
receives (an input) they are assumed, so the proof covers every producer that keeps them, and
the consumer side (``ready`` of an output) is left free (``AnySeq``): any back-pressure.

Rule 3, ``valid`` does not depend combinationally on ``ready``, is a property of the netlist,
not of a run: ``comb_paths.py`` checks it.
"""

from amaranth import *
from amaranth.asserts import AnySeq
from amaranth.lib import stream, wiring
from amaranth.hdl import Assert, Assume, Cover

from .harness import Past, harness_module


__all__ = ["stream_output", "stream_input", "contract_harness"]


def _bits(payload):
    """A payload as a plain value (a layout's view, or a signal)."""
    return payload.as_value() if hasattr(payload, "as_value") else payload


def _rules(m, s, statement, name, cover):
    started = Signal(name=f"{name}_started")
    m.d.sync += started.eq(1)
    payload = _bits(s.payload)
    was_waiting = Past(m, s.valid & ~s.ready)
    was_payload = Past(m, payload)
    # named, so a counterexample trace shows which rule of which stream broke
    valid_held = Signal(name=f"{name}_valid_held")
    payload_held = Signal(name=f"{name}_payload_held")
    m.d.comb += [valid_held.eq(s.valid), payload_held.eq(payload == was_payload)]
    with m.If(started & was_waiting):
        m.d.comb += [statement(valid_held, f"{name}_valid_held"),
                     statement(payload_held, f"{name}_payload_held")]
    if cover:
        # a transfer after back-pressure: the rules had something to bite on
        m.d.comb += Cover(started & was_waiting & s.valid & s.ready, f"{name}_waited")


def stream_output(m, s, name="out", *, ready=None, cover=True):
    """Assert the rules on ``s``, a stream the block drives; ``ready`` is free unless given."""
    if ready is None:
        ready = AnySeq(1)
    m.d.comb += s.ready.eq(ready)
    _rules(m, s, Assert, name, cover)


def stream_input(m, s, name="in"):
    """Drive ``s``, a stream the block receives, from any producer that keeps the rules."""
    m.d.comb += [s.valid.eq(AnySeq(1)), s.payload.eq(AnySeq(len(_bits(s.payload))))]
    _rules(m, s, Assume, name, cover=False)


def _elements(value, path, dimensions):
    """A member's values with their paths: one, or each of an array member's (``.array(n)``)."""
    if not dimensions:
        return [(path, value)]
    return [item for k, v in enumerate(value)
            for item in _elements(v, f"{path}{k}", dimensions[1:])]


def _walk(m, obj, signature, flipped, prefix, streams):
    for name, member in signature.members.items():
        for path, value in _elements(getattr(obj, name), f"{prefix}{name}", member.dimensions):
            _member(m, value, member, flipped, path, streams)


def _member(m, value, member, flipped, path, streams):
    inward = (member.flow == wiring.In) != flipped
    if member.is_signature:
        if isinstance(member.signature, stream.Signature):
            streams.append((path, value, inward))
        else:
            # an ``In`` member's signature comes flipped already: its flows are the
            # component's own, as at this level
            _walk(m, value, member.signature, flipped, f"{path}.", streams)
    elif inward:
        m.d.comb += value.eq(AnySeq(Shape.cast(member.shape).width))


def _invariants(obj, seen=None):
    """``(name, value)`` for ``obj`` and each component it holds (its attributes, walked down)
    that states an ``invariant()``: what holds in every state a reset reaches."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return []
    seen.add(id(obj))
    found = [(type(obj).__name__, obj.invariant())] if callable(getattr(obj, "invariant", None)) \
        else []
    for value in vars(obj).values():
        if isinstance(value, wiring.Component):
            found += _invariants(value, seen)
    return found


def contract_harness(component, held=None, assume=None):
    """A harness for ``component`` alone: every input port free (``AnySeq``), every input stream
    from any producer that keeps the rules, every output stream's rules asserted against any
    consumer. One line per component: ``formal(contract_harness(Block()), ...)``.

    ``held`` maps input ports to the input stream they travel with, for ports a component's
    documentation says hold still while that stream's transfer waits (as its payload does):
    ``held={"sample": "results"}`` assumes ``sample`` keeps its value in every cycle after one
    with ``results.valid & ~results.ready``.

    ``assume`` (a function of the component, giving a value) states what its documentation
    asks of its user in every cycle, assumed: e.g. a FIFO's rewind only while no offered byte
    waits.

    A component that states an ``invariant()`` of its internal state (one it holds, or it,
    walked down its attributes) has it asserted as well: proven with the rules, it keeps the
    induction to the states a reset reaches, where the block may rely on it (the
    ``RewindableFIFO`` offers a byte while ``read != write``)."""
    m = harness_module()
    m.submodules.dut = component
    streams = []
    _walk(m, component, component.signature, False, "", streams)
    for port, stream_name in (held or {}).items():
        value, s = _bits(getattr(component, port)), getattr(component, stream_name)
        started = Signal(name=f"{port}_held_started")
        m.d.sync += started.eq(1)
        # the Past registers outside the If: inside, they would load only when it holds
        was_waiting, was_value = Past(m, s.valid & ~s.ready), Past(m, value)
        with m.If(started & was_waiting):
            m.d.comb += Assume(value == was_value, f"{port}_held")
    if assume is not None:
        m.d.comb += Assume(assume(component), "documented_use")
    for k, (name, value) in enumerate(_invariants(component)):
        m.d.comb += Assert(value, f"{name}_invariant_{k}")
    for path, s, inward in streams:
        name = path.replace(".", "_")
        if inward:
            stream_input(m, s, name)
        else:
            stream_output(m, s, name, cover=False)
    return m
