//! Levenberg–Marquardt on the rates of a fit that the grid missed, and the dense least
//! squares solve it takes its steps with.

use super::{design, values, Lags};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::{factor, solve};
use faer::{Conj, Mat, Par};

/// Levenberg–Marquardt on min Σ_rows (r(s_l) − Σ a_i e^{−b_i s_l})² over the weights a_i and
/// the logarithms of the positive rates θ_i = ln b_i (a constant term keeps b = 0), with
/// Marquardt's column scaling; a step is taken only if it lowers the sum and keeps every
/// a_i > 0, so the fit stays a positive sum of exponentials.
pub(super) fn polish(lags: &Lags, rows: &[usize], terms: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let y = values(lags, rows);
    let m = rows.len();
    let model = |terms: &[(f64, f64)]| -> (Mat<f64>, f64) {
        let rates: Vec<f64> = terms.iter().map(|t| t.1).collect();
        let e = design(lags, rows, &rates);
        let res = (0..m)
            .map(|i| {
                y[i] - (0..terms.len())
                    .map(|j| terms[j].0 * e[(i, j)])
                    .sum::<f64>()
            })
            .map(|r| r * r)
            .sum();
        (e, res)
    };
    let mut cur = terms.to_vec();
    let (mut e, mut cost) = model(&cur);
    let mut lambda: f64 = 1e-3;
    for _ in 0..200 {
        let free: Vec<usize> = (0..cur.len()).filter(|&j| cur[j].1 > 0.0).collect();
        let n = cur.len() + free.len();
        let mut jac = Mat::<f64>::zeros(m + n, n);
        let mut rhs = vec![0.0; m + n];
        for i in 0..m {
            let s = lags.lag(rows[i]) as f64 * lags.k;
            let mut fit = 0.0;
            for (j, t) in cur.iter().enumerate() {
                jac[(i, j)] = e[(i, j)];
                fit += t.0 * e[(i, j)];
            }
            for (c, &j) in free.iter().enumerate() {
                jac[(i, cur.len() + c)] = -cur[j].0 * cur[j].1 * s * e[(i, j)];
            }
            rhs[i] = y[i] - fit;
        }
        for c in 0..n {
            let norm = (0..m).map(|i| jac[(i, c)].powi(2)).sum::<f64>().sqrt();
            jac[(m + c, c)] = lambda.sqrt() * norm.max(f64::MIN_POSITIVE);
        }
        let step = lstsq(&jac, &(0..n).collect::<Vec<_>>(), &rhs);
        let mut next = cur.clone();
        for (j, t) in next.iter_mut().enumerate() {
            t.0 += step[j];
        }
        for (c, &j) in free.iter().enumerate() {
            next[j].1 *= step[cur.len() + c].exp();
        }
        let trial = next
            .iter()
            .all(|t| t.0 > 0.0 && t.1.is_finite())
            .then(|| model(&next));
        match trial {
            Some((e_next, c_next)) if c_next < cost => {
                let done = cost - c_next <= 1e-12 * cost;
                (cur, e, cost) = (next, e_next, c_next);
                lambda = (lambda / 3.0).max(1e-12);
                if done {
                    break;
                }
            }
            _ => {
                lambda *= 4.0;
                if lambda > 1e12 {
                    break;
                }
            }
        }
    }
    cur.sort_by(|p, q| q.1.total_cmp(&p.1));
    cur
}

/// The least squares solution on the columns `cols` of `a`.
fn lstsq(a: &Mat<f64>, cols: &[usize], y: &[f64]) -> Vec<f64> {
    let m = a.nrows();
    let p = cols.len();
    let mut qr = Mat::from_fn(m, p, |i, j| a[(i, cols[j])]);
    let block = factor::recommended_block_size::<f64>(m, p);
    let mut coeff = Mat::<f64>::zeros(block, p.min(m));
    let par = Par::Seq;
    let mut buf = MemBuffer::new(
        factor::qr_in_place_scratch::<f64>(m, p, block, par, Default::default()).or(
            solve::solve_lstsq_in_place_scratch::<f64>(m, p, block, 1, par),
        ),
    );
    let stack = MemStack::new(&mut buf);
    factor::qr_in_place(qr.as_mut(), coeff.as_mut(), par, stack, Default::default());
    let mut rhs = Mat::from_fn(m, 1, |i, _| y[i]);
    solve::solve_lstsq_in_place_with_conj(
        qr.as_ref(),
        coeff.as_ref(),
        qr.as_ref(),
        Conj::No,
        rhs.as_mut(),
        par,
        stack,
    );
    (0..p).map(|i| rhs[(i, 0)]).collect()
}
