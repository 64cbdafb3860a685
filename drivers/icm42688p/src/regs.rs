//! Register addresses and bit fields (datasheet section 14, user banks 0
//! and 1).

/// Register addresses (datasheet names). Bank 0 unless noted.
#[allow(missing_docs)]
pub mod reg {
    pub const DEVICE_CONFIG: u8 = 0x11;
    pub const INT_CONFIG: u8 = 0x14;
    pub const FIFO_CONFIG: u8 = 0x16;
    pub const TEMP_DATA1: u8 = 0x1D;
    pub const GYRO_DATA_X1: u8 = 0x25;
    pub const INT_STATUS: u8 = 0x2D;
    pub const FIFO_COUNTH: u8 = 0x2E;
    pub const FIFO_COUNTL: u8 = 0x2F;
    pub const FIFO_DATA: u8 = 0x30;
    pub const SIGNAL_PATH_RESET: u8 = 0x4B;
    pub const INTF_CONFIG0: u8 = 0x4C;
    pub const INTF_CONFIG1: u8 = 0x4D;
    pub const PWR_MGMT0: u8 = 0x4E;
    pub const GYRO_CONFIG0: u8 = 0x4F;
    pub const GYRO_CONFIG1: u8 = 0x51;
    pub const GYRO_ACCEL_CONFIG0: u8 = 0x52;
    pub const TMST_CONFIG: u8 = 0x54;
    pub const FIFO_CONFIG1: u8 = 0x5F;
    pub const FIFO_CONFIG2: u8 = 0x60;
    pub const FIFO_CONFIG3: u8 = 0x61;
    pub const INT_CONFIG1: u8 = 0x64;
    pub const INT_SOURCE0: u8 = 0x65;
    pub const SELF_TEST_CONFIG: u8 = 0x70;
    pub const WHO_AM_I: u8 = 0x75;
    pub const REG_BANK_SEL: u8 = 0x76;
    /// Bank 1: GYRO_AAF_DIS (bit 1), GYRO_NF_DIS (bit 0).
    pub const GYRO_CONFIG_STATIC2: u8 = 0x0B;
    /// Bank 1: GYRO_AAF_DELT (bits 5:0).
    pub const GYRO_CONFIG_STATIC3: u8 = 0x0C;
    /// Bank 1: GYRO_AAF_DELTSQR\[7:0\].
    pub const GYRO_CONFIG_STATIC4: u8 = 0x0D;
    /// Bank 1: GYRO_AAF_BITSHIFT (7:4), GYRO_AAF_DELTSQR\[11:8\] (3:0).
    pub const GYRO_CONFIG_STATIC5: u8 = 0x0E;
    /// Bank 1: factory self-test codes for the gyro axes.
    pub const XG_ST_DATA: u8 = 0x5F;
    pub const YG_ST_DATA: u8 = 0x60;
    pub const ZG_ST_DATA: u8 = 0x61;
    /// Bank 1: PIN9_FUNCTION (bits 2:1; 0b10 = CLKIN).
    pub const INTF_CONFIG5: u8 = 0x7B;
}

/// Register bit fields (datasheet section 14), bank 0 unless noted.
#[allow(missing_docs)]
pub mod bits {
    /// INT_STATUS.
    pub const DATA_RDY: u8 = 1 << 3;
    pub const FIFO_THS: u8 = 1 << 2;
    pub const FIFO_FULL: u8 = 1 << 1;
    /// FIFO_CONFIG.FIFO_MODE (bits 7:6).
    pub const FIFO_MODE_MASK: u8 = 0b11 << 6;
    pub const FIFO_MODE_STREAM: u8 = 0b01 << 6;
    pub const FIFO_MODE_STOP_ON_FULL: u8 = 0b10 << 6;
    /// FIFO_CONFIG1.
    pub const FIFO_RESUME_PARTIAL_RD: u8 = 1 << 6;
    pub const FIFO_WM_GT_TH: u8 = 1 << 5;
    pub const FIFO_HIRES_EN: u8 = 1 << 4;
    pub const FIFO_TMST_FSYNC_EN: u8 = 1 << 3;
    pub const FIFO_TEMP_EN: u8 = 1 << 2;
    pub const FIFO_GYRO_EN: u8 = 1 << 1;
    pub const FIFO_ACCEL_EN: u8 = 1 << 0;
    /// SIGNAL_PATH_RESET.
    pub const FIFO_FLUSH: u8 = 1 << 1;
    /// INTF_CONFIG0.
    pub const FIFO_COUNT_REC: u8 = 1 << 6;
    pub const FIFO_COUNT_ENDIAN: u8 = 1 << 5;
    pub const SENSOR_DATA_ENDIAN: u8 = 1 << 4;
    /// INTF_CONFIG1: AFSR (bits 7:6, undocumented; 0b01 turns it off, as
    /// PX4, ArduPilot and Betaflight write), RTC_MODE, CLKSEL (bits 1:0).
    pub const AFSR_MASK: u8 = 0b11 << 6;
    pub const AFSR_OFF: u8 = 0b01 << 6;
    pub const RTC_MODE: u8 = 1 << 2;
    pub const CLKSEL_MASK: u8 = 0b11;
    pub const CLKSEL_PLL: u8 = 0b01;
    /// TMST_CONFIG.
    pub const TMST_TO_REGS_EN: u8 = 1 << 4;
    pub const TMST_RES: u8 = 1 << 3;
    pub const TMST_DELTA_EN: u8 = 1 << 2;
    pub const TMST_EN: u8 = 1 << 0;
    /// INT_CONFIG: INT1 push-pull (bit 1), active high (bit 0), pulsed
    /// (bit 2 clear).
    pub const INT1_PUSH_PULL_HIGH: u8 = 0b011;
    /// INT_CONFIG1.INT_ASYNC_RESET (bit 4): must be cleared for the INT
    /// pins to work (datasheet 14.x; PX4 clears it).
    pub const INT_ASYNC_RESET: u8 = 1 << 4;
    /// INT_CONFIG1.INT_TPULSE_DURATION (bit 6): an 8 µs interrupt pulse
    /// instead of 100 µs, and INT_TDEASSERT_DISABLE (bit 5): no 100 µs
    /// minimum de-assertion; both "required if ODR ≥ 4 kHz" (datasheet,
    /// INT_CONFIG1; PX4 and TDK's examples set them).
    pub const INT_TPULSE_DURATION: u8 = 1 << 6;
    pub const INT_TDEASSERT_DISABLE: u8 = 1 << 5;
    /// INT_SOURCE0.UI_DRDY_INT1_EN: data ready on INT1.
    pub const UI_DRDY_INT1_EN: u8 = 1 << 3;
    /// Bank 1 GYRO_CONFIG_STATIC2.
    pub const GYRO_AAF_DIS: u8 = 1 << 1;
    /// Bank 1 INTF_CONFIG5.PIN9_FUNCTION (bits 2:1).
    pub const PIN9_MASK: u8 = 0b11 << 1;
    pub const PIN9_CLKIN: u8 = 0b10 << 1;
    /// FIFO header (datasheet 6.2).
    pub const HEADER_MSG: u8 = 1 << 7;
    pub const HEADER_ACCEL: u8 = 1 << 6;
    pub const HEADER_GYRO: u8 = 1 << 5;
    pub const HEADER_20: u8 = 1 << 4;
    pub const HEADER_TIMESTAMP_ODR: u8 = 0b10 << 2;
    pub const HEADER_ODR_ACCEL: u8 = 1 << 1;
    pub const HEADER_ODR_GYRO: u8 = 1 << 0;
}

/// Reset values the driver and the emulated chip agree on (datasheet
/// section 14).
#[allow(missing_docs)]
pub mod reset {
    pub const INTF_CONFIG0: u8 = 0x30;
    pub const INTF_CONFIG1: u8 = 0x91;
    pub const GYRO_CONFIG1: u8 = 0x16;
    pub const GYRO_ACCEL_CONFIG0: u8 = 0x11;
    pub const TMST_CONFIG: u8 = 0x23;
    pub const INT_CONFIG1: u8 = 0x10;
    pub const INT_SOURCE0: u8 = 0x10;
}
