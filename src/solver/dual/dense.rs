//! One vector against a dense Newton matrix or its Cholesky factor (the conjugate
//! gradients' products H x and the solves (L Lᵀ)⁻¹ r), on the team's threads from
//! `DualSettings::par_min` rows on, with bits that depend on the size alone.
//!
//! faer's parallel kernels of a single vector split their sums by the thread count
//! (`threads`), so below `par_min` rows these passes are faer's on one thread, as they
//! were. From `par_min` on they are these, the same on any number of threads:
//!
//! - **H x** by blocks of rows: each row's sum runs over the columns in order, whatever
//!   the block.
//! - **L y = r** (forward): in panels of `PANEL` columns, the panel's triangle on one
//!   thread, then the rows below take the panel's columns' updates in column order, in
//!   blocks of rows over the threads. Every row gets its updates in column order: the
//!   bits of the column-oriented substitution, whatever the panels and the blocks.
//! - **Lᵀ x = y** (backward): from the last panel up, the sums of the panel's columns over
//!   the rows below the panel, by blocks of columns over the threads, each column's sum
//!   whole; then the panel's triangle on one thread. A column's sum is cut at its panel's
//!   end, a place fixed by the size.
//!
//! On the plate 0.03 (Newton matrices of up to 2 838 rows) the conjugate gradients were
//! an eighth of the dual's time on two cores and ran on one thread whatever the machine.

use super::cut;
use super::delassus::column;
use super::groups::dot;
use crate::threads::team::Team;
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::{Mat, Par};

/// The columns of a panel of the triangular solves.
const PANEL: usize = 128;

/// Rows (or sums) from which a pass is cut into pieces for the threads.
const SHARE: usize = 256;

/// The vector passes of a Newton matrix of `n` rows and its factor.
pub(super) struct Vectors {
    team: Team,
    /// `DualSettings::par_min`: from this many rows on, this module's passes.
    from: usize,
}

impl Vectors {
    pub(super) fn new(from: usize) -> Self {
        Vectors {
            team: Team::default(),
            from,
        }
    }

    /// x = (L Lᵀ)⁻¹ rhs for L in the lower triangle of `l` and one right side.
    pub(super) fn llt_solve(&self, l: &Mat<f64>, rhs: &Mat<f64>) -> Mat<f64> {
        let mut x = rhs.clone();
        if l.nrows() < self.from {
            llt::solve::solve_in_place_with_conj(
                l.as_ref(),
                faer::Conj::No,
                x.as_mut(),
                Par::Seq,
                MemStack::new(&mut MemBuffer::new(StackReq::EMPTY)),
            );
            return x;
        }
        let y = x.col_mut(0).try_as_col_major_mut().unwrap().as_slice_mut();
        self.forward(l, y);
        self.backward(l, y);
        x
    }

    /// H x for one column x.
    pub(super) fn mat_vec(&self, h: &Mat<f64>, x: &Mat<f64>) -> Mat<f64> {
        let mut y = Mat::zeros(h.nrows(), x.ncols());
        if h.nrows() < self.from {
            faer::linalg::matmul::matmul(y.as_mut(), faer::Accum::Replace, h, x, 1.0, Par::Seq);
            return y;
        }
        let out = y.col_mut(0).try_as_col_major_mut().unwrap().as_slice_mut();
        let pieces = cut(out, self.team.pieces(true));
        self.team.each(pieces, |(rows, out)| {
            for (j, &xj) in x.col(0).iter().enumerate() {
                for (o, hij) in out.iter_mut().zip(&column(h, j)[rows.clone()]) {
                    *o += hij * xj;
                }
            }
        });
        y
    }

    /// y ← L⁻¹ y (the module doc).
    fn forward(&self, l: &Mat<f64>, y: &mut [f64]) {
        let n = y.len();
        for c0 in (0..n).step_by(PANEL) {
            let c1 = (c0 + PANEL).min(n);
            for j in c0..c1 {
                y[j] /= l[(j, j)];
                let yj = y[j];
                for (yi, lij) in y[j + 1..c1].iter_mut().zip(&column(l, j)[j + 1..c1]) {
                    *yi -= lij * yj;
                }
            }
            let (top, below) = y.split_at_mut(c1);
            let panel = &top[c0..c1];
            let pieces = cut(below, self.team.pieces(below.len() >= SHARE));
            self.team.each(pieces, |(rows, below)| {
                for (j, &yj) in (c0..c1).zip(panel) {
                    let col = &column(l, j)[c1 + rows.start..c1 + rows.end];
                    for (yi, lij) in below.iter_mut().zip(col) {
                        *yi -= lij * yj;
                    }
                }
            });
        }
    }

    /// x ← L⁻ᵀ x (the module doc).
    fn backward(&self, l: &Mat<f64>, x: &mut [f64]) {
        let n = x.len();
        let mut sums = vec![0.0; PANEL];
        for c0 in (0..n).step_by(PANEL).rev() {
            let c1 = (c0 + PANEL).min(n);
            let (top, below) = x.split_at_mut(c1);
            let below = &*below;
            let pieces = self.team.pieces(below.len() >= SHARE);
            self.team
                .each(cut(&mut sums[..c1 - c0], pieces), |(cols, s)| {
                    for (j, sj) in cols.zip(s) {
                        *sj = dot(&column(l, c0 + j)[c1..], below);
                    }
                });
            for j in (c0..c1).rev() {
                let inner = dot(&column(l, j)[j + 1..c1], &top[j + 1..c1]);
                top[j] = (top[j] - sums[j - c0] - inner) / l[(j, j)];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::SplitMix;

    /// The passes on 1, 2, 3 and 5 threads give the same bits, and agree with faer's on
    /// one thread to rounding: an SPD matrix of 700 rows (panels of 128 and 60 columns,
    /// the rows below the first panels cut into pieces).
    #[test]
    fn passes_are_identical_for_every_thread_count() {
        let n = 700;
        let mut rng = SplitMix(41);
        let a = Mat::from_fn(n, n, |_, _| rng.range(-1.0, 1.0));
        let h = &a * a.transpose() * (1.0 / n as f64) + Mat::<f64>::identity(n, n);
        let mut l = h.clone();
        llt::factor::cholesky_in_place(
            l.as_mut(),
            Default::default(),
            Par::Seq,
            MemStack::new(&mut MemBuffer::new(
                llt::factor::cholesky_in_place_scratch::<f64>(n, Par::Seq, Default::default()),
            )),
            Default::default(),
        )
        .unwrap();
        let x = Mat::from_fn(n, 1, |_, _| rng.range(-1.0, 1.0));
        let faer = Vectors::new(n + 1);
        let (want_solve, want_product) = (faer.llt_solve(&l, &x), faer.mat_vec(&h, &x));
        let mut first: Option<(Mat<f64>, Mat<f64>)> = None;
        for threads in [1, 2, 3, 5] {
            let v = Vectors {
                team: Team::of(threads),
                from: 100,
            };
            // Twice: the team times both ways, one thread and several.
            for _ in 0..2 {
                let (solve, product) = (v.llt_solve(&l, &x), v.mat_vec(&h, &x));
                assert!((&solve - &want_solve).norm_max() < 1e-12 * want_solve.norm_max());
                assert!((&product - &want_product).norm_max() < 1e-12 * want_product.norm_max());
                let (s0, p0) = first.get_or_insert_with(|| (solve.clone(), product.clone()));
                let bits = |a: &Mat<f64>, b: &Mat<f64>| {
                    (0..n).all(|i| a[(i, 0)].to_bits() == b[(i, 0)].to_bits())
                };
                assert!(bits(&solve, s0) && bits(&product, p0), "{threads} threads");
            }
        }
    }
}
