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
        }
    }

    /// Largest averaging factor with at least one term for `n` phase
    /// points.
    pub fn max_factor(self, n: usize) -> usize {
        match self {
            Kind::Adev | Kind::Oadev | Kind::Totdev => n.saturating_sub(1) / 2,
            Kind::Mdev | Kind::Tdev | Kind::Hdev | Kind::Ohdev => n.saturating_sub(1) / 3,
        }
    }
}
