"""The attitude engine's two memories, as small components.

``RegisterFile``: ``depth`` × 32-bit words with initial values, one write port and two
synchronous read ports that see a write in the same cycle (transparent), each with an enable
that holds its data while low. ``MicrocodeROM``: the program, one synchronous read port with
enable. On a MAX10 both fit M9K blocks (the register file takes two, one per read port, as
Quartus duplicates a RAM for a second read address).

``blackbox`` (a class attribute, False; ``report`` sets it on the instances it synthesises)
instantiates empty modules (``blackbox_stub()`` gives their Verilog) in place of
``lib.memory.Memory``: Debian's Yosys 0.23 cannot map initialised RAM onto MAX10 M9K blocks,
so ``report`` counts their bits and keeps them out of the logic-element count. The register
file's blackbox reads old data, as an M9K does between its ports, and the logic Quartus adds for
the transparent reads (the written word, a registered address match, a multiplexer per port)
is built around it, so that it is counted.
"""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.memory import Memory, MemoryData
from amaranth.lib.wiring import In, Out


__all__ = ["RegisterFile", "MicrocodeROM", "FrameRAM", "blackbox_stub", "m9k_blocks"]


# A MAX10 M9K's depth × width modes (Intel's MAX 10 Embedded Memory User Guide): 8,192 bits,
# or 9,216 in the modes with a ninth bit a byte
M9K_MODES = ((8192, 1), (4096, 2), (2048, 4), (1024, 9), (512, 18), (256, 36))


def m9k_blocks(depth, width, *, byte_enables=False):
    """The M9K blocks a ``depth`` × ``width`` memory takes on a MAX10: the fewest over the
    block's modes (blocks side by side for the width, stacked for the depth). With
    ``byte_enables``, only the ×18 and ×36 modes, which have them."""
    modes = M9K_MODES[-2:] if byte_enables else M9K_MODES
    return min(-(-depth // d) * -(-width // w) for d, w in modes)


class RegisterFile(wiring.Component):
    """``depth`` × 32-bit words with initial values (``init``): one write port and two
    synchronous read ports that see a write in the same cycle (transparent).

    Members
        ``w_en``, ``w_addr``, ``w_data`` (in): the write.
        ``r_en`` (in): both read ports read (low: their data holds). ``ra_addr``, ``rb_addr``
            (in) / ``ra_data``, ``rb_data`` (out, signed 32): the two reads.
    Latency: a read's word is on ``ra_data``/``rb_data`` the cycle after its address (with
    ``r_en``); a write in that same cycle is what it reads. Throughput: a write and two reads
    per cycle.
    """
    blackbox = False                # ``report`` sets it: module docstring

    def __init__(self, depth, init):
        self.depth = depth
        self.init = list(init)
        abits = (depth - 1).bit_length()
        super().__init__({
            "w_en": In(1), "w_addr": In(abits), "w_data": In(signed(32)),
            "r_en": In(1), "ra_addr": In(abits), "rb_addr": In(abits),
            "ra_data": Out(signed(32)), "rb_data": Out(signed(32)),
        })

    @property
    def bits(self):
        return 2 * self.depth * 32

    def elaborate(self, platform):
        m = Module()
        if self.blackbox:
            ram_a, ram_b = Signal(signed(32)), Signal(signed(32))
            m.submodules.ram = Instance(
                f"mpu9250_ahrs_regfile{self.depth}x32", i_clk=ClockSignal(), i_w_en=self.w_en,
                i_w_addr=self.w_addr, i_w_data=self.w_data, i_r_en=self.r_en,
                i_ra_addr=self.ra_addr, i_rb_addr=self.rb_addr, o_ra_data=ram_a,
                o_rb_data=ram_b)
            # read-during-write bypass: what makes the M9K's old-data reads transparent
            written = Signal(signed(32), reset_less=True)
            hit_a, hit_b = Signal(reset_less=True), Signal(reset_less=True)
            with m.If(self.r_en):
                m.d.sync += [written.eq(self.w_data),
                             hit_a.eq(self.w_en & (self.w_addr == self.ra_addr)),
                             hit_b.eq(self.w_en & (self.w_addr == self.rb_addr))]
            m.d.comb += [self.ra_data.eq(Mux(hit_a, written, ram_a)),
                         self.rb_data.eq(Mux(hit_b, written, ram_b))]
            return m
        m.submodules.mem = mem = Memory(shape=signed(32), depth=self.depth, init=self.init)
        wp = mem.write_port()
        rpa = mem.read_port(transparent_for=(wp,))
        rpb = mem.read_port(transparent_for=(wp,))
        m.d.comb += [
            wp.en.eq(self.w_en), wp.addr.eq(self.w_addr), wp.data.eq(self.w_data),
            rpa.addr.eq(self.ra_addr), rpb.addr.eq(self.rb_addr),
            rpa.en.eq(self.r_en), rpb.en.eq(self.r_en),
            self.ra_data.eq(rpa.data), self.rb_data.eq(rpb.data),
        ]
        return m


class MicrocodeROM(wiring.Component):
    """The program: ``words`` of ``width`` bits, one synchronous read port with enable.

    Members
        ``addr``, ``en`` (in); ``data`` (out): the word at ``addr`` of the last cycle with
            ``en`` (it holds while ``en`` is low).
    Latency: one cycle. Throughput: a word per cycle.
    """
    blackbox = False                # ``report`` sets it: module docstring

    def __init__(self, words, width):
        self.words = list(words)
        self.width = width
        self.abits = max(1, (len(self.words) - 1).bit_length())
        super().__init__({"addr": In(self.abits), "en": In(1), "data": Out(width)})

    @property
    def bits(self):
        return len(self.words) * self.width

    @property
    def m9k_blocks(self):
        """M9Ks it takes on a MAX10 (``m9k_blocks``)."""
        return m9k_blocks(len(self.words), self.width)

    def elaborate(self, platform):
        m = Module()
        if self.blackbox:
            m.submodules.rom = Instance(
                f"mpu9250_ahrs_rom{len(self.words)}x{self.width}", i_clk=ClockSignal(),
                i_addr=self.addr, i_en=self.en, o_data=self.data)
            return m
        m.submodules.mem = mem = Memory(shape=self.width, depth=len(self.words),
                                        init=self.words)
        rp = mem.read_port()
        m.d.comb += [rp.addr.eq(self.addr), rp.en.eq(self.en), self.data.eq(rp.data)]
        return m


class FrameRAM(wiring.Component):
    """``depth`` words of ``width`` bits, one write port and one synchronous read port with
    enable (the read data holds while ``r_en`` is low; a read of the address being written
    returns the old word). One M9K on a MAX10: the telemetry framer's copy of a frame, the
    command decoder's input FIFO, the self-test's sums and its table (``init``: a ROM).

    ``lanes``: the write's enables, one per ``width // lanes`` bits (``w_en`` bit k writes
    ``w_data``'s lane k: the M9K's byte enables; the sample store writes a byte at a time).

    Latency: a read's word is on ``r_data`` the cycle after its address (with ``r_en``).
    Throughput: a write and a read per cycle.
    """
    blackbox = False                # ``report`` sets it: module docstring

    def __init__(self, depth, width=8, init=(), *, lanes=1):
        if lanes < 1 or width % lanes:
            raise ValueError(f"FrameRAM: {lanes} write lanes do not divide {width} bits")
        self.depth = depth
        self.width = width
        self.lanes = lanes
        self.init = list(init)          # initial words: a ROM when nothing writes it
        self.abits = max(1, (depth - 1).bit_length())
        # the words, made here so that a testbench can read them (``ctx.get(ram.data[i])``)
        self.data = MemoryData(shape=width, depth=depth, init=self.init)
        super().__init__({"w_en": In(lanes), "w_addr": In(self.abits), "w_data": In(width),
                          "r_en": In(1), "r_addr": In(self.abits), "r_data": Out(width)})

    @property
    def name(self):
        lanes = "" if self.lanes == 1 else f"e{self.lanes}"
        return f"mpu9250_ahrs_ram{self.depth}x{self.width}{lanes}"

    @property
    def bits(self):
        return self.depth * self.width

    @property
    def m9k_blocks(self):
        """M9Ks it takes on a MAX10 (``m9k_blocks``; with lanes, the modes with byte enables)."""
        return m9k_blocks(self.depth, self.width, byte_enables=self.lanes > 1)

    def stub(self):
        """Verilog declaring the blackbox module (``report``)."""
        a, w = self.abits, self.width
        e = "" if self.lanes == 1 else f"[{self.lanes - 1}:0] "
        return (f"(* blackbox *) module {self.name}(input clk, input {e}w_en, "
                f"input [{a - 1}:0] w_addr, input [{w - 1}:0] w_data, input r_en, "
                f"input [{a - 1}:0] r_addr, output [{w - 1}:0] r_data);\nendmodule\n")

    def elaborate(self, platform):
        m = Module()
        if self.blackbox:
            m.submodules.ram = Instance(
                self.name, i_clk=ClockSignal(), i_w_en=self.w_en,
                i_w_addr=self.w_addr, i_w_data=self.w_data, i_r_en=self.r_en,
                i_r_addr=self.r_addr, o_r_data=self.r_data)
            return m
        m.submodules.mem = mem = Memory(self.data)
        wp = mem.write_port(granularity=None if self.lanes == 1 else self.width // self.lanes)
        rp = mem.read_port()
        m.d.comb += [wp.en.eq(self.w_en), wp.addr.eq(self.w_addr), wp.data.eq(self.w_data),
                     rp.en.eq(self.r_en), rp.addr.eq(self.r_addr), self.r_data.eq(rp.data)]
        return m


def blackbox_stub(regfile, rom):
    """Verilog declaring the two blackbox modules with their port directions."""
    ra = (regfile.depth - 1).bit_length()
    return (
        f"(* blackbox *) module mpu9250_ahrs_regfile{regfile.depth}x32(input clk, input w_en, "
        f"input [{ra - 1}:0] w_addr, input [31:0] w_data, input r_en, input [{ra - 1}:0] "
        f"ra_addr, input [{ra - 1}:0] rb_addr, output [31:0] ra_data, output [31:0] rb_data);\n"
        f"endmodule\n"
        f"(* blackbox *) module mpu9250_ahrs_rom{len(rom.words)}x{rom.width}(input clk, "
        f"input [{rom.abits - 1}:0] addr, input en, output [{rom.width - 1}:0] data);\n"
        f"endmodule\n")
