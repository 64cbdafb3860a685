//! The fusion methods of `nav-eval`, each a set of filters stepped once per
//! epoch, each giving a position estimate and its covariance.

use gyro_array::algo::kalman::Kf;
use gyro_array::algo::mixture::{
    covariance_intersection, covariance_weighted, entropy_product, entropy_weights, mixture, reset,
    CovReset, Guard,
};
use nalgebra::{Matrix3, SMatrix, Vector3};

use super::model::{Epoch, M, N, NS};

pub type M15 = SMatrix<f64, NS, NS>;
pub type V15 = SMatrix<f64, NS, 1>;

/// What one epoch measured (None: no measurement this epoch).
pub struct Meas {
    pub usbl: Option<Vector3<f64>>,
    pub dvl: Option<Vector3<f64>>,
}

fn sub15(m: &M) -> M15 {
    m.fixed_view::<NS, NS>(0, 0).into_owned()
}

/// A position estimate and its covariance.
#[derive(Clone, Copy)]
pub struct Est {
    pub p: Vector3<f64>,
    pub cov: Matrix3<f64>,
}

fn est15(x: &V15, p: &M15) -> Est {
    Est {
        p: x.fixed_view::<3, 1>(6, 0).into_owned(),
        cov: p.fixed_view::<3, 3>(6, 6).into_owned(),
    }
}

/// The two local filters: SINS/USBL (15 states) and SINS/DVL (21).
#[derive(Clone, Copy)]
pub struct Pair {
    pub f1: Kf<f64, NS>,
    pub f2: Kf<f64, N>,
    /// The covariances after prediction (for the P(k/k−1) reading).
    pub pred: (M15, M15),
}

impl Pair {
    pub fn new(p0: &M) -> Self {
        let x0 = SMatrix::<f64, N, 1>::zeros();
        let f1 = Kf::new(x0.fixed_view::<NS, 1>(0, 0).into_owned(), sub15(p0)).expect("P0");
        let f2 = Kf::new(x0, *p0).expect("P0");
        Self {
            f1,
            f2,
            pred: (sub15(p0), sub15(p0)),
        }
    }

    /// Predict both, update each with its sensor. A refused step leaves a
    /// filter as it was (counted by the caller as nothing here: the model
    /// keeps every matrix finite and definite).
    pub fn step(&mut self, e: &Epoch, z: &Meas) {
        self.step_shared(e, z, [1.0, 1.0]);
    }

    /// [`Pair::step`] with the common states' process noise shared as in a
    /// federated filter: Q_i = Q/β_i on the 15 common states.
    pub fn step_shared(&mut self, e: &Epoch, z: &Meas, beta: [f64; 2]) {
        let q1 = sub15(&e.q) / beta[0];
        let mut q2 = e.q;
        q2.fixed_view_mut::<NS, NS>(0, 0)
            .copy_from(&(sub15(&e.q) / beta[1]));
        let _ = self.f1.predict(&sub15(&e.f), &q1);
        let _ = self.f2.predict(&e.f, &q2);
        self.pred = (self.f1.p, sub15(&self.f2.p));
        if let Some(u) = z.usbl {
            let h = e.h_usbl.fixed_view::<3, NS>(0, 0).into_owned();
            let _ = self.f1.update(&u, &h, &e.r_usbl);
        }
        if let Some(d) = z.dvl {
            let _ = self.f2.update(&d, &e.h_dvl, &e.r_dvl);
        }
    }

    /// The common 15 states of both.
    pub fn common(&self) -> ([V15; 2], [M15; 2]) {
        (
            [self.f1.x, self.f2.x.fixed_view::<NS, 1>(0, 0).into_owned()],
            [self.f1.p, sub15(&self.f2.p)],
        )
    }

    /// Write fused common states back (the seed's step 4) and, if `ps` is
    /// given, the reset covariances. The SINS/DVL filter's own states (the
    /// DVL errors) follow the change of its common states through their
    /// correlation, as the conditional of the joint Gaussian: with the
    /// common block going from (x_c, A) to (x_c', A') and cross-covariance
    /// B, x_d ← x_d + Bᵀ A⁻¹ (x_c' − x_c), B ← A' A⁻¹ B,
    /// P_dd ← P_dd − Bᵀ A⁻¹ B + Bᵀ A⁻¹ A' A⁻¹ B. P stays definite.
    pub fn write_back(&mut self, xs: &[V15; 2], ps: Option<&[M15; 2]>) {
        self.f1.x = xs[0];
        if let Some(ps) = ps {
            self.f1.p = ps[0];
        }
        let a = sub15(&self.f2.p);
        let Some(chol) = a.cholesky() else {
            return;
        };
        let b = self.f2.p.fixed_view::<NS, 6>(0, NS).into_owned();
        let ainv_b = chol.solve(&b); // A⁻¹ B (15×6)
        let xc = self.f2.x.fixed_view::<NS, 1>(0, 0).into_owned();
        let dx = ainv_b.transpose() * (xs[1] - xc);
        let a_new = ps.map_or(a, |p| p[1]);
        let b_new = a_new * ainv_b;
        let c = self.f2.p.fixed_view::<6, 6>(NS, NS).into_owned();
        let c_new = c - b.transpose() * ainv_b + ainv_b.transpose() * a_new * ainv_b;
        let c_new = (c_new + c_new.transpose()) * 0.5;
        self.f2.x.fixed_view_mut::<NS, 1>(0, 0).copy_from(&xs[1]);
        let xd = self.f2.x.fixed_view::<6, 1>(NS, 0).into_owned() + dx;
        self.f2.x.fixed_view_mut::<6, 1>(NS, 0).copy_from(&xd);
        self.f2.p.fixed_view_mut::<NS, NS>(0, 0).copy_from(&a_new);
        self.f2.p.fixed_view_mut::<NS, 6>(0, NS).copy_from(&b_new);
        self.f2
            .p
            .fixed_view_mut::<6, NS>(NS, 0)
            .copy_from(&b_new.transpose());
        self.f2.p.fixed_view_mut::<6, 6>(NS, NS).copy_from(&c_new);
    }
}

/// σ of the position block in metres, as the seed's entropy takes it:
/// √(trace/3) (ambiguity 3's RMS reading).
pub fn pos_sigma(p: &M15) -> f64 {
    (p.fixed_view::<3, 3>(6, 6).trace() / 3.0).sqrt()
}

/// The seed's entropy-weighted mixture on a pair, its reset rule, and
/// feedback of the fused state, with σ in metres × `unit` (1: metres,
/// 1000: millimetres; ambiguity 1: in metres SH ≤ 0 below 0.242 m and the
/// floor then hands that filter the weight). Returns the estimate, the
/// weights and whether an SH ≤ 0 was met (floored).
pub fn entropy_step(
    pair: &mut Pair,
    rule: CovReset,
    feedback: bool,
    unit: f64,
) -> (Est, [f64; 2], bool) {
    let (xs, ps) = pair.common();
    let sig = [pos_sigma(&ps[0]) * unit, pos_sigma(&ps[1]) * unit];
    let nonpos = sig.iter().any(|&s| entropy_product(s) <= 0.0);
    let alpha = entropy_weights(&sig, Guard::Floor(1e-9)).unwrap_or([0.5, 0.5]);
    let (xm, pm) = mixture(&xs, &ps, &alpha);
    let est = est15(&xm, &pm);
    if feedback || rule != CovReset::None {
        let (mut xr, mut pr) = (xs, ps);
        reset(rule, &mut xr, &mut pr, &(xm, pm), &alpha);
        if feedback {
            xr = [xm, xm];
        }
        let changed = rule != CovReset::None;
        pair.write_back(&xr, changed.then_some(&pr));
    }
    (est, alpha, nonpos)
}

/// The standard federated filter: information fusion, then x_i ← x_g and
/// P_i ← P_g/β_i with β = ½ each.
pub fn federated_step(pair: &mut Pair) -> Est {
    let (xs, ps) = pair.common();
    let Ok(g) = covariance_weighted(&xs, &ps) else {
        return est15(&xs[0], &ps[0]);
    };
    let mut xr = xs;
    let mut pr = ps;
    reset(CovReset::Federated, &mut xr, &mut pr, &g, &[0.5, 0.5]);
    pair.write_back(&xr, Some(&pr));
    est15(&g.0, &g.1)
}

/// The paper's weighted Kalman fusion of an independent pair: P(k/k)
/// weights, or the P(k/k−1) reading (predicted covariances weigh the
/// updated states).
pub fn weighted(pair: &Pair, predicted: bool) -> Est {
    let (xs, ps) = pair.common();
    let wp = if predicted {
        [pair.pred.0, pair.pred.1]
    } else {
        ps
    };
    match covariance_weighted(&xs, &wp) {
        Ok(g) => est15(&g.0, &g.1),
        Err(_) => est15(&xs[0], &ps[0]),
    }
}

/// Covariance intersection of an independent pair.
pub fn ci(pair: &Pair) -> Est {
    let (xs, ps) = pair.common();
    match covariance_intersection(&xs[0], &ps[0], &xs[1], &ps[1]) {
        Ok((x, p, _)) => est15(&x, &p),
        Err(_) => est15(&xs[0], &ps[0]),
    }
}

/// A local filter alone.
pub fn local(pair: &Pair, which: usize) -> Est {
    let (xs, ps) = pair.common();
    est15(&xs[which], &ps[which])
}

/// The centralized filter over both sensors, 21 states.
pub struct Central {
    pub f: Kf<f64, N>,
}

impl Central {
    pub fn new(p0: &M) -> Self {
        Self {
            f: Kf::new(SMatrix::zeros(), *p0).expect("P0"),
        }
    }

    pub fn step(&mut self, e: &Epoch, z: &Meas) -> Est {
        let _ = self.f.predict(&e.f, &e.q);
        if let Some(u) = z.usbl {
            let _ = self.f.update(&u, &e.h_usbl, &e.r_usbl);
        }
        if let Some(d) = z.dvl {
            let _ = self.f.update(&d, &e.h_dvl, &e.r_dvl);
        }
        self.est()
    }

    pub fn est(&self) -> Est {
        Est {
            p: self.f.x.fixed_view::<3, 1>(6, 0).into_owned(),
            cov: self.f.p.fixed_view::<3, 3>(6, 6).into_owned(),
        }
    }
}

/// Ours: the centralized filter, made to survive wrong noise models.
/// Each sensor's error model is trusted up to one scale c ≥ 1 of all its
/// noise: the USBL's R; the DVL's white noise R and its Markov velocity
/// error's process noise (a DVL "k times worse" is worse in both).
/// - c is learnt from the normalised innovation squared (χ²₃ when the
///   model is right, mean 3): c ← c·(1 + (NIS/3 − 1)/50), each NIS/3
///   clipped at 6, so c follows a sensor that is worse than nominal within
///   some 50–100 epochs and a single outlier raises it by 10 % at most.
/// - A reading whose NIS (with the learnt c) exceeds the χ²₃ 99.99 % point
///   (21.1) is refused as an outlier, and counted.
/// - A missing reading is a step without update.
///
/// With correct noise c stays near 1 and this is the centralized filter.
pub struct Ours {
    pub c: Central,
    pub scale: [f64; 2],
    pub refused: u64,
}

const GATE: f64 = 21.108;
const MEMORY: f64 = 50.0;
const CLIP: f64 = 6.0;

impl Ours {
    pub fn new(p0: &M) -> Self {
        Self {
            c: Central::new(p0),
            scale: [1.0, 1.0],
            refused: 0,
        }
    }

    fn learn_and_update(
        f: &mut Kf<f64, N>,
        scale: &mut f64,
        refused: &mut u64,
        z: &Vector3<f64>,
        h: &SMatrix<f64, 3, N>,
        r: &Matrix3<f64>,
    ) {
        let reff = r * *scale;
        let y = z - h * f.x;
        let s = h * f.p * h.transpose() + reff;
        let nis = s
            .cholesky()
            .map_or(f64::INFINITY, |c| (y.transpose() * c.solve(&y))[(0, 0)]);
        *scale = (*scale * (1.0 + ((nis / 3.0).min(CLIP) - 1.0) / MEMORY)).max(1.0);
        if nis > GATE {
            *refused += 1;
            return;
        }
        let _ = f.update(z, h, &reff);
    }

    pub fn step(&mut self, e: &Epoch, z: &Meas) -> Est {
        // The DVL's Markov error driven by c_DVL × its nominal noise.
        let mut q = e.q;
        for i in 15..18 {
            q[(i, i)] *= self.scale[1];
        }
        let _ = self.c.f.predict(&e.f, &q);
        if let Some(u) = z.usbl {
            Self::learn_and_update(
                &mut self.c.f,
                &mut self.scale[0],
                &mut self.refused,
                &u,
                &e.h_usbl,
                &e.r_usbl,
            );
        }
        if let Some(d) = z.dvl {
            Self::learn_and_update(
                &mut self.c.f,
                &mut self.scale[1],
                &mut self.refused,
                &d,
                &e.h_dvl,
                &e.r_dvl,
            );
        }
        self.c.est()
    }
}
