//! The products with D = P K_A⁻¹ Pᵀ: the gradient g = D z − d from D's lower triangle.

use super::Team;
use faer::Mat;
use std::ops::Range;

/// D, with its products split over two threads where it is large (`Team`).
pub(super) struct Delassus {
    pub(super) mat: Mat<f64>,
    pub(super) team: Team,
    /// `DualSettings::split_rows`.
    pub(super) split_rows: usize,
}

impl Delassus {
    /// g = D z − d from the lower triangle of D alone: the entry D_ij below the diagonal of
    /// column j serves both (D z)_i (with z_j) and (D z)_j (with z_i), so a product reads half
    /// of D (the multipliers are almost all non-zero: 97% on the 3D block, so skipping zero
    /// columns of the whole D read more). The columns are split into [0, c) and [c, m) with
    /// about as many entries each, c = m(1 − 1/√2); the second part's sums (rows ≥ c) are
    /// added to the first's at the end, so the arithmetic is the same on one thread or two.
    /// (Not more: each entry serves two rows, so every further cut of the columns would
    /// add a partial sum to the rows below it and change their bits, and a cut by rows
    /// would read D twice.)
    pub(super) fn gradient(&self, z: &[f64], d: &[f64], g: &mut [f64]) {
        let m = g.len();
        let c = m - (m as f64 / std::f64::consts::SQRT_2) as usize;
        // The columns `cols`' share of D z, accumulated into y (rows first.. of D z).
        let part = |(cols, y, first): (Range<usize>, &mut [f64], usize)| {
            for j in cols {
                let col = &column(&self.mat, j)[j..];
                let (y_j, y_below) = y[j - first..].split_first_mut().unwrap();
                let below = axpy_dot(&col[1..], z[j], &z[j + 1..], y_below);
                *y_j += col[0] * z[j] + below;
            }
        };
        for (gi, di) in g.iter_mut().zip(d) {
            *gi = -di;
        }
        let mut tail = vec![0.0; m - c];
        let parts = vec![(0..c, &mut *g, 0), (c..m, &mut tail[..], c)];
        self.team.each_if(m >= self.split_rows, parts, part);
        for (gi, ti) in g[c..].iter_mut().zip(&tail) {
            *gi += ti;
        }
    }
}

/// Column j of a dense matrix (faer's owned matrices are column-major).
pub(super) fn column(mat: &Mat<f64>, j: usize) -> &[f64] {
    mat.col(j).try_as_col_major().unwrap().as_slice()
}

/// y += x a, and returns a·v (in four partial sums, so that it vectorizes): the two uses of
/// a column of a symmetric matrix's lower triangle, in one pass over it.
fn axpy_dot(a: &[f64], x: f64, v: &[f64], y: &mut [f64]) -> f64 {
    let n = a.len() / 4 * 4;
    let mut acc = [0.0; 4];
    for ((a, v), y) in a[..n]
        .chunks_exact(4)
        .zip(v[..n].chunks_exact(4))
        .zip(y[..n].chunks_exact_mut(4))
    {
        for k in 0..4 {
            y[k] += x * a[k];
            acc[k] += a[k] * v[k];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for i in n..a.len() {
        y[i] += x * a[i];
        s += a[i] * v[i];
    }
    s
}
