//! The trailing block L_CC of the factor: the constrained dofs C, ordered last, and all a
//! contact solver needs of K_A⁻¹.
//!
//! With L = [L_II 0; L_CI L_CC], S_C = L_CC L_CCᵀ is the Schur complement of K_A on C
//! (K_CC − K_CI K_II⁻¹ K_IC) and (K_A⁻¹)_CC = S_C⁻¹. So for a vector v on C:
//!
//!   (K_A⁻¹)_CC v = L_CC⁻ᵀ L_CC⁻¹ v     (`trailing_solve`: the condensed operator D),
//!   S_C v      = L_CC L_CCᵀ v         (`trailing_product`: its inverse, the Dirichlet-type
//!                                      preconditioner of FETI),
//!
//! each one pass up and one down over the |C|(|C| + 1)/2 values of L_CC alone, instead of a
//! whole forward and backward solve with L (nnz(L_CC) is 22 % of nnz(L) on the plate on its
//! foundation at size 0.03, 2 % on the block at h = 1/24). The vectors hold C in the factor's
//! order: entry i is position `dim() − last() + i`.
//!
//! faer's amalgamation may merge a supernode across the boundary between the interior dofs
//! and C (it does on every mesh of the repository: the top separator and C share the root
//! supernode), so these passes go column by column over the columns of C: column j holds
//! rows j..s₁ of its supernode's diagonal block, contiguous, then its off-diagonal rows R,
//! all in C. A supernode's columns in C are a run; a run is done in panels of `PANEL`
//! columns, and where its rows below a panel are many, they are shared out over the
//! process's threads (`Team`): the forward pass's updates by blocks of rows (each row still
//! receives the columns' updates in column order), the backward pass's sums by columns (each
//! sum whole on one thread). The panels are fixed, so the bits are the same for every thread
//! count.

use super::{dot, Factor};
use crate::threads::team::{blocks, Team};
use faer::Mat;

/// The columns of a panel (`Trailing::forward`, `Trailing::backward`).
const PANEL: usize = 128;

/// Rows below a panel from which its work is shared out over the threads.
const SHARE_ROWS: usize = 1024;

/// A column j ≥ first of L: where its values start, how many of them are the contiguous
/// rows j.. of its supernode's diagonal block, and its supernode (for the rows R after).
#[derive(Clone, Copy, Debug)]
struct Column {
    start: usize,
    dense: usize,
    supernode: usize,
}

/// The columns of L_CC, their runs (a supernode's columns in C, by index in C) and the
/// threads of the two kinds of pass.
#[derive(Default)]
pub(super) struct Trailing {
    columns: Vec<Column>,
    runs: Vec<std::ops::Range<usize>>,
    pub(super) forward_team: Team,
    pub(super) backward_team: Team,
    /// `SHARE_ROWS`, or another threshold in the tests.
    pub(super) share_rows: usize,
}

impl Trailing {
    /// The columns first..n of `factor`'s L (first = n − last).
    pub(super) fn new(factor: &Factor) -> Self {
        let first = factor.n - factor.last;
        let layout = &factor.layout;
        let (mut columns, mut runs) = (Vec::with_capacity(factor.last), Vec::new());
        for s in 0..layout.n_supernodes() {
            let (c0, c1) = (layout.begin[s], layout.begin[s + 1]);
            if c1 <= first {
                continue;
            }
            let r = layout.pattern(s).len();
            let mut start = layout.val_ptr[s];
            runs.push(columns.len()..c1 - first);
            for j in c0..c1 {
                if j >= first {
                    columns.push(Column {
                        start,
                        dense: c1 - j,
                        supernode: s,
                    });
                }
                start += c1 - j + r;
            }
        }
        Trailing {
            columns,
            runs,
            share_rows: SHARE_ROWS,
            ..Trailing::default()
        }
    }
}

impl Factor {
    /// Column j of L_CC: its values on the contiguous rows j.. (the diagonal first), and on
    /// the rows R of its supernode (their indices in C, offset by `first`).
    fn column_parts(&self, j: usize) -> (&[f64], &[f64], &[u32]) {
        let col = &self.trailing.columns[j];
        let rows = self.layout.pattern(col.supernode);
        let values = &self.values[col.start..col.start + col.dense + rows.len()];
        let (dense, sparse) = values.split_at(col.dense);
        (dense, sparse, rows)
    }

    /// y ← L_CC⁻ᵀ L_CC⁻¹ y = (K_A⁻¹)_CC y for y on C (the module doc).
    pub fn trailing_solve(&self, y: &mut [f64]) {
        self.trailing_forward(y);
        self.trailing_backward(y);
    }

    /// y ← L_CC⁻¹ y for y on C.
    pub fn trailing_forward(&self, y: &mut [f64]) {
        debug_assert_eq!(y.len(), self.last);
        for run in &self.trailing.runs {
            for p0 in run.clone().step_by(PANEL) {
                self.forward_panel(p0..(p0 + PANEL).min(run.end), run.end, y);
            }
        }
    }

    /// y ← L_CC⁻ᵀ y for y on C.
    pub fn trailing_backward(&self, y: &mut [f64]) {
        debug_assert_eq!(y.len(), self.last);
        for run in self.trailing.runs.iter().rev() {
            let panels: Vec<usize> = run.clone().step_by(PANEL).collect();
            for &p0 in panels.iter().rev() {
                self.backward_panel(p0..(p0 + PANEL).min(run.end), run.end, y);
            }
        }
    }

    /// y ← L⁻¹ y on the panel's columns: their triangle, then the rows below it to the end
    /// of the run (`end`) in blocks over the threads, then the rows R of their supernode.
    fn forward_panel(&self, panel: std::ops::Range<usize>, end: usize, y: &mut [f64]) {
        let first = self.n - self.last;
        let (p0, p1) = (panel.start, panel.end);
        for j in panel.clone() {
            let (dense, _, _) = self.column_parts(j);
            let yj = y[j] / dense[0];
            y[j] = yj;
            for (yi, l) in y[j + 1..p1].iter_mut().zip(&dense[1..]) {
                *yi -= l * yj;
            }
        }
        let (head, below) = y.split_at_mut(p1);
        let (solved, below) = (&head[p0..], &mut below[..end - p1]);
        let n = below.len();
        let pieces = self
            .trailing
            .forward_team
            .pieces(n >= self.trailing.share_rows);
        let mut rest = below;
        let mut parts = Vec::with_capacity(pieces);
        for rows in blocks(n, pieces) {
            let (piece, tail) = std::mem::take(&mut rest).split_at_mut(rows.len());
            parts.push((rows.start, piece));
            rest = tail;
        }
        self.trailing.forward_team.each(parts, |(offset, piece)| {
            for (k, j) in panel.clone().enumerate() {
                let (dense, _, _) = self.column_parts(j);
                // Row p1 + offset of C is entry p1 + offset − j of column j's dense part.
                let from = p1 + offset - j;
                for (yi, l) in piece.iter_mut().zip(&dense[from..]) {
                    *yi -= l * solved[k];
                }
            }
        });
        for j in panel {
            let (_, sparse, rows) = self.column_parts(j);
            for (&r, l) in rows.iter().zip(sparse) {
                y[r as usize - first] -= l * y[j];
            }
        }
    }

    /// y ← L⁻ᵀ y on the panel's columns: their sums over the rows below the panel (to the
    /// run's `end`, and R) in blocks of columns over the threads, then their triangle.
    fn backward_panel(&self, panel: std::ops::Range<usize>, end: usize, y: &mut [f64]) {
        let first = self.n - self.last;
        let (p0, p1) = (panel.start, panel.end);
        let mut sums = vec![0.0; p1 - p0];
        let pieces = self
            .trailing
            .backward_team
            .pieces(end - p1 >= self.trailing.share_rows);
        let mut rest = &mut sums[..];
        let mut parts = Vec::with_capacity(pieces);
        for cols in blocks(p1 - p0, pieces) {
            let (piece, tail) = std::mem::take(&mut rest).split_at_mut(cols.len());
            parts.push((p0 + cols.start, piece));
            rest = tail;
        }
        let below = &y[p1..end];
        self.trailing.backward_team.each(parts, |(j0, piece)| {
            for (k, s) in piece.iter_mut().enumerate() {
                let j = j0 + k;
                let (dense, sparse, rows) = self.column_parts(j);
                *s = dot(&dense[p1 - j..], below);
                for (&r, l) in rows.iter().zip(sparse) {
                    *s += l * y[r as usize - first];
                }
            }
        });
        for j in panel.rev() {
            let (dense, _, _) = self.column_parts(j);
            let s = sums[j - p0] + dot(&dense[1..p1 - j], &y[j + 1..p1]);
            y[j] = (y[j] - s) / dense[0];
        }
    }

    /// out = L_CC L_CCᵀ v = S_C v for v on C (the module doc).
    pub fn trailing_product(&self, v: &[f64], out: &mut [f64]) {
        debug_assert_eq!(v.len(), self.last);
        let first = self.n - self.last;
        out.fill(0.0);
        for j in 0..self.last {
            // u_j = (L_CCᵀ v)_j, then out += u_j · column j.
            let (dense, sparse, rows) = self.column_parts(j);
            let mut u = dot(dense, &v[j..j + dense.len()]);
            for (&r, l) in rows.iter().zip(sparse) {
                u += l * v[r as usize - first];
            }
            for (o, l) in out[j..j + dense.len()].iter_mut().zip(dense) {
                *o += l * u;
            }
            for (&r, l) in rows.iter().zip(sparse) {
                out[r as usize - first] += l * u;
            }
        }
    }

    /// The trailing block L_CC (last × last, lower triangular) of L.
    pub fn trailing_block(&self) -> Mat<f64> {
        let first = self.n - self.last;
        let mut out = Mat::zeros(self.last, self.last);
        for j in 0..self.last {
            let (dense, sparse, rows) = self.column_parts(j);
            for (i, &v) in dense.iter().enumerate() {
                out[(j + i, j)] = v;
            }
            for (&r, &v) in rows.iter().zip(sparse) {
                out[(r as usize - first, j)] = v;
            }
        }
        out
    }
}
