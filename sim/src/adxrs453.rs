//! Frame-level model of the ADXRS453: 32-bit pipelined frames with parity,
//! status and fault bits, the CHK start-up check and the register file.

use super::mount::Mount;
use super::noise::{quantise, AxisNoise, NoiseParams, RateProfile};
use super::timing::{Biquad, ClockParams, Vibration};
use super::{corrupt, Fault, Rng};
use gyro_array::drivers::adxrs453::{c_to_tem, cmd, fault, reg, BANDWIDTH_HZ, LSB_PER_DPS};

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

/// The ADXRS453's internal rate update, Hz. Assumed: the datasheet gives
/// the output's bandwidth, not the rate at which the rate register is
/// refreshed; 4 kHz is well above the 77.5 Hz bandwidth and makes the
/// update's own half-period delay (0.125 ms) small beside the filter's.
pub const ADX_UPDATE_HZ: f64 = 4000.0;

/// How an emulated ADXRS453 keeps time: its internal oscillator (no clock
/// input) and the vibration at its die.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdxTiming {
    /// The internal clock's frequency error.
    pub clock: ClockParams,
    /// Out-of-band vibration (board axes; the part's own axis counts).
    pub vibration: Vibration,
}

/// The state of an ADXRS453 on its own clock. Modelling assumptions: the
/// rate passes a 2nd-order Butterworth low-pass at the datasheet's 77.5 Hz
/// (the order is not stated; its group delay at DC, √2/ω = 2.9 ms, is the
/// "few milliseconds" the part is known for), run at [`ADX_UPDATE_HZ`];
/// the white noise enters before it, so its density is the datasheet's at
/// low frequency and falls above the bandwidth, as the part's does.
#[derive(Clone, Copy, Debug)]
struct AdxTimed {
    timing: AdxTiming,
    next_tick_s: Option<f64>,
    now_s: f64,
    lp: Biquad,
    primed: bool,
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
    timed: Option<AdxTimed>,
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
            timed: None,
        }
    }

    /// Keep time as the part does (`Some`): its own clock, its filter.
    /// `None` is the ideal lockstep sampler.
    pub fn set_timing(&mut self, timing: Option<AdxTiming>) {
        self.timed = timing.map(|timing| AdxTimed {
            timing,
            next_tick_s: None,
            now_s: 0.0,
            lp: Biquad::lowpass(
                BANDWIDTH_HZ as f64,
                core::f64::consts::FRAC_1_SQRT_2,
                ADX_UPDATE_HZ,
            ),
            primed: false,
        });
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

    pub(super) fn advance(&mut self, t_s: f32, dt_s: f32, t64_s: f64) {
        if self.timed.is_some() {
            self.advance_timed(t64_s);
            return;
        }
        self.true_rate_dps = self.profile.at(t_s);
        let axis = self.axis.min(2);
        let chip = self.mount.chip_rate(self.true_rate_dps);
        let (thermal, temp_c) = self.mount.thermal(t_s);
        self.temp_c = temp_c;
        let dps = self
            .noise
            .step(&self.params, &mut self.rng, chip[axis], dt_s)
            + thermal[axis];
        self.latch(dps);
    }

    /// Spikes and faults, then the rate register.
    fn latch(&mut self, mut dps: f32) {
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

    fn advance_timed(&mut self, t_end_s: f64) {
        let Some(mut t) = self.timed.take() else {
            return;
        };
        self.true_rate_dps = self.profile.at(t_end_s as f32);
        let axis = self.axis.min(2);
        let dt = (1.0 / ADX_UPDATE_HZ) as f32;
        loop {
            let rate = ADX_UPDATE_HZ * (1.0 + t.timing.clock.error_at(t.now_s));
            let next = t.next_tick_s.unwrap_or(t.now_s + 1.0 / rate);
            if next > t_end_s {
                t.next_tick_s = Some(next);
                break;
            }
            t.now_s = next;
            t.next_tick_s = Some(next + 1.0 / rate);
            if self.fault == Fault::PoweredOff {
                continue;
            }
            let b = self.profile.at_f64(next);
            let v = t.timing.vibration.at(next);
            let board: [f32; 3] = core::array::from_fn(|i| (b[i] + v[i]) as f32);
            let chip = self.mount.chip_rate(board);
            let (thermal, temp_c) = self.mount.thermal(next as f32);
            self.temp_c = temp_c;
            let x = self.noise.step(&self.params, &mut self.rng, chip[axis], dt) + thermal[axis];
            if !t.primed {
                t.primed = true;
                t.lp.settle(x as f64);
            }
            let y = t.lp.step(x as f64) as f32;
            self.latch(y);
        }
        t.now_s = t_end_s;
        self.timed = Some(t);
    }
}
