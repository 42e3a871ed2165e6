"""AK8963 register map (datasheet MS1356-E-02, as summarised in ``shared/mpu9250-notes.md``)."""

I2C_ADDRESS = 0x0C

WIA   = 0x00
INFO  = 0x01
ST1   = 0x02
HXL   = 0x03
HZH   = 0x08
ST2   = 0x09
CNTL1 = 0x0A
CNTL2 = 0x0B
ASTC  = 0x0C
I2CDIS = 0x0F
ASAX  = 0x10
ASAY  = 0x11
ASAZ  = 0x12

WIA_VALUE = 0x48

ST1_DRDY = 0x01
ST1_DOR  = 0x02
ST2_HOFL = 0x08       # the AK8975's overflow flag was bit 7; on the AK8963 it is bit 3
ST2_BITM = 0x10

CNTL1_BIT_16 = 0x10
MODE_POWER_DOWN = 0x0
MODE_SINGLE     = 0x1
MODE_CONT_8HZ   = 0x2
MODE_CONT_100HZ = 0x6
MODE_EXT_TRIG   = 0x4
MODE_SELF_TEST  = 0x8
MODE_FUSE_ROM   = 0xF
CNTL2_SRST = 0x01
ASTC_SELF = 0x40                      # the self-test field generator (self-test mode)

# Bytes a sample read takes: ST1, HXL..HZH, ST2 (reading ST2 releases the data registers).
SAMPLE_BYTES = ST2 - ST1 + 1          # 8

OVERFLOW_UT = 4912                    # |X| + |Y| + |Z| at or above this sets HOFL
UT_PER_LSB_16 = 0.15
UT_PER_LSB_14 = 0.6


def asa_adjust(raw, asa):
    """Sensitivity adjustment: H_adj = H · ((ASA − 128) · 0.5 / 128 + 1)."""
    return raw * ((asa - 128) * 0.5 / 128 + 1)
