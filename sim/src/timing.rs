//! Chips that keep their own time: oscillators, the ICM-42688-P's signal
//! path at its internal rate, the FIFO, and the out-of-band vibration the
//! board's mounting passes to the dies.
//!
//! Modelling assumptions, each where the datasheets (ICM-42688-P DS-000347
//! rev 1.8, ADXRS453 rev B) and the public drivers (TDK's, PX4's,
//! ArduPilot's, Zephyr's, Linux `inv_icm42600`) are silent:
//!
//! - **Oscillator.** A chip's internal sample grid runs at its nominal rate
//!   times `1 + e(t)`, `e(t) = offset + drift·t + wander·sin(2πt/period)`
//!   ([`ClockParams`]): an initial error, a thermal drift, and a slow
//!   wander, bounded. The PLL (CLKSEL = 01, the default) is within ±1 %
//!   (datasheet table 2, "ODR accuracy"), the RC oscillator within ±8 %.
//! - **CLKIN.** With RTC_MODE set and pin 9 as CLKIN, the internal grid runs
//!   on the CLKIN edges: its rate is the CLKIN frequency (32 kHz gives the
//!   nominal ODRs; 32.768 kHz gives each ODR × 1.024). If CLKIN stops while
//!   RTC_MODE is set, the grid stops: no samples, no FIFO packets, no
//!   timestamps, until CLKIN returns or RTC_MODE is cleared. The datasheet
//!   does not say; this is the harsher of the plausible readings, so a
//!   driver built against it also copes with the gentler one.
//! - **Signal path** ([`SignalPath`]). The anti-alias filter (AAF) is a
//!   2nd-order Butterworth low-pass at the 3 dB frequency of datasheet
//!   table 17 for GYRO_AAF_DELT ([`aaf_hz`]), run at the internal rate;
//!   GYRO_AAF_DELTSQR and GYRO_AAF_BITSHIFT are taken as the table's pair
//!   for that DELT (the driver's read-back checks them). The notch filter
//!   is not modelled. The UI filter (GYRO_UI_FILT_ORD 1–3,
//!   GYRO_UI_FILT_BW) is a Butterworth low-pass of that order at
//!   `max(400 Hz, ODR)/k`, also run at the internal rate, then picked every
//!   `internal/ODR` ticks (trivial decimation): content the two filters
//!   pass above ODR/2 aliases. The low-latency settings (14, 15) bypass the
//!   UI filter.
//! - **Noise** is added after the filters, at the output rate, with the
//!   datasheet's density (the density is specified at the output).
//! - **AFSR** (adaptive full-scale range, INTF_CONFIG1 bits 7:6, on unless
//!   they read 0b01): when an axis's rate crosses 100 °/s either way, that
//!   axis's output holds its last value, bit for bit, for 1.5 ms (the
//!   1–2 ms reported in ArduPilot/ardupilot#25025).
//! - **FIFO** ([`Fifo`]): 2048 bytes of whole packets. Stream mode drops
//!   the oldest packets to make room, stop-on-full drops the new one; both
//!   set FIFO_FULL. Reading it empty returns 0x80 (the header's "FIFO
//!   empty" bit) for every byte. A packet read in part is read again from
//!   its start in the next transaction unless FIFO_RESUME_PARTIAL_RD is
//!   set. A configuration change takes effect on new packets only (the
//!   datasheet asks for a flush after one).
//! - **Timestamps** count the chip's own time: 1 µs per count nominally
//!   (TMST_RES = 0) or 16 µs (TMST_RES = 1), i.e. 32 or 2 counts per
//!   internal tick of 31.25 µs, so a chip whose clock is fast stamps its
//!   samples with a clock that is fast by the same ratio. With RTC_MODE and
//!   TMST_RES = 1 a count is one CLKIN period.

pub use gyro_array::drivers::icm42688::{aaf_hz, ui_divisor};

/// Nominal internal sample rate of the ICM-42688-P gyro (datasheet 5.1).
pub const ICM_INTERNAL_HZ: f64 = 32_000.0;
/// FIFO capacity, bytes (datasheet 6.1: 2 KiB).
pub const FIFO_BYTES: usize = 2048;
/// How long an AFSR switch freezes an axis, s (see the module notes).
pub const AFSR_FREEZE_S: f64 = 1.5e-3;
/// The rate at which AFSR switches range, °/s.
pub const AFSR_SWITCH_DPS: f32 = 100.0;

/// A chip oscillator's frequency error over time (see the module notes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockParams {
    /// Fractional error at power-up (0.01: 1 % fast).
    pub offset: f64,
    /// Linear drift of the fractional error, per second.
    pub drift_per_s: f64,
    /// Amplitude of the slow wander (fractional).
    pub wander: f64,
    /// Period of the wander, s.
    pub wander_period_s: f64,
}

impl ClockParams {
    /// A perfect oscillator.
    pub const EXACT: Self = Self {
        offset: 0.0,
        drift_per_s: 0.0,
        wander: 0.0,
        wander_period_s: 1.0,
    };

    /// A constant error `offset`.
    pub const fn fixed(offset: f64) -> Self {
        Self {
            offset,
            ..Self::EXACT
        }
    }

    /// The fractional error at `t_s`.
    pub fn error_at(&self, t_s: f64) -> f64 {
        let w = if self.wander != 0.0 && self.wander_period_s > 0.0 {
            self.wander * libm::sin(2.0 * core::f64::consts::PI * t_s / self.wander_period_s)
        } else {
            0.0
        };
        self.offset + self.drift_per_s * t_s + w
    }
}

/// Where an ICM-42688-P takes its internal clock from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockUse {
    /// Its PLL (the default; the RC oscillator if the PLL has failed).
    Internal,
    /// CLKIN (RTC_MODE with pin 9 as CLKIN).
    ClkIn,
}

/// One tone of vibration on the board, per board axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tone {
    /// Amplitude per board axis, °/s.
    pub amp_dps: [f32; 3],
    /// Frequency, Hz.
    pub hz: f64,
}

/// Up to four tones of vibration the chips' dies see (the rate profile's
/// motion is in band; these are the engine's and the road's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vibration {
    /// The tones; a zero amplitude is no tone.
    pub tones: [Tone; 4],
}

impl Vibration {
    /// No vibration.
    pub const NONE: Self = Self {
        tones: [Tone {
            amp_dps: [0.0; 3],
            hz: 0.0,
        }; 4],
    };

    /// One tone of `amp_dps` on every axis.
    pub fn tone(amp_dps: f32, hz: f64) -> Self {
        let mut v = Self::NONE;
        v.tones[0] = Tone {
            amp_dps: [amp_dps; 3],
            hz,
        };
        v
    }

    /// The vibration's rate at `t_s`, per board axis.
    pub fn at(&self, t_s: f64) -> [f64; 3] {
        let mut r = [0.0f64; 3];
        for t in &self.tones {
            if t.amp_dps == [0.0; 3] {
                continue;
            }
            let s = libm::sin(2.0 * core::f64::consts::PI * t.hz * t_s);
            for (ri, a) in r.iter_mut().zip(t.amp_dps) {
                *ri += a as f64 * s;
            }
        }
        r
    }
}

/// One second-order section, transposed direct form II, f64 (at 32 kHz a
/// 42 Hz pole sits 0.8 % from the unit circle: f32 would move it).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
    s: [f64; 2],
}

impl Biquad {
    /// A pass-through section.
    pub const THROUGH: Self = Self {
        b: [1.0, 0.0, 0.0],
        a: [0.0, 0.0],
        s: [0.0, 0.0],
    };

    /// Butterworth-style low-pass of quality `q` at `fc_hz`, sampled at
    /// `fs_hz` (bilinear, pre-warped so `fc_hz` is exact).
    pub fn lowpass(fc_hz: f64, q: f64, fs_hz: f64) -> Self {
        let k = libm::tan(core::f64::consts::PI * (fc_hz / fs_hz).min(0.49));
        let n = 1.0 / (1.0 + k / q + k * k);
        let b0 = k * k * n;
        Self {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * n, (1.0 - k / q + k * k) * n],
            s: [0.0; 2],
        }
    }

    /// First-order low-pass at `fc_hz` (bilinear, pre-warped).
    pub fn lowpass1(fc_hz: f64, fs_hz: f64) -> Self {
        let k = libm::tan(core::f64::consts::PI * (fc_hz / fs_hz).min(0.49));
        let n = 1.0 / (1.0 + k);
        Self {
            b: [k * n, k * n, 0.0],
            a: [(k - 1.0) * n, 0.0],
            s: [0.0; 2],
        }
    }

    /// Start at the steady state of a constant input `x` (a filter that has
    /// run since power-up on a still board).
    pub fn settle(&mut self, x: f64) {
        // Steady state: y = x (unit DC gain); s1 = b2·x − a2·y,
        // s0 = b1·x − a1·y + s1.
        let s1 = self.b[2] * x - self.a[1] * x;
        let s0 = self.b[1] * x - self.a[0] * x + s1;
        self.s = [s0, s1];
    }

    /// One sample.
    pub fn step(&mut self, x: f64) -> f64 {
        let y = self.b[0] * x + self.s[0];
        self.s[0] = self.b[1] * x - self.a[0] * y + self.s[1];
        self.s[1] = self.b[2] * x - self.a[1] * y;
        y
    }
}

/// The settings that shape an ICM-42688-P's gyro signal path, decoded from
/// its registers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSettings {
    /// AAF 3 dB bandwidth, Hz; `None` when GYRO_AAF_DIS is set.
    pub aaf_hz: Option<f32>,
    /// UI filter order (1..=3) and bandwidth, Hz; `None` when bypassed.
    pub ui: Option<(u8, f32)>,
    /// Output data rate, Hz (nominal, internal clock).
    pub odr_hz: f32,
    /// What the datasheet leaves open about these filters.
    pub reading: PathReading,
}

/// What the datasheet leaves open about the signal path's filters: it
/// gives the AAF's 3 dB bandwidth (table 17) and the UI filter's order and
/// a bandwidth code (section 5.3), not their shapes. Each reading is a
/// case the evaluations run; the driver states the instant on the
/// documented one ([`PathReading::DOCUMENTED`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathReading {
    /// The AAF's Q at its documented 3 dB bandwidth: 1/√2 (Butterworth,
    /// the reading the driver takes) or 1/2 (critically damped: 51 µs less
    /// delay at the board's 394 Hz).
    pub aaf_q: f64,
    /// The UI filter's true bandwidth over the one its code names: 1, or
    /// 0.56, a filter whose delay at the board's setting (second order at
    /// ODR/8, 500 Hz) is 0.8 ms, as a flight stack's developers quote for
    /// it, where √2/ω gives 0.45 ms.
    pub ui_bw_scale: f64,
}

impl PathReading {
    /// The datasheet's figures read as the driver reads them.
    pub const DOCUMENTED: Self = Self {
        aaf_q: core::f64::consts::FRAC_1_SQRT_2,
        ui_bw_scale: 1.0,
    };
    /// A critically damped AAF.
    pub const CRITICAL_AAF: Self = Self {
        aaf_q: 0.5,
        ui_bw_scale: 1.0,
    };
    /// A slower UI filter.
    pub const SLOW_UI: Self = Self {
        aaf_q: core::f64::consts::FRAC_1_SQRT_2,
        ui_bw_scale: 0.56,
    };
    /// Both.
    pub const BOTH: Self = Self {
        aaf_q: 0.5,
        ui_bw_scale: 0.56,
    };
    /// Every reading.
    pub const ALL: [Self; 4] = [
        Self::DOCUMENTED,
        Self::CRITICAL_AAF,
        Self::SLOW_UI,
        Self::BOTH,
    ];
}

/// The natural frequency of a second-order low-pass of quality `q` whose
/// 3 dB point is at `f3db_hz`: with x = f/f₀, |H|² = 1/((1 − x²)² + x²/q²)
/// is ½ where x² = (2 − 1/q² + √((1/q² − 2)² + 4)) / 2.
pub fn natural_hz(f3db_hz: f64, q: f64) -> f64 {
    let b = 1.0 / (q * q) - 2.0;
    let x2 = (-b + libm::sqrt(b * b + 4.0)) / 2.0;
    f3db_hz / libm::sqrt(x2)
}

impl Default for PathReading {
    fn default() -> Self {
        Self::DOCUMENTED
    }
}

impl PathSettings {
    /// The group delay at DC of the path these settings make, s: the
    /// driver's formula ([`gyro_array::drivers::icm42688::path_delay_us`]) on
    /// the documented reading, which the model's simulated filters are
    /// checked against; on another, a second-order low-pass's 1/(Q·ω) and
    /// the UI filter's delay over its bandwidth's scale.
    pub fn group_delay_s(&self) -> f64 {
        let r = self.reading;
        let aaf = self.aaf_hz.map_or(0.0, |hz| {
            let w0 = 2.0 * core::f64::consts::PI * natural_hz(f64::from(hz), r.aaf_q);
            1.0 / (r.aaf_q * w0)
        });
        let ui = gyro_array::drivers::icm42688::path_delay_us(None, self.ui) as f64 * 1e-6;
        aaf + ui / r.ui_bw_scale
    }
}

/// One axis's filters at the internal rate: AAF, then the UI filter (up
/// to third order: a first-order section and a biquad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignalPath {
    aaf: Biquad,
    ui: [Biquad; 2],
    /// The settings the filters were designed for.
    pub settings: PathSettings,
    primed: bool,
}

impl SignalPath {
    /// The filters for `s`, sampled at `fs_hz`.
    pub fn new(s: PathSettings, fs_hz: f64) -> Self {
        let aaf = match s.aaf_hz {
            Some(hz) => Biquad::lowpass(
                natural_hz(hz as f64, s.reading.aaf_q),
                s.reading.aaf_q,
                fs_hz,
            ),
            None => Biquad::THROUGH,
        };
        let ui =
            s.ui.map(|(order, bw)| (order, bw * s.reading.ui_bw_scale as f32));
        let ui = match ui {
            Some((1, bw)) => [Biquad::lowpass1(bw as f64, fs_hz), Biquad::THROUGH],
            Some((2, bw)) => [
                Biquad::lowpass(bw as f64, core::f64::consts::FRAC_1_SQRT_2, fs_hz),
                Biquad::THROUGH,
            ],
            // Third-order Butterworth: a real pole and a pair of Q = 1.
            Some((_, bw)) => [
                Biquad::lowpass1(bw as f64, fs_hz),
                Biquad::lowpass(bw as f64, 1.0, fs_hz),
            ],
            None => [Biquad::THROUGH; 2],
        };
        Self {
            aaf,
            ui,
            settings: s,
            primed: false,
        }
    }

    /// One internal sample.
    pub fn step(&mut self, x: f64) -> f64 {
        if !self.primed {
            self.primed = true;
            self.aaf.settle(x);
            self.ui[0].settle(x);
            self.ui[1].settle(x);
        }
        let y = self.aaf.step(x);
        let y = self.ui[0].step(y);
        self.ui[1].step(y)
    }
}

/// The FIFO: whole packets in a ring of [`FIFO_BYTES`].
#[derive(Clone, Debug)]
pub struct Fifo {
    buf: [u8; FIFO_BYTES],
    head: usize,
    len: usize,
    /// Bytes of the oldest packet already read out.
    read_in_packet: usize,
    /// Size of the packets in the ring.
    pub packet_len: usize,
    /// Packets dropped for want of room since the last flush.
    pub dropped: u32,
    /// What a read past the count gives.
    pub past: PastCount,
    /// Bytes held when this transaction read the count (none read yet).
    latched: Option<usize>,
    /// Whole packets this transaction read out.
    served: usize,
    /// Bytes handed over past the count and kept ([`PastCount::Resend`]).
    peek: usize,
    /// Distinct packets handed over whole since the FIFO was made (what a
    /// driver must hand on once each: the fault campaign's count of lost
    /// and doubled samples); one sent again counts once.
    pub read_out: u64,
    /// Packets stored since the FIFO was made: the serial of the next.
    pushed: u64,
    /// The serial after the newest packet handed over whole.
    next_unhanded: u64,
}

/// What a burst that reads on past the FIFO count it read gets, which
/// the datasheet leaves open (it asks for the count's bytes to be read,
/// section 6.2, and says nothing of more). PX4 and TDK's driver size
/// their reads by the count and never see it; a board that reads a fixed
/// burst does. Each reading is a case the evaluations run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PastCount {
    /// A packet that came during the burst, which leaves the FIFO with it.
    HandOver,
    /// The empty marker (0x80), whatever came since: the packet stays.
    Marker,
    /// The packet, which also stays and is sent again by the next read.
    Resend,
}

impl PastCount {
    /// Every reading.
    pub const ALL: [PastCount; 3] = [PastCount::HandOver, PastCount::Marker, PastCount::Resend];
}

impl Default for Fifo {
    fn default() -> Self {
        Self {
            buf: [0; FIFO_BYTES],
            head: 0,
            len: 0,
            read_in_packet: 0,
            packet_len: 16,
            dropped: 0,
            past: PastCount::HandOver,
            latched: None,
            served: 0,
            peek: 0,
            read_out: 0,
            pushed: 0,
            next_unhanded: 0,
        }
    }
}

/// What a push did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pushed {
    /// There was room.
    Stored,
    /// The FIFO was full: the oldest packet went (stream mode).
    DroppedOldest,
    /// The FIFO was full: this packet went (stop-on-full).
    DroppedNew,
}

impl Fifo {
    /// An empty FIFO whose reads past the count get `past`.
    pub fn reading(past: PastCount) -> Self {
        Self {
            past,
            ..Self::default()
        }
    }

    /// Empty it (SIGNAL_PATH_RESET.FIFO_FLUSH, a reset).
    pub fn flush(&mut self) {
        self.head = 0;
        self.len = 0;
        self.read_in_packet = 0;
        self.dropped = 0;
        self.latched = None;
        self.served = 0;
        self.peek = 0;
    }

    /// Bytes held (whole packets, the partly read one included); in a
    /// transaction that read the count, as it was then: the emulator takes
    /// the count's first byte to latch both, as the InvenSense parts
    /// before it document for their FIFO_COUNTH.
    pub fn bytes(&self) -> usize {
        self.latched.unwrap_or(self.len)
    }

    /// Packets held (as [`Fifo::bytes`]).
    pub fn records(&self) -> usize {
        self.bytes() / self.packet_len.max(1)
    }

    /// The count is read: what a read past it gets starts after it.
    pub fn latch(&mut self) {
        if self.latched.is_none() {
            self.latched = Some(self.len);
        }
    }

    /// Add one packet; `stop_on_full` chooses what goes when there is no
    /// room.
    pub fn push(&mut self, p: &[u8], stop_on_full: bool) -> Pushed {
        if p.len() != self.packet_len {
            // The format changed: what is held no longer parses as packets
            // of the new size (the datasheet asks for a flush).
            self.flush();
            self.packet_len = p.len();
        }
        let mut r = Pushed::Stored;
        if self.len + p.len() > FIFO_BYTES {
            if stop_on_full {
                self.dropped = self.dropped.wrapping_add(1);
                return Pushed::DroppedNew;
            }
            while self.len + p.len() > FIFO_BYTES && self.len > 0 {
                self.pop_packet();
                self.dropped = self.dropped.wrapping_add(1);
            }
            r = Pushed::DroppedOldest;
        }
        for (i, b) in p.iter().enumerate() {
            self.buf[(self.head + self.len + i) % FIFO_BYTES] = *b;
        }
        self.len += p.len();
        self.pushed += 1;
        r
    }

    fn pop_packet(&mut self) {
        let n = self.packet_len.min(self.len);
        self.head = (self.head + n) % FIFO_BYTES;
        self.len -= n;
        self.read_in_packet = 0;
    }

    /// One byte of FIFO_DATA: the next byte of the oldest packet, or 0x80
    /// when empty; past the count this transaction read, as
    /// [`Fifo::past`] says.
    pub fn read_byte(&mut self) -> u8 {
        let plen = self.packet_len.max(1);
        let beyond = matches!(self.latched, Some(l) if self.served >= l / plen);
        if beyond {
            match self.past {
                PastCount::HandOver => {}
                PastCount::Marker => return 0x80,
                PastCount::Resend => {
                    if self.peek >= self.len {
                        return 0x80;
                    }
                    let b = self.buf[(self.head + self.peek) % FIFO_BYTES];
                    self.peek += 1;
                    if self.peek.is_multiple_of(plen) {
                        self.handed(self.head_serial() + (self.peek / plen - 1) as u64);
                    }
                    return b;
                }
            }
        }
        if self.len == 0 {
            return 0x80;
        }
        let b = self.buf[(self.head + self.read_in_packet) % FIFO_BYTES];
        self.read_in_packet += 1;
        if self.read_in_packet >= self.packet_len {
            self.handed(self.head_serial());
            self.pop_packet();
            self.served += 1;
        }
        b
    }

    /// The serial of the oldest packet held.
    fn head_serial(&self) -> u64 {
        self.pushed - (self.len / self.packet_len.max(1)) as u64
    }

    /// Packet `serial` was handed over whole.
    fn handed(&mut self, serial: u64) {
        if serial >= self.next_unhanded {
            self.read_out += 1;
            self.next_unhanded = serial + 1;
        }
    }

    /// A new transaction begins: a packet read in part is read again from
    /// its start unless partial reads resume (datasheet 6.2,
    /// FIFO_RESUME_PARTIAL_RD); the count is not yet read.
    pub fn begin_transaction(&mut self, resume_partial: bool) {
        if !resume_partial {
            self.read_in_packet = 0;
        }
        self.latched = None;
        self.served = 0;
        self.peek = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Amplitude response of a path at `f_hz`, measured by running a sine
    /// through it (an independent check of the bilinear designs).
    fn gain(s: PathSettings, f_hz: f64) -> f64 {
        let fs = ICM_INTERNAL_HZ;
        let mut p = SignalPath::new(s, fs);
        let n = (fs * 0.5) as usize;
        let mut peak: f64 = 0.0;
        for i in 0..n {
            let x = libm::sin(2.0 * core::f64::consts::PI * f_hz * i as f64 / fs);
            let y = p.step(x);
            if i > n / 2 {
                peak = peak.max(y.abs());
            }
        }
        peak
    }

    #[test]
    fn aaf_table_and_interpolation() {
        assert_eq!(aaf_hz(6), 258.0);
        assert_eq!(aaf_hz(13), 585.0);
        assert_eq!(aaf_hz(21), 997.0);
        // Between 14 (634 Hz) and 21 (997 Hz).
        assert!((aaf_hz(17) - (634.0 + 3.0 / 7.0 * 363.0)).abs() < 1e-3);
        assert_eq!(aaf_hz(0), 42.0);
        assert_eq!(aaf_hz(200), 3979.0);
    }

    #[test]
    fn filters_are_minus_3_db_at_their_bandwidth() {
        for (aaf, ui) in [(Some(258.0), None), (None, Some((1, 250.0)))] {
            let s = PathSettings {
                aaf_hz: aaf,
                ui,
                reading: Default::default(),
                odr_hz: 1000.0,
            };
            let f = aaf.or(ui.map(|u| u.1)).unwrap() as f64;
            let g = gain(s, f);
            assert!((g - core::f64::consts::FRAC_1_SQRT_2).abs() < 0.01, "{g}");
        }
        // Third order falls 60 dB a decade: at 4× its bandwidth, 1/√(1+4⁶).
        let s = PathSettings {
            aaf_hz: None,
            ui: Some((3, 250.0)),
            reading: Default::default(),
            odr_hz: 1000.0,
        };
        let g = gain(s, 1000.0);
        assert!(
            (g / (1.0 / libm::sqrt(1.0 + 4096.0)) - 1.0).abs() < 0.05,
            "{g}"
        );
    }

    #[test]
    fn every_aaf_reading_is_3_db_down_at_its_documented_bandwidth() {
        for reading in PathReading::ALL {
            let s = PathSettings {
                aaf_hz: Some(585.0),
                ui: None,
                reading,
                odr_hz: 1000.0,
            };
            let g = gain(s, 585.0);
            assert!(
                (g - core::f64::consts::FRAC_1_SQRT_2).abs() < 0.01,
                "{reading:?}: {g}"
            );
        }
    }

    #[test]
    fn group_delay_matches_a_ramp_through_the_path() {
        // A ramp comes out of a low-pass late by its DC group delay, on
        // every reading of the filters' shapes.
        for reading in PathReading::ALL {
            let s = PathSettings {
                aaf_hz: Some(585.0),
                ui: Some((2, 250.0)),
                reading,
                odr_hz: 1000.0,
            };
            let fs = ICM_INTERNAL_HZ;
            let mut p = SignalPath::new(s, fs);
            p.step(0.0);
            let mut y = 0.0;
            let n = 32_000;
            for i in 0..n {
                y = p.step(i as f64 / fs);
            }
            let lag = (n - 1) as f64 / fs - y;
            assert!((lag - s.group_delay_s()).abs() < 2e-6, "{reading:?}: {lag}");
        }
    }

    #[test]
    fn fifo_keeps_whole_packets_and_reports_drops() {
        let mut f = Fifo::default();
        let p = [0x68u8; 16];
        for _ in 0..128 {
            assert_eq!(f.push(&p, true), Pushed::Stored);
        }
        assert_eq!(f.records(), 128);
        assert_eq!(f.push(&p, true), Pushed::DroppedNew);
        let mut q = p;
        q[1] = 7;
        assert_eq!(f.push(&q, false), Pushed::DroppedOldest);
        assert_eq!(f.dropped, 2);
        assert_eq!(f.bytes(), FIFO_BYTES);
        // A partial read is read again from the start of its packet.
        assert_eq!(f.read_byte(), 0x68);
        f.begin_transaction(false);
        for _ in 0..16 {
            f.read_byte();
        }
        assert_eq!(f.records(), 127);
        f.flush();
        assert_eq!(f.read_byte(), 0x80);
    }

    #[test]
    fn clock_error_is_offset_drift_and_wander() {
        let c = ClockParams {
            offset: 0.01,
            drift_per_s: 1e-6,
            wander: 1e-4,
            wander_period_s: 100.0,
        };
        assert!((c.error_at(0.0) - 0.01).abs() < 1e-12);
        assert!((c.error_at(25.0) - (0.01 + 25e-6 + 1e-4)).abs() < 1e-9);
    }
}
