//! Small dense linear algebra for primitive fitting: symmetric eigen-decomposition
//! (cyclic Jacobi), Gaussian elimination and a Levenberg-Marquardt driver. Matrices here
//! are at most 8 x 8, so plain row-major `Vec<f64>` is simpler than pulling nalgebra.

use glam::DVec3;

/// Eigen-decomposition of a symmetric n x n matrix (row-major) by cyclic Jacobi rotations.
/// Returns eigenvalues in ascending order and the matching unit eigenvectors (as rows).
pub(crate) fn sym_eigen(a: &[f64], n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut a = a.to_vec();
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _sweep in 0..64 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for i in 0..n {
            diag += a[i * n + i] * a[i * n + i];
            for j in i + 1..n {
                off += a[i * n + j] * a[i * n + j];
            }
        }
        if off <= 1e-30 * diag.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let akp = a[k * n + p];
                    let akq = a[k * n + q];
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let apk = a[p * n + k];
                    let aqk = a[q * n + k];
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let vkp = v[k * n + p];
                    let vkq = v[k * n + q];
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| a[i * n + i].total_cmp(&a[j * n + j]));
    let values = order.iter().map(|&i| a[i * n + i]).collect();
    let vectors = order
        .iter()
        .map(|&i| (0..n).map(|k| v[k * n + i]).collect())
        .collect();
    (values, vectors)
}

/// Eigen-decomposition of a symmetric 3 x 3 matrix given by its rows: ascending
/// eigenvalues and unit eigenvectors.
pub(crate) fn sym_eigen3(m: [[f64; 3]; 3]) -> ([f64; 3], [DVec3; 3]) {
    let flat: Vec<f64> = m.iter().flatten().copied().collect();
    let (vals, vecs) = sym_eigen(&flat, 3);
    let v = |i: usize| DVec3::new(vecs[i][0], vecs[i][1], vecs[i][2]);
    ([vals[0], vals[1], vals[2]], [v(0), v(1), v(2)])
}

/// Solves `a x = b` (a: n x n row-major) by Gaussian elimination with partial pivoting.
/// `None` when singular.
pub(crate) fn solve(mut a: Vec<f64>, mut b: Vec<f64>, n: usize) -> Option<Vec<f64>> {
    for col in 0..n {
        let piv =
            (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs()))?;
        if a[piv * n + col].abs() < 1e-300 || !a[piv * n + col].is_finite() {
            return None;
        }
        if piv != col {
            for k in 0..n {
                a.swap(piv * n + k, col * n + k);
            }
            b.swap(piv, col);
        }
        for r in col + 1..n {
            let f = a[r * n + col] / a[col * n + col];
            if f != 0.0 {
                for k in col..n {
                    a[r * n + k] -= f * a[col * n + k];
                }
                b[r] -= f * b[col];
            }
        }
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[i * n + k] * x[k];
        }
        x[i] = s / a[i * n + i];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Levenberg-Marquardt on `residuals(params, out)` (m residuals) with a central-difference
/// Jacobian. Parameters should be of order 1 (callers normalise coordinates). Returns the
/// final sum of squared residuals. Deterministic: fixed iteration rules, no randomness.
pub(crate) fn levenberg_marquardt(
    params: &mut [f64],
    m: usize,
    residuals: impl Fn(&[f64], &mut [f64]),
    max_iter: usize,
) -> f64 {
    let n = params.len();
    let mut r = vec![0.0; m];
    let mut r_try = vec![0.0; m];
    let mut rp = vec![0.0; m];
    let cost = |r: &[f64]| r.iter().map(|x| x * x).sum::<f64>();
    residuals(params, &mut r);
    let mut c = cost(&r);
    if !c.is_finite() {
        return c;
    }
    let mut lambda = 1e-3;
    let mut jac = vec![0.0; m * n];
    let mut p_try = params.to_vec();
    for _ in 0..max_iter {
        // Jacobian by forward differences (column j at jac[i * n + j]); the step is
        // sqrt(machine epsilon) relative, accurate to ~1e-8, plenty for Gauss-Newton.
        for j in 0..n {
            let h = 1.5e-8 * (1.0 + params[j].abs());
            p_try.copy_from_slice(params);
            p_try[j] = params[j] + h;
            residuals(&p_try, &mut rp);
            for i in 0..m {
                jac[i * n + j] = (rp[i] - r[i]) / h;
            }
        }
        let mut jtj = vec![0.0; n * n];
        let mut jtr = vec![0.0; n];
        for i in 0..m {
            let row = &jac[i * n..(i + 1) * n];
            for a in 0..n {
                jtr[a] -= row[a] * r[i];
                for b in a..n {
                    jtj[a * n + b] += row[a] * row[b];
                }
            }
        }
        for a in 0..n {
            for b in 0..a {
                jtj[a * n + b] = jtj[b * n + a];
            }
        }
        let mut improved = false;
        for _ in 0..8 {
            let mut damped = jtj.clone();
            for a in 0..n {
                damped[a * n + a] += lambda * (jtj[a * n + a] + 1e-12);
            }
            let Some(step) = solve(damped, jtr.clone(), n) else {
                lambda *= 10.0;
                continue;
            };
            for j in 0..n {
                p_try[j] = params[j] + step[j];
            }
            residuals(&p_try, &mut r_try);
            let c_try = cost(&r_try);
            if c_try.is_finite() && c_try < c {
                let rel = (c - c_try) / c.max(f64::MIN_POSITIVE);
                params.copy_from_slice(&p_try);
                std::mem::swap(&mut r, &mut r_try);
                c = c_try;
                lambda = (lambda * 0.3).max(1e-12);
                improved = true;
                if rel < 1e-8 {
                    return c;
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved || c < 1e-28 {
            break;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigen_reconstructs() {
        let m = [[4.0, 1.0, -2.0], [1.0, 2.0, 0.5], [-2.0, 0.5, 3.0]];
        let (vals, vecs) = sym_eigen3(m);
        assert!(vals[0] <= vals[1] && vals[1] <= vals[2]);
        for k in 0..3 {
            let v = vecs[k];
            let mv = DVec3::new(
                m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
                m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
                m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
            );
            assert!((mv - vals[k] * v).length() < 1e-12);
            assert!((v.length() - 1.0).abs() < 1e-12);
        }
        // Trace is preserved.
        assert!((vals.iter().sum::<f64>() - 9.0).abs() < 1e-12);
    }

    #[test]
    fn solve_and_lm() {
        let x = solve(vec![2.0, 1.0, 1.0, 3.0], vec![3.0, 5.0], 2).unwrap();
        assert!((x[0] - 0.8).abs() < 1e-14 && (x[1] - 1.4).abs() < 1e-14);
        assert!(solve(vec![1.0, 2.0, 2.0, 4.0], vec![1.0, 1.0], 2).is_none());
        // Fit y = a exp(b t).
        let ts: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
        let mut p = [1.0, 0.0];
        let c = levenberg_marquardt(
            &mut p,
            ts.len(),
            |p, out| {
                for (o, &t) in out.iter_mut().zip(&ts) {
                    *o = p[0] * (p[1] * t).exp() - 2.5 * (-0.7 * t).exp();
                }
            },
            100,
        );
        assert!(c < 1e-20, "{c}");
        assert!((p[0] - 2.5).abs() < 1e-8 && (p[1] + 0.7).abs() < 1e-8);
    }
}
