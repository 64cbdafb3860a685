//! How an emulated chip sits on the board: its mounting rotation, scale
//! and misalignment as one matrix from board rates to chip rates, its
//! bias-versus-temperature slope, and the die temperature over time. The
//! default is a chip aligned with the board at a constant 25 °C, which
//! leaves every earlier result bit for bit as it was.

use gyro_array::algo::static_cal::mul3;

/// Mounting and temperature terms of one chip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mount {
    /// chip rate = `m` · board rate (rotation × (I + scale/misalignment)).
    pub m: [[f32; 3]; 3],
    /// Bias change per °C away from 25 °C, per chip axis, °/s/°C.
    pub bias_tc_dps_per_c: [f32; 3],
    /// Die temperature over time.
    pub temp: TempProfile,
}

impl Mount {
    /// Aligned with the board, no temperature effect, 25 °C.
    pub const ALIGNED: Self = Self {
        m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        bias_tc_dps_per_c: [0.0; 3],
        temp: TempProfile::ROOM,
    };

    /// Rates in the chip's axes of board-frame rates `w`.
    pub fn chip_rate(&self, w: [f32; 3]) -> [f32; 3] {
        mul3(&self.m, &w)
    }

    /// The bias added by the temperature at `t_s`, per chip axis, and the
    /// temperature.
    pub fn thermal(&self, t_s: f32) -> ([f32; 3], f32) {
        let c = self.temp.at(t_s);
        (self.bias_tc_dps_per_c.map(|k| k * (c - 25.0)), c)
    }
}

impl Default for Mount {
    fn default() -> Self {
        Self::ALIGNED
    }
}

/// Die temperature: `start_c`, then a ramp of `ramp_c_per_s` from
/// `ramp_from_s`, held at `end_c`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TempProfile {
    /// Temperature at power-up, °C.
    pub start_c: f32,
    /// Ramp, °C/s (either sign).
    pub ramp_c_per_s: f32,
    /// When the ramp starts, s.
    pub ramp_from_s: f32,
    /// Where it stops, °C.
    pub end_c: f32,
}

impl TempProfile {
    /// A constant 25 °C.
    pub const ROOM: Self = Self {
        start_c: 25.0,
        ramp_c_per_s: 0.0,
        ramp_from_s: 0.0,
        end_c: 25.0,
    };

    /// A constant temperature.
    pub const fn constant(c: f32) -> Self {
        Self {
            start_c: c,
            ramp_c_per_s: 0.0,
            ramp_from_s: 0.0,
            end_c: c,
        }
    }

    /// Temperature at `t_s`, °C.
    pub fn at(&self, t_s: f32) -> f32 {
        if self.ramp_c_per_s == 0.0 || t_s <= self.ramp_from_s {
            return self.start_c;
        }
        let c = self.start_c + self.ramp_c_per_s * (t_s - self.ramp_from_s);
        if self.ramp_c_per_s > 0.0 {
            c.min(self.end_c)
        } else {
            c.max(self.end_c)
        }
    }
}
