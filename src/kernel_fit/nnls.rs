//! Non-negative least squares for the weights of a fit on a grid of rates.

use super::polish::lstsq;
use faer::Mat;

/// Non-negative least squares min ‖A x − y‖₂, x ≥ 0, by Lawson and Hanson's active set
/// method (Solving Least Squares Problems, 1974, ch. 23). No maintained Rust crate offers it
/// on faer matrices; each passive-set subproblem is a dense least squares solve by faer's
/// Householder QR (sequential, hence deterministic).
pub(super) fn nnls(a: &Mat<f64>, y: &[f64]) -> Vec<f64> {
    let (m, n) = (a.nrows(), a.ncols());
    let mut x = vec![0.0; n];
    let mut passive = vec![false; n];
    // w = Aᵀ(y − A x): the negative gradient, with the residual y − A x in double-double
    // arithmetic. The columns are nearly dependent, so near the optimum the gradient of a
    // residual of 1e-9 is ~1e-17: a residual rounded to double (error ~1e-16 per row) would
    // drown it and stop the active set method early (measured: 2e-9 instead of 1e-11 on
    // s^(−0.2), T/k = 10^6). A gradient within the rounding of its dot products (tol) is
    // taken as zero.
    let gradient = |x: &[f64]| -> (Vec<f64>, f64) {
        let res: Vec<f64> = (0..m)
            .map(|i| {
                let (mut hi, mut lo) = (y[i], 0.0);
                for j in 0..n {
                    // TwoProduct and TwoSum: −a_ij x_j added without rounding error.
                    let p = -a[(i, j)] * x[j];
                    let p_err = (-a[(i, j)]).mul_add(x[j], -p);
                    let s = hi + p;
                    let bb = s - hi;
                    lo += (hi - (s - bb)) + (p - bb) + p_err;
                    hi = s;
                }
                hi + lo
            })
            .collect();
        let w = (0..n)
            .map(|j| (0..m).map(|i| a[(i, j)] * res[i]).sum())
            .collect();
        let tol = 16.0 * f64::EPSILON * m as f64 * res.iter().fold(0.0f64, |t, r| t.max(r.abs()));
        (w, tol)
    };
    for _ in 0..3 * n {
        // A passive set as large as the number of rows already interpolates y (and a larger
        // one would make the least squares problem underdetermined: few lags, many rates).
        if passive.iter().filter(|&&p| p).count() >= m {
            break;
        }
        let (w, tol) = gradient(&x);
        let Some(j) = (0..n)
            .filter(|&j| !passive[j] && w[j] > tol)
            .max_by(|&p, &q| w[p].total_cmp(&w[q]))
        else {
            break;
        };
        passive[j] = true;
        loop {
            let cols: Vec<usize> = (0..n).filter(|&j| passive[j]).collect();
            let z = lstsq(a, &cols, y);
            if z.iter().all(|&v| v > 0.0) {
                for (&c, &v) in cols.iter().zip(&z) {
                    x[c] = v;
                }
                break;
            }
            // Step from x towards z until the first passive weight reaches zero.
            let alpha = cols
                .iter()
                .zip(&z)
                .filter(|(_, &v)| v <= 0.0)
                .map(|(&c, &v)| x[c] / (x[c] - v))
                .fold(f64::INFINITY, f64::min);
            for (&c, &v) in cols.iter().zip(&z) {
                let blocking = v <= 0.0 && x[c] / (x[c] - v) <= alpha;
                x[c] += alpha * (v - x[c]);
                if blocking || x[c] <= 0.0 {
                    x[c] = 0.0;
                    passive[c] = false;
                }
            }
            if !passive.iter().any(|&p| p) {
                break;
            }
        }
    }
    x
}
