//! The datasheet self-test against the bank-1 factory codes.

use super::*;

/// The configuration a self-test saved, restored by
/// [`Icm42688::self_test_end`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SavedConfig {
    gyro_config0: u8,
    config: Config,
}

/// Self-test outcome per axis (x, y, z), in LSB at ±250 °/s.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SelfTest {
    /// Measured response: mean with self-test on minus mean with it off.
    pub response_lsb: [f32; 3],
    /// Factory response from the bank-1 codes.
    pub factory_lsb: [f32; 3],
}

impl SelfTest {
    /// Ratio of measured to factory response; the datasheet's pass criterion
    /// is a ratio above 0.5.
    pub fn ratio(&self) -> [f32; 3] {
        let mut r = [0.0; 3];
        for (i, v) in r.iter_mut().enumerate() {
            *v = if self.factory_lsb[i] > 0.0 {
                self.response_lsb[i] / self.factory_lsb[i]
            } else {
                0.0
            };
        }
        r
    }
}

impl<SPI: SpiDevice> Icm42688<SPI> {
    /// Gyro self-test (datasheet section 10 and AN-000150): at ±250 °/s and
    /// 1 kHz, average `samples` readings with self-test off and on; the
    /// response must exceed half the factory value
    /// `ST_OTP = 2620 / 2^3 · 1.01^(code − 1)` LSB. The previous
    /// configuration is restored afterwards.
    ///
    /// This is the single-chip test of the datasheet: it needs the board
    /// still, since a change of rate between the two averages reads as
    /// response. On a moving board, an array of chips is tested together
    /// with [`Self::self_test_begin`], [`Self::set_self_test`] and
    /// [`Self::self_test_end`] on every chip at once, the motion taken out
    /// with the chips whose self-test is off (the gyro-array firmware's
    /// start-up does this).
    pub fn self_test(
        &mut self,
        delay: &mut impl DelayNs,
        samples: u16,
    ) -> Result<SelfTest, Error<SPI::Error>> {
        if samples == 0 {
            return Err(Error::InvalidArgument);
        }
        let saved = self.self_test_begin()?;
        delay.delay_ms(20);
        let off = self.mean_raw(delay, samples)?;
        self.set_self_test(true)?;
        delay.delay_ms(200); // datasheet: settle before reading
        let on = self.mean_raw(delay, samples)?;
        self.self_test_end(saved, [on[0] - off[0], on[1] - off[1], on[2] - off[2]])
    }

    /// First step of a self-test: save the configuration and set ±250 °/s
    /// and 1 kHz (the range the factory codes are defined at). Pass the
    /// returned value to [`Self::self_test_end`].
    pub fn self_test_begin(&mut self) -> Result<SavedConfig, Error<SPI::Error>> {
        let saved = SavedConfig {
            gyro_config0: self.read(reg::GYRO_CONFIG0)?,
            config: self.config,
        };
        self.configure(Config {
            full_scale: FullScale::Dps250,
            odr: Odr::Hz1000,
            ..self.config
        })?;
        Ok(saved)
    }

    /// Switch the self-test actuation of all three axes on or off (the
    /// datasheet asks for 200 ms of settling after switching it on).
    pub fn set_self_test(&mut self, on: bool) -> Result<(), Error<SPI::Error>> {
        self.write(reg::SELF_TEST_CONFIG, if on { EN_G_ALL } else { 0 })
    }

    /// Last step of a self-test: switch the actuation off, read the factory
    /// codes, restore the saved
    /// configuration and judge the measured response (LSB at ±250 °/s, per
    /// axis) against half the factory response.
    pub fn self_test_end(
        &mut self,
        saved: SavedConfig,
        response_lsb: [f32; 3],
    ) -> Result<SelfTest, Error<SPI::Error>> {
        self.write(reg::SELF_TEST_CONFIG, 0)?;
        self.write(reg::REG_BANK_SEL, 1)?;
        let codes = [
            self.read(reg::XG_ST_DATA)?,
            self.read(reg::YG_ST_DATA)?,
            self.read(reg::ZG_ST_DATA)?,
        ];
        self.write(reg::REG_BANK_SEL, 0)?;
        self.write_checked(reg::GYRO_CONFIG0, saved.gyro_config0)?;
        self.full_scale = FullScale::from_bits(saved.gyro_config0 >> 5);
        self.config = saved.config;
        self.delay_us = saved.config.polled_delay_us();
        self.per_read = saved.config.per_read();
        self.stamp_lim = saved.config.stamp_step_max();

        let mut st = SelfTest {
            response_lsb,
            factory_lsb: [0.0; 3],
        };
        let mut failed = 0u8;
        for (i, &code) in codes.iter().enumerate() {
            st.factory_lsb[i] = factory_response_lsb(code);
            // A NaN response (no samples averaged) fails too.
            if st.response_lsb[i].partial_cmp(&(0.5 * st.factory_lsb[i]))
                != Some(core::cmp::Ordering::Greater)
            {
                failed |= 1 << i;
            }
        }
        if failed != 0 {
            return Err(Error::SelfTestFailed(failed));
        }
        Ok(st)
    }

    pub(super) fn mean_raw(
        &mut self,
        delay: &mut impl DelayNs,
        n: u16,
    ) -> Result<[f32; 3], Error<SPI::Error>> {
        let mut acc = [0i32; 3];
        for _ in 0..n {
            delay.delay_us(1000); // one sample at 1 kHz
            let r = self.read_raw()?;
            for i in 0..3 {
                acc[i] += r[i] as i32;
            }
        }
        Ok([
            acc[0] as f32 / n as f32,
            acc[1] as f32 / n as f32,
            acc[2] as f32 / n as f32,
        ])
    }
}

/// Factory self-test response in LSB at ±250 °/s from a bank-1 code
/// (datasheet: `ST_OTP = (2620 / 2^FS) · 1.01^(code − 1)`, FS = 3).
pub fn factory_response_lsb(code: u8) -> f32 {
    if code == 0 {
        return 0.0;
    }
    2620.0 / 8.0 * libm::powf(1.01, code as f32 - 1.0)
}
