"""Top levels.

``AHRSCore`` is everything that is not a pin buffer: the sensor front end, the attitude engine
(calibration and filters), and the telemetry framer with its UART. It is what
``build --verilog-only`` exports and what simulations of the whole design drive. Ports:
``imu`` (SPI pins, or I2C pins with ``config.wiring == "i2c"``), ``imu_int``, ``uart_tx``,
``status``, ``asa``, ``samples_seen`` (counts samples, for a heartbeat LED), ``cfg``
(register writes to the engine, before the command channel's; tie ``valid`` low on a board)
and ``cfg_read`` / ``cfg_read_data`` (read-back), ``uart_rx`` (the command channel,
``hdl/FRAMES.md``) and ``pwm`` (four PWM outputs, ``hdl/link/pwm.py``).

Telemetry: an ``AttitudeFrame`` (type 0x02: the result, the raw sample it came from, the
driver status latched with it, the counters) for every ``TELEMETRY_DIV``-th result, while every
sample is filtered; in raw-sample mode (a host command) a ``SensorFrame`` (0x01) instead.
The engine's filters are set up for the sensor configuration: T = 1/ODR, gyro LSB per °/s
from the full scale, the published Q, R, P₀ converted from physical units at that rate
(``FilterRates``). ``rate_budget`` says what the design sustains at a clock; ``build`` and
``simulate`` check a configuration with it.

On an I2C-wired board the MPU9250's SCL/SDA are the pins SCLK/SDI use with SPI; ``BoardTop``
then holds NCS high (I2C mode) and drives AD0 (SDO) to select 0x68 or 0x69.

``BoardTop`` puts ``lib.io`` buffers between ``AHRSCore`` and a ``MAX10Platform``'s pins and
shows the driver status on the LEDs:

====  ==================================================
LED   meaning
====  ==================================================
0     streaming (bring-up done, samples flowing)
1     WHO_AM_I wrong
2     no response (WHO_AM_I read 0x00 or 0xFF)
3     data-ready interrupt timed out
4     heartbeat: toggles every 256 samples
5-7   bring-up restarts (low three bits)
====  ==================================================
"""

import math

from amaranth import *
from amaranth.lib import data, io, stream, wiring
from amaranth.lib.cdc import ResetSynchronizer
from amaranth.lib.wiring import In, Out, connect, flipped

from ..primitives.clocking import SYSTEM_CLOCK_HZ, cycles
from ..sensor.mpu9250_driver import DriverTiming, MPU9250Config
from ..engine.attitude_isa import REG_BITS
from ..engine.register_map import TELEMETRY_DIV_ADDR
from ..engine.attitude_engine import (PEEKED, WORST_UPDATE_CYCLES, AttitudeEngine,
                                      default_filter_config, default_flagship_config)
from ..engine.attitude_result import Attitude
from ..engine.config_write import ConfigWrite
from ..sensor.driver_status import DriverStatus
from ..sensor.sample import Sample
from ..sensor.sample_store import STORE_BITS, sample_store_ram
from ..sensor.data_ready_timer import tick_cycles
from ..sensor.sensor_frontend import SensorFrontEnd, sample_read_cycles
from ..sensor.i2c_controller import I2CPinsSignature
from ..sensor.spi_controller import IO_BUDGET, SPIPinsSignature, SPITiming
from ..engine.register_map import HOST_WRITABLE
from ..link.command_decoder import CommandDecoder
from ..link.register_executor import RegisterExecutor
from ..engine.config_port_arbiter import ConfigPortArbiter
from ..link.frame_arbiter import FrameArbiter
from ..link.frame_types import ATTITUDE, REPLY, SENSOR
from ..contract.pwm_regs import PWM_CHANNELS
from ..link.pwm import PWMOutputs
from ..link.frame_types import (CRC, AttitudeFrame, Reply, SensorFrame, TelemetryCounters,
                                frame_bytes)
from ..link.axi_lite_slave import AXILiteSignature, AXILiteSlave
from ..control.balance_controller import BalanceController
from ..link.stream_tap import StreamTap
from ..link.telemetry import TelemetryFramer
from ..link.telemetry_scheduler import TelemetryScheduler
from ..link.uart_rx import UARTReceiver
from ..contract.defaults import DEFAULT_BAUD
from ..link.uart_tx import UARTTransmitter


__all__ = ["AHRSCore", "result_fetch", "sample_borrow", "AsyncResetCore", "core_verilog",
           "BoardTop", "telemetry_divider_for", "rate_budget", "VERSION", "version_word",
           "io_constraints", "io_register_settings"]


VERSION = (0, 2)        # major, minor: the version/build word's top bytes


def result_fetch():
    """The attitude framer's ``fetch``: the bit offset of an ``AttitudeFrame``'s quaternion,
    angles and bias (consecutive 32-bit words, the engine's ``PEEKED`` order) and their count."""
    fields = data.Layout.cast(data.Layout.cast(AttitudeFrame)["attitude"].shape)
    offset = data.Layout.cast(AttitudeFrame)["attitude"].offset
    words = [(name, i) for name in ("quat", "angles", "bias")
             for i in range(fields[name].shape.length)]
    assert len(words) == len(PEEKED)
    assert all(fields[name].offset + 32 * i == 32 * k
               for k, (name, i) in enumerate(words)), "the fetched words are not consecutive"
    return offset, len(PEEKED)


def sample_borrow():
    """The attitude framer's ``borrow``: an ``AttitudeFrame``'s sample, the words the
    engine's ``sample_word`` gives from the sample store (``hdl/sensor/sample_store.py``: the
    sample's bits, the last word padded with zeros)."""
    sample = data.Layout.cast(AttitudeFrame)["sample"]
    assert sample.offset == 0
    return 0, STORE_BITS


def version_word(**build):
    """The word "who are you" returns: major (8 bits), minor (8), then a build number: the
    CRC-16 of the build's options (``repr`` of ``build``'s sorted items), so two bitstreams
    built with other options answer differently."""
    text = repr(sorted(build.items())).encode()
    return (VERSION[0] << 24) | (VERSION[1] << 16) | CRC(data_width=8).compute(text)


def telemetry_divider_for(config, baud, divider=None, *, rate=None):
    """``divider`` checked (1..65535), or when None the smallest divider of the sample rate at
    which attitude frames (10 bits a byte on the UART) fit the link: 1 sends every result.
    ``rate``: the samples' rate (Hz) if not ``config``'s (a co-simulation's shortened sample
    period)."""
    if divider is None:
        frame_s = 10 * frame_bytes(AttitudeFrame) / baud
        rate = config.output_data_rate if rate is None else rate
        divider = max(1, math.ceil(frame_s * rate - 1e-9))
        if divider >= 1 << 16:
            raise ValueError(f"at {baud:g} baud an attitude frame takes {frame_s:.3g} s: one "
                             f"in {divider} samples, more than the telemetry divider's 65535; "
                             f"a faster baud")
    if not 1 <= divider < 1 << 16:
        raise ValueError(f"telemetry divider {divider} is not 1..65535")
    return divider


def rate_budget(config, clk_freq, baud=DEFAULT_BAUD, telemetry_divider=None):
    """What the design sustains for ``config`` at ``clk_freq`` (a dict): ``read_cycles`` (a
    sample's read, ``sample_read_cycles``), ``update_cycles`` (the engine's worst update,
    ``WORST_UPDATE_CYCLES``), ``cycles_per_sample`` (the larger: the driver reads the next
    sample while the engine works on the last), ``max_sample_rate_hz``, and the telemetry's
    ``telemetry_divider``, ``frame_bytes``, ``frame_us``, ``frames_per_s``."""
    read = sample_read_cycles(config, clk_freq)
    update = WORST_UPDATE_CYCLES
    per_sample = max(read, update)
    rate = config.output_data_rate
    size = frame_bytes(AttitudeFrame)
    divider = telemetry_divider_for(config, baud, telemetry_divider)
    return {"sample_rate_hz": rate, "read_cycles": read, "update_cycles": update,
            "cycles_per_sample": per_sample, "max_sample_rate_hz": clk_freq / per_sample,
            "baud": baud, "telemetry_divider": divider, "frame_bytes": size,
            "frame_us": 10 * size / baud * 1e6, "frames_per_s": rate / divider}


class AHRSCore(wiring.Component):
    """Everything but the pins: sensor front end, attitude engine, telemetry.

    Parameters
        ``clk_freq``: system clock, Hz (``SYSTEM_CLOCK_HZ`` unless told).
        ``config`` (``MPU9250Config``), ``timing`` (``DriverTiming``): the sensor and driver.
        ``baud``: the UART's rate.
        ``attitude``: with the engine (attitude frames) or without (sensor frames only).
        ``filter_config``, ``flagship_config``, ``calibration``, ``filter``: the engine's
            reset values (default: set up for ``config``'s sample rate and full scales).
        ``telemetry_divider``: frame every n-th result at reset (default: the smallest n at
            which the frames fit the baud rate, ``telemetry_divider_for``); run time: register
            ``TELEMETRY_DIV_ADDR`` of the ``cfg`` port.
    Members
        ``imu``, ``imu_int``: sensor pins (raw; synchronised inside).
        ``uart_tx``: telemetry out.
        ``status`` (``DriverStatus``), ``asa``: the driver's, live.
        ``samples_seen`` (8): samples read, wrapping (a heartbeat for an LED).
        ``cfg``, ``cfg_read``, ``cfg_read_data``: the engine's register port (with ``attitude``).
        ``counters`` (``TelemetryCounters``): results filtered, samples lost, results not sent.
        ``cfg_refused`` (16): host writes the engine refused (read-only or state registers).
        ``uart_rx``: commands in (``UARTReceiver`` -> ``CommandDecoder``, replies out
            through the ``FrameArbiter`` before telemetry); ``pwm`` (4): ``PWMOutputs``;
            ``raw_mode``: the command channel's (its counters are in the decoder's
            ``EventCounters``, read as board registers).
        ``command_timeout_s``: a command frame with no byte for this long is dropped (5 ms).
        ``commands`` (True): with the command channel (``uart_rx``, the decoder, replies);
            False leaves it out (no ``uart_rx`` and ``raw_mode`` ports; the
            ``cfg`` ports alone write the engine) and with it the PWM outputs.
        ``pwm`` (default: as ``commands``): with the PWM outputs (the ``pwm`` port); without,
            the command channel answers ``bad_address`` for the PWM registers. Both options
            are for users who need the room (``report`` counts each build).
        ``controller`` (None): "balance" adds the balance controller
            (``BalanceController``: a self-balancing robot's loop on the chip, issue #57),
            its registers in space 0x03, the PWM block left out (space 0x02), the ``pwm``
            port its two H-bridges, ``arm`` (in) its arming pin; ``controller_regs`` its
            registers' values at reset, by name (``balance_regs.BALANCE_REGS``).
        ``attitude_port`` (False): with ``attitude`` (out, stream of ``Attitude``): every
            result the engine gives, for logic on the same chip, held until taken and never
            holding the engine or the telemetry up (``StreamTap``: a result that comes while
            the one before still waits is not offered, counted in ``attitude_dropped``, out,
            16, saturating); and ``sample`` (out, stream of ``Sample``), ``sample_dropped``
            (out, 16): each sample as the engine takes it, the same way (its ``counter`` is
            its result's). Its cost: registers of the result's 362 bits and the sample's
            and the counters (``report --attitude-port`` counts the build with it);
            unconnected in a board top, synthesis removes it.
        ``axi_lite`` (False): with ``s_axi`` (an AXI4-Lite slave, ``AXILiteSlave``: the
            last result (read from the engine's registers: a sequence count says whether a
            block of words is one result's), status, counters, the host's registers through the command channel's executor and rules;
            ``hdl/AXI_LITE.md``) and ``irq`` (out: a result came, write-one-to-clear).

    With the engine, every sample the driver reads is filtered: the engine takes a sample as
    soon as its previous update is done (``WORST_UPDATE_CYCLES`` at most) and the
    ``TelemetryScheduler`` takes every result at once, or after the framer's 22-cycle copy of
    a result it frames; the UART never holds the filter up.

    Latency: data-ready edge to result: at most ``sample_read_cycles`` plus the engine's update
    (``report`` prints both, and their sum as the latency in µs); the result then waits for
    its frame's turn on the UART.
    """
    def __init__(self, *, clk_freq=SYSTEM_CLOCK_HZ, config=MPU9250Config(),
                 timing=DriverTiming(), baud=DEFAULT_BAUD, filter_config=None,
                 calibration=None, flagship_config=None, filter="flagship",
                 telemetry_divider=None, command_timeout_s=0.005, commands=True, pwm=None,
                 attitude_port=False, axi_lite=False, controller=None, controller_regs=None):
        if controller not in (None, "balance"):
            raise ValueError(f"controller {controller!r}: None or 'balance'")
        if controller and not commands:
            raise ValueError("the balance controller's registers are set through the command "
                             "channel: controller='balance' needs commands=True")
        if pwm is None:
            pwm = commands and not controller
        if pwm and not commands:
            raise ValueError("the PWM outputs are set through the command channel: "
                             "pwm=True needs commands=True")
        if pwm and controller:
            raise ValueError("the balance controller drives the PWM outputs: it leaves the "
                             "PWM block out (pwm=False)")
        self.commands = commands
        self.has_pwm = pwm and self.commands
        self.controller = controller
        self.attitude_port = attitude_port
        self.axi_lite = axi_lite
        self.clk_freq = clk_freq
        self.config = config
        self.baud = baud
        # checked before any component exists, so that a bad value is one clear error
        telemetry_divider = telemetry_divider_for(config, baud, telemetry_divider)
        self.frontend = SensorFrontEnd(clk_freq=clk_freq, config=config, timing=timing)
        if filter_config is None:
            filter_config = default_filter_config(config)
        if flagship_config is None:
            flagship_config = default_flagship_config(config)
        self.framer = TelemetryFramer(AttitudeFrame, ATTITUDE, buffered=True,
                                      short=(SENSOR, SensorFrame), fetch=result_fetch(),
                                      borrow=sample_borrow(), shared_crc=commands)
        self.telemetry_divider = telemetry_divider
        self.engine = AttitudeEngine(filter_config, calibration, flagship_config,
                                     filter=filter,
                                     extra_registers={"TELEMETRY_DIV": telemetry_divider},
                                     sample_store=True)
        # the samples, from the reader to the engine's loader and the framer
        self.sample_store = sample_store_ram()
        self.scheduler = TelemetryScheduler()
        # the build's options in the version word only when they leave something out,
        # so that the default build's word is as before
        left_out = {k: False for k, on in (("commands", self.commands),
                                           ("pwm", self.has_pwm)) if not on}
        if controller:
            left_out = {"controller": controller}     # the PWM block gives way to it
        self.version = version_word(clk_freq=clk_freq, baud=baud, config=repr(config),
                                    filter=filter, **left_out)
        if self.commands:
            self.receiver = UARTReceiver(divisor=UARTTransmitter.divisor_for(clk_freq, baud))
            # the time-out in the sample reader's ticks (``decoder.tick``, from the front end)
            # with the AXI slave, the decoder's executor has a second front end: the slave
            self.decoder = CommandDecoder(
                writable=HOST_WRITABLE, version=self.version, ports=2 if axi_lite else 1,
                timeout=cycles(command_timeout_s, clk_freq),
                tick_cycles=tick_cycles(self.frontend.driver.period_cycles))
            # the two framers share a CRC processor (the arbiter never interleaves their
            # frames): ``_command_channel``
            self.reply_framer = TelemetryFramer(Reply, REPLY, shared_crc=True)
            self.arbiter = FrameArbiter(2)             # replies first, then telemetry
        else:
            self.arbiter = FrameArbiter(1)
        if self.has_pwm:
            self.pwm_block = PWMOutputs(clk_freq=clk_freq)
        if controller:
            self.balance = BalanceController(clk_freq=clk_freq, reset=controller_regs)
        self.uart = UARTTransmitter.for_baud(clk_freq, baud)
        ports = {
            "imu": Out(SPIPinsSignature() if config.wiring == "spi" else I2CPinsSignature()),
            "imu_int": In(1),
            "uart_tx": Out(1, init=1),
            "status": Out(DriverStatus),
            "asa": Out(data.ArrayLayout(8, 3)),
            "samples_seen": Out(8),
            "cfg": In(stream.Signature(ConfigWrite)),
            "cfg_read": In(stream.Signature(REG_BITS)),
            "cfg_read_data": Out(stream.Signature(signed(32))),
            "counters": Out(TelemetryCounters),
            "cfg_refused": Out(16),
        }
        if self.commands:
            ports["uart_rx"] = In(1, init=1)
            ports["raw_mode"] = Out(1)
        if self.has_pwm or controller:
            ports["pwm"] = Out(PWM_CHANNELS)
        if controller:
            ports["arm"] = In(1)
        if attitude_port:
            self.attitude_tap = StreamTap(Attitude)
            self.sample_tap = StreamTap(Sample)
            ports["attitude"] = Out(stream.Signature(Attitude))
            ports["attitude_dropped"] = Out(16)
            ports["sample"] = Out(stream.Signature(Sample))
            ports["sample_dropped"] = Out(16)
        if axi_lite:
            self.axi_slave = AXILiteSlave()
            if not self.commands:
                self.axi_executor = RegisterExecutor(writable=HOST_WRITABLE,
                                                     version=self.version)
            ports["s_axi"] = In(AXILiteSignature())
            ports["irq"] = Out(1)
        super().__init__(ports)

    def elaborate(self, platform):
        m = Module()
        m.submodules.frontend = fe = self.frontend
        m.submodules.framer = framer = self.framer
        m.submodules.uart = uart = self.uart
        m.submodules.arbiter = arbiter = self.arbiter

        connect(m, fe.pins, flipped(self.imu))
        m.d.comb += [fe.int_pin.eq(self.imu_int), self.status.eq(fe.status),
                     self.asa.eq(fe.asa), self.uart_tx.eq(uart.tx)]

        # Sample -> engine -> scheduler (every result taken; every n-th framed) -> UART.
        # The engine takes a sample only when its previous result is out, and the scheduler
        # takes results at once or after the framer's copy, so the sample the engine holds
        # (and the status read with it, held here) belongs to the result the scheduler sees.
        m.submodules.engine = engine = self.engine
        m.submodules.scheduler = sched = self.scheduler
        connect(m, fe.samples, engine.samples)
        connect(m, engine.results, sched.results)
        connect(m, sched.frames, framer.i_stream)
        # the result's quaternion, angles and bias: copied from the engine's register file
        # while the scheduler offers it (the engine is idle then), not from its payload
        m.d.comb += [engine.peek_en.eq(framer.fetch_en), engine.peek_index.eq(framer.fetch_index),
                     framer.fetch_data.eq(engine.peek_data)]
        # The sample: written into the sample store by the reader (its sensor bytes as they
        # come off the bus), read by the engine's loader and, through the engine's port of
        # the store, by the framer (no multiplexer of the sample's words anywhere)
        m.submodules.sample_store = store = self.sample_store
        m.d.comb += [store.w_en.eq(fe.store.w_en), store.w_addr.eq(fe.store.w_addr),
                     store.w_data.eq(fe.store.w_data), store.r_en.eq(1),
                     store.r_addr.eq(engine.store_addr), engine.store_data.eq(store.r_data),
                     engine.sample_slot.eq(fe.sample_slot), engine.imu_ready.eq(fe.imu_ready),
                     engine.sample_index.eq(framer.borrow_index),
                     framer.borrow_data.eq(engine.sample_word)]
        held_status = Signal(DriverStatus, reset_less=True)
        with m.If(fe.samples.valid & fe.samples.ready):
            m.d.sync += held_status.eq(fe.status)

        # the engine's first register port: the ``cfg`` ports; the second a register
        # executor's (the command decoder's, or the AXI slave's own without one)
        cfg_port = (flipped(self.cfg), flipped(self.cfg_read), flipped(self.cfg_read_data))
        if self.commands:
            self._command_channel(m, engine, framer, arbiter, fe, cfg_port)
        else:
            if self.axi_lite:
                m.submodules.axi_executor = executor = self.axi_executor
                m.d.comb += [executor.frames_sent.eq(arbiter.frames),
                             executor.frames_stable.eq(arbiter.frames_stable),
                             executor.early_sample.eq(fe.early_sample),
                             executor.who_am_i.eq(fe.who_am_i),
                             executor.self_test.eq(fe.self_test),
                             executor.level.eq(fe.level)]
                self._cfg_arbiter(m, engine, cfg_port, executor)
            else:
                connect(m, cfg_port[0], engine.cfg)
                connect(m, cfg_port[1], engine.cfg_read)
                connect(m, engine.cfg_read_data, cfg_port[2])
            connect(m, framer.o_stream, arbiter.i0)
        if self.axi_lite:
            self._axi(m, engine, sched, fe)
        # the divider register: the engine keeps its copy for read-back
        divider = Signal(16, init=self.telemetry_divider)
        with m.If(engine.cfg.valid & engine.cfg.ready &
                  (engine.cfg.payload.addr == TELEMETRY_DIV_ADDR)):
            m.d.sync += divider.eq(engine.cfg.payload.data[:16])
        m.d.comb += [
            engine.asa.eq(fe.asa),
            sched.sample.eq(engine.sample), sched.status.eq(held_status),
            sched.divider.eq(divider), self.counters.eq(sched.counters),
            sched.cfg_refused.eq(engine.cfg_refused), self.cfg_refused.eq(engine.cfg_refused),
            sched.framer_idle.eq(framer.idle),
        ]
        m.d.comb += framer.seq.eq(arbiter.seq)
        connect(m, arbiter.o_stream, uart.i_stream)
        with m.If(fe.samples.valid & fe.samples.ready):
            m.d.sync += self.samples_seen.eq(self.samples_seen + 1)
        if self.attitude_port:
            # every result as the scheduler takes it (it takes every one): the tap watches
            # the transfer and takes no part in it
            m.submodules.attitude_tap = tap = self.attitude_tap
            m.d.comb += [*tap.watch(engine.results), self.attitude_dropped.eq(tap.dropped)]
            connect(m, tap.o, flipped(self.attitude))
            # each sample as the engine takes it (the reader's payload: the whole sample)
            m.submodules.sample_tap = stap = self.sample_tap
            m.d.comb += [*stap.watch(fe.samples), self.sample_dropped.eq(stap.dropped)]
            connect(m, stap.o, flipped(self.sample))
        return m


    def _axi(self, m, engine, sched, fe):
        """The AXI4-Lite slave (the result's words read from the engine's registers and its
        payload: no copy), its host registers through the command decoder's executor (its
        second port) or, without the command channel, one of its own."""
        m.submodules.axi_slave = axi = self.axi_slave
        result = engine.results
        m.d.comb += [axi.done.eq(result.valid & result.ready), axi.busy.eq(engine.busy),
                     axi.counter.eq(result.payload.counter), axi.flags.eq(result.payload.flags),
                     axi.status.eq(fe.status), axi.counters.eq(sched.counters),
                     self.irq.eq(axi.irq)]
        connect(m, flipped(self.s_axi), axi.axi)
        executor, port = (self.decoder.executor, 1) if self.commands else \
            (self.axi_executor, 0)
        connect(m, axi.request, executor.request[port])
        connect(m, executor.response[port], axi.response)

    def _balance(self, m, engine, fe, decoder):
        """The balance controller: its registers on the command channel's space 0x03, the
        result and the sample the engine takes, the driver's faults, a pulse per sample period,
        the arming pin; it drives the PWM outputs (the PWM block is left out: space 0x02
        answers bad_address)."""
        m.submodules.balance = balance = self.balance
        connect(m, decoder.control, balance.bus)
        result, sample, status = engine.results, fe.samples, fe.status
        # one pulse per sample period, for the controller's stale and watchdog counts
        period = self.frontend.driver.period_cycles
        count = Signal(range(period))
        m.d.sync += count.eq(Mux(count == period - 1, 0, count + 1))
        m.d.comb += [
            balance.done.eq(result.valid & result.ready),
            balance.angles.eq(Cat(result.payload.angles[0], result.payload.angles[1])),
            balance.bias.eq(Cat(result.payload.bias[0], result.payload.bias[1])),
            balance.sample_taken.eq(sample.valid & sample.ready),
            balance.gyro.eq(Cat(sample.payload.gyro[0], sample.payload.gyro[1])),
            balance.fault.eq(~status.streaming | status.no_response | status.int_timeout |
                             status.bad_burst | status.self_test_fail.any()),
            balance.period.eq(count == period - 1),
            balance.kick.eq(decoder.kick),
            balance.arm_pin.eq(self.arm),
            self.pwm.eq(balance.pwm),
        ]

    def _cfg_arbiter(self, m, engine, cfg_port, client):
        """The engine's register port: the ``cfg`` ports (a test bench, or tied off) first,
        then ``client``'s (a decoder's or an executor's); a waiting transfer keeps its
        client."""
        m.submodules.cfg_arbiter = cfg_arbiter = ConfigPortArbiter()
        connect(m, cfg_port[0], cfg_arbiter.first)
        connect(m, client.cfg, cfg_arbiter.second)
        connect(m, cfg_arbiter.cfg, engine.cfg)
        connect(m, cfg_port[1], cfg_arbiter.first_read)
        connect(m, client.cfg_read, cfg_arbiter.second_read)
        connect(m, cfg_arbiter.cfg_read, engine.cfg_read)
        connect(m, engine.cfg_read_data, cfg_arbiter.cfg_read_data)
        connect(m, cfg_arbiter.first_read_data, cfg_port[2])
        connect(m, cfg_arbiter.second_read_data, client.cfg_read_data)

    def _command_channel(self, m, engine, framer, arbiter, fe, cfg_port):
        """Host -> UART receiver -> command decoder (its FIFO inside) -> engine / board / PWM,
        and its replies -> framer -> arbiter (before telemetry) -> UART."""
        m.submodules.uart_rx = rx = self.receiver
        m.submodules.decoder = decoder = self.decoder
        m.submodules.reply_framer = reply_framer = self.reply_framer
        m.d.comb += rx.rx.eq(self.uart_rx)
        connect(m, rx.o_stream, decoder.i_stream)
        connect(m, decoder.replies, reply_framer.i_stream)
        # one CRC for both framers: only the one the arbiter lets send drives it
        m.submodules.frame_crc = crc = CRC(data_width=8).create()
        m.d.comb += [crc.data.eq(Mux(framer.crc_start | framer.crc_valid, framer.crc_data,
                                     reply_framer.crc_data)),
                     crc.start.eq(framer.crc_start | reply_framer.crc_start),
                     crc.valid.eq(framer.crc_valid | reply_framer.crc_valid),
                     framer.crc_value.eq(crc.crc), reply_framer.crc_value.eq(crc.crc)]
        if self.has_pwm:
            m.submodules.pwm = pwm = self.pwm_block
            connect(m, decoder.pwm, pwm.bus)
            m.d.comb += [pwm.kick.eq(decoder.kick), self.pwm.eq(pwm.pwm)]
        if self.controller:
            self._balance(m, engine, fe, decoder)
        m.d.comb += [decoder.tick.eq(fe.tick), decoder.rx_framing_error.eq(rx.framing_error),
                     decoder.rx_overrun.eq(rx.overrun),
                     decoder.frames_sent.eq(arbiter.frames),
                     decoder.frames_stable.eq(arbiter.frames_stable),
                     decoder.early_sample.eq(fe.early_sample),
                     decoder.who_am_i.eq(fe.who_am_i), decoder.self_test.eq(fe.self_test),
                     decoder.level.eq(fe.level),
                     self.raw_mode.eq(decoder.raw_mode),
                     framer.short.eq(decoder.raw_mode)]
        self._cfg_arbiter(m, engine, cfg_port, decoder)
        connect(m, reply_framer.o_stream, arbiter.i0)
        connect(m, framer.o_stream, arbiter.i1)
        m.d.comb += reply_framer.seq.eq(arbiter.seq)


def io_constraints(config, clk_freq, *, pll=True, budget=IO_BUDGET):
    """``top.sdc`` lines that give Quartus the sensor pins' timing, from the same figures the
    SPI controller's sample point was chosen with (``IOBudget``), so that its timing analysis
    checks them (no Quartus here: these are not checked by this project's tests).

    SPI: SCLK, COPI and CS leave from registers and must reach the board within
    ``board_ns``; CIPO's next bit arrives at most ``fpga_out + 2 board + sdo_max`` ns after the
    clock edge that launched SCLK's falling edge and is sampled ``first`` cycles later (a
    multicycle path): Quartus checks the rest of the budget (the pad to the input register,
    the margin). I2C: SCL and SDA are sampled through synchronisers, their timing is the
    bus's (µs): false paths in, ``board_ns`` out. INT likewise."""
    clock = "[get_clocks {*pll1|clk[0]}]" if pll else "[get_clocks {clk12_0__io}]"
    # outside the FPGA's input: Quartus adds the pad-to-register path itself
    out_ns, in_ns = budget.board_ns, budget.arrival_ns - budget.fpga_in_ns
    lines = ["# the MPU9250's pins (hdl/board/top.py io_constraints, figures: IOBudget in "
             "hdl/sensor/spi_controller.py)"]

    def outputs(ports):
        names = " ".join(ports)
        lines.extend([f"set_output_delay -clock {clock} -max {out_ns:g} [get_ports {{{names}}}]",
                      f"set_output_delay -clock {clock} -min {-out_ns:g} "
                      f"[get_ports {{{names}}}]"])

    if config.wiring == "spi":
        timing = SPITiming.for_clock(clk_freq, io_budget=budget)
        first, _ = timing.sample_window(fast=True)
        outputs(["imu_spi_0__clk__io", "imu_spi_0__copi__io", "imu_spi_0__cs__io"])
        cipo = "[get_ports {imu_spi_0__cipo__io}]"
        lines += [f"set_input_delay -clock {clock} -max {in_ns:g} {cipo}",
                  f"set_input_delay -clock {clock} -min 0 {cipo}",
                  f"# sampled {first} cycles after SCLK's falling edge leaves its register",
                  f"set_multicycle_path -setup -from {cipo} {first}",
                  f"set_multicycle_path -hold -from {cipo} {first - 1}",
                  "set_false_path -from [get_ports {imu_spi_0__int__io}]"]
    else:
        outputs(["imu_i2c_0__scl__io", "imu_i2c_0__sda__io", "imu_i2c_0__ncs__io",
                 "imu_i2c_0__ad0__io"])
        lines += ["set_false_path -from [get_ports {imu_i2c_0__scl__io imu_i2c_0__sda__io "
                  "imu_i2c_0__int__io}]"]
    return "\n".join(lines) + "\n"


def io_register_settings(config):
    """``top.qsf`` lines that put the SPI pins' registers in the I/O elements (SCLK, COPI and
    CS's output registers, CIPO's first synchroniser stage), so that their delays are the
    short, fixed ones ``IOBudget`` allows for. I2C's pins are slow and synchronised: none."""
    if config.wiring != "spi":
        return ""
    lines = [f"set_instance_assignment -name FAST_OUTPUT_REGISTER ON -to imu_spi_0__{p}__io"
             for p in ("clk", "copi", "cs")]
    lines.append("set_instance_assignment -name FAST_INPUT_REGISTER ON -to imu_spi_0__cipo__io")
    return "\n".join(lines) + "\n"


def core_verilog(core, name="mpu9250_ahrs_core"):
    """``core``'s Verilog as a board builds it (``AsyncResetCore``): ports ``clk``, ``rst``
    (asynchronous, active high) and the core's own."""
    from amaranth.back import verilog
    wrapped = AsyncResetCore(core)
    return verilog.convert(wrapped, name=name, ports=wrapped.ports())


class AsyncResetCore(Elaboratable):
    """A design (``AHRSCore``) in a ``sync`` domain with an asynchronous reset: what a board
    builds (``BoardTop``) and what ``build --verilog-only``, ``report`` and ``report --timing``
    convert (``core_verilog``). The design's own module gets the domain, so the hierarchy and
    the port names are the design's, plus ``clk`` and ``rst``.

    Why asynchronous: it is Intel's recommended reset for its devices (asserted at any time,
    released in step with the clock by a ``ResetSynchronizer``), and the MAX10 LE's register
    clears asynchronously at no cost, where Yosys 0.23's MAX10 mapping builds a synchronous
    reset from a LUT in front of each register bit that has one (about 750 LEs of this design
    by ``report``'s count). The co-simulations clock the core with Amaranth's default
    synchronous reset and never assert it, so both behave the same cycle for cycle
    (``tests/hdl/test_pwm.py`` asserts the asynchronous one on the PWM outputs).

    Members
        ``clk``, ``rst`` (in): the clock, and the reset (active high; assert it at any time,
            release it synchronously to ``clk``).
    """
    def __init__(self, design):
        self.design = design
        self.clk = Signal()
        self.rst = Signal()

    def ports(self):
        return [self.clk, self.rst,
                *(Value.cast(v) for _, _, v in self.design.signature.flatten(self.design))]

    def elaborate(self, platform):
        m = self.design.elaborate(platform)
        # the design is elaborated here, as this module: not left unused
        self.design._MustUse__silence = True
        m.domains.sync = ClockDomain("sync", async_reset=True)
        m.d.comb += [ClockSignal("sync").eq(self.clk), ResetSignal("sync").eq(self.rst)]
        return m


class BoardTop(Elaboratable):
    """``AHRSCore`` on a board's platform (``MAX10Platform``, or ``ULX3SPlatform`` for the open
    ECP5 flow): pin buffers, the status LEDs, and the clock.

    The system clock (``clk_freq``, default ``SYSTEM_CLOCK_HZ``) comes from the platform's PLL
    (``platform.system_pll``: a ``SystemPLL`` on the MAX10, an ``ECP5PLL`` on the ULX3S)
    fed by the board's oscillator; the whole design is held in reset until the PLL locks (a
    ``ResetSynchronizer`` releases it on the system clock). With ``clk_freq`` equal to the
    oscillator's frequency there is no PLL and the oscillator clocks the design directly.
    ``PLL_CONSTRAINTS`` go into ``top.sdc`` (``build`` passes them as ``add_constraints``).
    """
    PLL_CONSTRAINTS = "derive_pll_clocks -create_base_clocks\nderive_clock_uncertainty\n"

    def __init__(self, *, clk_freq=SYSTEM_CLOCK_HZ, **core_kwargs):
        self.clk_freq = clk_freq
        self.core_kwargs = core_kwargs

    def elaborate(self, platform):
        m = Module()
        osc = platform.request(platform.default_clk, 0, dir="-")
        m.submodules.osc_buf = osc_buf = io.Buffer("i", osc)
        # an asynchronous reset (``AsyncResetCore`` says why), released in step with the clock
        # by the synchroniser: after the PLL locks, or (no PLL) after configuration and the
        # board's reset input if it has one, as the platform's own default domain would
        m.domains.sync = ClockDomain("sync", async_reset=True)
        if self.clk_freq != platform.default_clk_frequency:
            # the platform's own PLL: the MAX10's altpll, the ECP5's EHXPLLL
            m.submodules.pll = pll = platform.system_pll(self.clk_freq)
            m.d.comb += [pll.clk_in.eq(osc_buf.i), ClockSignal("sync").eq(pll.clk_out)]
            reset = ~pll.locked
        else:
            m.d.comb += ClockSignal("sync").eq(osc_buf.i)
            reset = C(0)
            if platform.default_rst is not None:
                rst = platform.request(platform.default_rst, 0, dir="-")
                m.submodules.rst_buf = rst_buf = io.Buffer("i", rst)
                reset = rst_buf.i
        m.submodules.reset_sync = ResetSynchronizer(reset, domain="sync")
        m.submodules.core = core = AHRSCore(clk_freq=self.clk_freq, **self.core_kwargs)
        config = core.config
        uart = platform.request("uart", 0, dir="-")
        m.submodules.uart_tx = uart_tx = io.Buffer("o", uart.tx)
        m.submodules.uart_rx = uart_rx = io.Buffer("i", uart.rx)
        m.d.comb += uart_tx.o.eq(core.uart_tx)
        if core.commands:
            m.d.comb += core.uart_rx.eq(uart_rx.i)       # synchronised in the receiver
        if core.has_pwm or core.controller:
            for i in range(len(core.pwm)):
                pwm = io.Buffer("o", platform.request("pwm", i, dir="-"))
                m.submodules[f"pwm{i}"] = pwm
                m.d.comb += pwm.o.eq(core.pwm[i])
        if core.controller:
            # the arming input (synchronised in the controller), from a pin of its own
            m.submodules.arm = arm = io.Buffer("i", platform.request("arm", 0, dir="-"))
            m.d.comb += core.arm.eq(arm.i)

        if config.wiring == "spi":
            imu = platform.request("imu_spi", 0, dir="-")
            buffers = {"imu_cs": io.Buffer("o", imu.cs), "imu_sclk": io.Buffer("o", imu.clk),
                       "imu_copi": io.Buffer("o", imu.copi),
                       "imu_cipo": io.Buffer("i", imu.cipo), "imu_int": io.Buffer("i", imu.int)}
            # The resource declares CS as PinsN, so the buffer's "o" is chip-select-active.
            m.d.comb += [
                buffers["imu_cs"].o.eq(~core.imu.cs_n),
                buffers["imu_sclk"].o.eq(core.imu.sclk),
                buffers["imu_copi"].o.eq(core.imu.copi),
                core.imu.cipo.eq(buffers["imu_cipo"].i),  # synchronised in the SPI controller
            ]
        else:
            imu = platform.request("imu_i2c", 0, dir="-")
            buffers = {"imu_scl": io.Buffer("io", imu.scl), "imu_sda": io.Buffer("io", imu.sda),
                       "imu_ncs": io.Buffer("o", imu.ncs), "imu_ad0": io.Buffer("o", imu.ad0),
                       "imu_int": io.Buffer("i", imu.int)}
            # Open drain: the output is always 0, enabled to pull the line low.
            m.d.comb += [
                buffers["imu_scl"].o.eq(0), buffers["imu_scl"].oe.eq(core.imu.scl_oe),
                buffers["imu_sda"].o.eq(0), buffers["imu_sda"].oe.eq(core.imu.sda_oe),
                core.imu.scl_i.eq(buffers["imu_scl"].i),  # synchronised in the I2C controller
                core.imu.sda_i.eq(buffers["imu_sda"].i),
                buffers["imu_ncs"].o.eq(1),               # NCS high: the MPU9250 stays on I2C
                buffers["imu_ad0"].o.eq(config.i2c_address & 1),
            ]
        for name, buf in buffers.items():
            m.submodules[name] = buf
        m.d.comb += core.imu_int.eq(buffers["imu_int"].i)   # synchronised in the driver

        status = core.status
        leds = [status.streaming, status.whoami_error, status.no_response, status.int_timeout,
                core.samples_seen[7], *status.restarts[:3]]
        for i, value in enumerate(leds):
            led = io.Buffer("o", platform.request("led", i, dir="-"))
            m.submodules[f"led{i}"] = led
            m.d.comb += led.o.eq(value)
        return m
