//! The products with D = P K_A⁻¹ Pᵀ: the gradient g = D z − d from D's lower triangle; the
//! same product serves the large Newton matrices' conjugate gradients (`newton::pcg`).

use super::{blocks, Team};
use faer::Mat;
use std::ops::Range;

/// D, with its products split over the threads where it is large (`Team`).
pub(super) struct Delassus {
    pub(super) mat: Mat<f64>,
    pub(super) team: Team,
    /// `DualSettings::split_rows`.
    pub(super) split_rows: usize,
}

/// From this many rows D's columns are cut into `MANY_PARTS` parts, below it into two: a
/// property of the problem, not of the machine, so the bits do not depend on the threads.
/// Two parts keep the bits of every scene below it as they were (the golden scenes' m are
/// all smaller); eight let up to eight threads share a product (at m = 1 850, the block at
/// h = 1/24, a product reads 13.7 MB).
const MANY_FROM: usize = 1024;
const MANY_PARTS: usize = 8;

impl Delassus {
    /// g = D z − d from the lower triangle of D alone: the entry D_ij below the diagonal of
    /// column j serves both (D z)_i (with z_j) and (D z)_j (with z_i), so a product reads half
    /// of D (the multipliers are almost all non-zero: 97% on the 3D block, so skipping zero
    /// columns of the whole D read more). The columns are cut into K parts [c_k, c_k+1)
    /// with about as many entries each, c_k = m − m √((K − k)/K) (K = 2, or `MANY_PARTS` from
    /// `MANY_FROM` rows); part k ≥ 1 sums its rows (≥ c_k) in a vector of its own, added to
    /// g in the order of k at the end, so the arithmetic depends on m alone, not on how many
    /// threads run the parts. (Each entry serves two rows, so a cut of the columns adds a
    /// partial sum to the rows below it; a cut by rows would read D twice.)
    pub(super) fn gradient(&self, z: &[f64], d: &[f64], g: &mut [f64]) {
        lower_product(&self.mat, &self.team, self.split_rows, z, d, g);
    }
}

/// g = M z − d for the symmetric M in `mat`'s lower triangle, as `Delassus::gradient` says,
/// on `team`'s threads from `split_rows` rows on.
pub(super) fn lower_product(
    mat: &Mat<f64>,
    team: &Team,
    split_rows: usize,
    z: &[f64],
    d: &[f64],
    g: &mut [f64],
) {
    let m = g.len();
    let parts = if m >= MANY_FROM { MANY_PARTS } else { 2 };
    let cuts: Vec<usize> = (0..=parts)
        .map(|k| match k {
            0 => 0,
            k if k == parts => m,
            k => m - (m as f64 / (parts as f64 / (parts - k) as f64).sqrt()) as usize,
        })
        .collect();
    let cut = |k: usize| cuts[k];
    // The columns `cols`' share of M z, accumulated into y (rows first.. of M z).
    let part = |cols: Range<usize>, y: &mut [f64], first: usize| {
        for j in cols {
            let col = &column(mat, j)[j..];
            let (y_j, y_below) = y[j - first..].split_first_mut().unwrap();
            let below = axpy_dot(&col[1..], z[j], &z[j + 1..], y_below);
            *y_j += col[0] * z[j] + below;
        }
    };
    for (gi, di) in g.iter_mut().zip(d) {
        *gi = -di;
    }
    let mut tails: Vec<Vec<f64>> = (1..parts).map(|k| vec![0.0; m - cut(k)]).collect();
    let mut ys: Vec<(usize, &mut [f64])> = vec![(0, &mut *g)];
    ys.extend((1..parts).zip(tails.iter_mut().map(|t| &mut t[..])));
    // The parts in as many consecutive groups as the team runs pieces.
    let large = m >= split_rows;
    let mut groups: Vec<Vec<(usize, &mut [f64])>> = Vec::new();
    let mut ys = ys.into_iter();
    for range in blocks(parts, team.pieces(large)) {
        groups.push(ys.by_ref().take(range.len()).collect());
    }
    team.each_if(large, groups, |group| {
        for (k, y) in group {
            part(cut(k)..cut(k + 1), y, cut(k));
        }
    });
    for (k, tail) in (1..parts).zip(&tails) {
        for (gi, ti) in g[cut(k)..].iter_mut().zip(tail) {
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
