//! Each chip's clock against the board's: a tracker that maps a chip's
//! own timestamps (µs of its oscillator, or of CLKIN) onto the board's
//! microsecond clock.
//!
//! Its observations are pairs (chip stamp, board time) of one sample: the
//! chip's FIFO timestamp and the board timer's capture of the same
//! sample's data-ready pulse on INT1, exact to the timer's 1 µs tick. The
//! read's own time would only bound the sample from above; a free-running
//! chip sweeps every phase against the reads, so the lower envelope of
//! those bounds converges, but a chip on CLKIN keeps one phase for ever,
//! and so does one whose clock is within 0.05 % of the board's for
//! seconds: only the capture gives the instant within microseconds every
//! time, so the board wires INT1 of each ICM-42688-P to a capture channel.
//!
//! The tracker is a second-order loop on the anchor (a stamp and its board
//! time) and the ratio (board µs per chip µs): each observation moves the
//! anchor by 1/16 of its residual and the ratio by 1/1024 of it per µs of
//! stamp since the last one (critically damped, a time constant of some 16
//! observations). It starts from the ratio of two observations 20 reads
//! apart, so an RC oscillator 8 % off is acquired at once, and chips that
//! started together acquire together. Sums stay in
//! f32 over deltas of milliseconds, so no f64 runs on the board.

/// An instant on the board's clock, in 1/16 µs (wraps after 268 s;
/// compared by wrapping difference, valid within ±134 s).
pub type Instant16 = u32;

/// 1/16 µs per µs.
pub const Q: f32 = 16.0;

/// Difference `a − b` of two instants, in 1/16 µs.
pub fn since(a: Instant16, b: Instant16) -> i32 {
    a.wrapping_sub(b) as i32
}

/// ⌊x⌋ for |x| < 2³¹ by the FPU's truncating conversion (libm's `floorf`
/// is some 20 instructions of bit arithmetic on the Cortex-M4).
pub(crate) fn floor_i32(x: f32) -> i32 {
    let t = x as i32;
    t - i32::from((t as f32) > x)
}

/// Where a tracker is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClockState {
    /// No observation yet.
    #[default]
    Empty,
    /// One observation: waiting for a second far enough for a ratio.
    Acquiring,
    /// Tracking anchor and ratio.
    Tracking,
}

/// Observations the first ratio spans: one a read, so chips that started
/// together (the board flushes every FIFO at once) acquire on the same
/// read, whatever their clocks; 20 reads, 20 ms.
const ACQUIRE_OBS: u8 = 20;
/// The shortest baseline of the first ratio, chip µs.
const ACQUIRE_US: i32 = 10_000;
/// A baseline longer than this is not one count of stamps (a flush or a
/// restart came between): acquisition starts again.
const ACQUIRE_MAX_US: i32 = 1_000_000;
/// The shortest baseline, chip µs, that the ratio learns from: a quarter
/// of the fastest sample period (4 kHz).
const MIN_BASELINE_US: f32 = 62.5;
/// Gain on the anchor.
const K_ANCHOR: f32 = 1.0 / 16.0;
/// Gain on the ratio (per µs of baseline).
const K_RATIO: f32 = 1.0 / 1024.0;
/// A residual beyond this many µs is not a clock's wander but a jump (a
/// chip reset, a capture of another sample): it is counted and not
/// learnt; three in a row start the tracker again.
pub const JUMP_US: f32 = 40.0;
/// One chip's clock against the board's.
#[derive(Clone, Copy, Debug, Default)]
pub struct ChipClock {
    state: ClockState,
    anchor_stamp: u32,
    /// Board time of the anchor, µs, and its fraction of a µs.
    anchor_us: u32,
    anchor_frac: f32,
    /// Board µs per chip µs.
    ratio: f32,
    jumps_in_row: u8,
    /// Observations since acquisition began.
    seen: u8,
    /// The observations that jumped in a row (stamp, capture µs).
    jumped: [(u32, u32); 2],
    /// Observations that jumped (see [`JUMP_US`]).
    pub jumps: u32,
    /// Times the tracker gave up: three jumps in a row, or a first ratio
    /// no clock could have (a stamp or a capture that is not one).
    pub lost: u32,
    /// The last residual, µs (observed minus predicted).
    pub last_residual_us: f32,
}

impl ChipClock {
    /// A tracker with no observation.
    pub const fn new() -> Self {
        Self {
            state: ClockState::Empty,
            anchor_stamp: 0,
            anchor_us: 0,
            anchor_frac: 0.0,
            ratio: 1.0,
            jumps_in_row: 0,
            seen: 0,
            jumped: [(0, 0); 2],
            jumps: 0,
            lost: 0,
            last_residual_us: 0.0,
        }
    }

    /// Where it is.
    pub fn state(&self) -> ClockState {
        self.state
    }

    /// Board µs per chip µs (1.0 before the first ratio).
    pub fn ratio(&self) -> f32 {
        self.ratio
    }

    /// The chip's clock error against the board's, parts per million
    /// (positive: the chip's clock is fast).
    pub fn error_ppm(&self) -> f32 {
        (1.0 / self.ratio - 1.0) * 1e6
    }

    /// Forget everything (the chip restarted: its stamps start again).
    pub fn reset(&mut self) {
        let (jumps, lost) = (self.jumps, self.lost);
        *self = Self::new();
        self.jumps = jumps;
        self.lost = lost;
    }

    /// The residual of board time `board_us` + `frac` against the
    /// prediction for `stamp`, µs, and the stamp's distance from the
    /// anchor, chip µs.
    fn residual(&self, stamp: u32, board_us: u32, frac: f32) -> (f32, f32) {
        let d = stamp.wrapping_sub(self.anchor_stamp) as i32 as f32;
        let b = board_us.wrapping_sub(self.anchor_us) as i32 as f32 + frac - self.anchor_frac;
        (b - self.ratio * d, d)
    }

    /// Move the anchor to `stamp`, at its predicted board time plus `by`
    /// µs.
    fn advance_anchor(&mut self, stamp: u32, d: f32, by: f32) {
        let t = self.anchor_frac + self.ratio * d + by;
        let whole = floor_i32(t);
        self.anchor_us = self.anchor_us.wrapping_add(whole as u32);
        self.anchor_frac = t - whole as f32;
        self.anchor_stamp = stamp;
    }

    /// One sample's stamp and the board time of its data-ready pulse,
    /// captured by a 1 µs timer (truncated: the pulse came within the
    /// µs after).
    pub fn observe(&mut self, stamp: u32, capture_us: u32) {
        let frac = 0.5;
        match self.state {
            ClockState::Empty => {
                self.anchor_stamp = stamp;
                self.anchor_us = capture_us;
                self.anchor_frac = frac;
                self.seen = 1;
                self.state = ClockState::Acquiring;
            }
            ClockState::Acquiring => {
                let d = stamp.wrapping_sub(self.anchor_stamp) as i32;
                if !(0..=ACQUIRE_MAX_US).contains(&d) {
                    // The stamps went back, or jumped far: a new count
                    // (a flush, a restart). Start from this one.
                    self.anchor_stamp = stamp;
                    self.anchor_us = capture_us;
                    self.anchor_frac = frac;
                    self.seen = 1;
                    return;
                }
                self.seen = self.seen.saturating_add(1);
                if self.seen < ACQUIRE_OBS || d < ACQUIRE_US {
                    return;
                }
                let b = capture_us.wrapping_sub(self.anchor_us) as i32 as f32;
                let r = b / d as f32;
                if (0.8..1.25).contains(&r) {
                    self.ratio = r;
                    self.anchor_stamp = stamp;
                    self.anchor_us = capture_us;
                    self.state = ClockState::Tracking;
                } else {
                    self.lost = self.lost.wrapping_add(1);
                    self.reset();
                }
            }
            ClockState::Tracking => {
                let (e, d) = self.residual(stamp, capture_us, frac);
                self.last_residual_us = e;
                if libm::fabsf(e) > JUMP_US {
                    self.jumps = self.jumps.wrapping_add(1);
                    if self.jumps_in_row < 2 {
                        self.jumped[self.jumps_in_row as usize] = (stamp, capture_us);
                        self.jumps_in_row += 1;
                        return;
                    }
                    // Three in a row. If they lie on one line, the clock
                    // changed its rate (a PLL that failed over to the RC
                    // oscillator, 5–8 % off): take the new rate and go on.
                    // If not, the stamps are not a clock's: lost.
                    let [(s0, c0), (s1, c1)] = self.jumped;
                    let d = stamp.wrapping_sub(s0) as i32;
                    let r = capture_us.wrapping_sub(c0) as i32 as f32 / d as f32;
                    let mid =
                        c0.wrapping_add(
                            floor_i32(r * s1.wrapping_sub(s0) as i32 as f32 + 0.5) as u32
                        );
                    let fits = d > 0 && (0.8..1.25).contains(&r) && c1.abs_diff(mid) <= 3;
                    self.jumps_in_row = 0;
                    if fits {
                        self.ratio = r;
                        self.anchor_stamp = stamp;
                        self.anchor_us = capture_us;
                        self.anchor_frac = frac;
                    } else {
                        self.lost = self.lost.wrapping_add(1);
                        self.reset();
                    }
                    return;
                }
                self.jumps_in_row = 0;
                // A baseline of a few µs says nothing of the ratio (one
                // capture seen twice, its stamps a rounding apart, moved it
                // by 0.6 %).
                if d >= MIN_BASELINE_US {
                    self.ratio += K_RATIO * e / d;
                }
                self.advance_anchor(stamp, d, K_ANCHOR * e);
            }
        }
    }

    /// The board time of chip stamp `stamp`, whole µs (wrapping as the
    /// board's µs clock does), or `None` before the tracker has a ratio.
    pub fn board_us(&self, stamp: u32) -> Option<u32> {
        if self.state != ClockState::Tracking {
            return None;
        }
        Some(self.project((self.anchor_stamp, self.anchor_us), self.anchor_frac, stamp))
    }

    /// Where the capture of the sample stamped `stamp` is expected, board
    /// µs: from the last observation that jumped while the tracker waits
    /// out a possible rate step (the anchor's prediction drifts by the
    /// step times the time since it, up to 80 µs a read after an 8 %
    /// step; the last jump's, by one read's worth), else [`Self::board_us`].
    pub fn expected_us(&self, stamp: u32) -> Option<u32> {
        match self.jumps_in_row.checked_sub(1) {
            Some(k) if self.state == ClockState::Tracking => {
                Some(self.project(self.jumped[k as usize], 0.5, stamp))
            }
            _ => self.board_us(stamp),
        }
    }

    /// Chip stamp `stamp` on the board's clock from the point (stamp,
    /// capture µs) `from`, whose capture lies `frac` µs into its
    /// microsecond, at the tracked ratio.
    fn project(&self, from: (u32, u32), frac: f32, stamp: u32) -> u32 {
        let d = stamp.wrapping_sub(from.0) as i32 as f32;
        from.1.wrapping_add(floor_i32(frac + self.ratio * d) as u32)
    }

    /// The chip stamp of board time `board_us`, or `None` before the
    /// tracker has a ratio (the inverse of [`Self::board_us`]).
    pub fn stamp_at(&self, board_us: u32) -> Option<u32> {
        if self.state != ClockState::Tracking {
            return None;
        }
        let b = board_us.wrapping_sub(self.anchor_us) as i32 as f32 - self.anchor_frac;
        Some(
            self.anchor_stamp
                .wrapping_add(floor_i32(b / self.ratio + 0.5) as u32),
        )
    }

    /// Take this observation as the anchor, keeping the ratio: after a gap
    /// in the samples, where the clock's wander over the gap (up to some
    /// 100 µs over a third of a second) is a phase to take, not a jump.
    pub fn reanchor(&mut self, stamp: u32, capture_us: u32) {
        if self.state == ClockState::Tracking {
            self.anchor_stamp = stamp;
            self.anchor_us = capture_us;
            self.anchor_frac = 0.5;
            self.jumps_in_row = 0;
        }
    }

    /// The board instant of chip stamp `stamp`, or `None` before the
    /// tracker has a ratio.
    pub fn board_instant(&self, stamp: u32) -> Option<Instant16> {
        self.board_instant16(stamp.wrapping_mul(16))
    }

    /// The board instant of chip instant `chip16` (1/16 µs of the chip's
    /// stamps), or `None` before the tracker has a ratio.
    pub fn board_instant16(&self, chip16: u32) -> Option<Instant16> {
        if self.state != ClockState::Tracking {
            return None;
        }
        let d = chip16.wrapping_sub(self.anchor_stamp.wrapping_mul(16)) as i32 as f32;
        let off = self.anchor_frac * Q + self.ratio * d;
        Some(
            self.anchor_us
                .wrapping_mul(16)
                .wrapping_add(floor_i32(off + 0.5) as u32),
        )
    }

    /// The chip instant (1/16 µs of its stamps) of board instant `at`, or
    /// `None` before the tracker has a ratio: the inverse of
    /// [`Self::board_instant16`], what an aligner in the chip's own time
    /// asks for. One conversion a read, where converting each sample
    /// would be two.
    pub fn chip_instant(&self, at: Instant16) -> Option<u32> {
        if self.state != ClockState::Tracking {
            return None;
        }
        let b =
            at.wrapping_sub(self.anchor_us.wrapping_mul(16)) as i32 as f32 - self.anchor_frac * Q;
        Some(
            self.anchor_stamp
                .wrapping_mul(16)
                .wrapping_add(floor_i32(b / self.ratio + 0.5) as u32),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Board time (µs, f64) of chip stamp `s` for a chip whose clock runs
    /// `1 + e` times the board's, started at board time `t0`.
    fn board_of(s: u32, e: f64, t0: f64) -> f64 {
        t0 + s as f64 / (1.0 + e)
    }

    #[test]
    fn captures_give_the_sample_instants_to_a_fraction_of_a_microsecond() {
        for e in [0.08, 0.01, 0.0, -0.01, -0.08] {
            let mut c = ChipClock::new();
            let t0 = 12_345.678;
            let mut worst: f64 = 0.0;
            for k in 0..4000u32 {
                let s = k * 500; // 2 kHz in chip µs
                let b = board_of(s, e, t0);
                c.observe(s, b as u32);
                if k > 200 {
                    let got = c.board_instant(s).unwrap() as f64 / 16.0;
                    worst = worst.max((got - b).abs());
                }
            }
            assert!(worst < 0.7, "clock {e}: {worst} µs");
            assert!(
                (c.error_ppm() as f64 - e * 1e6).abs() < 20.0,
                "{}",
                c.error_ppm()
            );
        }
    }

    #[test]
    fn a_jump_is_counted_not_learnt_and_three_restart() {
        let mut c = ChipClock::new();
        for k in 0..100u32 {
            c.observe(k * 1000, 5000 + k * 1000);
        }
        let before = c.board_instant(100_000).unwrap();
        c.observe(100_000, 5000 + 100_000 + 300);
        assert_eq!(c.jumps, 1);
        assert_eq!(c.board_instant(100_000), Some(before));
        c.observe(101_000, 9_000_000);
        c.observe(102_000, 9_001_500);
        assert_eq!(c.state(), ClockState::Empty);
        assert_eq!((c.jumps, c.lost), (3, 1));
    }

    #[test]
    fn acquisition_starts_again_when_the_stamps_go_back() {
        let mut c = ChipClock::new();
        c.observe(900_000, 10);
        // A flush: the stamps restart low. Without a fresh anchor the
        // baseline would stay negative for 900 ms.
        for k in 1..=20u32 {
            c.observe(k * 1_000, k * 1_000);
        }
        assert_eq!(c.state(), ClockState::Tracking);
        assert!((c.ratio() - 1.0).abs() < 1e-4);
    }

    #[test]
    fn a_step_in_the_clock_rate_is_followed_not_lost() {
        // 1 000 chip µs a ms, then the PLL fails: 1 000 chip µs take
        // 1 070 board µs from then on.
        let mut c = ChipClock::new();
        let mut b = 0u32;
        for k in 0..300u32 {
            b += if k < 200 { 1000 } else { 1070 };
            c.observe(k * 1000, b);
        }
        assert_eq!(c.lost, 0);
        assert!((c.ratio() - 1.07).abs() < 1e-3, "{}", c.ratio());
        let got = c.board_us(299_000).unwrap();
        assert!(got.abs_diff(b) <= 2, "{got} vs {b}");
    }

    #[test]
    fn while_a_rate_step_is_waited_out_captures_are_expected_from_the_last_jump() {
        // The PLL gives way to an RC oscillator 8 % slow: each read's
        // capture then lands 80 µs further from the anchor's prediction,
        // past half a 4 kHz period (125 µs) by the second jump; from the
        // last jump it stays within one read's step.
        let mut c = ChipClock::new();
        let mut b = 0u32;
        for k in 0..200u32 {
            b += 1000;
            c.observe(k * 1000, b);
        }
        for k in 200..202u32 {
            b += 1080;
            let s = k * 1000;
            let expected = c.expected_us(s).unwrap();
            assert!(expected.abs_diff(b) <= 81, "read {k}: {expected} vs {b}");
            c.observe(s, b);
        }
        let s = 202_000;
        b += 1080;
        let anchored = c.board_us(s).unwrap();
        assert!(b.abs_diff(anchored) > 125, "{anchored} vs {b}");
        assert!(c.expected_us(s).unwrap().abs_diff(b) <= 81);
        c.observe(s, b);
        assert_eq!(c.lost, 0);
    }

    #[test]
    fn stamp_at_inverts_board_us() {
        let mut c = ChipClock::new();
        for k in 0..200u32 {
            c.observe(k * 1000, 7_000 + (k as f64 * 1000.0 / 1.01) as u32);
        }
        for s in [150_000u32, 199_000, 500_000] {
            let b = c.board_us(s).unwrap();
            assert!(c.stamp_at(b).unwrap().abs_diff(s) <= 2, "{s}");
        }
    }

    #[test]
    fn chip_instant_inverts_board_instant16() {
        let mut c = ChipClock::new();
        for k in 0..200u32 {
            c.observe(k * 500, 7_000 + (k as f64 * 500.0 / 0.93) as u32);
        }
        // Instants a few ms either side of the anchor, in 1/16 µs.
        for chip16 in [
            199 * 500 * 16 - 40_000,
            199 * 500 * 16 + 7,
            199 * 500 * 16 + 9_999,
        ] {
            let b = c.board_instant16(chip16).unwrap();
            let back = c.chip_instant(b).unwrap();
            assert!(since(back, chip16).abs() <= 1, "{chip16}: {back}");
        }
    }

    #[test]
    fn stamps_and_board_time_wrap() {
        let mut c = ChipClock::new();
        let s0 = u32::MAX - 50_000;
        let b0 = u32::MAX - 30_000;
        for k in 0..200u32 {
            c.observe(s0.wrapping_add(k * 1000), b0.wrapping_add(k * 1000));
        }
        let s = s0.wrapping_add(199 * 1000);
        let want = b0.wrapping_add(199 * 1000).wrapping_mul(16);
        assert!(since(c.board_instant(s).unwrap(), want).abs() <= 12);
    }
}
