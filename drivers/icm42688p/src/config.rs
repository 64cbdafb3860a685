//! What the driver sets: clock input, sampling (polled or FIFO), range,
//! rate and filters, and the checked writes a restart makes.

use super::*;

/// Where the chip takes its clock from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClockInput {
    /// Its own PLL (±1 %; datasheet table 2).
    Internal,
    /// The board's 31–50 kHz clock on pin 9 (INTF_CONFIG5.PIN9_FUNCTION =
    /// CLKIN, INTF_CONFIG1.RTC_MODE): the ODR follows it.
    ClkIn,
}

/// How samples reach the host.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Sampling {
    /// The data registers, polled.
    Registers,
    /// The FIFO: 16-byte packets with a 16-bit timestamp (datasheet 6.2,
    /// packet 3), stop-on-full, the count in records.
    Fifo,
}

/// Gyro configuration applied by [`Icm42688::init`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Full-scale range.
    pub full_scale: FullScale,
    /// Output data rate.
    pub odr: Odr,
    /// Signal-path filters.
    pub filter: Filter,
    /// Clock source.
    pub clock: ClockInput,
    /// Registers or FIFO.
    pub sampling: Sampling,
}

impl Default for Config {
    /// ±250 °/s (the finest range, for platforms that turn at up to some
    /// 200 °/s), 1 kHz, ArduPilot's
    /// filters at 1 kHz, AFSR off (always: it freezes the output for
    /// 1–2 ms when the rate crosses 100 °/s), the internal clock, the data
    /// registers.
    fn default() -> Self {
        Self {
            full_scale: FullScale::Dps250,
            odr: Odr::Hz1000,
            filter: Filter::ARDUPILOT,
            clock: ClockInput::Internal,
            sampling: Sampling::Registers,
        }
    }
}

impl Config {
    /// The delay a polled read of this configuration carries, µs: the
    /// filters' group delay and half a sample period.
    pub fn polled_delay_us(&self) -> u32 {
        libm::roundf(self.filter.group_delay_us(self.odr) + 0.5e6 / self.odr.hz()) as u32
    }

    /// GYRO_CONFIG0.
    pub(super) fn gyro_config0(&self) -> u8 {
        ((self.full_scale as u8) << 5) | self.odr as u8
    }
    /// INTF_CONFIG1: the reset value with AFSR off and RTC_MODE as chosen.
    pub(super) fn intf_config1(&self) -> u8 {
        let rtc = if self.clock == ClockInput::ClkIn {
            bits::RTC_MODE
        } else {
            0
        };
        (reset::INTF_CONFIG1 & !(bits::AFSR_MASK | bits::RTC_MODE)) | bits::AFSR_OFF | rtc
    }
    /// GYRO_CONFIG1: the reset value with the UI filter's order.
    pub(super) fn gyro_config1(&self) -> u8 {
        (reset::GYRO_CONFIG1 & !(0b11 << 2)) | self.filter.order_bits()
    }
    /// GYRO_ACCEL_CONFIG0: the accelerometer's half at reset, the UI
    /// filter's bandwidth.
    pub(super) fn gyro_accel_config0(&self) -> u8 {
        (reset::GYRO_ACCEL_CONFIG0 & 0xF0) | (self.filter.ui_bw & 0x0F)
    }
    /// INTF_CONFIG0: big-endian data and count (reset), the count in
    /// records with the FIFO.
    pub(super) fn intf_config0(&self) -> u8 {
        match self.sampling {
            Sampling::Fifo => reset::INTF_CONFIG0 | bits::FIFO_COUNT_REC,
            Sampling::Registers => reset::INTF_CONFIG0,
        }
    }
    /// FIFO_CONFIG1: accel, gyro and temperature slots (packet 3 carries the
    /// timestamp; the accelerometer stays off and reads −32768).
    pub(super) fn fifo_config1(&self) -> u8 {
        match self.sampling {
            Sampling::Fifo => bits::FIFO_TEMP_EN | bits::FIFO_GYRO_EN | bits::FIFO_ACCEL_EN,
            Sampling::Registers => 0,
        }
    }
    /// INT_CONFIG, INT_CONFIG1 and INT_SOURCE0: with the FIFO, a pulse on
    /// INT1 at every sample (the board captures its time: the instant each
    /// sample was made, on the board's clock); otherwise their reset values.
    /// From 4 kHz the short pulse and no minimum de-assertion, as the
    /// datasheet requires: with the 100 µs pulse and 100 µs de-assertion a
    /// pulse cannot follow one less than 200 µs before, and at 8 kHz every
    /// other sample's edge was lost.
    pub(super) fn int1(&self) -> [u8; 3] {
        let fast = if self.odr.hz() >= 4000.0 {
            bits::INT_TPULSE_DURATION | bits::INT_TDEASSERT_DISABLE
        } else {
            0
        };
        match self.sampling {
            Sampling::Fifo => [
                bits::INT1_PUSH_PULL_HIGH,
                (reset::INT_CONFIG1 & !bits::INT_ASYNC_RESET) | fast,
                bits::UI_DRDY_INT1_EN,
            ],
            Sampling::Registers => [0, reset::INT_CONFIG1, reset::INT_SOURCE0],
        }
    }
    /// FIFO_CONFIG: stop-on-full (what is kept stays in order; an overflow
    /// is flagged and flushed), or bypass.
    pub(super) fn fifo_config(&self) -> u8 {
        match self.sampling {
            Sampling::Fifo => bits::FIFO_MODE_STOP_ON_FULL,
            Sampling::Registers => 0,
        }
    }
    /// Bank-1 GYRO_CONFIG_STATIC2..5 (0x0B..0x0E) and INTF_CONFIG5, or
    /// `None` for an AAF setting the driver does not know.
    pub(super) fn bank1(&self) -> Option<([u8; 4], u8)> {
        // With the AAF off its coefficients stay at the reset entry.
        let (d, dis) = match self.filter.aaf_delt {
            0 => (13, bits::GYRO_AAF_DIS),
            d => (d, 0),
        };
        let (sq, shift) = aaf_coefficients(d)?;
        let static2 = (STATIC2_RESET & !bits::GYRO_AAF_DIS) | dis;
        let st = [
            static2,
            d & 0x3F,
            sq as u8,
            (shift << 4) | ((sq >> 8) as u8 & 0x0F),
        ];
        let pin9 = if self.clock == ClockInput::ClkIn {
            bits::PIN9_CLKIN
        } else {
            0
        };
        Some((st, pin9))
    }
}

/// The restart step after the gyro's start-up.
pub(super) const RESTART_FLUSH: u8 = 201;

impl Config {
    /// Packets the first burst of [`Icm42688::read_fifo`] makes room for:
    /// one per millisecond of the ODR (the board reads every millisecond).
    pub fn per_read(&self) -> usize {
        self.odr.per_ms().min(MAX_PER_READ)
    }

    /// The largest step between two FIFO stamps this rate allows, counts:
    /// a sample period in µs (a count is 1 µs or more in every reading of
    /// the unit, `pipeline::stamps`), half as much again for a slow clock.
    pub fn stamp_step_max(&self) -> u16 {
        (1.5e6 / self.odr.hz()) as u16
    }

    /// Write `i` of the checked writes a restart makes, in order, as
    /// (bank, register, value): bank 1 (the AAF, pin 9), then
    /// INTF_CONFIG1, the UI filter, range and rate, the FIFO and INT1, and
    /// the gyro's power last. `None` past the last; `Some(None)` for an
    /// AAF setting the driver does not know. Worked out one at a time: a
    /// restart step makes a few of them, and the whole table built and
    /// returned by value (a `heapless::Vec`) cost some 1 300 instructions
    /// a step in copies on the Cortex-M4 (`cargo xtask bench-loop`,
    /// scenario A, the loop's worst sample).
    pub fn setup_write(&self, i: usize) -> Option<Option<(u8, u8, u8)>> {
        let fifo = self.sampling == Sampling::Fifo;
        let w = match i {
            0..=3 => self
                .bank1()
                .map(|(st, _)| (1, reg::GYRO_CONFIG_STATIC2 + i as u8, st[i])),
            4 => self.bank1().map(|(_, pin9)| (1, reg::INTF_CONFIG5, pin9)),
            5 => Some((0, reg::INTF_CONFIG1, self.intf_config1())),
            6 => Some((0, reg::GYRO_CONFIG1, self.gyro_config1())),
            7 => Some((0, reg::GYRO_ACCEL_CONFIG0, self.gyro_accel_config0())),
            8 => Some((0, reg::GYRO_CONFIG0, self.gyro_config0())),
            9 => Some((0, reg::INTF_CONFIG0, self.intf_config0())),
            10 => Some((0, reg::FIFO_CONFIG1, self.fifo_config1())),
            11 => Some((0, reg::FIFO_CONFIG, self.fifo_config())),
            12..=14 if fifo => {
                let v = self.int1();
                let r = [reg::INT_CONFIG, reg::INT_CONFIG1, reg::INT_SOURCE0];
                Some((0, r[i - 12], v[i - 12]))
            }
            12 if !fifo => Some((0, reg::PWR_MGMT0, GYRO_MODE_LN)),
            15 if fifo => Some((0, reg::PWR_MGMT0, GYRO_MODE_LN)),
            _ => return None,
        };
        Some(w)
    }
}
