//! The signal path's filters: the anti-alias filter at the 32 kHz internal
//! rate and the UI filter that decimates to the ODR (datasheet section 5),
//! and the delay they add.

use super::*;

/// The gyro's signal path (datasheet section 5): the anti-alias filter
/// (AAF) at the 32 kHz internal rate, then the UI filter that decimates to
/// the ODR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Filter {
    /// GYRO_AAF_DELT: 0 turns the AAF off; otherwise an entry of
    /// datasheet table 17 that [`aaf_coefficients`] knows.
    pub aaf_delt: u8,
    /// GYRO_UI_FILT_ORD as an order, 1..=3.
    pub ui_order: u8,
    /// GYRO_UI_FILT_BW: 0..=7 for ODR/2, /4, /5, /8, /10, /16, /20, /40;
    /// 14 or 15 for the low-latency settings.
    pub ui_bw: u8,
}

impl Filter {
    /// The chip's reset values: AAF at 585 Hz (assumed; see
    /// `gyro_sim::icm42688`), UI filter of 2nd order at ODR/4.
    pub const RESET: Self = Self {
        aaf_delt: 13,
        ui_order: 2,
        ui_bw: 1,
    };
    /// PX4's: AAF at 585 Hz, the UI filter left at reset (run at 8 kHz
    /// there, averaged down in software).
    pub const PX4: Self = Self::RESET;
    /// ArduPilot's at a 1 kHz ODR: AAF at 258 Hz, the UI filter at reset.
    pub const ARDUPILOT: Self = Self {
        aaf_delt: 6,
        ui_order: 2,
        ui_bw: 1,
    };
    /// GYRO_CONFIG1's GYRO_UI_FILT_ORD bits (3:2).
    pub(super) fn order_bits(self) -> u8 {
        (self.ui_order.clamp(1, 3) - 1) << 2
    }
}

/// GYRO_AAF_DELTSQR and GYRO_AAF_BITSHIFT for GYRO_AAF_DELT `delt`
/// (datasheet table 17: DELTSQR is close to DELT² but not always equal),
/// for DELT 1..=56 and 63; `None` for the others, which the driver does
/// not set.
pub fn aaf_coefficients(delt: u8) -> Option<(u16, u8)> {
    const T: [(u16, u8); 56] = [
        (1, 15),
        (4, 13),
        (9, 12),
        (16, 11),
        (25, 10),
        (36, 10),
        (49, 9),
        (64, 9),
        (81, 9),
        (100, 8),
        (122, 8),
        (144, 8),
        (170, 8),
        (196, 7),
        (224, 7),
        (256, 7),
        (288, 7),
        (324, 7),
        (360, 6),
        (400, 6),
        (440, 6),
        (488, 6),
        (528, 6),
        (576, 6),
        (624, 6),
        (680, 6),
        (736, 5),
        (784, 5),
        (848, 5),
        (896, 5),
        (960, 5),
        (1024, 5),
        (1088, 5),
        (1152, 5),
        (1232, 5),
        (1296, 5),
        (1376, 4),
        (1440, 4),
        (1536, 4),
        (1600, 4),
        (1696, 4),
        (1760, 4),
        (1856, 4),
        (1952, 4),
        (2016, 4),
        (2112, 4),
        (2208, 4),
        (2304, 4),
        (2400, 4),
        (2496, 4),
        (2592, 4),
        (2720, 4),
        (2816, 3),
        (2944, 3),
        (3008, 3),
        (3136, 3),
    ];
    match delt {
        1..=56 => Some(T[delt as usize - 1]),
        63 => Some((3968, 3)),
        _ => None,
    }
}

/// Datasheet table 17: GYRO_AAF_DELT against the AAF's 3 dB bandwidth, Hz,
/// at the entries the public drivers quote (1–14, 21, 38, 52, 63).
pub(super) const AAF_TABLE: [(u8, f32); 18] = [
    (1, 42.0),
    (2, 84.0),
    (3, 126.0),
    (4, 170.0),
    (5, 213.0),
    (6, 258.0),
    (7, 303.0),
    (8, 348.0),
    (9, 394.0),
    (10, 441.0),
    (11, 488.0),
    (12, 536.0),
    (13, 585.0),
    (14, 634.0),
    (21, 997.0),
    (38, 2029.0),
    (52, 3057.0),
    (63, 3979.0),
];

/// The AAF's 3 dB bandwidth, Hz, for GYRO_AAF_DELT `delt` (1..=63):
/// table 17, linear between the entries the public drivers quote (the
/// table is within 2 % of linear between them). 0 reads as 1.
pub fn aaf_hz(delt: u8) -> f32 {
    let d = delt.clamp(1, 63);
    let mut prev = AAF_TABLE[0];
    for &(k, hz) in AAF_TABLE.iter() {
        if k == d {
            return hz;
        }
        if k > d {
            let f = (d - prev.0) as f32 / (k - prev.0) as f32;
            return prev.1 + f * (hz - prev.1);
        }
        prev = (k, hz);
    }
    prev.1
}

/// The UI filter's bandwidth divisor for GYRO_UI_FILT_BW (datasheet
/// GYRO_ACCEL_CONFIG0: BW = max(400 Hz, ODR)/k); `None` for the
/// low-latency settings 14 and 15 (and reserved codes), which bypass it.
pub fn ui_divisor(code: u8) -> Option<f32> {
    const K: [f32; 8] = [2.0, 4.0, 5.0, 8.0, 10.0, 16.0, 20.0, 40.0];
    K.get(code as usize).copied()
}

impl Filter {
    /// The signal path's group delay at DC for output rate `odr`, µs: the
    /// AAF as a 2nd-order Butterworth at its table-17 bandwidth (√2/ω) and
    /// the UI filter as a Butterworth of its order at its bandwidth (1/ω,
    /// √2/ω, 2/ω). The datasheet gives bandwidths, not delays; the chip
    /// model's filters are built the same way and their delay is measured
    /// against this (`host-tests/tests/chip_timing.rs`).
    pub fn group_delay_us(&self, odr: Odr) -> f32 {
        let aaf = (self.aaf_delt != 0).then(|| aaf_hz(self.aaf_delt));
        let ui = ui_divisor(self.ui_bw).map(|k| (self.ui_order, odr.hz().max(400.0) / k));
        path_delay_us(aaf, ui)
    }
}

/// The DC group delay of an AAF of 3 dB bandwidth `aaf_hz` (2nd-order
/// Butterworth, √2/ω) followed by a UI filter of (order, bandwidth)
/// `ui` (Butterworth: 1/ω, √2/ω, 2/ω), µs; `None` for a stage that is off.
pub fn path_delay_us(aaf_hz: Option<f32>, ui: Option<(u8, f32)>) -> f32 {
    let w = |hz: f32| 2.0 * core::f32::consts::PI * hz;
    let mut d = 0.0;
    if let Some(a) = aaf_hz {
        d += core::f32::consts::SQRT_2 / w(a);
    }
    if let Some((order, bw)) = ui {
        d += match order {
            0 | 1 => 1.0,
            2 => core::f32::consts::SQRT_2,
            _ => 2.0,
        } / w(bw);
    }
    d * 1e6
}
