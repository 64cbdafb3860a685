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
///
/// The samples stay in counts (the aligner's interpolation is the same in
/// any unit linear in the chip's time); what the µs are needed for is one
/// sample a read (the clock tracker's observation) and one instant (the
/// read's, into counts). [`StampScale::convert`] moves the scale's base to
/// a read's newest sample, and [`StampScale::us_of`],
/// [`StampScale::counts16_of`] and [`StampScale::us16_of`] map near it.
/// Sixteen samples a millisecond on the board each need no multiply.
#[derive(Clone, Copy, Debug)]
pub struct StampScale {
    /// Nominal chip µs between samples.
    period_us: u32,
    /// µs per count × 2¹⁶ (within 10⁻⁶ of the unit: a clock error of
    /// 1 ppm, which the tracker measures with the rest). A step times it
    /// is one 32 × 32 → 64-bit multiply on the Cortex-M4 (a 2³² fraction
    /// would be a 64-bit multiply by call).
    k16: u32,
    /// Counts per µs (the inverse of [`Self::k16`], kept: a division),
    /// for the map of an instant into counts.
    counts_per_us: f32,
    /// The base: the last count converted (as the driver extended it),
    /// and the µs it stands for (with the remainder of the product,
    /// 2⁻¹⁶ µs).
    last: Option<u32>,
    us: u32,
    rem: u32,
    /// While learning on CLKIN: the last count seen, each reading's votes.
    seen: Option<u16>,
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
        let mut s = Self {
            period_us,
            k16: 0,
            counts_per_us: 1.0,
            last: None,
            us: 0,
            rem: 0,
            seen: None,
            votes: [0; 3],
            // On the chip's own clock the documented unit holds at once.
            decided: input != ClockInput::ClkIn,
            changed: false,
        };
        s.set_unit(guess);
        s
    }

    fn set_unit(&mut self, us_per_count: f64) {
        self.k16 = k16_of(us_per_count);
        self.counts_per_us = 65_536.0 / self.k16 as f32;
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

    /// The sample stamped `count` (as the driver extended it; the step
    /// from the base is taken on its low 16 bits, as the driver extends
    /// it, so it holds across a flush), µs of the chip's nominal clock,
    /// continuous from the first (wrapping at 2³² µs); it becomes the
    /// base. Once a read, for its newest sample.
    pub fn convert(&mut self, count: u32) -> u32 {
        let c = count as u16;
        if let Some(l) = self.last {
            let d = c.wrapping_sub(l as u16) as u32;
            let acc = u64::from(d) * u64::from(self.k16) + u64::from(self.rem);
            self.us = self.us.wrapping_add((acc >> 16) as u32);
            self.rem = (acc & 0xFFFF) as u32;
        } else {
            let acc = u64::from(c) * u64::from(self.k16);
            self.us = (acc >> 16) as u32;
            self.rem = (acc & 0xFFFF) as u32;
        }
        self.last = Some(count);
        self.us
    }

    /// The µs of `count`, a sample of the base's stream within ±2³¹
    /// counts of it (a read's other samples), as [`Self::convert`] would
    /// have made them, without moving the base. Before any base, the
    /// count converted alone.
    pub fn us_of(&self, count: u32) -> u32 {
        let Some(l) = self.last else {
            return ((u64::from(count as u16) * u64::from(self.k16)) >> 16) as u32;
        };
        let d = i64::from(count.wrapping_sub(l) as i32);
        let acc = d * i64::from(self.k16) + i64::from(self.rem);
        self.us.wrapping_add((acc >> 16) as i32 as u32)
    }

    /// The instant `us16` (1/16 µs on this scale, within some 2²⁰ µs of
    /// the base) in 1/16 counts of the base's stream, to the nearest.
    pub fn counts16_of(&self, us16: u32) -> u32 {
        let l = self.last.unwrap_or(0);
        let du = us16.wrapping_sub(self.us.wrapping_mul(16)) as i32 as f32
            - self.rem as f32 * (16.0 / 65_536.0);
        l.wrapping_mul(16)
            .wrapping_add(super::clock::floor_i32(du * self.counts_per_us + 0.5) as u32)
    }

    /// The inverse of [`Self::counts16_of`]: 1/16 counts of the base's
    /// stream in 1/16 µs on this scale, to the nearest.
    pub fn us16_of(&self, counts16: u32) -> u32 {
        let l = self.last.unwrap_or(0);
        let dc = counts16.wrapping_sub(l.wrapping_mul(16)) as i32 as f32;
        let f = dc * self.us_per_count() + self.rem as f32 * (16.0 / 65_536.0);
        self.us
            .wrapping_mul(16)
            .wrapping_add(super::clock::floor_i32(f + 0.5) as u32)
    }

    /// One sample's count while the unit is being learnt on CLKIN (each
    /// step votes): call it for every sample until [`Self::decided`].
    #[cold]
    #[inline(never)]
    pub fn learn(&mut self, count: u32) {
        let c = count as u16;
        if let Some(l) = self.seen.replace(c) {
            self.vote(u32::from(c.wrapping_sub(l)));
        }
    }

    /// A step of `d` counts while learning on CLKIN.
    fn vote(&mut self, d: u32) {
        // The nearest reading, if within the band. In f32, which the
        // Cortex-M4F has in hardware (the readings are 6.7 % apart, the
        // band 15 %): in f64, soft float, the first 64 steps after a
        // start on CLKIN cost some 15 000 instructions a sample.
        let mut best = None;
        let mut off = VOTE_WITHIN as f32;
        let per = 1.0 / self.period_us as f32;
        for (k, &u) in CLKIN_US_PER_COUNT.iter().enumerate() {
            let e = (d as f32 * u as f32 * per - 1.0).abs();
            if e <= off {
                (best, off) = (Some(k), e);
            }
        }
        let Some(k) = best else {
            return;
        };
        self.votes[k] += 1;
        if self.votes[k] >= LEARN_SAMPLES {
            let guess = self.k16;
            self.set_unit(CLKIN_US_PER_COUNT[k]);
            self.changed = self.k16 != guess;
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

    /// A sample's count as a read hands it on: learnt while undecided,
    /// then converted (the scale's base).
    fn feed(s: &mut StampScale, count: u32) -> u32 {
        if !s.decided() {
            s.learn(count);
        }
        s.convert(count)
    }

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
            let us = feed(&mut s, count);
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
                feed(&mut s, ((k * 32) as f64 * per_tick) as u32);
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
            feed(&mut s, sent);
        }
        assert!(s.decided());
        assert_eq!(s.us_per_count(), 31.25);
        let mut g = StampScale::new(ClockInput::ClkIn, 1000);
        for k in 0..400u32 {
            feed(&mut g, k.wrapping_mul(40_503));
        }
        assert!(!g.decided());
        assert_eq!(g.us_per_count(), 1.0);
    }

    /// A read converts its newest sample only: its other samples' µs, and
    /// instants both ways, come out as converting each would have made
    /// them (to the rounding of one µs, and 1/16 of a µs or a count for
    /// instants), across the 16-bit and the 2³² wraps.
    #[test]
    fn the_maps_near_the_base_agree_with_converting_each() {
        let mut each = StampScale::new(ClockInput::Internal, 250);
        let mut lazy = StampScale::new(ClockInput::Internal, 250);
        let start = u32::MAX - 50_000;
        let count = |k: u32| start.wrapping_add(k * 234 + k % 3);
        for read in 0..5_000u32 {
            let ks = [4 * read, 4 * read + 1, 4 * read + 2, 4 * read + 3];
            let us = ks.map(|k| each.convert(count(k)));
            lazy.convert(count(ks[3]));
            for (k, u) in ks.iter().zip(us) {
                let got = lazy.us_of(count(*k));
                assert!((got.wrapping_sub(u) as i32).abs() <= 1, "{got} vs {u}");
                // An instant between samples, both ways.
                let c16 = count(*k).wrapping_mul(16).wrapping_add(5);
                let u16_ = lazy.us16_of(c16);
                let want = u.wrapping_mul(16) as i64 + (5.0 * 32.0 / 30.0) as i64;
                assert!(
                    (u16_.wrapping_sub(want as u32) as i32).abs() <= 17,
                    "read {read}"
                );
                let back = lazy.counts16_of(u16_);
                assert!((back.wrapping_sub(c16) as i32).abs() <= 1, "read {read}");
            }
        }
    }
}
