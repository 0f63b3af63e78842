//! Non-negative least squares for the weights of a fit on a grid of rates, in double-double
//! arithmetic.
//!
//! min ‖A x − y‖₂ over x ≥ 0 by Lawson and Hanson's active set method (Solving Least Squares
//! Problems, 1974, ch. 23): the passive set P grows by the column of the largest gradient
//! w_j = a_jᵀ(y − A x) > 0; x moves towards the least squares solution z on P until z > 0,
//! dropping the passive weights that reach zero on the way. No maintained Rust crate offers
//! it. The least squares problem on P is solved by a Householder QR that grows a column at
//! a time and shrinks by undoing the reflections back to the first column removed
//! (`GrowingQr`), so a step costs O(m·|P|) instead of a new factorization.
//!
//! **Why double-double.** The exponential columns are nearly dependent: near the optimum the
//! gradient of a column that would still lower the residual is ~1e-21 where the residual is
//! 1e-11 (measured on s^(−0.3), 10^6 lags, 7 rates per decade). In f64 the weights alone
//! carry a rounding of 1e-16 relative, which puts a gradient of ~1e-17 on the passive
//! columns and stops the method at 3e-11 — although a positive sum on the same grid (the
//! trapezoid rule of s^(−α) = Γ(α)^{−1} ∫ e^{−s eˣ + αx} dx) is good to 3e-13. With the
//! weights, the residual, the gradients and the QR in double-double (~1e-32), the same solve
//! reaches 7e-16. Only the weights returned are rounded to f64.
//!
//! Everything is sequential: the same A and y give the same bits.

use super::dd::Dd;
use faer::Mat;

/// A column whose component off the span of the passive ones is below this fraction of its
/// norm is numerically dependent on them (distinct rates whose one-step decays e^{−b k}
/// round to the same f64 give equal columns) and is not added.
const DEPENDENT: f64 = 1e-24;

/// min ‖A x − y‖₂, x ≥ 0, stopped early once max_i |(y − A x)_i| ≤ `target`: the greedy
/// order adds the columns that matter most first, so stopping at the error asked for keeps
/// the sum short.
pub(super) fn nnls(a: &Mat<f64>, y: &[f64], target: f64) -> Vec<f64> {
    let (m, n) = (a.nrows(), a.ncols());
    let mut x = vec![Dd::ZERO; n];
    let mut passive: Vec<usize> = Vec::new();
    let mut dependent = vec![false; n];
    let mut qr = GrowingQr::new(y);
    // The rounding of a double-double gradient: a smaller one is taken as zero.
    let y_max = y.iter().fold(0.0f64, |t, v| t.max(v.abs()));
    let tol = 16.0 * f64::EPSILON * f64::EPSILON * m as f64 * y_max;
    for _ in 0..3 * n {
        // A passive set as large as the number of rows already interpolates y.
        if passive.len() >= m {
            break;
        }
        let (w, largest) = gradient(a, y, &x);
        if largest <= target {
            break;
        }
        let Some(j) = (0..n)
            .filter(|&j| !dependent[j] && !passive.contains(&j) && w[j] > tol)
            .max_by(|&p, &q| w[p].total_cmp(&w[q]))
        else {
            break;
        };
        if !qr.push(&column(a, j)) {
            dependent[j] = true;
            continue;
        }
        passive.push(j);
        descend(a, &mut qr, &mut passive, &mut x);
    }
    x.iter().map(|v| v.to_f64()).collect()
}

/// Column j of A.
fn column(a: &Mat<f64>, j: usize) -> Vec<Dd> {
    (0..a.nrows()).map(|i| Dd::from(a[(i, j)])).collect()
}

/// w = Aᵀ(y − A x) and max_i |(y − A x)_i|, all in double-double.
fn gradient(a: &Mat<f64>, y: &[f64], x: &[Dd]) -> (Vec<f64>, f64) {
    let active: Vec<usize> = (0..x.len()).filter(|&j| x[j] != Dd::ZERO).collect();
    let residual: Vec<Dd> = (0..a.nrows())
        .map(|i| {
            active
                .iter()
                .fold(Dd::from(y[i]), |r, &j| r - x[j] * Dd::from(a[(i, j)]))
        })
        .collect();
    let w = (0..a.ncols())
        .map(|j| {
            let dot = residual
                .iter()
                .enumerate()
                .fold(Dd::ZERO, |s, (i, &r)| s + r * Dd::from(a[(i, j)]));
            dot.to_f64()
        })
        .collect();
    let largest = residual.iter().fold(0.0f64, |t, r| t.max(r.to_f64().abs()));
    (w, largest)
}

/// Lawson and Hanson's inner loop: z = the least squares solution on P; while some z_j ≤ 0,
/// x steps towards z until the first passive weight reaches zero, and the weights at zero
/// leave P. Ends with x = z > 0 on P.
fn descend(a: &Mat<f64>, qr: &mut GrowingQr, passive: &mut Vec<usize>, x: &mut [Dd]) {
    while !passive.is_empty() {
        let z = qr.solve();
        if z.iter().all(|&v| v > Dd::ZERO) {
            for (&c, &v) in passive.iter().zip(&z) {
                x[c] = v;
            }
            return;
        }
        let ratio = |x: Dd, v: Dd| x / (x - v);
        let alpha = passive
            .iter()
            .zip(&z)
            .filter(|(_, v)| **v <= Dd::ZERO)
            .map(|(&c, &v)| ratio(x[c], v))
            .fold(Dd::from(f64::INFINITY), |p, q| if q < p { q } else { p });
        let mut kept = Vec::with_capacity(passive.len());
        for (&c, &v) in passive.iter().zip(&z) {
            let blocking = v <= Dd::ZERO && ratio(x[c], v) <= alpha;
            x[c] = x[c] + alpha * (v - x[c]);
            if blocking || x[c] <= Dd::ZERO {
                x[c] = Dd::ZERO;
            } else {
                kept.push(c);
            }
        }
        // The QR keeps the columns before the first one removed and takes the rest again.
        let first = passive
            .iter()
            .zip(&kept)
            .position(|(p, k)| p != k)
            .unwrap_or(kept.len());
        qr.truncate(first);
        passive.truncate(first);
        for &c in &kept[first..] {
            if qr.push(&column(a, c)) {
                passive.push(c);
            } else {
                x[c] = Dd::ZERO;
            }
        }
    }
}

/// The Householder QR A_P = Q R of the passive columns in the order they were added, in
/// double-double: the reflections H_k = I − v_k v_kᵀ/τ_k (v_k zero above row k,
/// τ_k = v_kᵀv_k/2), the columns of R, and Qᵀy.
struct GrowingQr {
    reflections: Vec<(Vec<Dd>, Dd)>,
    r: Vec<Vec<Dd>>,
    qty: Vec<Dd>,
}

impl GrowingQr {
    fn new(y: &[f64]) -> GrowingQr {
        GrowingQr {
            reflections: Vec::new(),
            r: Vec::new(),
            qty: y.iter().map(|&v| Dd::from(v)).collect(),
        }
    }

    /// x ← H x for the reflection (v, τ) of column `from`.
    fn reflect((v, tau): &(Vec<Dd>, Dd), x: &mut [Dd], from: usize) {
        let dot = (from..x.len()).fold(Dd::ZERO, |s, i| s + v[i] * x[i]);
        let f = dot / *tau;
        for (xi, &vi) in x[from..].iter_mut().zip(&v[from..]) {
            *xi = *xi - f * vi;
        }
    }

    /// Appends a column; false (and nothing changed) when it is numerically dependent on the
    /// columns already there (or there are as many columns as rows).
    fn push(&mut self, column: &[Dd]) -> bool {
        let p = self.r.len();
        if p >= column.len() {
            return false;
        }
        let mut x = column.to_vec();
        for (k, h) in self.reflections.iter().enumerate() {
            Self::reflect(h, &mut x, k);
        }
        let norm_of =
            |from: usize, x: &[Dd]| x[from..].iter().fold(Dd::ZERO, |s, &v| s + v * v).sqrt();
        let norm = norm_of(p, &x);
        if norm.to_f64() <= DEPENDENT * norm_of(0, column).to_f64() {
            return false;
        }
        // H x = α e_p with α = −sign(x_p)‖x_p..‖: v = x − α e_p below row p, τ = −α v_p.
        let alpha = if x[p] > Dd::ZERO { -norm } else { norm };
        let mut v = x.clone();
        v[..p].fill(Dd::ZERO);
        v[p] = x[p] - alpha;
        let h = (v, -alpha * x[p] + alpha * alpha);
        Self::reflect(&h, &mut self.qty, p);
        let mut r = x[..p].to_vec();
        r.push(alpha);
        self.reflections.push(h);
        self.r.push(r);
        true
    }

    /// Keeps the first `p` columns: the later reflections are undone on Qᵀy in reverse order
    /// (each is its own inverse).
    fn truncate(&mut self, p: usize) {
        while self.r.len() > p {
            let h = self.reflections.pop().expect("one reflection per column");
            self.r.pop();
            Self::reflect(&h, &mut self.qty, self.r.len());
        }
    }

    /// z with R z = (Qᵀy)_{0..p}: the least squares solution on the columns, by back
    /// substitution.
    fn solve(&self) -> Vec<Dd> {
        let p = self.r.len();
        let mut z = self.qty[..p].to_vec();
        for j in (0..p).rev() {
            z[j] = z[j] / self.r[j][j];
            let zj = z[j];
            for (zi, &rij) in z[..j].iter_mut().zip(&self.r[j]) {
                *zi = *zi - rij * zj;
            }
        }
        z
    }
}
