//! Empirical mode decomposition (seed 003 eq. 5) and MASM trend-scale
//! detection (eq. 6–7).
//!
//! The sifting follows PyEMD's `EMD` (defaults), so that results can be
//! compared 1:1: "simple" extrema with plateau midpoints, two extrema
//! mirrored at each end (Rilling's rule), not-a-knot cubic-spline envelopes
//! (natural for three points), and its stopping rules, applied from the
//! first sift: an IMF is accepted
//! when its maxima are positive and minima negative, extrema and zero
//! crossings differ by at most one, and one of scaled variance < 0.001,
//! Σ((h_k − h_{k−1})/h_k)² < 0.2 (Huang's SD, Cauchy-type) or energy ratio
//! < 0.2 holds. Sifting is capped (`max_sift`), and so is the IMF count;
//! the decomposition ends when the residue's range is < 0.001 or its L1
//! norm < 0.005, or when it has fewer than three extrema (the trend).
//! Every loop is bounded.

use super::{check_finite, QualifyError, Real};

/// EMD settings (PyEMD's defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmdConfig {
    /// Most sifting iterations per IMF.
    pub max_sift: usize,
    /// Most IMFs.
    pub max_imfs: usize,
    /// Scaled-variance threshold.
    pub svar_thr: f64,
    /// Huang SD threshold.
    pub std_thr: f64,
    /// Energy-ratio threshold.
    pub energy_ratio_thr: f64,
    /// Residue range below which the decomposition ends.
    pub range_thr: f64,
    /// Residue L1 norm below which the decomposition ends.
    pub total_power_thr: f64,
}

impl Default for EmdConfig {
    fn default() -> Self {
        Self {
            max_sift: 1000,
            max_imfs: 16,
            svar_thr: 0.001,
            std_thr: 0.2,
            energy_ratio_thr: 0.2,
            range_thr: 0.001,
            total_power_thr: 0.005,
        }
    }
}

/// Buffer length [`emd`] needs for `n` samples (work area).
pub fn work_len(n: usize) -> usize {
    // residue, imf, old, env max, env min (5n) + extrema positions and
    // values for maxima and minima with 4 mirrored points each (4(n + 4))
    // + spline scratch (4(n + 4)).
    5 * n + 8 * (n + 4)
}

/// Outcome of a decomposition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decomposition {
    /// IMFs written (rows 0..imfs of the output).
    pub imfs: usize,
    /// Whether a non-zero residue follows as row `imfs`.
    pub residue: bool,
    /// Sifting iterations per IMF, capped ones included.
    pub sifts: [u16; 16],
}

/// `twice / 2` rounded half to even (np.round).
fn round_half_even(twice: usize) -> usize {
    let half = twice / 2;
    if twice % 2 == 1 && half % 2 == 1 {
        half + 1
    } else {
        half
    }
}

/// Local extrema (PyEMD "simple"): indices of maxima and minima; returns
/// (maxima, minima, zero crossings).
fn extrema<F: Real>(s: &[F], maxs: &mut [u32], mins: &mut [u32]) -> (usize, usize, usize) {
    let n = s.len();
    let zero = F::of(0.0);
    // Zero crossings: sign changes plus the midpoints of runs of zeros.
    let mut nz = 0;
    for i in 0..n.saturating_sub(1) {
        if s[i] * s[i + 1] < zero {
            nz += 1;
        }
    }
    let mut i = 0;
    while i < n {
        if s[i] == zero {
            while i < n && s[i] == zero {
                i += 1;
            }
            nz += 1;
        } else {
            i += 1;
        }
    }
    let (mut nmax, mut nmin) = (0, 0);
    if n < 3 {
        return (0, 0, nz);
    }
    let d = |i: usize| s[i + 1] - s[i];
    let mut i = 0;
    // Walk the differences; a run of zero differences (a plateau) counts
    // at its rounded midpoint when the slope changes sign across it.
    //
    // Two edge rules of PyEMD 1.10 are kept, so that integer gyro counts
    // decompose as it does: a signal that starts on a plateau judges it
    // against its *last* difference (numpy's d[debs − 1] with debs = 0
    // wraps around), and when the first plateau starts at the second
    // sample it is dropped (its `debs[0] == 1` test, a 1-based leftover).
    // A maximum (`up`) or a minimum at `pos`, while there is room.
    let mut push = |up: bool, pos: usize| {
        let (list, count) = if up {
            (&mut *maxs, &mut nmax)
        } else {
            (&mut *mins, &mut nmin)
        };
        if let Some(slot) = list.get_mut(*count) {
            *slot = pos as u32;
            *count += 1;
        }
    };
    let mut lead = 0;
    while lead < n - 1 && d(lead) == zero {
        lead += 1;
    }
    if lead > 0 && lead < n - 1 {
        let (before, after) = (d(n - 2), d(lead));
        if before * after < zero {
            push(before > zero, round_half_even(lead));
        }
    }
    while i + 1 < n - 1 {
        let d1 = d(i);
        if d1 == zero {
            i += 1;
            continue;
        }
        let mut j = i + 1;
        while j < n - 1 && d(j) == zero {
            j += 1;
        }
        if j >= n - 1 {
            break;
        }
        let d2 = d(j);
        // (i = 0 with a non-zero d(0): the signal does not start on a
        // plateau, so this is its first.)
        let dropped = i == 0 && j > 1;
        if d1 * d2 < zero && !dropped {
            // Plateau samples i+1 ..= j (PyEMD: debs = i+1, fins = j); its
            // extremum is at round((debs + fins)/2), half to even
            // (np.round). Rounding (debs + fins + 1)/2 moved it one sample
            // on every plateau of four or more samples.
            let pos = if j == i + 1 {
                i + 1
            } else {
                round_half_even((i + 1) + j)
            };
            push(d1 > zero, pos);
        }
        i = j;
    }
    (nmax, nmin, nz)
}

/// Mirror `nbsym` = 2 extrema at each end (PyEMD `prepare_points_simple`):
/// writes (positions, values) of the extended maxima and minima.
#[allow(clippy::too_many_arguments)]
fn prepare<'a, F: Real>(
    s: &[F],
    imax: &'a [u32],
    imin: &'a [u32],
    tmax: &mut [F],
    zmax: &mut [F],
    tmin: &mut [F],
    zmin: &mut [F],
) -> Option<(usize, usize)> {
    const NB: usize = 2;
    let n = s.len();
    let (em, en) = (imax.len(), imin.len());
    if em == 0 || en == 0 || n == 0 {
        return None;
    }
    // Every index below is checked: an inconsistent input (extrema outside
    // the signal) gives `None`, the caller's "stop sifting", not a panic.
    let at = |i: usize| s.get(i).copied();
    let sl = |v: &'a [u32], r: core::ops::Range<usize>| v.get(r);
    // Index lists as small fixed arrays (at most NB + 1 entries).
    let rev = |v: &[u32], out: &mut [usize; 4]| -> usize {
        for (o, &x) in out.iter_mut().zip(v.iter().rev()) {
            *o = x as usize;
        }
        v.len().min(4)
    };
    let imax0 = *imax.first()? as usize;
    let imin0 = *imin.first()? as usize;
    let imax_l = *imax.last()? as usize;
    let imin_l = *imin.last()? as usize;
    let (mut lmax, mut lmin, mut rmax, mut rmin) =
        ([0usize; 4], [0usize; 4], [0usize; 4], [0usize; 4]);
    let (mut nlmax, mut nlmin, mut nrmax, mut nrmin);
    let mut lsym;
    if imax0 < imin0 {
        if at(0)? > at(imin0)? {
            nlmax = rev(sl(imax, 1.min(em)..em.min(NB + 1))?, &mut lmax);
            nlmin = rev(sl(imin, 0..en.min(NB))?, &mut lmin);
            lsym = imax0;
        } else {
            nlmax = rev(sl(imax, 0..em.min(NB))?, &mut lmax);
            nlmin = rev(sl(imin, 0..en.min(NB - 1))?, &mut lmin);
            *lmin.get_mut(nlmin)? = 0;
            nlmin += 1;
            lsym = 0;
        }
    } else if at(0)? < at(imax0)? {
        nlmax = rev(sl(imax, 0..em.min(NB))?, &mut lmax);
        nlmin = rev(sl(imin, 1.min(en)..en.min(NB + 1))?, &mut lmin);
        lsym = imin0;
    } else {
        nlmax = rev(sl(imax, 0..em.min(NB - 1))?, &mut lmax);
        *lmax.get_mut(nlmax)? = 0;
        nlmax += 1;
        nlmin = rev(sl(imin, 0..en.min(NB))?, &mut lmin);
        lsym = 0;
    }
    let last = n - 1;
    let mut rsym;
    if imax_l < imin_l {
        if at(last)? < at(imax_l)? {
            nrmax = rev(sl(imax, em.saturating_sub(NB)..em)?, &mut rmax);
            nrmin = rev(sl(imin, en.saturating_sub(NB + 1)..en - 1)?, &mut rmin);
            rsym = imin_l;
        } else {
            // append(ind_max[max(em-NB+1,0):], n-1)[::-1]
            let src = sl(imax, (em + 1).saturating_sub(NB)..em)?;
            rmax[0] = last;
            for (o, &x) in rmax.iter_mut().skip(1).zip(src.iter().rev()) {
                *o = x as usize;
            }
            nrmax = (src.len() + 1).min(4);
            nrmin = rev(sl(imin, en.saturating_sub(NB)..en)?, &mut rmin);
            rsym = last;
        }
    } else if at(last)? > at(imin_l)? {
        nrmax = rev(sl(imax, em.saturating_sub(NB + 1)..em - 1)?, &mut rmax);
        nrmin = rev(sl(imin, en.saturating_sub(NB)..en)?, &mut rmin);
        rsym = imax_l;
    } else {
        nrmax = rev(sl(imax, em.saturating_sub(NB)..em)?, &mut rmax);
        let src = sl(imin, (en + 1).saturating_sub(NB)..en)?;
        rmin[0] = last;
        for (o, &x) in rmin.iter_mut().skip(1).zip(src.iter().rev()) {
            *o = x as usize;
        }
        nrmin = (src.len() + 1).min(4);
        rsym = last;
    }
    // Empty lists fall back to all extrema: cannot happen with ≥ 1 of each
    // and NB = 2 except in degenerate cases; mirror what is there.
    if nlmin == 0 {
        nlmin = rev(sl(imin, 0..en.min(4))?, &mut lmin);
    }
    if nrmin == 0 {
        nrmin = rev(sl(imin, en.saturating_sub(4)..en)?, &mut rmin);
    }
    if nlmax == 0 {
        nlmax = rev(sl(imax, 0..em.min(4))?, &mut lmax);
    }
    if nrmax == 0 {
        nrmax = rev(sl(imax, em.saturating_sub(4)..em)?, &mut rmax);
    }
    let mirror = |sym: usize, i: usize| 2.0 * sym as f64 - i as f64;
    // Mirrored points must fall outside the signal; otherwise mirror about
    // the end sample (PyEMD's second pass).
    if mirror(lsym, lmin[0]) > 0.0 || mirror(lsym, lmax[0]) > 0.0 {
        if lsym == imax0 {
            nlmax = rev(sl(imax, 0..em.min(NB))?, &mut lmax);
        } else {
            nlmin = rev(sl(imin, 0..en.min(NB))?, &mut lmin);
        }
        if lsym == 0 {
            return None;
        }
        lsym = 0;
    }
    let (rmin_end, rmax_end) = (
        *rmin.get(nrmin.checked_sub(1)?)?,
        *rmax.get(nrmax.checked_sub(1)?)?,
    );
    if mirror(rsym, rmin_end) < last as f64 || mirror(rsym, rmax_end) < last as f64 {
        if rsym == imax_l {
            nrmax = rev(sl(imax, em.saturating_sub(NB)..em)?, &mut rmax);
        } else {
            nrmin = rev(sl(imin, en.saturating_sub(NB)..en)?, &mut rmin);
        }
        if rsym == last {
            return None;
        }
        rsym = last;
    }
    let fill =
        |t: &mut [F], z: &mut [F], l: &[usize], inner: &[u32], r: &[usize]| -> Option<usize> {
            let mut c: usize = 0;
            let mut push = |pos: f64, val: F, t: &mut [F], z: &mut [F]| -> Option<()> {
                // Drop a point at the same position as the previous one.
                if let Some(&prev) = c.checked_sub(1).and_then(|p| t.get(p)) {
                    if prev.f64() == pos {
                        return Some(());
                    }
                }
                *t.get_mut(c)? = F::of(pos);
                *z.get_mut(c)? = val;
                c += 1;
                Some(())
            };
            for &i in l {
                push(mirror(lsym, i), at(i)?, t, z)?;
            }
            for &i in inner {
                push(i as f64, at(i as usize)?, t, z)?;
            }
            for &i in r {
                push(mirror(rsym, i), at(i)?, t, z)?;
            }
            Some(c)
        };
    let cmax = fill(tmax, zmax, lmax.get(..nlmax)?, imax, rmax.get(..nrmax)?)?;
    let cmin = fill(tmin, zmin, lmin.get(..nlmin)?, imin, rmin.get(..nrmin)?)?;
    Some((cmax, cmin))
}

/// Cubic spline through (t, z) (not-a-knot for ≥ 4 points, natural for 3)
/// evaluated at 0..n into `out`; `m2` is scratch of ≥ 3·len.
fn spline<F: Real>(t: &[F], z: &[F], out: &mut [F], m2: &mut [F]) -> bool {
    spline_checked(t, z, out, m2).is_some()
}

/// [`spline`] with every index checked (`None` for inconsistent lengths).
fn spline_checked<F: Real>(t: &[F], z: &[F], out: &mut [F], m2: &mut [F]) -> Option<()> {
    let k = t.len();
    if k < 3 || z.len() < k || m2.len() < 3 * k {
        return None;
    }
    let (m, rest) = m2.split_at_mut(k);
    let (cp, dp) = rest.split_at_mut(k);
    let tt = |i: usize| t.get(i).copied();
    let zz = |i: usize| z.get(i).copied();
    let h = |i: usize| Some(tt(i + 1)? - tt(i)?);
    let slope = |i: usize| Some((zz(i + 1)? - zz(i)?) / h(i)?);
    let six = F::of(6.0);
    let two = F::of(2.0);
    let zero = F::of(0.0);
    // Unknowns M_1..M_{k−2}; rows i = 1..k−2: a M_{i−1} + b M_i + c M_{i+1} = r.
    let rows = k - 2;
    for r in 0..rows {
        let i = r + 1;
        let (h0, h1) = (h(i - 1)?, h(i)?);
        let (mut lo, mut di, mut up) = (h0, two * (h0 + h1), h1);
        let rhs = six * (slope(i)? - slope(i - 1)?);
        if k >= 4 {
            // Not-a-knot: M_0 = ((h0 + h1) M_1 − h0 M_2)/h1 on the first row,
            // M_{k−1} = ((h_{k−2} + h_{k−3}) M_{k−2} − h_{k−2} M_{k−3})/h_{k−3} on the last.
            if i == 1 {
                let (g0, g1) = (h(0)?, h(1)?);
                di += lo * (g0 + g1) / g1;
                up -= lo * g0 / g1;
                lo = zero;
            }
            if i == k - 2 {
                let (g2, g3) = (h(k - 2)?, h(k - 3)?);
                di += up * (g2 + g3) / g3;
                lo -= up * g2 / g3;
                up = zero;
            }
        } else {
            // Natural: M_0 = M_{k−1} = 0.
            if i == 1 {
                lo = zero;
            }
            if i == k - 2 {
                up = zero;
            }
        }
        // Thomas forward sweep.
        let (c, d) = match r.checked_sub(1) {
            None => (up / di, rhs / di),
            Some(p) => {
                let (cprev, dprev) = (*cp.get(p)?, *dp.get(p)?);
                let den = di - lo * cprev;
                (up / den, (rhs - lo * dprev) / den)
            }
        };
        *cp.get_mut(r)? = c;
        *dp.get_mut(r)? = d;
    }
    for r in (0..rows).rev() {
        let v = if r + 1 == rows {
            *dp.get(r)?
        } else {
            *dp.get(r)? - *cp.get(r)? * *m.get(r + 2)?
        };
        *m.get_mut(r + 1)? = v;
    }
    let (first, last) = if k >= 4 {
        (
            ((h(0)? + h(1)?) * *m.get(1)? - h(0)? * *m.get(2)?) / h(1)?,
            ((h(k - 2)? + h(k - 3)?) * *m.get(k - 2)? - h(k - 2)? * *m.get(k - 3)?) / h(k - 3)?,
        )
    } else {
        (zero, zero)
    };
    *m.get_mut(0)? = first;
    *m.get_mut(k - 1)? = last;
    let mut seg = 0;
    for (x, o) in out.iter_mut().enumerate() {
        let x = F::of(x as f64);
        while seg + 2 < k && x > tt(seg + 1)? {
            seg += 1;
        }
        let hi = h(seg)?;
        let (u, v) = (tt(seg + 1)? - x, x - tt(seg)?);
        let (m0, m1) = (*m.get(seg)?, *m.get(seg + 1)?);
        *o = m0 * u * u * u / (six * hi)
            + m1 * v * v * v / (six * hi)
            + (zz(seg)? / hi - m0 * hi / six) * u
            + (zz(seg + 1)? / hi - m1 * hi / six) * v;
    }
    Some(())
}

/// Decompose `x` into IMFs (rows of `n` samples in `out`, then the residue
/// if it is not ≈ 0). `out` needs `(max_imfs + 1)·n`, `work` [`work_len`],
/// `idx` n entries (extremum indices).
pub fn emd<F: Real>(
    x: &[F],
    cfg: &EmdConfig,
    out: &mut [F],
    work: &mut [F],
    idx: &mut [u32],
) -> Result<Decomposition, QualifyError> {
    let n = x.len();
    if n < 4 {
        return Err(QualifyError::TooShort);
    }
    check_finite(x)?;
    let max_imfs = cfg.max_imfs.min(16);
    if max_imfs == 0 || cfg.max_sift == 0 {
        return Err(QualifyError::Parameter);
    }
    if out.len() < (max_imfs + 1) * n || work.len() < work_len(n) || idx.len() < n {
        return Err(QualifyError::Buffer);
    }
    let (residue, w) = work.split_at_mut(n);
    let (imf, w) = w.split_at_mut(n);
    let (old, w) = w.split_at_mut(n);
    let (emax, w) = w.split_at_mut(n);
    let (emin, w) = w.split_at_mut(n);
    let (tmax, w) = w.split_at_mut(n + 4);
    let (zmax, w) = w.split_at_mut(n + 4);
    let (tmin, w) = w.split_at_mut(n + 4);
    let (zmin, w) = w.split_at_mut(n + 4);
    let scratch = w;
    let (idx_max, idx_min) = idx
        .get_mut(..n)
        .ok_or(QualifyError::Buffer)?
        .split_at_mut(n / 2);
    let mut dec = Decomposition {
        imfs: 0,
        residue: false,
        sifts: [0; 16],
    };
    let mut ext_no;
    residue.copy_from_slice(x);
    let mut finished = false;
    let zero = F::of(0.0);
    let mut last_ext_no = 0;
    while !finished && dec.imfs < max_imfs {
        // residue = x − Σ IMFs so far
        residue.copy_from_slice(x);
        for row in out.chunks_exact(n).take(dec.imfs) {
            for (v, o) in residue.iter_mut().zip(row) {
                *v -= *o;
            }
        }
        imf.copy_from_slice(residue);
        let mut it = 0;
        loop {
            it += 1;
            if it >= cfg.max_sift {
                break;
            }
            let (nmax, nmin, _) = extrema(imf, idx_max, idx_min);
            ext_no = nmax + nmin;
            last_ext_no = ext_no;
            if ext_no <= 2 {
                finished = true;
                break;
            }
            let (Some(im), Some(in_)) = (idx_max.get(..nmax), idx_min.get(..nmin)) else {
                finished = true;
                break;
            };
            let Some((cmax, cmin)) = prepare(imf, im, in_, tmax, zmax, tmin, zmin) else {
                finished = true;
                break;
            };
            let (Some(tx), Some(zx), Some(tn), Some(zn)) = (
                tmax.get(..cmax),
                zmax.get(..cmax),
                tmin.get(..cmin),
                zmin.get(..cmin),
            ) else {
                finished = true;
                break;
            };
            if !spline(tx, zx, emax, scratch) || !spline(tn, zn, emin, scratch) {
                finished = true;
                break;
            }
            // PyEMD's IMF test uses the extended extrema of this pass.
            let signs_ok = zx.iter().all(|v| !(*v < zero)) && zn.iter().all(|v| !(*v > zero));
            old.copy_from_slice(imf);
            for ((v, a), b) in imf.iter_mut().zip(emax.iter()).zip(emin.iter()) {
                *v -= (*a + *b) / F::of(2.0);
            }
            let (nmax2, nmin2, nz) = extrema(imf, idx_max, idx_min);
            let ext2 = nmax2 + nmin2;
            // The stop test applies from the first sift, as PyEMD's (its
            // "imf_old is nan" guard never fires: imf_old is assigned just
            // before it). Skipping it on the first sift made every IMF
            // sift at least twice and split a chirp into 7 rows, not 5.
            let f1 = signs_ok && check_imf(imf, old, cfg);
            let f2 = (ext2 as isize - nz as isize).abs() < 2;
            if f1 && f2 {
                break;
            }
        }
        if dec.imfs < 16 {
            dec.sifts[dec.imfs] = it.min(u16::MAX as usize) as u16;
        }
        if let Some(row) = out.chunks_exact_mut(n).nth(dec.imfs) {
            row.copy_from_slice(imf);
        }
        dec.imfs += 1;
        if end_condition(x, out, dec.imfs, n, cfg) {
            finished = true;
        }
    }
    if last_ext_no <= 2 && dec.imfs > 0 {
        dec.imfs -= 1; // the last "IMF" was the trend
    }
    // Residue = x − Σ IMFs; kept unless ≈ 0 (np.allclose).
    residue.copy_from_slice(x);
    for row in out.chunks_exact(n).take(dec.imfs) {
        for (v, o) in residue.iter_mut().zip(row) {
            *v -= *o;
        }
    }
    dec.residue = residue.iter().any(|v| v.abs() > F::of(1e-8));
    if dec.residue {
        if let Some(row) = out.chunks_exact_mut(n).nth(dec.imfs) {
            row.copy_from_slice(residue);
        }
    }
    Ok(dec)
}

fn check_imf<F: Real>(new: &[F], old: &[F], cfg: &EmdConfig) -> bool {
    let (mut e_new, mut diff2, mut e_old) = (0.0f64, 0.0f64, 0.0f64);
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    let mut sd = 0.0f64;
    for (a, b) in new.iter().zip(old) {
        let (a, b) = (a.f64(), b.f64());
        e_new += a * a;
        e_old += b * b;
        let d = a - b;
        diff2 += d * d;
        lo = lo.min(b);
        hi = hi.max(b);
        sd += (d / a) * (d / a);
    }
    if e_new < 1e-10 {
        return false;
    }
    if diff2 / (hi - lo) < cfg.svar_thr {
        return true;
    }
    if sd < cfg.std_thr {
        return true;
    }
    diff2 / e_old < cfg.energy_ratio_thr
}

fn end_condition<F: Real>(x: &[F], out: &[F], imfs: usize, n: usize, cfg: &EmdConfig) -> bool {
    let (mut lo, mut hi, mut l1) = (f64::MAX, f64::MIN, 0.0f64);
    for (i, xi) in x.iter().enumerate().take(n) {
        let mut v = xi.f64();
        for r in 0..imfs {
            v -= out.get(r * n + i).map_or(0.0, |o| o.f64());
        }
        lo = lo.min(v);
        hi = hi.max(v);
        l1 += v.abs();
    }
    hi - lo < cfg.range_thr || l1 < cfg.total_power_thr
}

/// MASM (eq. 6), reading "standardised mean of the fine-to-coarse partial
/// sums": h_m = mean(Σ_{i≤m} imf_i) / std(Σ_{i≤m} imf_i), m = 1..imfs.
/// `acc` is scratch of n. Writes h into `h[..count]`.
///
/// Errors: `TooShort` for n = 0; `Buffer` when `imfs` holds fewer than
/// `count` rows of n, or `acc` or `h` is too short (they panicked before).
pub fn masm<F: Real>(
    imfs: &[F],
    n: usize,
    count: usize,
    acc: &mut [F],
    h: &mut [F],
) -> Result<(), QualifyError> {
    if n == 0 {
        return Err(QualifyError::TooShort);
    }
    let rows = imfs.chunks_exact(n).take(count);
    let (Some(acc), Some(h)) = (acc.get_mut(..n), h.get_mut(..count)) else {
        return Err(QualifyError::Buffer);
    };
    if rows.len() < count {
        return Err(QualifyError::Buffer);
    }
    check_finite(imfs.get(..count * n).unwrap_or(&[]))?;
    for v in acc.iter_mut() {
        *v = F::of(0.0);
    }
    for (row, hm) in rows.zip(h.iter_mut()) {
        for (a, v) in acc.iter_mut().zip(row) {
            *a += *v;
        }
        let mean = acc.iter().fold(0.0f64, |s, v| s + v.f64()) / n as f64;
        let var = acc
            .iter()
            .fold(0.0f64, |s, v| s + (v.f64() - mean) * (v.f64() - mean))
            / n as f64;
        *hm = F::of(if var > 0.0 {
            mean / libm::sqrt(var)
        } else {
            0.0
        });
    }
    Ok(())
}

/// The trend starts at the first mode m (1-based) where |h_m| exceeds
/// `threshold` (the paper gives none; 0.2 by default in `qualify-eval`).
pub fn trend_start<F: Real>(h: &[F], threshold: f64) -> Option<usize> {
    h.iter()
        .position(|v| v.f64().abs() > threshold)
        .map(|i| i + 1)
}
