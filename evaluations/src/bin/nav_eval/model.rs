//! The SINS/USBL/DVL error model of seed 001 (the paper's eq. 1–6), linear,
//! 1 s epochs. State (21): δv ENU (m/s), φ ENU (rad), δp ENU (m),
//! ∇ body (m/s²), ε body (rad/s), DVL Markov velocity error body (m/s),
//! DVL scale error (–). The SINS filter uses the first 15; the SINS/DVL
//! filter and the centralized one all 21.
//!
//! Named choices for what the paper left out (SEEDS ambiguity 8): position
//! errors in metres (R_M·δL, R_N·cos L·δλ, δh) rather than radians; speed
//! 2 m/s at heading 45°; the vehicle 100 m below the USBL's ship, which
//! stays at the start (slant range √(d² + 100²)); the DVL Markov
//! correlation time 100 s and its white noise 0.01 m/s; the IMU's random
//! parts as white noise (80 µg per √s, 8 °/h per √s); body frame x right,
//! y forward, z up, C_b^n = R_z(ψ) R_x(θ) R_y(γ).

use nalgebra::{Matrix3, SMatrix, Vector3};

pub const N: usize = 21;
pub const NS: usize = 15;
pub type M = SMatrix<f64, N, N>;
pub type V = SMatrix<f64, N, 1>;

const G: f64 = 9.78;
const W_IE: f64 = 7.292_115e-5;
const R_E: f64 = 6_378_137.0;
const LAT: f64 = 20.0 * std::f64::consts::PI / 180.0;
const DEG: f64 = std::f64::consts::PI / 180.0;
const DEG_H: f64 = DEG / 3600.0;
const UG: f64 = 1e-6 * G;

/// The sensors' and the IMU's error levels.
#[derive(Clone, Copy, Debug)]
pub struct Params {
    /// USBL error, fraction of the slant range (1σ).
    pub usbl_frac: f64,
    /// DVL Markov velocity error σ, body x, y, z (m/s).
    pub dvl_sigma: [f64; 3],
    /// DVL white noise (m/s).
    pub dvl_white: f64,
    /// DVL Markov correlation time (s).
    pub dvl_tau: f64,
    /// DVL scale error σ.
    pub dvl_scale: f64,
    /// Accelerometer constant bias and white noise (m/s², m/s²·√s).
    pub accel_bias: f64,
    pub accel_noise: f64,
    /// Gyro constant drift and white noise (rad/s, rad/s·√s).
    pub gyro_bias: f64,
    pub gyro_noise: f64,
    /// Multiplier of the process noise (the degraded case: ×3).
    pub q_scale: f64,
}

impl Params {
    /// The paper's normal case.
    pub fn normal() -> Self {
        Self {
            usbl_frac: 1e-3,
            dvl_sigma: [0.1, 0.1, 0.2],
            dvl_white: 0.01,
            dvl_tau: 100.0,
            dvl_scale: 0.01,
            accel_bias: 80.0 * UG,
            accel_noise: 80.0 * UG,
            gyro_bias: 8.0 * DEG_H,
            gyro_noise: 8.0 * DEG_H,
            q_scale: 1.0,
        }
    }

    /// The paper's degraded case: USBL 2‰, DVL 0.4/0.8 m/s, process ×3.
    pub fn degraded() -> Self {
        Self {
            usbl_frac: 2e-3,
            dvl_sigma: [0.4, 0.4, 0.8],
            q_scale: 3.0,
            ..Self::normal()
        }
    }

    /// The sensors `k` times worse (USBL, DVL Markov and white noise).
    pub fn sensors_times(self, k: f64) -> Self {
        Self {
            usbl_frac: self.usbl_frac * k,
            dvl_sigma: self.dvl_sigma.map(|s| s * k),
            dvl_white: self.dvl_white * k,
            ..self
        }
    }
}

/// The vehicle's motion: constant velocity, the paper's sea motion.
pub struct Motion {
    pub speed: f64,
    pub heading: f64,
    pub depth: f64,
}

impl Default for Motion {
    fn default() -> Self {
        Self {
            speed: 2.0,
            heading: 45.0 * DEG,
            depth: 100.0,
        }
    }
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v[2], v[1], v[2], 0.0, -v[0], -v[1], v[0], 0.0)
}

/// C_b^n at time t: yaw ψ₀ + 6° sin(2πt/6), pitch 9° sin(2πt/10), roll
/// 6° sin(2πt/8).
pub fn attitude(m: &Motion, t: f64) -> Matrix3<f64> {
    let tau = 2.0 * std::f64::consts::PI;
    let psi = m.heading + 6.0 * DEG * (tau * t / 6.0).sin();
    let th = 9.0 * DEG * (tau * t / 10.0).sin();
    let ga = 6.0 * DEG * (tau * t / 8.0).sin();
    // ψ as a heading (clockwise from north): a rotation of −ψ about up.
    let rz = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), -psi);
    let rx = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), th);
    let ry = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), ga);
    (rz * rx * ry).into_inner()
}

/// Velocity, ENU (m/s).
pub fn velocity(m: &Motion) -> Vector3<f64> {
    Vector3::new(m.speed * m.heading.sin(), m.speed * m.heading.cos(), 0.0)
}

/// One epoch's model: transition, process noise, the two measurements'
/// H and their noise covariances for the given parameters.
pub struct Epoch {
    pub f: M,
    pub q: M,
    pub h_usbl: SMatrix<f64, 3, N>,
    pub r_usbl: Matrix3<f64>,
    pub h_dvl: SMatrix<f64, 3, N>,
    pub r_dvl: Matrix3<f64>,
}

/// The model at epoch k (t = k s) for `p`.
pub fn epoch(m: &Motion, p: &Params, k: usize) -> Epoch {
    let dt = 1.0;
    let t = k as f64 * dt;
    let c = attitude(m, t);
    let v = velocity(m);
    let w_ie = Vector3::new(0.0, W_IE * LAT.cos(), W_IE * LAT.sin());
    let w_en = Vector3::new(-v[1] / R_E, v[0] / R_E, v[0] * LAT.tan() / R_E);
    let w_in = w_ie + w_en;
    let f_n = Vector3::new(0.0, 0.0, G);
    let mut fc = M::zeros();
    fc.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-skew(&(2.0 * w_ie + w_en))));
    fc.fixed_view_mut::<3, 3>(0, 3).copy_from(&skew(&f_n));
    fc.fixed_view_mut::<3, 3>(0, 9).copy_from(&c);
    fc.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-skew(&w_in)));
    fc.fixed_view_mut::<3, 3>(3, 12).copy_from(&(-c));
    // δω_in from the velocity errors.
    fc[(3, 1)] = -1.0 / R_E;
    fc[(4, 0)] = 1.0 / R_E;
    fc[(5, 0)] = LAT.tan() / R_E;
    fc.fixed_view_mut::<3, 3>(6, 0)
        .copy_from(&Matrix3::identity());
    for i in 15..18 {
        fc[(i, i)] = -1.0 / p.dvl_tau;
    }
    let a = fc * dt;
    let f = M::identity() + a + a * a * 0.5;
    let mut q = M::zeros();
    for i in 0..3 {
        q[(i, i)] = p.accel_noise * p.accel_noise * dt * p.q_scale;
        q[(3 + i, 3 + i)] = p.gyro_noise * p.gyro_noise * dt * p.q_scale;
        q[(15 + i, 15 + i)] = 2.0 * p.dvl_sigma[i] * p.dvl_sigma[i] / p.dvl_tau * dt;
    }
    let mut h_usbl = SMatrix::<f64, 3, N>::zeros();
    h_usbl
        .fixed_view_mut::<3, 3>(0, 6)
        .copy_from(&Matrix3::identity());
    let d = v * t;
    let range = (d.norm_squared() + m.depth * m.depth).sqrt();
    let r_usbl = Matrix3::identity() * (p.usbl_frac * range).powi(2);
    let cnb = c.transpose();
    let vb = cnb * v;
    let mut h_dvl = SMatrix::<f64, 3, N>::zeros();
    h_dvl.fixed_view_mut::<3, 3>(0, 0).copy_from(&cnb);
    h_dvl
        .fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-cnb * skew(&v)));
    h_dvl
        .fixed_view_mut::<3, 3>(0, 15)
        .copy_from(&(-Matrix3::identity()));
    h_dvl
        .fixed_view_mut::<3, 3>(0, 18)
        .copy_from(&(-Matrix3::from_diagonal(&vb)));
    let r_dvl = Matrix3::identity() * p.dvl_white * p.dvl_white;
    Epoch {
        f,
        q,
        h_usbl,
        r_usbl,
        h_dvl,
        r_dvl,
    }
}

/// The initial covariance: position 0.1 m (the paper's "0.1 m/s" read as
/// metres), velocity 0.01 m/s, attitude 0.01°, the biases' constant parts,
/// the DVL errors' σ.
pub fn p0(p: &Params) -> M {
    let mut d = [0.0; N];
    for i in 0..3 {
        d[i] = 0.01f64.powi(2);
        d[3 + i] = (0.01 * DEG).powi(2);
        d[6 + i] = 0.1f64.powi(2);
        d[9 + i] = p.accel_bias.powi(2);
        d[12 + i] = p.gyro_bias.powi(2);
        d[15 + i] = p.dvl_sigma[i].powi(2);
        d[18 + i] = p.dvl_scale.powi(2);
    }
    M::from_diagonal(&V::from_row_slice(&d))
}
