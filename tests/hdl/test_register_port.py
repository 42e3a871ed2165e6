"""The SPI register port: a command becomes one transaction (header, then data or dummy
bytes), the bytes read come out in order, and a consumer that is not ready holds the bus back
rather than losing a byte. (The I2C register port runs against the bus model in
``test_i2c_wiring.py``; both ports' stream rules are proven in ``tests/formal``.)"""

from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.register_port import SPIRegisterPort
from mpu9250_ahrs.sim.bench.streams import check_stream_rules, stream_get, stream_put


def run(commands, *, rx_stall=0):
    """Send ``commands`` (dicts of ``RegisterCommand`` fields) through the port to a simulated
    SPI controller that answers every byte with its index in the transaction + 0x40; return
    the bytes the controller was given, the ``rx`` bytes and the responses."""
    dut = SPIRegisterPort()
    sent, received, responses = [], [], []

    async def controller(ctx):
        index = 0
        while True:
            byte = await stream_get(ctx, dut.spi_o)
            sent.append((byte.data, byte.fast, byte.last))
            await stream_put(ctx, dut.spi_i, 0x40 + index)
            index = 0 if byte.last else index + 1

    async def client(ctx):
        for command in commands:
            await stream_put(ctx, dut.port.cmd, command)
            while True:
                if ctx.get(dut.port.rsp.valid):
                    responses.append(ctx.get(dut.port.rsp.payload.error))
                    ctx.set(dut.port.rsp.ready, 1)
                    await ctx.tick()
                    ctx.set(dut.port.rsp.ready, 0)
                    break
                if ctx.get(dut.port.rx.valid):
                    if rx_stall:
                        await ctx.tick().repeat(rx_stall)    # a slow consumer
                    received.append(await stream_get(ctx, dut.port.rx))
                else:
                    await ctx.tick()

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(controller, background=True)
    sim.add_testbench(client)
    for name, s in (("spi_o", dut.spi_o), ("rx", dut.port.rx), ("rsp", dut.port.rsp)):
        check_stream_rules(sim, s, name)
    sim.run()
    return sent, received, responses


READ = {"device": 0, "reg": 0x3B, "write": 0, "data": 0, "length": 3, "fast": 1}
WRITE = {"device": 0, "reg": 0x6B, "write": 1, "data": 0x80, "length": 1, "fast": 1}


def test_read_and_write_transactions():
    sent, received, responses = run([READ, WRITE])
    # read: header with bit 7 set, three dummy bytes, fast clock; write: header, data, slow
    assert sent == [(0xBB, 1, 0), (0, 1, 0), (0, 1, 0), (0, 1, 1),
                    (0x6B, 0, 0), (0x80, 0, 1)]
    assert received == [0x41, 0x42, 0x43]            # the header's answer is not a byte read
    assert responses == [0, 0]


def test_a_slow_consumer_loses_no_byte():
    assert run([READ], rx_stall=5)[1] == [0x41, 0x42, 0x43]
