//! The controller's clock on the board: every instant the board states,
//! also in the antenna controller's own time.
//!
//! The controller sends a pulse (its sync output, into the board's sync
//! input: the pulse's edge captured on the board's µs clock) and then, over
//! the link, the time its own clock read at that pulse
//! ([`super::msg::Op::SyncTime`]). Each pulse and its time make a pair
//! (board µs, controller µs); the tracker fits a line through the last
//! [`WINDOW`] pairs by least squares: the controller's time at the newest
//! pulse, and its clock's rate against the board's (the two crystals' ppm).
//! A line over 16 pulses averages the controller's timestamp jitter down
//! by about four and follows the crystals' slow drift; what it cannot
//! follow (drift that changes within the window) shows in the fit's
//! residuals, which the tracker reports as its error.
//!
//! The time message comes a little after its pulse (through the
//! controller's UART queue); it pairs with the newest pulse captured
//! before it. A pulse whose message was lost is overwritten by the next;
//! a message whose pulse was not captured pairs with the pulse before,
//! a whole period off, and the gate (a pair far from the line) drops it.
//! When no pulse has come for [`LOST_PERIODS`] periods (or no time message
//! for [`STALE_PERIODS`]) the tracker says so ([`SyncState::Lost`]) and
//! states nothing in the controller's clock until pulses come again: the
//! board's own clock is what remains.

use serde::{Deserialize, Serialize};

/// Pairs the line is fitted to.
pub const WINDOW: usize = 16;

/// Pulse periods without a pulse after which the tracker calls the pulse
/// lost.
pub const LOST_PERIODS: u64 = 3;

/// Pulse periods without a pair (pulses still coming, their time messages
/// not) after which the line is no longer trusted: over ten seconds a
/// crystal drifting 10 ppm an hour moves the line by 0.1 µs.
pub const STALE_PERIODS: u64 = 10;

/// Pairs before the line is trusted (two give the rate; the third checks
/// it).
pub const LOCK_PAIRS: usize = 3;

/// A pair further than this from the line (µs), or than 8 times the fit's
/// residual, is not the pulse's: dropped.
const GATE_US: f64 = 500.0;

/// The tracker's state, as the link reports it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SyncState {
    /// No pair yet: instants in the board's clock only.
    #[default]
    Off,
    /// Fewer than [`LOCK_PAIRS`] pairs since the pulse (re)started.
    Acquiring,
    /// The line is fitted: instants are stated in the controller's clock.
    Locked,
    /// No pair for [`LOST_PERIODS`] periods: back on the board's clock.
    Lost,
}

/// The controller's clock as the board tracks it.
#[derive(Clone, Debug, Default)]
pub struct CtrlClock {
    /// (board µs, controller µs) pairs, oldest first.
    pairs: heapless::Deque<(u64, u64), WINDOW>,
    /// The newest pulse captured and not yet paired, board µs.
    pending: Option<u64>,
    /// The newest pulse captured, paired or not.
    last_pulse: u64,
    /// The line: controller µs at `anchor` (board µs), and the rate
    /// (controller µs per board µs, minus 1).
    anchor: u64,
    at_anchor: f64,
    rate: f64,
    /// RMS residual of the fit, µs.
    residual: f64,
    /// The pulse period seen, board µs (the median gap of the window).
    period: u64,
    state: SyncState,
    /// Pairs dropped by the gate.
    pub dropped: u32,
    /// Messages that came with no pulse captured before them.
    pub unpaired: u32,
    /// Pairs dropped in a row: a line started on a wrong pair drops every
    /// right one after it, so after [`RESTART_MISSES`] it starts again.
    misses: u8,
}

/// Pairs dropped in a row before the line starts again from the newest.
const RESTART_MISSES: u8 = 3;

/// The pulse period taken before two pairs have shown it, µs.
const DEFAULT_PERIOD_US: u64 = 1_000_000;

impl CtrlClock {
    /// A tracker with nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Where it is.
    #[must_use]
    pub fn state(&self) -> SyncState {
        self.state
    }

    /// The sync input's edge, captured at `board_us`.
    pub fn pulse(&mut self, board_us: u64) {
        self.pending = Some(board_us);
        self.last_pulse = board_us;
    }

    /// The controller's time at its last pulse: paired with the newest
    /// pulse captured; true when the pair went into the line.
    pub fn time(&mut self, ctrl_us: u64) -> bool {
        let Some(b) = self.pending.take() else {
            self.unpaired = self.unpaired.wrapping_add(1);
            return false;
        };
        if self.pairs.len() >= 2 {
            let off = (self.at(b) - ctrl_us as f64).abs();
            if off > GATE_US.max(8.0 * self.residual) {
                self.dropped = self.dropped.wrapping_add(1);
                self.misses += 1;
                if self.misses < RESTART_MISSES {
                    return false;
                }
                self.pairs.clear();
            }
        }
        self.misses = 0;
        if self.pairs.is_full() {
            self.pairs.pop_front();
        }
        let _ = self.pairs.push_back((b, ctrl_us));
        self.fit();
        true
    }

    /// The board's time is now `board_us`: a pulse that has stopped is
    /// called lost.
    pub fn tick(&mut self, board_us: u64) {
        if !matches!(self.state, SyncState::Locked | SyncState::Acquiring) {
            return;
        }
        let Some(&(last, _)) = self.pairs.back() else {
            return;
        };
        let period = if self.pairs.len() >= 2 {
            self.period.max(1)
        } else {
            DEFAULT_PERIOD_US
        };
        let no_pulse = board_us.saturating_sub(last.max(self.last_pulse)) > LOST_PERIODS * period;
        let no_pair = board_us.saturating_sub(last) > STALE_PERIODS * period;
        if no_pulse || no_pair {
            self.state = SyncState::Lost;
            // Pulses that come again start a new line: the crystals have
            // drifted meanwhile, and the controller may have been reset.
            self.pairs.clear();
            self.pending = None;
        }
    }

    /// `board_us` in the controller's clock, µs, while locked.
    pub fn to_ctrl(&self, board_us: u64) -> Option<u64> {
        (self.state == SyncState::Locked).then(|| libm::round(self.at(board_us)) as u64)
    }

    /// The line's anchor: the newest pulse (board µs), the controller's
    /// time there (µs), its rate against the board's (ppm) and the fit's
    /// RMS residual (µs); `None` before two pairs.
    pub fn line(&self) -> Option<(u64, u64, f32, f32)> {
        (self.pairs.len() >= 2).then(|| {
            (
                self.anchor,
                libm::round(self.at_anchor) as u64,
                (self.rate * 1e6) as f32,
                self.residual as f32,
            )
        })
    }

    fn at(&self, board_us: u64) -> f64 {
        let dx = board_us as i64 - self.anchor as i64;
        self.at_anchor + dx as f64 * (1.0 + self.rate)
    }

    /// The least-squares line through the pairs, in differences from the
    /// newest (f64: at one pulse a second its cost is nothing).
    fn fit(&mut self) {
        let Some(&(b0, c0)) = self.pairs.back() else {
            return;
        };
        let n = self.pairs.len();
        // x: board µs from the newest pulse; y: the controller's µs from
        // its time there, less x (so only the ppm and the jitter are left).
        let xy = |&(b, c): &(u64, u64)| {
            let x = (b as i64 - b0 as i64) as f64;
            (x, (c as i64 - c0 as i64) as f64 - x)
        };
        let (sx, sy) = self
            .pairs
            .iter()
            .map(xy)
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        let (mx, my) = (sx / n as f64, sy / n as f64);
        let (sxx, sxy) = self
            .pairs
            .iter()
            .map(xy)
            .fold((0.0, 0.0), |(a, b), (x, y)| {
                (a + (x - mx) * (x - mx), b + (x - mx) * (y - my))
            });
        let slope = if n >= 2 && sxx > 0.0 { sxy / sxx } else { 0.0 };
        self.anchor = b0;
        self.rate = slope;
        self.at_anchor = c0 as f64 + (my - slope * mx);
        let ss: f64 = self
            .pairs
            .iter()
            .map(xy)
            .map(|(x, y)| {
                let e = y - (my + slope * (x - mx));
                e * e
            })
            .sum();
        self.residual = if n > 2 {
            libm::sqrt(ss / (n - 2) as f64)
        } else {
            0.0
        };
        // The period: the median gap between the pairs.
        let mut gaps: heapless::Vec<u64, WINDOW> = heapless::Vec::new();
        let mut prev = None;
        for &(b, _) in &self.pairs {
            if let Some(p) = prev {
                let _ = gaps.push(b - p);
            }
            prev = Some(b);
        }
        gaps.sort_unstable();
        if let Some(&g) = gaps.get(gaps.len() / 2) {
            self.period = g;
        }
        self.state = if n >= LOCK_PAIRS {
            SyncState::Locked
        } else {
            SyncState::Acquiring
        };
    }
}
