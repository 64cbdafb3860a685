//! The deviations the tool computes, by name: what `dev` computes and
//! `edf` gives the degrees of freedom of (both depend on this, not on each
//! other).

/// The deviations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// Allan, non-overlapping.
    Adev,
    /// Overlapping Allan.
    Oadev,
    /// Modified Allan.
    Mdev,
    /// Time deviation, τ/√3 · MDEV (in the phase's unit).
    Tdev,
    /// Hadamard, non-overlapping.
    Hdev,
    /// Overlapping Hadamard.
    Ohdev,
    /// Total (reflected extension of the phase).
    Totdev,
    /// Modified total: MDEV over each 3m-point stretch of the phase with
    /// its linear trend taken out, extended by even reflection to 9m
    /// (SP 1065 eq. 27, Howe 1999).
    Mtotdev,
    /// Time total: τ/√3 · MTOTDEV (in the phase's unit).
    Ttotdev,
    /// Hadamard total: the same extension on the rate, Hadamard
    /// differences (SP 1065 eq. 29); OHDEV at m = 1.
    Htotdev,
    /// Maximum time interval error: the largest peak-to-peak excursion of
    /// the phase over any window of m + 1 points (in the phase's unit; for
    /// a gyro, the angle).
    Mtie,
    /// Time interval error, RMS: √⟨(x[i + m] − x[i])²⟩ (in the phase's
    /// unit).
    Tierms,
    /// Theo1 (Howe & Peppar; SP 1065 eq. 30) at even factors m; its
    /// averaging time is 0.75 m τ0, reported at m τ0 as allantools does.
    Theo1,
    /// Bias-removed Theo1 (Howe & Tasset; SP 1065 eq. 31): Theo1 times the
    /// mean ratio of OAVAR to Theo1 at the same averaging times over the
    /// record's first tenth; at Theo1's factors, reported as Theo1 is.
    Theobr,
    /// TheoH (SP 1065 eq. 32): OADEV up to a tenth of the record, TheoBR
    /// beyond, each point at its own averaging time m τ0 (there TheoBR at
    /// Theo1 factor 4m/3: m a multiple of 3).
    Theoh,
}

impl Kind {
    /// The deviation of lower-case name `name` ([`Kind::name`], the
    /// command line's value).
    pub fn from_name(name: &str) -> Option<Kind> {
        <Kind as clap::ValueEnum>::from_str(name, false).ok()
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Adev => "adev",
            Kind::Oadev => "oadev",
            Kind::Mdev => "mdev",
            Kind::Tdev => "tdev",
            Kind::Hdev => "hdev",
            Kind::Ohdev => "ohdev",
            Kind::Totdev => "totdev",
            Kind::Mtotdev => "mtotdev",
            Kind::Ttotdev => "ttotdev",
            Kind::Htotdev => "htotdev",
            Kind::Mtie => "mtie",
            Kind::Tierms => "tierms",
            Kind::Theo1 => "theo1",
            Kind::Theobr => "theobr",
            Kind::Theoh => "theoh",
        }
    }

    /// In the phase's unit (for a gyro, an angle), not the rate's: the
    /// time deviations and the time interval errors.
    pub fn in_phase_unit(self) -> bool {
        matches!(self, Kind::Tdev | Kind::Ttotdev | Kind::Mtie | Kind::Tierms)
    }

    /// Largest averaging factor with at least one term for `n` phase
    /// points.
    pub fn max_factor(self, n: usize) -> usize {
        match self {
            Kind::Adev | Kind::Oadev | Kind::Totdev => n.saturating_sub(1) / 2,
            Kind::Mdev | Kind::Tdev | Kind::Hdev | Kind::Ohdev => n.saturating_sub(1) / 3,
            // One 3m-point stretch of the phase (of the rate for HTOTDEV).
            Kind::Mtotdev | Kind::Ttotdev => n / 3,
            Kind::Htotdev => n.saturating_sub(1) / 3,
            // At least two windows.
            Kind::Mtie | Kind::Tierms => n.saturating_sub(2),
            Kind::Theo1 | Kind::Theobr => n.saturating_sub(1),
            // TheoBR at 4m/3 ≤ n − 1.
            Kind::Theoh => n.saturating_sub(1) * 3 / 4,
        }
    }

    /// Whether it has a value at factor `m` over `n` phase points (Theo1
    /// and TheoBR: even factors only; TheoH beyond a tenth of the record:
    /// multiples of 3; TheoBR, and TheoH there, from
    /// [`THEO_BR_MIN_POINTS`] on).
    pub fn takes_factor(self, m: usize, n: usize) -> bool {
        let ratio = n >= THEO_BR_MIN_POINTS;
        m > 0
            && match self {
                Kind::Theo1 => m.is_multiple_of(2),
                Kind::Theobr => m.is_multiple_of(2) && ratio,
                Kind::Theoh => theoh_is_oadev(m, n) || (m.is_multiple_of(3) && ratio),
                _ => true,
            }
    }
}

impl Kind {
    /// A grid's factor `m` over `n` phase points moved to where the kind
    /// has a value: TheoH's long averaging times are at multiples of 3
    /// (the nearest within [`Kind::max_factor`]); any other, as it is.
    pub fn snap_factor(self, m: usize, n: usize) -> usize {
        if self != Kind::Theoh || theoh_is_oadev(m, n) {
            return m;
        }
        let r = (m + 1) / 3 * 3;
        if r > self.max_factor(n) {
            r.saturating_sub(3)
        } else {
            r
        }
    }
}

/// The fewest phase points TheoBR's bias ratio has a pair in (SP 1065
/// eq. 31: ⌊0.1 N/3 − 3⌋ ≥ 0).
pub const THEO_BR_MIN_POINTS: usize = 90;

/// Whether TheoH's point at factor `m` over `n` phase points is OADEV's:
/// its averaging time within a tenth of the record's span (SP 1065 eq. 32's
/// k, the largest τ ≤ 0.1 T).
pub fn theoh_is_oadev(m: usize, n: usize) -> bool {
    10 * m <= n.saturating_sub(1)
}
