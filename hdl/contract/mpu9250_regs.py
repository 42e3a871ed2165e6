"""MPU9250 register map: the addresses and bit fields that both the driver and the model use.

Sources: register map RM-MPU-9250A-00 rev 1.4 as summarised in ``shared/mpu9250-notes.md``.
Keeping them in one module means the gateware and the behavioural model cannot drift apart
on an address.
"""

# -- addresses ------------------------------------------------------------------------------------
SELF_TEST_X_GYRO  = 0x00    # ..Z at 0x02: the factory self-test codes (``hdl/sensor/self_test.py``)
SELF_TEST_X_ACCEL = 0x0D    # ..Z at 0x0F
SMPLRT_DIV     = 0x19
CONFIG         = 0x1A
GYRO_CONFIG    = 0x1B
ACCEL_CONFIG   = 0x1C
ACCEL_CONFIG2  = 0x1D
I2C_MST_CTRL   = 0x24
I2C_MST_STATUS = 0x36
INT_PIN_CFG    = 0x37
INT_ENABLE     = 0x38
INT_STATUS     = 0x3A
ACCEL_XOUT_H   = 0x3B
TEMP_OUT_H     = 0x41
GYRO_XOUT_H    = 0x43
EXT_SENS_DATA_00 = 0x49
EXT_SENS_DATA_23 = 0x60
USER_CTRL      = 0x6A
PWR_MGMT_1     = 0x6B
PWR_MGMT_2     = 0x6C
FIFO_COUNTH    = 0x72
FIFO_COUNTL    = 0x73
WHO_AM_I       = 0x75

# -- bit fields -----------------------------------------------------------------------------------
SPI_READ = 0x80                 # first byte of a transaction: bit 7 = read

PWR_MGMT_1_H_RESET = 0x80
PWR_MGMT_1_SLEEP   = 0x40
PWR_MGMT_1_CLKSEL_AUTO = 0x01   # PLL when ready, else internal oscillator

USER_CTRL_I2C_MST_EN  = 0x20
USER_CTRL_I2C_IF_DIS  = 0x10
USER_CTRL_SELF_CLEARING = 0x0F  # FIFO_RST, I2C_MST_RST, SIG_COND_RST, DMP_RST read back as 0

INT_PIN_CFG_ACTL          = 0x80
INT_PIN_CFG_OPEN          = 0x40
INT_PIN_CFG_LATCH_INT_EN  = 0x20
INT_PIN_CFG_ANYRD_2CLEAR  = 0x10
INT_PIN_CFG_BYPASS_EN     = 0x02

INT_ENABLE_RAW_RDY = 0x01
INT_STATUS_RAW_RDY = 0x01
# INT_STATUS's reserved bits (7, 5, 2, 1: PS-MPU-9250A-01's register map) read 0 on a working
# part: a read shifted by a bit either way sets bit 1 or clears RAW_RDY (issue #58)
INT_STATUS_RESERVED = 0xA6

# -- reset values (all others are 0x00) -----------------------------------------------------------
WHO_AM_I_MPU9250 = 0x71
WHO_AM_I_MPU9255 = 0x73
RESET_VALUES = {PWR_MGMT_1: PWR_MGMT_1_CLKSEL_AUTO, WHO_AM_I: WHO_AM_I_MPU9250}

# GYRO_CONFIG [7:5] XGYRO/YGYRO/ZGYRO_Cten, ACCEL_CONFIG [7:5] ax/ay/az_st_en: self-test on
SELF_TEST_ENABLE = 0xE0


# Registers the host can only read. Writing one is a protocol violation in the model.
READ_ONLY = frozenset({I2C_MST_STATUS, INT_STATUS, *range(ACCEL_XOUT_H, EXT_SENS_DATA_23 + 1),
                       FIFO_COUNTH, FIFO_COUNTL, WHO_AM_I})

# "Sensor and interrupt registers": the only ones that may be read with SCLK above 1 MHz.
FAST_READ_FIRST = INT_STATUS
FAST_READ_LAST  = EXT_SENS_DATA_23

# Bytes of one accel + temperature + gyro sample, big-endian, starting at ACCEL_XOUT_H.
SENSOR_BYTES = GYRO_XOUT_H + 6 - ACCEL_XOUT_H   # 14

GYRO_FS_DPS = (250, 500, 1000, 2000)            # GYRO_CONFIG[4:3]
ACCEL_FS_G  = (2, 4, 8, 16)                     # ACCEL_CONFIG[4:3]


def gyro_config(fs_dps):
    """GYRO_CONFIG value for a full scale in degrees per second (FCHOICE_B = 00)."""
    if fs_dps not in GYRO_FS_DPS:
        raise ValueError(f"gyro full scale must be one of {GYRO_FS_DPS} °/s, not {fs_dps!r}")
    return GYRO_FS_DPS.index(fs_dps) << 3


def accel_config(fs_g):
    """ACCEL_CONFIG value for a full scale in g."""
    if fs_g not in ACCEL_FS_G:
        raise ValueError(f"accelerometer full scale must be one of {ACCEL_FS_G} g, not {fs_g!r}")
    return ACCEL_FS_G.index(fs_g) << 3


def output_data_rate(config, gyro_config_value, smplrt_div):
    """Sample rate in Hz that CONFIG, GYRO_CONFIG (FCHOICE_B) and SMPLRT_DIV select.

    The divider applies only with DLPF_CFG 1..6 and FCHOICE_B = 00 (1 kHz internal rate);
    DLPF_CFG 0 or 7 run at 8 kHz and FCHOICE_B != 00 at 32 kHz.
    """
    if gyro_config_value & 0x03:
        return 32_000.0
    dlpf = config & 0x07
    if dlpf in (0, 7):
        return 8_000.0
    return 1_000.0 / (1 + smplrt_div)


# -- auxiliary I2C master -------------------------------------------------------------------------
I2C_SLV_ADDR = (0x25, 0x28, 0x2B, 0x2E)   # SLV0..SLV3: ADDR, then REG, CTRL
I2C_SLV4_ADDR = 0x31
I2C_SLV4_REG  = 0x32
I2C_SLV4_DO   = 0x33
I2C_SLV4_CTRL = 0x34
I2C_SLV4_DI   = 0x35
I2C_SLV_DO    = (0x63, 0x64, 0x65, 0x66)
I2C_MST_DELAY_CTRL = 0x67
I2C_MST_DELAY_CTRL_DELAY_ES_SHADOW = 0x80
I2C_MST_DELAY_CTRL_SLV0_DLY_EN = 0x01

I2C_SLV_RNW = 0x80            # in I2C_SLVx_ADDR
I2C_SLV_EN = 0x80             # in I2C_SLVx_CTRL
I2C_SLV_BYTE_SW = 0x40
I2C_SLV_REG_DIS = 0x20
I2C_SLV_GRP = 0x10
I2C_SLV_LENG = 0x0F
I2C_SLV4_INT_EN = 0x40
I2C_SLV4_MST_DLY = 0x1F

I2C_MST_CTRL_WAIT_FOR_ES = 0x40
I2C_MST_CLK_400KHZ = 13
# I2C_MST_CLK[3:0] -> master clock in kHz (register map, I2C_MST_CTRL)
I2C_MST_CLK_KHZ = (348, 333, 320, 308, 296, 286, 276, 267, 258, 500, 471, 444, 421, 400, 381, 364)

I2C_MST_STATUS_SLV4_DONE = 0x40
I2C_MST_STATUS_SLV4_NACK = 0x10
I2C_MST_STATUS_LOST_ARB = 0x20

MPU9250_I2C_ADDRESS = 0x68    # 0x69 with AD0 high
