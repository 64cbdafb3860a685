//! Pure algorithms: no hardware, no heap, capacity in the types.

pub mod allan;
pub mod calib;
pub mod davar;
pub mod fusion;
pub mod kalman;
pub mod math;
pub mod mixture;
pub mod predict;
pub mod qualify;
pub mod static_cal;
pub mod stats;
