//! Register-level model of the ICM-42688-P gyro (banks 0 and 1).

use super::mount::Mount;
use super::noise::{quantise, AxisNoise, NoiseParams, RateProfile};
use super::timing::{
    aaf_hz, ui_divisor, ClockParams, ClockUse, Fifo, PastCount, PathReading, PathSettings, Pushed,
    SignalPath, Vibration, AFSR_FREEZE_S, AFSR_SWITCH_DPS, ICM_INTERNAL_HZ,
};
use super::{corrupt, Fault, Rng};
use gyro_array::drivers::icm42688::{
    bits, factory_response_lsb, reg, reset, FullScale, Odr, RESET_DONE, TEMP_LSB_PER_C,
    WHO_AM_I_VALUE,
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

/// How an emulated ICM-42688-P keeps time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChipTiming {
    /// Its PLL's frequency error.
    pub pll: ClockParams,
    /// Its RC oscillator's, used when CLKSEL selects it or the PLL fails.
    pub rc: ClockParams,
    /// Out-of-band vibration at the die.
    pub vibration: Vibration,
    /// How the signal path is modelled.
    pub path: PathModel,
    /// What a timestamp count is on CLKIN with TMST_RES = 0, which the
    /// public sources leave open.
    pub rtc_tick: RtcTick,
    /// What a burst past the FIFO count gets, which the datasheet leaves
    /// open.
    pub past_count: PastCount,
    /// What the datasheet leaves open about the filters' shapes.
    pub path_reading: PathReading,
}

/// What one FIFO timestamp count is with RTC_MODE on CLKIN and TMST_RES =
/// 0. TDK's register map says "1 µs resolution" for TMST_RES = 0 and "1
/// RTC clock period" for TMST_RES = 1 with RTC on; PX4 scales CLKIN stamps
/// by the input's period; on the chip's own clock TDK's driver
/// (`PLL_SCALE_FACTOR_Q24`) and PX4 (`FIFO_TIMESTAMP_SCALING = 16 · 32/30`
/// for 16 µs counts) scale a count by 32/30. Each reading is a case the
/// evaluations run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RtcTick {
    /// A µs of the CLKIN-derived grid: 31.25 counts per period at 32 kHz.
    Microsecond,
    /// A µs scaled by 32/30 as on the chip's own clock: 29.3 a period.
    Scaled,
    /// One CLKIN period.
    Period,
}

impl RtcTick {
    /// Every reading.
    pub const ALL: [RtcTick; 3] = [RtcTick::Microsecond, RtcTick::Scaled, RtcTick::Period];
}

/// How an emulated ICM-42688-P's signal path is modelled.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathModel {
    /// The AAF and UI filter run at the 32 kHz internal rate, then
    /// decimation: out-of-band content aliases as on the chip.
    Filters,
    /// Each output sample is the input at its instant less the path's
    /// group delay at DC ([`super::timing::PathSettings::group_delay_s`]):
    /// for motion well inside the filters' passband (a vehicle's, below
    /// some 20 Hz) the same as [`PathModel::Filters`] within a few µs of
    /// delay, with nothing to alias, and some 30 times cheaper: what the
    /// QEMU runs use (the filters in f64 at 32 kHz are too slow for
    /// minute-long emulated runs on the Cortex-M4). Its clock, FIFO,
    /// stamps and INT1 are those of [`PathModel::Filters`].
    Delay,
}

impl ChipTiming {
    /// A chip whose PLL is off by `offset`, its RC oscillator by 5 %.
    pub fn pll(offset: f64) -> Self {
        Self {
            pll: ClockParams::fixed(offset),
            rc: ClockParams::fixed(0.05),
            vibration: Vibration::NONE,
            path: PathModel::Filters,
            rtc_tick: RtcTick::Microsecond,
            past_count: PastCount::HandOver,
            path_reading: PathReading::DOCUMENTED,
        }
    }
}

/// The state of a chip that keeps its own time ([`super::timing`]).
#[derive(Clone, Debug)]
struct Timed {
    timing: ChipTiming,
    /// The PLL has failed: the chip runs on its RC oscillator.
    pll_failed: bool,
    /// Bus time of the last advance, s.
    now_s: f64,
    /// Bus time of the last reset: tick 0 of the timestamp counter.
    origin_s: f64,
    /// Bus time of the next internal tick, s (`None`: the grid is stopped).
    next_tick_s: Option<f64>,
    /// The clock the grid ran on at the last tick.
    clock: Option<ClockUse>,
    /// Internal ticks since the last reset (the timestamp's source).
    ticks: u64,
    /// Ticks since the last output sample.
    dec: u32,
    /// Output samples made since the last reset.
    made: u64,
    /// Bus time of the last data-ready pulse on INT1, s.
    int1_s: Option<f64>,
    paths: [SignalPath; 3],
    fifo: Fifo,
    /// Per axis, output samples still frozen by an AFSR switch.
    afsr_hold: [u32; 3],
    /// Per axis, the last filtered rate (°/s, chip axes) and output.
    last_dps: [f32; 3],
    last_out: [i16; 3],
}

impl Timed {
    fn new(timing: ChipTiming, now_s: f64) -> Self {
        let path = SignalPath::new(
            PathSettings {
                aaf_hz: None,
                ui: None,
                odr_hz: 1000.0,
                reading: timing.path_reading,
            },
            ICM_INTERNAL_HZ,
        );
        Self {
            timing,
            pll_failed: false,
            now_s,
            origin_s: now_s,
            next_tick_s: None,
            clock: None,
            ticks: 0,
            dec: 0,
            made: 0,
            int1_s: None,
            paths: [path; 3],
            fifo: Fifo::reading(timing.past_count),
            afsr_hold: [0; 3],
            last_dps: [0.0; 3],
            last_out: [0; 3],
        }
    }

    /// After a reset: a new phase from now, empty FIFO, filters restart.
    fn restart(&mut self) {
        let t = Self::new(self.timing, self.now_s);
        let (failed, read_out) = (self.pll_failed, self.fifo.read_out);
        *self = t;
        self.pll_failed = failed;
        // A new FIFO (new serials): what it hands over counts on.
        self.fifo.read_out = read_out;
    }
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
    /// What [`Fault::BiasDrift`] has added so far, °/s.
    drift_dps: f32,
    /// The true rate at the last update (board frame).
    pub true_rate_dps: [f32; 3],
    /// Mounting, scale/misalignment and temperature terms.
    pub mount: Mount,
    timed: Option<Timed>,
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
            drift_dps: 0.0,
            true_rate_dps: [0.0; 3],
            mount: Mount::ALIGNED,
            timed: None,
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

    /// Give it a scale error (a part's sensitivity off by this fraction).
    pub fn set_scale_error(&mut self, scale_error: f32) {
        self.params.scale_error = scale_error;
    }

    /// Keep time as a real chip does (`Some`): its own oscillator, its
    /// signal path at 32 kHz, its FIFO. `None` is the ideal lockstep
    /// sampler: a fresh, unfiltered sample at each bus step, the reference
    /// every timing figure is compared with.
    pub fn set_timing(&mut self, timing: Option<ChipTiming>) {
        self.timed = timing.map(|t| Timed::new(t, 0.0));
    }

    /// Fail the PLL (the chip falls back to its RC oscillator) or mend it.
    pub fn fail_pll(&mut self, failed: bool) {
        if let Some(t) = self.timed.as_mut() {
            t.pll_failed = failed;
        }
    }

    /// Bus time of the chip's last reset, s: its timestamps count from here
    /// on its own clock (`None` for the lockstep sampler).
    pub fn clock_origin_s(&self) -> Option<f64> {
        self.timed.as_ref().map(|t| t.origin_s)
    }

    /// Distinct FIFO packets handed over whole on the bus (every reset
    /// included; [`super::timing::Fifo`]).
    pub fn packets_read_out(&self) -> u64 {
        self.timed.as_ref().map_or(0, |t| t.fifo.read_out)
    }

    /// Output samples made since the last reset.
    pub fn samples_made(&self) -> u64 {
        self.timed.as_ref().map_or(0, |t| t.made)
    }

    fn reset(&mut self) {
        self.bank0 = [0; 128];
        self.bank0[reg::GYRO_CONFIG0 as usize] = GYRO_CONFIG0_RESET;
        self.bank0[reg::WHO_AM_I as usize] = WHO_AM_I_VALUE;
        self.bank0[reg::INT_STATUS as usize] = RESET_DONE;
        self.bank0[reg::INTF_CONFIG0 as usize] = reset::INTF_CONFIG0;
        self.bank0[reg::INTF_CONFIG1 as usize] = reset::INTF_CONFIG1;
        self.bank0[reg::GYRO_CONFIG1 as usize] = reset::GYRO_CONFIG1;
        self.bank0[reg::GYRO_ACCEL_CONFIG0 as usize] = reset::GYRO_ACCEL_CONFIG0;
        self.bank0[reg::TMST_CONFIG as usize] = reset::TMST_CONFIG;
        self.bank0[reg::INT_CONFIG1 as usize] = reset::INT_CONFIG1;
        self.bank0[reg::INT_SOURCE0 as usize] = reset::INT_SOURCE0;
        // Bank-1 reset values assumed (the datasheet's tables are not in
        // the public drivers): AAF and notch on, AAF at DELT 13 (585 Hz,
        // DELTSQR 170, BITSHIFT 8), pin 9 as INT2.
        self.bank1[reg::GYRO_CONFIG_STATIC2 as usize] = 0xA0;
        self.bank1[reg::GYRO_CONFIG_STATIC3 as usize] = 0x0D;
        self.bank1[reg::GYRO_CONFIG_STATIC4 as usize] = 0xAA;
        self.bank1[reg::GYRO_CONFIG_STATIC5 as usize] = 0x80;
        self.bank1[reg::INTF_CONFIG5 as usize] = 0x00;
        self.set_output([DATA_OFF; 3]);
        if let Some(t) = self.timed.as_mut() {
            t.restart();
        }
    }

    /// The signal path the registers select now.
    fn path_settings(&self) -> PathSettings {
        let odr = Odr::from_bits(self.bank0[reg::GYRO_CONFIG0 as usize]).map_or(1000.0, Odr::hz);
        let aaf = if self.bank1[reg::GYRO_CONFIG_STATIC2 as usize] & bits::GYRO_AAF_DIS != 0 {
            None
        } else {
            Some(aaf_hz(self.bank1[reg::GYRO_CONFIG_STATIC3 as usize] & 0x3F))
        };
        let order = match (self.bank0[reg::GYRO_CONFIG1 as usize] >> 2) & 0b11 {
            0 => 1,
            1 => 2,
            _ => 3,
        };
        let ui = ui_divisor(self.bank0[reg::GYRO_ACCEL_CONFIG0 as usize] & 0x0F)
            .map(|k| (order, odr.max(400.0) / k));
        PathSettings {
            aaf_hz: aaf,
            ui,
            odr_hz: odr,
            reading: PathReading::DOCUMENTED,
        }
    }

    /// Flip GYRO_FS_SEL's top bit (a corrupted register).
    pub fn corrupt_config(&mut self) {
        self.bank0[reg::GYRO_CONFIG0 as usize] ^= 0x80;
    }

    /// Set a register behind the driver's back (a single-event upset, a
    /// glitch on the bus): bank 0 or 1, any address.
    pub fn poke(&mut self, bank: u8, addr: u8, v: u8) {
        match bank {
            0 => self.bank0[addr as usize & 0x7F] = v,
            1 => self.bank1[addr as usize & 0x7F] = v,
            _ => {}
        }
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
            0 if a == reg::FIFO_COUNTH || a == reg::FIFO_COUNTL => {
                let c = self.fifo_count().to_be_bytes();
                let big = self.bank0[reg::INTF_CONFIG0 as usize] & bits::FIFO_COUNT_ENDIAN != 0;
                let first = (a == reg::FIFO_COUNTH) == big;
                if first {
                    c[0]
                } else {
                    c[1]
                }
            }
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
        if self.bank() == 1 {
            // The bank-1 registers the signal path and pin 9 use; the
            // others (factory codes among them) are not writable here.
            if matches!(
                a,
                reg::GYRO_CONFIG_STATIC2
                    | reg::GYRO_CONFIG_STATIC3
                    | reg::GYRO_CONFIG_STATIC4
                    | reg::GYRO_CONFIG_STATIC5
                    | reg::INTF_CONFIG5
            ) {
                self.bank1[a as usize] = v;
            }
            return;
        }
        if self.bank() != 0 {
            return; // banks 2..4 are not modelled
        }
        match a {
            reg::DEVICE_CONFIG if v & 1 != 0 => self.reset(),
            reg::SIGNAL_PATH_RESET => {
                if v & bits::FIFO_FLUSH != 0 {
                    if let Some(t) = self.timed.as_mut() {
                        t.fifo.flush();
                    }
                }
            }
            reg::WHO_AM_I | reg::INT_STATUS | reg::FIFO_COUNTH | reg::FIFO_COUNTL => {}
            reg::FIFO_DATA => {}
            a if (reg::TEMP_DATA1..=reg::GYRO_DATA_X1 + 5).contains(&a) => {}
            _ => self.bank0[a as usize] = v,
        }
    }

    pub(super) fn begin_frame(&mut self) {
        self.phase = Phase::Address;
        let resume = self.bank0[reg::FIFO_CONFIG1 as usize] & bits::FIFO_RESUME_PARTIAL_RD != 0;
        if let Some(t) = self.timed.as_mut() {
            t.fifo.begin_transaction(resume);
        }
    }

    /// FIFO_COUNT: bytes, or packets with FIFO_COUNT_REC.
    fn fifo_count(&self) -> u16 {
        let Some(t) = self.timed.as_ref() else {
            return 0;
        };
        if self.bank0[reg::INTF_CONFIG0 as usize] & bits::FIFO_COUNT_REC != 0 {
            t.fifo.records() as u16
        } else {
            t.fifo.bytes() as u16
        }
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
                let fifo = a == reg::FIFO_DATA && self.bank() == 0;
                // A burst that reaches FIFO_DATA stays there: each further
                // byte is the FIFO's next (as PX4 reads INT_STATUS, the
                // count and the packets in one transaction).
                self.phase = Phase::Read(if fifo { a } else { a.wrapping_add(1) & 0x7F });
                let count = (a == reg::FIFO_COUNTH || a == reg::FIFO_COUNTL) && self.bank() == 0;
                let v = match self.timed.as_mut() {
                    Some(t) if fifo && self.fault != Fault::PoweredOff => t.fifo.read_byte(),
                    Some(t) if count => {
                        t.fifo.latch();
                        self.read_reg(a)
                    }
                    _ => self.read_reg(a),
                };
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

    /// One output sample of the chip's measurement of `board_dps` (board
    /// axes): mounting, temperature, noise over `dt_s`, self-test
    /// deflection, spikes, counts at the range in force.
    fn measure(&mut self, board_dps: [f32; 3], t_s: f32, dt_s: f32) -> [i16; 3] {
        let chip = self.mount.chip_rate(board_dps);
        let (thermal, temp_c) = self.mount.thermal(t_s);
        let t = ((temp_c - 25.0) * TEMP_LSB_PER_C) as i16;
        let [hi, lo] = t.to_be_bytes();
        self.bank0[reg::TEMP_DATA1 as usize] = hi;
        self.bank0[reg::TEMP_DATA1 as usize + 1] = lo;
        self.drift_dps = match self.fault {
            Fault::BiasDrift { dps_per_s } => self.drift_dps + dps_per_s * dt_s,
            _ => 0.0,
        };
        let mut meas = [0.0f32; 3];
        for (i, m) in meas.iter_mut().enumerate() {
            *m = self.noise[i].step(&self.params, &mut self.rng, chip[i], dt_s)
                + thermal[i]
                + self.drift_dps;
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
        out
    }

    /// INT1 pulses on data ready: routed (INT_SOURCE0.UI_DRDY_INT1_EN),
    /// driven (INT_CONFIG push-pull) and enabled (INT_ASYNC_RESET clear).
    fn int1_drdy(&self) -> bool {
        self.bank0[reg::INT_SOURCE0 as usize] & bits::UI_DRDY_INT1_EN != 0
            && self.bank0[reg::INT_CONFIG as usize] & 0b010 != 0
            && self.bank0[reg::INT_CONFIG1 as usize] & bits::INT_ASYNC_RESET == 0
    }

    /// Bus time of the last data-ready pulse on INT1, s: what the board's
    /// timer captures (`None` before the first, or with INT1 not set up).
    pub fn int1_at_s(&self) -> Option<f64> {
        self.timed.as_ref().and_then(|t| t.int1_s)
    }

    fn gyro_on(&self) -> bool {
        (self.bank0[reg::PWR_MGMT0 as usize] >> 2) & 0b11 >= 0b10
    }

    /// Advance to bus time `t_s` (f32) / `t64_s` (f64), `dt_s` after the
    /// last step, with the board driving CLKIN at `clkin_hz`.
    pub(super) fn advance(&mut self, t_s: f32, dt_s: f32, t64_s: f64, clkin_hz: Option<f64>) {
        if self.timed.is_some() {
            self.advance_timed(t64_s, clkin_hz);
            return;
        }
        self.true_rate_dps = self.profile.at(t_s);
        let out = self.measure(self.true_rate_dps, t_s, dt_s);
        let gyro_on = self.gyro_on();
        match self.fault {
            Fault::Stuck => {}
            Fault::Saturated => self.set_output([i16::MAX; 3]),
            _ if !gyro_on => self.set_output([DATA_OFF; 3]),
            _ => self.set_output(out),
        }
    }

    /// The clock the grid runs on now and its rate, Hz (`None`: stopped).
    fn grid(&self, t: &Timed, at_s: f64, clkin_hz: Option<f64>) -> (ClockUse, Option<f64>) {
        let rtc = self.bank0[reg::INTF_CONFIG1 as usize] & bits::RTC_MODE != 0
            && self.bank1[reg::INTF_CONFIG5 as usize] & bits::PIN9_MASK == bits::PIN9_CLKIN;
        if rtc {
            return (ClockUse::ClkIn, clkin_hz.filter(|f| *f > 0.0));
        }
        let rc = t.pll_failed || self.bank0[reg::INTF_CONFIG1 as usize] & bits::CLKSEL_MASK == 0;
        let p = if rc { t.timing.rc } else { t.timing.pll };
        (
            ClockUse::Internal,
            Some(ICM_INTERNAL_HZ * (1.0 + p.error_at(at_s))),
        )
    }

    fn advance_timed(&mut self, t_end_s: f64, clkin_hz: Option<f64>) {
        let Some(mut t) = self.timed.take() else {
            return;
        };
        self.true_rate_dps = self.profile.at(t_end_s as f32);
        if self.fault == Fault::PoweredOff {
            t.now_s = t_end_s;
            t.next_tick_s = None;
            self.timed = Some(t);
            return;
        }
        let settings = PathSettings {
            reading: t.timing.path_reading,
            ..self.path_settings()
        };
        if t.paths[0].settings != settings {
            t.paths = [SignalPath::new(settings, ICM_INTERNAL_HZ); 3];
        }
        let dec = libm::round(ICM_INTERNAL_HZ / settings.odr_hz as f64).max(1.0) as u32;
        let dt_out = dec as f32 / ICM_INTERNAL_HZ as f32;
        let afsr_on = self.bank0[reg::INTF_CONFIG1 as usize] & bits::AFSR_MASK != bits::AFSR_OFF;
        let afsr_n = libm::ceil(AFSR_FREEZE_S * settings.odr_hz as f64) as u32;
        let light = t.timing.path == PathModel::Delay;
        let gd_s = settings.group_delay_s();
        loop {
            let (clock, rate) = self.grid(&t, t.now_s, clkin_hz);
            let Some(rate) = rate else {
                t.next_tick_s = None;
                t.clock = Some(clock);
                break;
            };
            // A change of clock (or a grid that was stopped) starts the
            // grid again: on CLKIN at its next edge, on an internal
            // oscillator one period from now.
            let next = match (t.next_tick_s, t.clock == Some(clock)) {
                (Some(n), true) => n,
                _ if clock == ClockUse::ClkIn => libm::ceil(t.now_s * rate) / rate,
                _ => t.now_s + 1.0 / rate,
            };
            t.clock = Some(clock);
            // The delay model steps from output tick to output tick (the
            // ticks between only count); the filters tick by tick.
            let inc = if light && self.gyro_on() {
                dec.saturating_sub(t.dec).max(1)
            } else {
                1
            };
            let next = next + f64::from(inc - 1) / rate;
            if next > t_end_s {
                t.next_tick_s = Some(next - f64::from(inc - 1) / rate);
                break;
            }
            t.now_s = next;
            t.next_tick_s = Some(next + 1.0 / rate);
            t.ticks = t.ticks.wrapping_add(u64::from(inc));
            if !self.gyro_on() {
                t.dec = 0;
                continue;
            }
            let mut y = [0.0f32; 3];
            if light {
                let board = self.profile.at_f64(next - gd_s);
                let vib = t.timing.vibration.at(next - gd_s);
                for i in 0..3 {
                    y[i] = (board[i] + vib[i]) as f32;
                }
            } else {
                let board = self.profile.at_f64(next);
                let vib = t.timing.vibration.at(next);
                for i in 0..3 {
                    y[i] = t.paths[i].step(board[i] + vib[i]) as f32;
                }
            }
            t.dec += inc;
            if t.dec < dec {
                continue;
            }
            t.dec = 0;
            t.made += 1;
            let mut out = self.measure(y, next as f32, dt_out);
            let lsb =
                FullScale::from_bits(self.bank0[reg::GYRO_CONFIG0 as usize] >> 5).lsb_per_dps();
            for i in 0..3 {
                let chip_dps = out[i] as f32 / lsb;
                if afsr_on
                    && (chip_dps.abs() > AFSR_SWITCH_DPS) != (t.last_dps[i].abs() > AFSR_SWITCH_DPS)
                {
                    t.afsr_hold[i] = afsr_n;
                }
                t.last_dps[i] = chip_dps;
                if t.afsr_hold[i] > 0 {
                    t.afsr_hold[i] -= 1;
                    out[i] = t.last_out[i];
                }
            }
            let out = match self.fault {
                Fault::Stuck => t.last_out,
                Fault::Saturated => [i16::MAX; 3],
                _ => out,
            };
            t.last_out = out;
            if self.fault != Fault::Stuck {
                self.set_output(out);
            }
            self.bank0[reg::INT_STATUS as usize] |= bits::DATA_RDY;
            if self.int1_drdy() {
                // A new rising edge only once the last pulse (100 µs, or
                // 8 µs with INT_TPULSE_DURATION) and the minimum
                // de-assertion after it (100 µs, none with
                // INT_TDEASSERT_DISABLE) are over (datasheet,
                // INT_CONFIG1); a data ready within them is no edge the
                // board's timer can capture.
                let c1 = self.bank0[reg::INT_CONFIG1 as usize];
                let pulse = if c1 & bits::INT_TPULSE_DURATION != 0 {
                    8e-6
                } else {
                    100e-6
                };
                let gap = if c1 & bits::INT_TDEASSERT_DISABLE != 0 {
                    0.0
                } else {
                    100e-6
                };
                if t.int1_s.is_none_or(|l| next - l >= pulse + gap) {
                    t.int1_s = Some(next);
                }
            }
            self.push_packet(&mut t, out);
        }
        t.now_s = t_end_s;
        if !self.gyro_on() {
            self.set_output([DATA_OFF; 3]);
        }
        self.timed = Some(t);
    }

    /// Build the FIFO packet of one sample (datasheet 6.2: packet 3, 16
    /// bytes: header, accel, gyro, 8-bit temperature, 16-bit timestamp;
    /// packet 1 with the gyro only, 8 bytes, no timestamp) and store it.
    fn push_packet(&mut self, t: &mut Timed, g: [i16; 3]) {
        let mode = self.bank0[reg::FIFO_CONFIG as usize] & bits::FIFO_MODE_MASK;
        let cfg1 = self.bank0[reg::FIFO_CONFIG1 as usize];
        if mode == 0 || cfg1 & (bits::FIFO_GYRO_EN | bits::FIFO_ACCEL_EN) == 0 {
            return; // bypass mode, or nothing routed to the FIFO
        }
        let big = self.bank0[reg::INTF_CONFIG0 as usize] & bits::SENSOR_DATA_ENDIAN != 0;
        let word = |v: i16| {
            if big {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let tmst = self.bank0[reg::TMST_CONFIG as usize];
        let stamp = if tmst & bits::TMST_EN == 0 {
            0
        } else {
            let rtc = t.clock == Some(ClockUse::ClkIn);
            // An internal tick is 31.25 µs of the grid's nominal rate; on
            // the chip's own clock a count is 32/30 of a µs (TDK's driver,
            // PLL_SCALE_FACTOR_Q24; PX4's FIFO_TIMESTAMP_SCALING), so a
            // tick is 31.25 · 30/32 = 1875/64 counts (16 µs counts:
            // 1875/1024); on CLKIN, 1 RTC period at TMST_RES = 1 (TDK's
            // register map) and the open reading at 0 (`RtcTick`).
            let counts = match (tmst & bits::TMST_RES != 0, rtc) {
                (true, true) => t.ticks,
                (true, false) => t.ticks * 1875 / 1024,
                (false, false) => t.ticks * 1875 / 64,
                (false, true) => match t.timing.rtc_tick {
                    RtcTick::Microsecond => t.ticks * 125 / 4,
                    RtcTick::Scaled => t.ticks * 1875 / 64,
                    RtcTick::Period => t.ticks,
                },
            };
            counts as u16
        };
        let temp_c = self.mount.temp.at(t.now_s as f32);
        let temp8 = libm::roundf((temp_c - 25.0) * 2.07).clamp(-128.0, 127.0) as i8;
        let mut p = [0u8; 16];
        let gyro_only = cfg1 & bits::FIFO_ACCEL_EN == 0;
        let n = if gyro_only {
            p[0] = bits::HEADER_GYRO;
            for (i, v) in g.iter().enumerate() {
                p[1 + 2 * i..3 + 2 * i].copy_from_slice(&word(*v));
            }
            p[7] = temp8 as u8;
            8
        } else {
            p[0] = bits::HEADER_ACCEL | bits::HEADER_GYRO;
            if tmst & bits::TMST_EN != 0 {
                p[0] |= bits::HEADER_TIMESTAMP_ODR;
            }
            // The accelerometer is off: its slots read −32768.
            for i in 0..3 {
                p[1 + 2 * i..3 + 2 * i].copy_from_slice(&word(i16::MIN));
            }
            for (i, v) in g.iter().enumerate() {
                p[7 + 2 * i..9 + 2 * i].copy_from_slice(&word(*v));
            }
            p[13] = temp8 as u8;
            p[14..16].copy_from_slice(&if big {
                stamp.to_be_bytes()
            } else {
                stamp.to_le_bytes()
            });
            16
        };
        let stop = mode != bits::FIFO_MODE_STREAM;
        let before = t.fifo.bytes();
        if t.fifo.push(&p[..n], stop) != Pushed::Stored {
            self.bank0[reg::INT_STATUS as usize] |= bits::FIFO_FULL;
        }
        let wm = (((self.bank0[reg::FIFO_CONFIG3 as usize] & 0x0F) as usize) << 8)
            | self.bank0[reg::FIFO_CONFIG2 as usize] as usize;
        let count = |bytes: usize| {
            if self.bank0[reg::INTF_CONFIG0 as usize] & bits::FIFO_COUNT_REC != 0 {
                bytes / n
            } else {
                bytes
            }
        };
        let now = count(t.fifo.bytes());
        let crossed = count(before) < wm && now >= wm;
        if wm > 0 && (crossed || (cfg1 & bits::FIFO_WM_GT_TH != 0 && now >= wm)) {
            self.bank0[reg::INT_STATUS as usize] |= bits::FIFO_THS;
        }
    }
}
