//! The ICM-42688-P's FIFO timestamp counts, put on µs of the chip's clock.
//!
//! A count is not a µs. On the chip's own clock (the PLL, or the RC
//! oscillator it falls back to) TDK's driver scales a count by 32/30
//! (`PLL_SCALE_FACTOR_Q24`) and PX4 by `16 · 32/30` for 16 µs counts
//! (`FIFO_TIMESTAMP_SCALING`): with TMST_RES = 0 a count is 16/15 µs of the
//! chip's nominal clock. On CLKIN (RTC_MODE) the sources leave open what a
//! count is at TMST_RES = 0: the register map says "1 µs resolution" (and
//! "1 RTC clock period" for TMST_RES = 1), PX4 scales CLKIN stamps by the
//! input's period. Taken as 1 µs, a chip on its PLL read 6 % fast, its
//! stated instant some 70 µs off through its 1 ms path, and its reads late.
//!
//! [`StampScale`] turns counts into µs of the chip's clock at its nominal
//! rate, so that the clock tracker's ratio is the chip's clock error and a
//! delay in the chip's µs is one in these units. On the chip's own clock
//! the unit is the documented one from the first sample. On CLKIN each
//! step between two stamps votes for the reading whose count of one
//! sample period it is nearest, if within 15 % (the readings of a µs and
//! of 32/30 µs are 6.7 % apart; the counts of a sample do not depend on
//! CLKIN's frequency, which the ODR follows), and the first reading to gather [`LEARN_SAMPLES`] votes is
//! taken; steps that fit none (a garbled stamp, a gap) vote for nothing.

use crate::drivers::icm42688::ClockInput;

/// Steps measured before the unit is decided.
pub const LEARN_SAMPLES: u16 = 64;

/// The documented µs per count on the chip's own clock, TMST_RES = 0.
pub const INTERNAL_US_PER_COUNT: f64 = 32.0 / 30.0;

/// The readings on CLKIN at TMST_RES = 0, µs of the nominal 32 kHz grid
/// per count: a µs, a µs scaled as on the chip's own clock, one period.
pub const CLKIN_US_PER_COUNT: [f64; 3] = [1.0, 32.0 / 30.0, 31.25];

/// How far a step may be from a reading's count of one sample period,
/// as a ratio, to vote for it.
const VOTE_WITHIN: f64 = 0.15;

/// FIFO timestamp counts onto µs of the chip's nominal clock.
#[derive(Clone, Copy, Debug)]
pub struct StampScale {
    /// Nominal chip µs between samples.
    period_us: u32,
    /// µs per count × 2¹⁶ (within 10⁻⁶ of the unit: a clock error of
    /// 1 ppm, which the tracker measures with the rest). A step times it
    /// is one 32 × 32 → 64-bit multiply on the Cortex-M4 (with 2³² it was
    /// a 64-bit multiply by call, some 640 instructions a sample on the
    /// board's frame path).
    k16: u32,
    /// The last count's low 16 bits, and the µs it stands for (with the
    /// remainder of the product, 2⁻¹⁶ µs).
    last: Option<u16>,
    us: u32,
    rem: u32,
    /// While learning on CLKIN: each reading's votes.
    votes: [u16; 3],
    decided: bool,
    /// The unit changed at the decision: µs before and after do not join.
    changed: bool,
}

fn k16_of(us_per_count: f64) -> u32 {
    // (Once a decision.)
    libm::round(us_per_count * 65_536.0) as u32
}

impl StampScale {
    /// A scale for a chip on `input` sampling every `period_us` nominal µs.
    pub fn new(input: ClockInput, period_us: u32) -> Self {
        let guess = match input {
            ClockInput::ClkIn => CLKIN_US_PER_COUNT[0],
            _ => INTERNAL_US_PER_COUNT,
        };
        Self {
            period_us,
            k16: k16_of(guess),
            last: None,
            us: 0,
            rem: 0,
            votes: [0; 3],
            // On the chip's own clock the documented unit holds at once.
            decided: input != ClockInput::ClkIn,
            changed: false,
        }
    }

    /// µs of the chip's nominal clock per count.
    pub fn us_per_count(&self) -> f32 {
        self.k16 as f32 / 65_536.0
    }

    /// One wrap of the 16-bit count, µs: what a count of unknown high bits
    /// (after a flush) may be off by.
    pub fn wrap_us(&self) -> u32 {
        self.k16
    }

    /// Whether the unit has been decided.
    pub fn decided(&self) -> bool {
        self.decided
    }

    /// The sample stamped `count` (its low 16 bits are the chip's; the
    /// step from the last is taken modulo 2¹⁶, as the driver extends it),
    /// µs of the chip's nominal clock, continuous from the first (wrapping
    /// at 2³² µs).
    #[inline]
    pub fn convert(&mut self, count: u32) -> u32 {
        let c = count as u16;
        if let Some(l) = self.last {
            let d = c.wrapping_sub(l) as u32;
            if !self.decided {
                self.learn(d);
            }
            let acc = u64::from(d) * u64::from(self.k16) + u64::from(self.rem);
            self.us = self.us.wrapping_add((acc >> 16) as u32);
            self.rem = (acc & 0xFFFF) as u32;
        } else {
            let acc = u64::from(c) * u64::from(self.k16);
            self.us = (acc >> 16) as u32;
            self.rem = (acc & 0xFFFF) as u32;
        }
        self.last = Some(c);
        self.us
    }

    /// A step of `d` counts while learning on CLKIN. Out of line: the
    /// first samples only.
    #[cold]
    #[inline(never)]
    fn learn(&mut self, d: u32) {
        // The nearest reading, if within the band.
        let mut best = None;
        let mut off = VOTE_WITHIN;
        for (k, &u) in CLKIN_US_PER_COUNT.iter().enumerate() {
            let e = (f64::from(d) * u / f64::from(self.period_us) - 1.0).abs();
            if e <= off {
                (best, off) = (Some(k), e);
            }
        }
        let Some(k) = best else {
            return;
        };
        self.votes[k] += 1;
        if self.votes[k] >= LEARN_SAMPLES {
            let k16 = k16_of(CLKIN_US_PER_COUNT[k]);
            self.changed = k16 != self.k16;
            self.k16 = k16;
            self.decided = true;
        }
    }

    /// Whether the unit changed at its decision since the last call: the
    /// µs before it do not join those after (the caller's clock tracker
    /// and aligner start again).
    pub fn take_changed(&mut self) -> bool {
        core::mem::take(&mut self.changed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stamps of a chip on its PLL at 1 kHz, a count 32/30 µs: 937.5
    /// counts a sample. The µs come out 1 000 a sample (times the unit's
    /// rounding, 1 ppm) to within the rounding of one count, for 10⁵
    /// samples (past the 16-bit wrap many times and the 2³² count too).
    #[test]
    fn pll_counts_come_out_as_microseconds() {
        let mut s = StampScale::new(ClockInput::Internal, 1000);
        let mut first = None;
        for k in 0..100_000u64 {
            let count = (k * 9375 / 10 + 4_294_000_000) as u32;
            let us = s.convert(count);
            let f = *first.get_or_insert(us);
            let want = (k as f64 * 937.5 * f64::from(s.us_per_count())).round() as i64;
            let got = us.wrapping_sub(f) as i64;
            assert!((got - want).abs() <= 2, "sample {k}: {got} vs {want}");
        }
        assert!(s.decided());
        assert!(!s.take_changed());
    }

    /// On CLKIN every documented reading is recognised from the stamps
    /// (32 CLKIN periods a sample, whatever CLKIN's frequency: the ODR
    /// follows it, and the clock tracker measures how far its µs are from
    /// the board's).
    #[test]
    fn every_clkin_reading_is_recognised() {
        for (i, &u) in CLKIN_US_PER_COUNT.iter().enumerate() {
            let mut s = StampScale::new(ClockInput::ClkIn, 1000);
            let per_tick = 31.25 / u;
            for k in 0..200u64 {
                s.convert(((k * 32) as f64 * per_tick) as u32);
            }
            assert!(s.decided());
            assert!(
                (f64::from(s.us_per_count()) - u).abs() < 1e-4 * u,
                "reading {i}: {}",
                s.us_per_count()
            );
            assert_eq!(s.take_changed(), i != 0);
        }
    }

    /// Garbled steps (a stamp's bits flipped, a gap) vote for nothing:
    /// a chip on CLKIN whose stamps are garbled one in four still finds its
    /// reading, and one that never sends a whole step keeps the guess.
    #[test]
    fn garbled_steps_vote_for_nothing() {
        let mut s = StampScale::new(ClockInput::ClkIn, 1000);
        let mut c = 0u32;
        for k in 0..400u32 {
            c += 32;
            let sent = if k % 4 == 3 { c ^ 0x5A5A } else { c };
            s.convert(sent);
        }
        assert!(s.decided());
        assert_eq!(s.us_per_count(), 31.25);
        let mut g = StampScale::new(ClockInput::ClkIn, 1000);
        for k in 0..400u32 {
            g.convert(k.wrapping_mul(40_503));
        }
        assert!(!g.decided());
        assert_eq!(g.us_per_count(), 1.0);
    }
}
