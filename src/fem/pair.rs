//! K_B u_n + K_R m_n in one pass: the two step matrices that share a pattern, stored once.

use super::Sparse;

/// Two symmetric matrices with the same sparsity pattern (K_B and K_R share the one
/// `assemble` builds) for y += α (A x + B z) in one pass, as the time loop forms K_B u_n +
/// K_R m_n every step: the diagonal and the strictly lower triangle only, row indices as u32
/// and the two values of an entry side by side. 9 bytes per stored entry instead of the 24
/// the two full matrices stream (h = 1/128: 5 MB instead of 11 MB per step, which leaves the
/// last-level cache to the factor the step's solves read next).
pub struct SymmetricPair {
    /// The strictly lower entries of column j are rows[col_ptr[j]..col_ptr[j + 1]].
    col_ptr: Vec<usize>,
    rows: Vec<u32>,
    /// (A_ij, B_ij) of those entries.
    values: Vec<[f64; 2]>,
    /// (A_jj, B_jj).
    diag: Vec<[f64; 2]>,
}

impl SymmetricPair {
    /// None unless `a` and `b` have the same pattern, sorted, with every diagonal entry, and
    /// fewer than 2^32 rows.
    pub fn new(a: &Sparse, b: &Sparse) -> Option<Self> {
        if !same_pattern(a.symbolic(), b.symbolic()) || u32::try_from(a.nrows()).is_err() {
            return None;
        }
        let (cp, ri) = (a.symbolic().col_ptr(), a.symbolic().row_idx());
        let (va, vb) = (a.val(), b.val());
        let n = a.ncols();
        let mut pair = SymmetricPair {
            col_ptr: Vec::with_capacity(n + 1),
            rows: Vec::with_capacity((ri.len() - n) / 2),
            values: Vec::with_capacity((ri.len() - n) / 2),
            diag: Vec::with_capacity(n),
        };
        pair.col_ptr.push(0);
        for j in 0..n {
            let col = cp[j]..cp[j + 1];
            let d = col.clone().find(|&p| ri[p] == j)?;
            if !ri[col.clone()].is_sorted() {
                return None;
            }
            pair.diag.push([va[d], vb[d]]);
            for p in d + 1..col.end {
                pair.rows.push(ri[p] as u32);
                pair.values.push([va[p], vb[p]]);
            }
            pair.col_ptr.push(pair.rows.len());
        }
        Some(pair)
    }

    /// y += alpha · (A x + B z).
    pub fn mul_add(&self, x: &[f64], z: &[f64], alpha: f64, y: &mut [f64]) {
        for (j, [da, db]) in self.diag.iter().enumerate() {
            let (xj, zj) = (x[j], z[j]);
            let (ax, az) = (alpha * xj, alpha * zj);
            let mut acc = da * xj + db * zj;
            let col = self.col_ptr[j]..self.col_ptr[j + 1];
            for (&i, [a, b]) in self.rows[col.clone()].iter().zip(&self.values[col]) {
                let i = i as usize;
                y[i] += a * ax + b * az;
                acc += a * x[i] + b * z[i];
            }
            y[j] += alpha * acc;
        }
    }
}

/// True when two matrices have the same pattern.
fn same_pattern(
    a: faer::sparse::SymbolicSparseColMatRef<'_, usize>,
    b: faer::sparse::SymbolicSparseColMatRef<'_, usize>,
) -> bool {
    a.nrows() == b.nrows()
        && a.col_ptr() == b.col_ptr()
        && a.row_idx() == b.row_idx()
        && a.col_nnz().is_none()
        && b.col_nnz().is_none()
}
