//! The sparse Cholesky factor of K_A, computed once per run (faer, supernodal LLᵀ).
//!
//! A fill-reducing ordering (AMD) is computed for K_A and then the constrained boundary dofs
//! C (both components of every Γ3 node) are moved to the end, keeping their relative order:
//! P K_A Pᵀ = L Lᵀ with L = [L_II 0; L_CI L_CC]. Then the forward solve L y = b leaves in
//! y_C everything the contact problem needs, the trailing block L_CC (dense, |C|×|C|) gives
//! the condensed operator, and one backward solve finishes the step (see `dual`). Without
//! constrained dofs the factor is the plain AMD-ordered one.

use crate::fem::Sparse;
use crate::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::supernodal::SupernodalLltRef;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::{Conj, Mat, MatMut, Par, Side};

pub struct Factor {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<f64>,
    n: usize,
    /// Permuted index i holds original dof fwd[i]; original dof j sits at inv[j].
    fwd: Vec<usize>,
    inv: Vec<usize>,
    /// The number of dofs ordered last (the block C).
    last: usize,
}

fn par() -> Par {
    faer::get_global_parallelism()
}

impl Factor {
    /// Factors `a`, with the dofs in `last` ordered last.
    pub fn new(a: &Sparse, last: &[usize]) -> Result<Self> {
        let n = a.nrows();
        let fail = |what: &str, e: &dyn std::fmt::Debug| {
            Error::solve(format!("{what} of K_A failed: {e:?}"))
        };
        // AMD on the whole matrix, then C moved to the end in AMD's relative order.
        let amd = factorize_symbolic_cholesky(
            a.symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| fail("symbolic analysis", &e))?;
        let order: Vec<usize> = match amd.perm() {
            Some(p) => p.arrays().0.to_vec(),
            None => (0..n).collect(),
        };
        drop(amd);
        let mut in_last = vec![false; n];
        for &d in last {
            in_last[d] = true;
        }
        let mut fwd: Vec<usize> = order.iter().copied().filter(|&d| !in_last[d]).collect();
        fwd.extend(order.iter().copied().filter(|&d| in_last[d]));
        let mut inv = vec![0; n];
        for (i, &d) in fwd.iter().enumerate() {
            inv[d] = i;
        }
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        let perm = PermRef::new_checked(&fwd, &inv, n);
        let symbolic = factorize_symbolic_cholesky(
            a.symbolic(),
            Side::Lower,
            SymmetricOrdering::Custom(perm),
            params,
        )
        .map_err(|e| fail("symbolic analysis", &e))?;
        let mut values = vec![0.0; symbolic.len_val()];
        {
            let mut mem = MemBuffer::new(
                symbolic.factorize_numeric_llt_scratch::<f64>(par(), Default::default()),
            );
            symbolic
                .factorize_numeric_llt(
                    &mut values,
                    a.as_ref(),
                    Side::Lower,
                    LltRegularization::default(),
                    par(),
                    MemStack::new(&mut mem),
                    Default::default(),
                )
                .map_err(|e| {
                    Error::solve(format!(
                        "K_A is not positive definite ({e:?}): is the clamped group Γ1 empty \
                         or is part of the mesh not connected to it?"
                    ))
                })?;
        }
        Ok(Factor {
            symbolic,
            values,
            n,
            fwd,
            inv,
            last: last.len(),
        })
    }

    fn llt(&self) -> SupernodalLltRef<'_, usize, f64> {
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => SupernodalLltRef::new(s, &self.values),
            SymbolicCholeskyRaw::Simplicial(_) => unreachable!("supernodal was forced"),
        }
    }

    fn scratch(&self, ncols: usize) -> MemBuffer {
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => {
                MemBuffer::new(s.solve_in_place_scratch::<f64>(ncols, par()))
            }
            SymbolicCholeskyRaw::Simplicial(_) => unreachable!("supernodal was forced"),
        }
    }

    pub fn dim(&self) -> usize {
        self.n
    }

    /// The number of dofs ordered last.
    pub fn last(&self) -> usize {
        self.last
    }

    /// The position of an original dof in the factor's ordering.
    pub fn position(&self, dof: usize) -> usize {
        self.inv[dof]
    }

    /// out[i] = x[fwd[i]]: into the factor's ordering.
    pub fn permute(&self, x: &[f64], out: &mut [f64]) {
        for (o, &d) in out.iter_mut().zip(&self.fwd) {
            *o = x[d];
        }
    }

    /// out[d] = x[inv[d]]: back to the original ordering.
    pub fn unpermute(&self, x: &[f64], out: &mut [f64]) {
        for (o, &i) in out.iter_mut().zip(&self.inv) {
            *o = x[i];
        }
    }

    /// y ← L⁻¹ y in the factor's ordering. The triangular solves run on one thread: a
    /// single right side is memory-bound and rayon's hand-offs cost more than they bring
    /// (measured at h = k = 1/256: steps 10.1 s with rayon, 9.1 s without); faer's
    /// parallelism pays in the numeric factorization and the dense products.
    pub fn forward(&self, y: MatMut<'_, f64>) {
        let mut mem = self.scratch(y.ncols());
        self.llt()
            .l_solve_with_conj(Conj::No, y, Par::Seq, MemStack::new(&mut mem));
    }

    /// y ← L⁻ᵀ y in the factor's ordering (one thread, see `forward`).
    pub fn backward(&self, y: MatMut<'_, f64>) {
        let mut mem = self.scratch(y.ncols());
        self.llt()
            .l_transpose_solve_with_conj(Conj::No, y, Par::Seq, MemStack::new(&mut mem));
    }

    /// x ← K_A⁻¹ x (original ordering).
    pub fn solve(&self, x: &mut [f64]) {
        let mut y = vec![0.0; self.n];
        self.permute(x, &mut y);
        let mut ym = MatMut::from_column_major_slice_mut(&mut y, self.n, 1);
        self.forward(ym.as_mut());
        self.backward(ym);
        self.unpermute(&y, x);
    }

    /// The trailing block L_CC (last × last, lower triangular) of L.
    pub fn trailing_block(&self) -> Mat<f64> {
        let (n, c) = (self.n, self.last);
        let first = n - c;
        let mut out = Mat::zeros(c, c);
        let llt = self.llt();
        let SymbolicCholeskyRaw::Supernodal(sym) = self.symbolic.raw() else {
            unreachable!("supernodal was forced")
        };
        for s in 0..sym.n_supernodes() {
            let node = llt.supernode(s);
            let (start, m) = (node.start(), node.val());
            let size = m.ncols();
            if start + size <= first {
                continue;
            }
            let pattern = node.pattern();
            for j in 0..size {
                let col = start + j;
                if col < first {
                    continue;
                }
                // Rows of the diagonal block, then the pattern rows (all > col).
                for i in j..size {
                    out[(start + i - first, col - first)] = m[(i, j)];
                }
                for (p, &row) in pattern.iter().enumerate() {
                    out[(row - first, col - first)] = m[(size + p, j)];
                }
            }
        }
        out
    }
}
