//! Non-negative least squares on the normal equations: minimise
//! ‖b − Ax‖² over x ≥ 0 from G = AᵀA and c = Aᵀb (Lawson & Hanson,
//! *Solving Least Squares Problems*, 1974, ch. 23, algorithm NNLS, in its
//! normal-equations form). The noise model has at most seven columns, so
//! the Gram matrix is all that is ever formed; each column is scaled to a
//! unit diagonal first, since the terms span many decades.

use nalgebra::{DMatrix, DVector};

/// The solution and the residual ‖b − Ax‖² (from `bb` = bᵀb).
pub fn nnls(g: &DMatrix<f64>, c: &DVector<f64>, bb: f64) -> (DVector<f64>, f64) {
    let k = c.len();
    let d: Vec<f64> = (0..k)
        .map(|i| {
            let v = g[(i, i)];
            if v > 0.0 && v.is_finite() {
                v.sqrt()
            } else {
                0.0
            }
        })
        .collect();
    // Scaled problem: G' = D⁻¹GD⁻¹, c' = D⁻¹c, x = D⁻¹x'.
    let gs = DMatrix::from_fn(k, k, |i, j| {
        if d[i] > 0.0 && d[j] > 0.0 {
            g[(i, j)] / (d[i] * d[j])
        } else {
            0.0
        }
    });
    let cs = DVector::from_fn(k, |i, _| if d[i] > 0.0 { c[i] / d[i] } else { 0.0 });
    let mut x = DVector::<f64>::zeros(k);
    let mut passive = vec![false; k];
    // A column that cannot join (collinear with the passive set, or empty).
    let mut barred: Vec<bool> = d.iter().map(|&v| v == 0.0).collect();
    let tol = 1e-12;
    for _ in 0..(3 * k + 10) {
        let w = &cs - &gs * &x;
        let Some(j) = (0..k)
            .filter(|&i| !passive[i] && !barred[i] && w[i] > tol)
            .max_by(|&a, &b| w[a].total_cmp(&w[b]))
        else {
            break;
        };
        passive[j] = true;
        loop {
            let idx: Vec<usize> = (0..k).filter(|&i| passive[i]).collect();
            let Some(z) = solve_on(&gs, &cs, &idx) else {
                // The newcomer made the set singular: it stays out.
                passive[j] = false;
                barred[j] = true;
                break;
            };
            if idx.iter().zip(z.iter()).all(|(_, &v)| v > tol) {
                for (&i, &v) in idx.iter().zip(z.iter()) {
                    x[i] = v;
                }
                break;
            }
            // Step towards z as far as feasibility allows, and drop the
            // variables that reach 0.
            let mut alpha = 1.0f64;
            for (&i, &v) in idx.iter().zip(z.iter()) {
                if v <= tol {
                    let a = x[i] / (x[i] - v);
                    alpha = alpha.min(a);
                }
            }
            for (&i, &v) in idx.iter().zip(z.iter()) {
                x[i] += alpha * (v - x[i]);
                if x[i] <= tol {
                    x[i] = 0.0;
                    passive[i] = false;
                }
            }
        }
    }
    let xs = DVector::from_fn(k, |i, _| if d[i] > 0.0 { x[i] / d[i] } else { 0.0 });
    let rss = bb - 2.0 * xs.dot(c) + xs.dot(&(g * &xs));
    (xs, rss.max(0.0))
}

/// The unconstrained solution on the columns `idx` (None if singular).
fn solve_on(g: &DMatrix<f64>, c: &DVector<f64>, idx: &[usize]) -> Option<Vec<f64>> {
    let n = idx.len();
    let sub = DMatrix::from_fn(n, n, |a, b| g[(idx[a], idx[b])]);
    let rhs = DVector::from_fn(n, |a, _| c[idx[a]]);
    let chol = nalgebra::Cholesky::new(sub)?;
    // A pivot this small: the columns are collinear over these τ.
    if chol.l_dirty().diagonal().iter().any(|&l| l * l < 1e-11) {
        return None;
    }
    Some(chol.solve(&rhs).iter().copied().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against every subset solved directly (the feasible one with the
    /// least residual is the NNLS solution), on random problems.
    #[test]
    fn equals_the_best_feasible_subset() {
        let mut rng = gyro_sim::Rng::new(3);
        for _ in 0..200 {
            let (rows, k) = (12usize, 5usize);
            let a = DMatrix::from_fn(rows, k, |_, _| f64::from(rng.gaussian()));
            let b = DVector::from_fn(rows, |_, _| f64::from(rng.gaussian()));
            let g = a.transpose() * &a;
            let c = a.transpose() * &b;
            let (x, rss) = nnls(&g, &c, b.dot(&b));
            assert!(x.iter().all(|&v| v >= 0.0));
            let direct = (b.clone() - &a * &x).norm_squared();
            assert!((direct - rss).abs() < 1e-9 * (1.0 + direct));
            let mut best = b.dot(&b);
            for mask in 1u32..(1 << k) {
                let idx: Vec<usize> = (0..k).filter(|i| mask & (1 << i) != 0).collect();
                let Some(z) = solve_on(&g, &c, &idx) else {
                    continue;
                };
                if z.iter().all(|&v| v >= 0.0) {
                    let mut xx = DVector::zeros(k);
                    for (&i, &v) in idx.iter().zip(&z) {
                        xx[i] = v;
                    }
                    best = best.min((b.clone() - &a * &xx).norm_squared());
                }
            }
            assert!((rss - best).abs() < 1e-8 * (1.0 + best), "{rss} vs {best}");
        }
    }
}
