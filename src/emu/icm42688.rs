//! Register-level model of the ICM-42688-P gyro (banks 0 and 1).

use super::mount::Mount;
use super::noise::{quantise, AxisNoise, NoiseParams, RateProfile};
use super::{corrupt, Fault, Rng};
use crate::drivers::icm42688::{
    factory_response_lsb, reg, FullScale, RESET_DONE, TEMP_LSB_PER_C, WHO_AM_I_VALUE,
};

const GYRO_CONFIG0_RESET: u8 = 0x06; // ±2000 °/s, 1 kHz
/// Data registers read −32768 while the gyro is off (datasheet 14.x).
const DATA_OFF: i16 = i16::MIN;

#[derive(Clone, Copy, PartialEq, Eq)]
enum Phase {
    Address,
    Read(u8),
    Write(u8),
}

/// An emulated ICM-42688-P.
pub struct Icm42688Model {
    bank0: [u8; 128],
    bank1: [u8; 128],
    phase: Phase,
    noise: [AxisNoise; 3],
    params: NoiseParams,
    profile: RateProfile,
    rng: Rng,
    /// Fault being injected.
    pub fault: Fault,
    /// The true rate at the last update (board frame).
    pub true_rate_dps: [f32; 3],
    /// Mounting, scale/misalignment and temperature terms.
    pub mount: Mount,
}

impl Icm42688Model {
    /// A chip with the given error terms, seeing `profile`; `st_code` is its
    /// factory self-test code for every gyro axis.
    pub fn new(params: NoiseParams, profile: RateProfile, seed: u64, st_code: u8) -> Self {
        let mut m = Self {
            bank0: [0; 128],
            bank1: [0; 128],
            phase: Phase::Address,
            noise: [AxisNoise::default(); 3],
            params,
            profile,
            rng: Rng::new(seed),
            fault: Fault::None,
            true_rate_dps: [0.0; 3],
            mount: Mount::ALIGNED,
        };
        m.reset();
        for r in [reg::XG_ST_DATA, reg::YG_ST_DATA, reg::ZG_ST_DATA] {
            m.bank1[r as usize] = st_code;
        }
        m
    }

    /// The error terms it was built with.
    pub fn params(&self) -> NoiseParams {
        self.params
    }

    fn reset(&mut self) {
        self.bank0 = [0; 128];
        self.bank0[reg::GYRO_CONFIG0 as usize] = GYRO_CONFIG0_RESET;
        self.bank0[reg::WHO_AM_I as usize] = WHO_AM_I_VALUE;
        self.bank0[reg::INT_STATUS as usize] = RESET_DONE;
        self.set_output([DATA_OFF; 3]);
    }

    /// Flip GYRO_FS_SEL's top bit (a corrupted register).
    pub fn corrupt_config(&mut self) {
        self.bank0[reg::GYRO_CONFIG0 as usize] ^= 0x80;
    }

    /// A power-on reset: registers to their reset values, gyro off,
    /// RESET_DONE set.
    pub fn power_cycle(&mut self) {
        self.reset();
    }

    fn set_output(&mut self, v: [i16; 3]) {
        for (i, c) in v.iter().enumerate() {
            let [hi, lo] = c.to_be_bytes();
            self.bank0[reg::GYRO_DATA_X1 as usize + 2 * i] = hi;
            self.bank0[reg::GYRO_DATA_X1 as usize + 2 * i + 1] = lo;
        }
    }

    fn bank(&self) -> u8 {
        self.bank0[reg::REG_BANK_SEL as usize] & 7
    }

    fn read_reg(&self, a: u8) -> u8 {
        if a == reg::REG_BANK_SEL {
            return self.bank0[a as usize];
        }
        if a == reg::WHO_AM_I && self.fault == Fault::WrongId {
            return 0x98; // another part's id
        }
        match self.bank() {
            0 => self.bank0[a as usize & 0x7F],
            1 => self.bank1[a as usize & 0x7F],
            _ => 0,
        }
    }

    fn write_reg(&mut self, a: u8, v: u8) {
        if self.fault == Fault::PoweredOff {
            return;
        }
        let a = a & 0x7F;
        if a == reg::REG_BANK_SEL {
            self.bank0[a as usize] = v & 7;
            return;
        }
        if self.bank() != 0 {
            return; // bank-1..4 registers are not modelled as writable
        }
        match a {
            reg::DEVICE_CONFIG if v & 1 != 0 => self.reset(),
            reg::WHO_AM_I | reg::INT_STATUS => {}
            a if (reg::TEMP_DATA1..=reg::GYRO_DATA_X1 + 5).contains(&a) => {}
            _ => self.bank0[a as usize] = v,
        }
    }

    pub(super) fn begin_frame(&mut self) {
        self.phase = Phase::Address;
    }

    pub(super) fn exchange(&mut self, mosi: u8) -> u8 {
        let out = match self.phase {
            Phase::Address => {
                let a = mosi & 0x7F;
                self.phase = if mosi & 0x80 != 0 {
                    Phase::Read(a)
                } else {
                    Phase::Write(a)
                };
                0
            }
            Phase::Read(a) => {
                self.phase = Phase::Read(a.wrapping_add(1) & 0x7F);
                let v = self.read_reg(a);
                // INT_STATUS clears on read (datasheet 14.x).
                if a == reg::INT_STATUS && self.bank() == 0 && self.fault != Fault::PoweredOff {
                    self.bank0[reg::INT_STATUS as usize] = 0;
                }
                v
            }
            Phase::Write(a) => {
                self.write_reg(a, mosi);
                self.phase = Phase::Write(a.wrapping_add(1) & 0x7F);
                0
            }
        };
        corrupt(&mut self.rng, out, self.fault)
    }

    pub(super) fn advance(&mut self, t_s: f32, dt_s: f32) {
        self.true_rate_dps = self.profile.at(t_s);
        let chip = self.mount.chip_rate(self.true_rate_dps);
        let (thermal, temp_c) = self.mount.thermal(t_s);
        let t = ((temp_c - 25.0) * TEMP_LSB_PER_C) as i16;
        let [hi, lo] = t.to_be_bytes();
        self.bank0[reg::TEMP_DATA1 as usize] = hi;
        self.bank0[reg::TEMP_DATA1 as usize + 1] = lo;
        let mut meas = [0.0f32; 3];
        for (i, m) in meas.iter_mut().enumerate() {
            *m = self.noise[i].step(&self.params, &mut self.rng, chip[i], dt_s) + thermal[i];
        }
        let cfg = self.bank0[reg::GYRO_CONFIG0 as usize];
        let lsb = FullScale::from_bits(cfg >> 5).lsb_per_dps();
        let st = self.bank0[reg::SELF_TEST_CONFIG as usize];
        let mut out = [0i16; 3];
        for i in 0..3 {
            let mut dps = meas[i];
            if st & (1 << i) != 0 && self.fault != Fault::DeadSelfTest {
                // The factory response is defined in LSB at ±250 °/s (131 LSB/°/s).
                dps +=
                    factory_response_lsb(self.bank1[(reg::XG_ST_DATA + i as u8) as usize]) / 131.0;
            }
            if let Fault::Spikes {
                prob,
                magnitude_dps,
            } = self.fault
            {
                if self.rng.uniform() < prob {
                    dps += if self.rng.uniform() < 0.5 {
                        magnitude_dps
                    } else {
                        -magnitude_dps
                    };
                }
            }
            out[i] = quantise(dps, lsb);
        }
        let gyro_on = (self.bank0[reg::PWR_MGMT0 as usize] >> 2) & 0b11 >= 0b10;
        match self.fault {
            Fault::Stuck => {}
            Fault::Saturated => self.set_output([i16::MAX; 3]),
            _ if !gyro_on => self.set_output([DATA_OFF; 3]),
            _ => self.set_output(out),
        }
    }
}
