//! K_B u_n + K_R m_n in one pass: the two step matrices that share a pattern, stored once,
//! and the product on the process's threads with the serial pass's bits.
//!
//! The serial pass runs over the columns j in order: each stored entry (i, j) below the
//! diagonal adds its term α(A_ij x_j + B_ij z_j) to y_i (a scatter) and A_ij x_i + B_ij z_i
//! to column j's sum (a gather), and y_j takes α times that sum at the end of column j. So
//! row i receives the terms of the columns j < i in the order of j, then its own sum.
//!
//! On several threads the columns are cut into consecutive blocks of about as many
//! entries, one per piece (`Blocks`). The entries of a column that lie below its block's
//! last column (the tail of the column: its rows are sorted) have their terms *recorded*
//! first, every block at once. Then every block's rows, at once: the recorded terms of the
//! earlier blocks into its rows, in the order of their columns, then its own columns as
//! the serial pass runs them, each tail entry gathered but not scattered. Every row thus
//! receives the same terms in the same order as in the serial pass, and every sum is the
//! same: the bits do not depend on the blocks, so neither on the threads. A finite element
//! matrix couples nearby nodes, so few entries are recorded where the nodes are numbered by
//! locality (gmsh's structured meshes: 2 % of the entries with 16 blocks on the 2D 1/512,
//! 23 % on the block 1/24); where they are not (gmsh's unstructured tetrahedra: 72 % on the
//! plate 0.03) the serial pass stays (`RECORDED_AT_MOST`).

use super::Sparse;
use crate::threads::team::Team;
use std::ops::Range;

/// The fewest stored entries for which the product is cut into blocks (a smaller one takes
/// less time than waking the threads: 2^16 entries are 1.3 MB).
const BLOCKS_FROM: usize = 1 << 16;

/// The blocks are kept only where at most 1 in `RECORDED_AT_MOST` entries is recorded:
/// each recorded entry costs a second pass (its term stored, then added), so where the
/// nodes' numbering is far from local the serial pass is faster: on two cores the blocks
/// lost at 28 % recorded, were about even at 8.8 % and won at 0.4 % (docs/performance.md,
/// "Threads").
const RECORDED_AT_MOST: usize = 4;

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
    /// The columns in blocks for the threads.
    blocks: Blocks,
    /// The recorded terms of a product (`Blocks::rec`), a buffer kept between products.
    record: Vec<f64>,
    /// The threads of the two parts of a product: recording, then the blocks' rows.
    record_team: Team,
    rows_team: Team,
}

/// The columns of a `SymmetricPair` cut in blocks (the module doc).
struct Blocks {
    /// Block k holds the columns start[k]..start[k + 1].
    start: Vec<usize>,
    /// The recorded terms of column j are record[rec[j]..rec[j + 1]]: those of the last
    /// rec[j + 1] − rec[j] entries of the column, the rows below its block.
    rec: Vec<usize>,
    /// For each block, the recorded terms into its rows in the order of their columns: the
    /// index in the record and the row.
    replay: Vec<Vec<(usize, u32)>>,
}

impl Blocks {
    /// The columns of `col_ptr` (a pattern's lower triangle, `rows`) cut in `count` blocks
    /// of about as many entries.
    fn new(col_ptr: &[usize], rows: &[u32], count: usize) -> Blocks {
        let (n, nnz) = (col_ptr.len() - 1, rows.len());
        let mut start: Vec<usize> = (0..count)
            .map(|k| col_ptr.partition_point(|&p| p < k * nnz / count).min(n))
            .collect();
        start.push(n);
        start.dedup();
        let block_of = |i: usize| start.partition_point(|&s| s <= i) - 1;
        let mut rec = vec![0];
        let mut replay = vec![Vec::new(); start.len() - 1];
        for k in 0..start.len() - 1 {
            for j in start[k]..start[k + 1] {
                let col = &rows[col_ptr[j]..col_ptr[j + 1]];
                let below = col.partition_point(|&i| (i as usize) < start[k + 1]);
                let first = *rec.last().unwrap_or(&0);
                for (t, &i) in col[below..].iter().enumerate() {
                    replay[block_of(i as usize)].push((first + t, i));
                }
                rec.push(first + col.len() - below);
            }
        }
        Blocks { start, rec, replay }
    }

    /// The number of recorded terms.
    fn recorded(&self) -> usize {
        *self.rec.last().unwrap_or(&0)
    }

    fn count(&self) -> usize {
        self.start.len() - 1
    }

    fn columns(&self, k: usize) -> Range<usize> {
        self.start[k]..self.start[k + 1]
    }
}

impl SymmetricPair {
    /// None unless `a` and `b` have the same pattern, sorted, with every diagonal entry, and
    /// fewer than 2^32 rows.
    pub fn new(a: &Sparse, b: &Sparse) -> Option<Self> {
        Self::with_blocks(a, b, crate::threads::count())
    }

    /// As `new`, the product cut in `count` blocks of columns if it stores at least
    /// `BLOCKS_FROM` entries.
    fn with_blocks(a: &Sparse, b: &Sparse, count: usize) -> Option<Self> {
        if !same_pattern(a.symbolic(), b.symbolic()) || u32::try_from(a.nrows()).is_err() {
            return None;
        }
        let (cp, ri) = (a.symbolic().col_ptr(), a.symbolic().row_idx());
        let (va, vb) = (a.val(), b.val());
        let n = a.ncols();
        let (mut col_ptr, mut rows, mut values, mut diag) = (
            Vec::with_capacity(n + 1),
            Vec::with_capacity((ri.len() - n) / 2),
            Vec::with_capacity((ri.len() - n) / 2),
            Vec::with_capacity(n),
        );
        col_ptr.push(0);
        for j in 0..n {
            let col = cp[j]..cp[j + 1];
            let d = col.clone().find(|&p| ri[p] == j)?;
            if !ri[col.clone()].is_sorted() {
                return None;
            }
            diag.push([va[d], vb[d]]);
            for p in d + 1..col.end {
                rows.push(ri[p] as u32);
                values.push([va[p], vb[p]]);
            }
            col_ptr.push(rows.len());
        }
        let count = if rows.len() >= BLOCKS_FROM { count } else { 1 };
        let mut blocks = Blocks::new(&col_ptr, &rows, count.max(1));
        if blocks.recorded() * RECORDED_AT_MOST > rows.len() {
            blocks = Blocks::new(&col_ptr, &rows, 1);
        }
        Some(SymmetricPair {
            record: vec![0.0; blocks.recorded()],
            blocks,
            col_ptr,
            rows,
            values,
            diag,
            record_team: Team::default(),
            rows_team: Team::default(),
        })
    }

    /// y += alpha · (A x + B z), with the serial pass's bits (the module doc).
    pub fn mul_add(&mut self, x: &[f64], z: &[f64], alpha: f64, y: &mut [f64]) {
        let mut record = std::mem::take(&mut self.record);
        let (pair, blocks) = (&*self, &self.blocks);
        let count = blocks.count();
        // 1. The terms below each block, recorded.
        let lengths = (0..count).map(|k| {
            let cols = blocks.columns(k);
            blocks.rec[cols.end] - blocks.rec[cols.start]
        });
        let pieces = (0..count).map(|k| blocks.columns(k));
        let pieces: Vec<_> = pieces.zip(consecutive(&mut record, lengths)).collect();
        pair.record_team.each(pieces, |(cols, piece)| {
            let mut terms = piece.iter_mut();
            for j in cols {
                let (ax, az) = (alpha * x[j], alpha * z[j]);
                let recorded = pair.tail(j)..pair.col_ptr[j + 1];
                for ([a, b], t) in pair.values[recorded].iter().zip(&mut terms) {
                    *t = a * ax + b * az;
                }
            }
        });
        // 2. Each block's rows: the earlier blocks' terms, then its own columns.
        let lengths = (0..count).map(|k| blocks.columns(k).len());
        let pieces: Vec<_> = consecutive(y, lengths).into_iter().enumerate().collect();
        pair.rows_team.each(pieces, |(k, y)| {
            let first = blocks.start[k];
            for &(t, i) in &blocks.replay[k] {
                y[i as usize - first] += record[t];
            }
            pair.columns(blocks.columns(k), x, z, alpha, y);
        });
        self.record = record;
    }

    /// Where column j's recorded entries (the rows below its block) begin in `rows`.
    fn tail(&self, j: usize) -> usize {
        self.col_ptr[j + 1] - (self.blocks.rec[j + 1] - self.blocks.rec[j])
    }

    /// The serial pass over the columns `cols` into y (rows cols.start..), the terms of
    /// their tails (recorded) left out.
    fn columns(&self, cols: Range<usize>, x: &[f64], z: &[f64], alpha: f64, y: &mut [f64]) {
        let first = cols.start;
        for j in cols {
            let [da, db] = self.diag[j];
            let (xj, zj) = (x[j], z[j]);
            let (ax, az) = (alpha * xj, alpha * zj);
            let mut acc = da * xj + db * zj;
            let col = self.col_ptr[j]..self.col_ptr[j + 1];
            let tail = self.tail(j);
            for (&i, [a, b]) in self.rows[col.start..tail]
                .iter()
                .zip(&self.values[col.start..tail])
            {
                let i = i as usize;
                y[i - first] += a * ax + b * az;
                acc += a * x[i] + b * z[i];
            }
            for (&i, [a, b]) in self.rows[tail..col.end]
                .iter()
                .zip(&self.values[tail..col.end])
            {
                let i = i as usize;
                acc += a * x[i] + b * z[i];
            }
            y[j - first] += alpha * acc;
        }
    }
}

/// On one of several MPI ranks, the rank's rows of two symmetric matrices with one pattern
/// (K_B and K_R^(0), of which it keeps its own columns: `Discretization::keep_columns`), in
/// one array: a column index as u32 and the two values side by side, 20 bytes an entry
/// where the two matrices' columns take 32. The product gives each row the bits of the two
/// matrices' own products one after the other (`fem::mul_add_rows`): each sum runs over
/// the row's columns in their order.
pub struct RowsPair {
    /// The rank's rows, in the order of `Discretization::own`: row k's entries are
    /// cols[ptr[k]..ptr[k + 1]].
    ptr: Vec<usize>,
    cols: Vec<u32>,
    values: Vec<[f64; 2]>,
}

impl RowsPair {
    /// The rows of `a` and `b` that their `columns` are (the matrices are symmetric), in
    /// that order; None unless the two have the same pattern and fewer than 2^32 rows.
    pub fn new(
        a: &Sparse,
        b: &Sparse,
        columns: impl Iterator<Item = usize> + Clone,
    ) -> Option<RowsPair> {
        if !same_pattern(a.symbolic(), b.symbolic()) || u32::try_from(a.nrows()).is_err() {
            return None;
        }
        let (cp, ri) = (a.symbolic().col_ptr(), a.symbolic().row_idx());
        let (va, vb) = (a.val(), b.val());
        let entries: usize = columns.clone().map(|i| cp[i + 1] - cp[i]).sum();
        let mut pair = RowsPair {
            ptr: Vec::with_capacity(columns.clone().count() + 1),
            cols: Vec::with_capacity(entries),
            values: Vec::with_capacity(entries),
        };
        pair.ptr.push(0);
        for i in columns {
            let col = cp[i]..cp[i + 1];
            pair.cols.extend(ri[col.clone()].iter().map(|&j| j as u32));
            pair.values.extend(col.map(|p| [va[p], vb[p]]));
            pair.ptr.push(pair.cols.len());
        }
        Some(pair)
    }

    /// No rows yet, room for `rows` rows of `entries` entries in all
    /// ([`RowsPair::extend`]).
    pub fn with_capacity(rows: usize, entries: usize) -> RowsPair {
        let mut ptr = Vec::with_capacity(rows + 1);
        ptr.push(0);
        RowsPair {
            ptr,
            cols: Vec::with_capacity(entries),
            values: Vec::with_capacity(entries),
        }
    }

    /// `more`'s rows after these.
    pub fn extend(&mut self, more: &RowsPair) {
        let base = self.cols.len();
        self.ptr.extend(more.ptr[1..].iter().map(|&p| base + p));
        self.cols.extend_from_slice(&more.cols);
        self.values.extend_from_slice(&more.values);
    }

    /// The columns of the rank's rows, each as often as it occurs.
    pub fn columns(&self) -> impl Iterator<Item = usize> + '_ {
        self.cols.iter().map(|&j| j as usize)
    }

    /// The columns numbered by `place` (increasing), where the vectors the products read
    /// hold their values alone (`Discretization::number_rows_over`).
    pub fn number_columns(&mut self, place: impl Fn(usize) -> usize) {
        for j in &mut self.cols {
            // A place is below the rows' count, itself below 2^32 (`RowsPair::new`).
            *j = place(*j as usize) as u32;
        }
    }

    /// y_i += α (A x)_i, then y_i += α (B z)_i where z is given, for the rows i of `own`
    /// (the rows the pair was made of).
    pub fn mul_add(&self, own: &[usize], x: &[f64], z: Option<&[f64]>, alpha: f64, y: &mut [f64]) {
        for (k, &i) in own.iter().enumerate() {
            let row = self.ptr[k]..self.ptr[k + 1];
            let entries = self.cols[row.clone()].iter().zip(&self.values[row]);
            match z {
                Some(z) => {
                    // −0.0, where `Iterator::sum` starts: the bits of `mul_add_rows`.
                    let (mut ax, mut bz) = (-0.0, -0.0);
                    for (&j, [a, b]) in entries {
                        ax += a * x[j as usize];
                        bz += b * z[j as usize];
                    }
                    y[i] += alpha * ax;
                    y[i] += alpha * bz;
                }
                None => y[i] += alpha * entries.map(|(&j, [a, _])| a * x[j as usize]).sum::<f64>(),
            }
        }
    }
}

/// `v` cut into consecutive pieces of the given lengths.
fn consecutive(v: &mut [f64], lengths: impl Iterator<Item = usize>) -> Vec<&mut [f64]> {
    let mut rest = v;
    lengths
        .map(|len| {
            let (piece, tail) = std::mem::take(&mut rest).split_at_mut(len);
            rest = tail;
            piece
        })
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::SplitMix;
    use faer::sparse::{SparseColMat, Triplet};

    /// Two symmetric matrices of one pattern: a band of nearby couplings (as a mesh's) and
    /// a few far ones, so that every block records terms into several later blocks.
    /// With `scatter`, every node is coupled to far ones instead (a numbering far from local).
    fn pair(n: usize, scatter: bool, rng: &mut SplitMix) -> (Sparse, Sparse) {
        let mut pattern = Vec::new();
        for i in 0..n {
            for d in 1..6 {
                let far = (i * 7919 + d * 104_729) % n;
                match scatter {
                    false if i + d < n => pattern.push((i + d, i)),
                    true => pattern.push((far.max(i), far.min(i))),
                    false => {}
                }
            }
            if i % 7 == 0 {
                pattern.push((((i * 7919) % n).max(i + 1).min(n - 1), i));
            }
        }
        pattern.retain(|&(r, c)| r > c);
        pattern.sort();
        pattern.dedup();
        let mut make = || {
            let mut t: Vec<_> = (0..n)
                .map(|i| Triplet::new(i, i, rng.range(1.0, 2.0)))
                .collect();
            for &(r, c) in &pattern {
                let v = rng.range(-1.0, 1.0);
                t.push(Triplet::new(r, c, v));
                t.push(Triplet::new(c, r, v));
            }
            SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
        };
        (make(), make())
    }

    /// The serial pass, as the product was before it had blocks.
    fn serial(pair: &SymmetricPair, x: &[f64], z: &[f64], alpha: f64, y: &mut [f64]) {
        for (j, [da, db]) in pair.diag.iter().enumerate() {
            let (ax, az) = (alpha * x[j], alpha * z[j]);
            let mut acc = da * x[j] + db * z[j];
            for p in pair.col_ptr[j]..pair.col_ptr[j + 1] {
                let (i, [a, b]) = (pair.rows[p] as usize, pair.values[p]);
                y[i] += a * ax + b * az;
                acc += a * x[i] + b * z[i];
            }
            y[j] += alpha * acc;
        }
    }

    /// The product cut in 1, 2, 3, 5 and 16 blocks, on the threads the tests have, gives
    /// the serial pass's bits, and 16 blocks do record terms.
    #[test]
    fn blocks_give_the_serial_bits() {
        let mut rng = SplitMix(29);
        let n = 40_000;
        let (a, b) = pair(n, false, &mut rng);
        let x: Vec<f64> = (0..n).map(|_| rng.range(-1.0, 1.0)).collect();
        let z: Vec<f64> = (0..n).map(|_| rng.range(-1.0, 1.0)).collect();
        let y0: Vec<f64> = (0..n).map(|_| rng.range(-1.0, 1.0)).collect();
        let one = SymmetricPair::with_blocks(&a, &b, 1).unwrap();
        assert!(one.rows.len() >= BLOCKS_FROM, "large enough to be cut");
        let mut want = y0.clone();
        serial(&one, &x, &z, -0.7, &mut want);
        for count in [1, 2, 3, 5, 16] {
            let mut pair = SymmetricPair::with_blocks(&a, &b, count).unwrap();
            assert_eq!(pair.blocks.count(), count);
            if count == 16 {
                assert!(pair.blocks.replay.iter().skip(2).all(|r| !r.is_empty()));
            }
            // Twice: the teams time both ways, one thread and several.
            for _ in 0..2 {
                let mut y = y0.clone();
                pair.mul_add(&x, &z, -0.7, &mut y);
                let same = y.iter().zip(&want).all(|(p, q)| p.to_bits() == q.to_bits());
                assert!(same, "{count} blocks");
            }
        }
    }

    /// Where most entries would be recorded the product keeps one block, and its bits.
    #[test]
    fn a_numbering_far_from_local_keeps_the_serial_pass() {
        let mut rng = SplitMix(31);
        let n = 30_000;
        let (a, b) = pair(n, true, &mut rng);
        let mut pair = SymmetricPair::with_blocks(&a, &b, 16).unwrap();
        assert_eq!(pair.blocks.count(), 1);
        let x: Vec<f64> = (0..n).map(|_| rng.range(-1.0, 1.0)).collect();
        let (mut want, mut y) = (vec![0.5; n], vec![0.5; n]);
        serial(&pair, &x, &x, 1.3, &mut want);
        pair.mul_add(&x, &x, 1.3, &mut y);
        assert!(y.iter().zip(&want).all(|(p, q)| p.to_bits() == q.to_bits()));
    }
}
