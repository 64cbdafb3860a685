//! Frame-level model of the ADXRS453: 32-bit pipelined frames with parity,
//! status and fault bits, the CHK start-up check and the register file.

use super::mount::Mount;
use super::noise::{quantise, AxisNoise, NoiseParams, RateProfile};
use super::{corrupt, Fault, Rng};
use crate::drivers::adxrs453::{c_to_tem, cmd, fault, reg, LSB_PER_DPS};

/// Give a response its parity bits: P0 (bit 28) odd over 31:16, P1 (bit 0)
/// odd over 15:0.
fn seal(mut r: u32) -> u32 {
    r &= !((1 << 28) | 1);
    if (r >> 16).count_ones().is_multiple_of(2) {
        r |= 1 << 28;
    }
    if (r & 0xFFFF).count_ones().is_multiple_of(2) {
        r |= 1;
    }
    r
}

/// An emulated ADXRS453 mounted on board axis `axis`.
pub struct Adxrs453Model {
    axis: usize,
    rx: u32,
    nbytes: u8,
    /// Response clocked out during the current frame.
    tx: u32,
    /// Response to the command being received, sent in the next frame.
    next: u32,
    rate: i16,
    noise: AxisNoise,
    params: NoiseParams,
    profile: RateProfile,
    rng: Rng,
    /// Fault being injected.
    pub fault: Fault,
    /// The true rate at the last update (board frame).
    pub true_rate_dps: [f32; 3],
    /// Mounting, scale/misalignment and temperature terms (the row of the
    /// sensitive axis counts).
    pub mount: Mount,
    temp_c: f32,
    /// Reset since the last start-up check: responses flag POR, data are
    /// not valid.
    por: bool,
}

impl Adxrs453Model {
    /// A power-on reset: POR until the next start-up check.
    pub fn power_cycle(&mut self) {
        self.por = true;
        self.next = 0;
    }

    /// A part on board axis `axis` (0..=2).
    pub fn new(params: NoiseParams, profile: RateProfile, seed: u64, axis: usize) -> Self {
        Self {
            axis: axis.min(2),
            rx: 0,
            nbytes: 0,
            tx: 0,
            next: 0,
            rate: 0,
            noise: AxisNoise::default(),
            params,
            profile,
            rng: Rng::new(seed),
            fault: Fault::None,
            true_rate_dps: [0.0; 3],
            mount: Mount::ALIGNED,
            temp_c: 25.0,
            por: false,
        }
    }

    /// The error terms it was built with.
    pub fn params(&self) -> NoiseParams {
        self.params
    }

    pub(super) fn begin_frame(&mut self) {
        self.tx = self.next;
        if let Fault::FrameBitError { prob } = self.fault {
            if self.rng.uniform() < prob {
                self.tx ^= 1 << (self.rng.next_u32() % 32);
            }
        }
        self.rx = 0;
        self.nbytes = 0;
    }

    pub(super) fn exchange(&mut self, mosi: u8) -> u8 {
        let shift = 24 - 8 * self.nbytes.min(3) as u32;
        let out = (self.tx >> shift) as u8;
        self.rx = (self.rx << 8) | mosi as u32;
        self.nbytes = self.nbytes.saturating_add(1);
        if self.nbytes == 4 && self.fault != Fault::PoweredOff {
            self.next = self.respond(self.rx);
        }
        corrupt(&mut self.rng, out, self.fault)
    }

    fn register(&self, addr: u16) -> u16 {
        match addr & !1 {
            reg::RATE1 => self.rate as u16,
            reg::TEM1 => c_to_tem(self.temp_c),
            reg::PID1 if self.fault == Fault::WrongId => 0x5A01,
            reg::PID1 => 0x5201,
            reg::FAULT1 if self.fault == Fault::ChipFault => 0x0080,
            reg::SN3 => 0x1234,
            _ => 0,
        }
    }

    /// The response to one complete command frame.
    fn respond(&mut self, c: u32) -> u32 {
        if c.count_ones().is_multiple_of(2) {
            // Command parity error: status "invalid", SPI fault.
            return seal(fault::CHK as u32);
        }
        match c >> 29 {
            0b001 => {
                let mut faults = 0u8;
                let mut st = 0b01u32;
                if c & cmd::CHK != 0 {
                    faults = fault::ALL;
                    st = 0b00;
                    self.por = false;
                } else if self.por {
                    faults = fault::POR;
                    st = 0b00;
                } else if self.fault == Fault::ChipFault {
                    faults = fault::PLL | fault::CST;
                    st = 0b00;
                }
                seal((st << 26) | ((self.rate as u16 as u32) << 10) | faults as u32)
            }
            0b100 => {
                let a = ((c >> 17) & 0x1FF) as u16;
                seal((0b010 << 29) | ((self.register(a) as u32) << 5))
            }
            0b010 => {
                let d = (c >> 1) & 0xFFFF;
                seal((0b001 << 29) | (d << 5))
            }
            _ => seal(0),
        }
    }

    pub(super) fn advance(&mut self, t_s: f32, dt_s: f32) {
        self.true_rate_dps = self.profile.at(t_s);
        let axis = self.axis.min(2);
        let chip = self.mount.chip_rate(self.true_rate_dps);
        let (thermal, temp_c) = self.mount.thermal(t_s);
        self.temp_c = temp_c;
        let mut dps = self
            .noise
            .step(&self.params, &mut self.rng, chip[axis], dt_s)
            + thermal[axis];
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
        match self.fault {
            Fault::Stuck => {}
            Fault::Saturated => self.rate = i16::MAX,
            _ => self.rate = quantise(dps, LSB_PER_DPS),
        }
    }
}
