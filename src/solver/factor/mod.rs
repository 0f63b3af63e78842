//! The sparse Cholesky factor of K_A, computed once per run (faer, supernodal LLᵀ).
//!
//! The ordering puts the constrained boundary dofs C (those the Γ3 rows touch) last
//! and orders the others by nested dissection (`ordering.rs`, METIS):
//! P K_A Pᵀ = L Lᵀ with L = [L_II 0; L_CI L_CC]. Then the forward solve L y = b leaves in
//! y_C everything the contact problem needs, the trailing block L_CC (dense, |C|×|C|) gives
//! the condensed operator, and one backward solve finishes the step (see `dual`). Without
//! constrained dofs the whole matrix is ordered by nested dissection.
//!
//! The ordering is computed on its own (no symbolic factorization for it), then one symbolic
//! analysis in that order; the numeric factorization is faer's. The step's solves are this
//! module's loops over faer's supernodes, one pass each over the stored values, which are
//! repacked after the factorization (`Layout`: the upper triangles of the diagonal blocks
//! dropped, 16% of the values at h = 1/128): supernode s (columns s₀..s₁, off-diagonal rows
//! R) is the block [L_ss; L_Rs], column by column; the forward pass, in supernode order, does
//! y_s ← L_ss⁻¹ y_s and y_R ← y_R − L_Rs y_s; the backward pass, in reverse order,
//! y_s ← L_ssᵀ⁻¹ (y_s − L_Rsᵀ y_R). A single right side is memory-bound, so a big factor's
//! passes run on two threads: two groups of disjoint subtrees of the elimination tree,
//! each on its own thread, and the rest (`Split`; nested dissection's top separator splits
//! the tree into two such halves).
//! faer's default amalgamation may merge a supernode across the boundary between the
//! interior dofs and C; `trailing_block` reads L_CC column by column and does not care.

use super::pair::Pair;
use crate::fem::Sparse;
use crate::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::{Mat, Par, Side};

pub struct Factor {
    /// L's values in the packed layout of `Layout`.
    values: Vec<f64>,
    n: usize,
    /// Permuted index i holds original dof fwd[i]; original dof j sits at inv[j].
    fwd: Vec<usize>,
    inv: Vec<usize>,
    /// The number of dofs ordered last (the block C).
    last: usize,
    layout: Layout,
    /// The solves' two groups of subtrees, for factors big enough to gain from them.
    split: Option<Split>,
    /// The forward and the backward pass's two groups, on two threads when that pays.
    forward_pair: Pair,
    backward_pair: Pair,
}

/// The supernodes of L as plain arrays, read by the step's solves, and the packed layout of
/// their values: column j of a supernode with `size` columns and off-diagonal rows R holds
/// the rows j..size of its diagonal block, then R (`size − j + |R|` values). faer stores the
/// diagonal block as a full square; its upper triangle (never read) is dropped.
struct Layout {
    /// Supernode s holds columns begin[s]..begin[s + 1].
    begin: Vec<usize>,
    /// Its off-diagonal rows are rows[row_ptr[s]..row_ptr[s + 1]] (u32: less to stream).
    row_ptr: Vec<usize>,
    rows: Vec<u32>,
    /// Its packed values start at val_ptr[s].
    val_ptr: Vec<usize>,
    /// The largest |rows| of a supernode.
    widest_pattern: usize,
}

impl Layout {
    /// The layout of faer's supernodal structure `sym`; its factor's values (`values`, in
    /// faer's layout: supernode by supernode, each column-major (size + |R|) × size) are
    /// packed in place.
    fn new(sym: &SymbolicSupernodalCholesky<usize>, values: &mut Vec<f64>) -> Result<Self> {
        let n_supernodes = sym.n_supernodes();
        let mut layout = Layout {
            begin: vec![0],
            row_ptr: vec![0],
            rows: Vec::new(),
            val_ptr: vec![0],
            widest_pattern: 0,
        };
        // Supernode s starts at `from` in faer's layout, at val_ptr[s] ≤ from in ours: the
        // columns move towards the start in order, never over values still to be moved.
        let mut from = 0;
        for s in 0..n_supernodes {
            let (start, end) = (sym.supernode_begin()[s], sym.supernode_end()[s]);
            let size = end - start;
            let pattern = sym.supernode(s).pattern();
            for &r in pattern {
                layout.rows.push(
                    u32::try_from(r)
                        .map_err(|_| Error::solve(format!("K_A has more than 2^32 dofs ({r})")))?,
                );
            }
            layout.begin.push(end);
            layout.row_ptr.push(layout.rows.len());
            let m = size + pattern.len();
            let mut to = layout.val_ptr[s];
            for j in 0..size {
                values.copy_within(from + j * m + j..from + (j + 1) * m, to);
                to += m - j;
            }
            from += m * size;
            layout.val_ptr.push(to);
            layout.widest_pattern = layout.widest_pattern.max(pattern.len());
        }
        values.truncate(layout.val_ptr[n_supernodes]);
        values.shrink_to_fit();
        Ok(layout)
    }

    fn n_supernodes(&self) -> usize {
        self.begin.len() - 1
    }

    /// Supernode s: its columns, its off-diagonal rows and its packed values.
    fn supernode<'a>(
        &'a self,
        s: usize,
        values: &'a [f64],
    ) -> (std::ops::Range<usize>, &'a [u32], &'a [f64]) {
        (
            self.begin[s]..self.begin[s + 1],
            &self.rows[self.row_ptr[s]..self.row_ptr[s + 1]],
            &values[self.val_ptr[s]..self.val_ptr[s + 1]],
        )
    }
}

/// Supernodes that the solves may treat on two threads: two groups, each a union of whole
/// subtrees of the supernodal elimination tree (so the rows a group's supernodes update
/// lie in the group or in `top`), and `top`, the rest (every ancestor of both groups).
/// The forward pass does both groups, then `top`; the backward pass `top`, then both
/// groups. The second group works in a vector of its own, merged in a fixed way, so the
/// arithmetic is the same with one thread or two.
#[derive(Clone, Debug)]
struct Split {
    /// The supernodes of each group and of `top`, increasing.
    groups: [Vec<usize>; 2],
    top: Vec<usize>,
}

impl Split {
    /// The split whose longest path, top + max(group), is shortest, counted in stored values;
    /// None when it would not save a fifth of a pass or the factor is smaller than `min`.
    fn new(layout: &Layout, min: usize) -> Option<Split> {
        let ns = layout.n_supernodes();
        let total = *layout.val_ptr.last()?;
        if total < min || ns < 2 {
            return None;
        }
        let mut owner = vec![0; *layout.begin.last()?];
        for s in 0..ns {
            owner[layout.begin[s]..layout.begin[s + 1]].fill(s);
        }
        // Children of each supernode (a parent's index exceeds its children's).
        let mut children = vec![Vec::new(); ns];
        let mut roots = Vec::new();
        for s in 0..ns {
            match layout.rows[layout.row_ptr[s]..layout.row_ptr[s + 1]].first() {
                Some(&r) => children[owner[r as usize]].push(s),
                None => roots.push(s),
            }
        }
        let mut weight: Vec<usize> = (0..ns)
            .map(|s| layout.val_ptr[s + 1] - layout.val_ptr[s])
            .collect();
        for s in 0..ns {
            if let Some(&r) = layout.rows[layout.row_ptr[s]..layout.row_ptr[s + 1]].first() {
                weight[owner[r as usize]] += weight[s];
            }
        }
        // Open the heaviest subtree of the frontier into its children, one at a time; each
        // frontier is dealt to two bins, heaviest first, into the lighter bin.
        let deal = |frontier: &[usize]| {
            let mut sorted = frontier.to_vec();
            sorted.sort_by_key(|&s| std::cmp::Reverse(weight[s]));
            let mut bins = [(0, Vec::new()), (0, Vec::new())];
            for s in sorted {
                let b = usize::from(bins[1].0 < bins[0].0);
                bins[b].0 += weight[s];
                bins[b].1.push(s);
            }
            bins
        };
        let (mut frontier, mut top_weight) = (roots, 0);
        let mut best: Option<(usize, Vec<usize>)> = None;
        for _ in 0..256 {
            let bins = deal(&frontier);
            let path = top_weight + bins[0].0.max(bins[1].0);
            if best.as_ref().is_none_or(|b| path < b.0) {
                best = Some((path, frontier.clone()));
            }
            let Some(heaviest) = frontier.iter().copied().max_by_key(|&s| weight[s]) else {
                break;
            };
            frontier.retain(|&s| s != heaviest);
            frontier.extend_from_slice(&children[heaviest]);
            top_weight += layout.val_ptr[heaviest + 1] - layout.val_ptr[heaviest];
        }
        let (path, frontier) = best?;
        if path * 5 > total * 4 {
            return None;
        }
        let mut label = vec![2u8; ns];
        for (b, (_, subtrees)) in deal(&frontier).into_iter().enumerate() {
            for root in subtrees {
                let mut stack = vec![root];
                while let Some(s) = stack.pop() {
                    label[s] = b as u8;
                    stack.extend_from_slice(&children[s]);
                }
            }
        }
        let members = |b: u8| (0..ns).filter(|&s| label[s] == b).collect::<Vec<_>>();
        Some(Split {
            groups: [members(0), members(1)],
            top: members(2),
        })
    }
}

/// Asks the CPU to bring the cache line holding `x` into cache (without waiting for it).
#[inline(always)]
fn prefetch(x: &f64) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint: it never faults and changes no memory.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (x as *const f64).cast(),
        )
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// Σ a_i b_i with eight partial sums (so that the loop vectorizes).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    let mut acc = [0.0; 8];
    for (x, y) in ca.zip(cb) {
        for k in 0..8 {
            acc[k] += x[k] * y[k];
        }
    }
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// (c_k · g)_k for four columns c_k as long as g: g is read once for the four.
#[inline(always)]
fn dot4(c: [&[f64]; 4], g: &[f64]) -> [f64; 4] {
    let n = g.len();
    let mut acc = [[0.0; 4]; 4];
    let mut i = 0;
    while i + 4 <= n {
        let gi = &g[i..i + 4];
        for (acc, c) in acc.iter_mut().zip(&c) {
            for ((a, x), y) in acc.iter_mut().zip(&c[i..i + 4]).zip(gi) {
                *a += x * y;
            }
        }
        i += 4;
    }
    let mut out = [0.0; 4];
    for ((o, acc), c) in out.iter_mut().zip(&acc).zip(&c) {
        *o = (acc[0] + acc[2]) + (acc[1] + acc[3]);
        for (x, y) in c[i..].iter().zip(&g[i..]) {
            *o += x * y;
        }
    }
    out
}

/// The columns of a supernode of K columns and r off-diagonal rows in the packed layout:
/// column j holds its K − j values in the diagonal block, then its r values below.
#[inline(always)]
fn columns<const K: usize>(vals: &[f64], r: usize) -> [&[f64]; K] {
    let mut rest = vals;
    std::array::from_fn(|j| {
        let (col, next) = rest.split_at(K - j + r);
        rest = next;
        col
    })
}

/// The forward pass over a supernode of K ≤ 4 columns (77% of the supernodes at h = 1/128
/// hold 2) starting at column c0: y_s ← L_ss⁻¹ y_s, then y_R ← y_R − L_Rs y_s row by row,
/// each row's sum in column order as in `wide_forward` (the same arithmetic), without its
/// buffer: the sums stay in registers.
#[inline(always)]
fn narrow_forward<const K: usize>(vals: &[f64], rows: &[u32], c0: usize, y: &mut [f64]) {
    let r = rows.len();
    let cols = columns::<K>(vals, r);
    let mut x = [0.0; K];
    x.copy_from_slice(&y[c0..c0 + K]);
    for j in 0..K {
        x[j] /= cols[j][0];
        for i in j + 1..K {
            x[i] -= cols[j][i - j] * x[j];
        }
    }
    y[c0..c0 + K].copy_from_slice(&x);
    let below: [&[f64]; K] = std::array::from_fn(|j| &cols[j][K - j..]);
    for (i, &row) in rows.iter().enumerate() {
        let mut t = 0.0;
        for j in 0..K {
            t += below[j][i] * x[j];
        }
        y[row as usize] -= t;
    }
}

/// The forward pass over a wider supernode: y_s ← L_ss⁻¹ y_s column by column, L_Rs y_s
/// accumulated in the contiguous buffer `t` and subtracted from y_R once. (Accumulating four
/// or eight columns per sweep of `t` measured 10–30% slower.)
fn wide_forward(
    vals: &[f64],
    rows: &[u32],
    cols: std::ops::Range<usize>,
    t: &mut [f64],
    y: &mut [f64],
) {
    let size = cols.len();
    let t = &mut t[..rows.len()];
    t.fill(0.0);
    let ys = &mut y[cols];
    let mut rest = vals;
    for j in 0..size {
        let (col, next) = rest.split_at(size - j + t.len());
        rest = next;
        let (diag, below) = col.split_at(size - j);
        let yj = ys[j] / diag[0];
        ys[j] = yj;
        for (yi, l) in ys[j + 1..].iter_mut().zip(&diag[1..]) {
            *yi -= l * yj;
        }
        for (ti, l) in t.iter_mut().zip(below) {
            *ti += l * yj;
        }
    }
    for (&r, ti) in rows.iter().zip(t.iter()) {
        y[r as usize] -= ti;
    }
}

/// The backward pass over a supernode of K ≤ 4 columns starting at column c0: y_s ←
/// L_ssᵀ⁻¹ (y_s − L_Rsᵀ y_R), y_R read as it is used, two partial sums per column (one
/// sum per column would wait on its additions).
#[inline(always)]
fn narrow_backward<const K: usize>(vals: &[f64], rows: &[u32], c0: usize, y: &mut [f64]) {
    let r = rows.len();
    let cols = columns::<K>(vals, r);
    let below: [&[f64]; K] = std::array::from_fn(|j| &cols[j][K - j..]);
    let mut acc = [[0.0; K]; 2];
    let pairs = rows.chunks_exact(2);
    let odd = pairs.remainder();
    for (p, pair) in pairs.enumerate() {
        let (g0, g1) = (y[pair[0] as usize], y[pair[1] as usize]);
        for j in 0..K {
            acc[0][j] += below[j][2 * p] * g0;
            acc[1][j] += below[j][2 * p + 1] * g1;
        }
    }
    if let [last] = odd {
        let g = y[*last as usize];
        for j in 0..K {
            acc[0][j] += below[j][r - 1] * g;
        }
    }
    let mut x = [0.0; K];
    for j in 0..K {
        x[j] = y[c0 + j] - (acc[0][j] + acc[1][j]);
    }
    for j in (0..K).rev() {
        for i in j + 1..K {
            x[j] -= cols[j][i - j] * x[i];
        }
        x[j] /= cols[j][0];
    }
    y[c0..c0 + K].copy_from_slice(&x);
}

/// The backward pass over a wider supernode: y_R gathered once into `g`, y_s − L_Rsᵀ y_R
/// four columns at a time in memory order, then L_ssᵀ⁻¹, the last column first.
fn wide_backward(
    vals: &[f64],
    rows: &[u32],
    cols: std::ops::Range<usize>,
    g: &mut [f64],
    y: &mut [f64],
) {
    // All loads of the block at once, before the dependent arithmetic needs them: the pass
    // runs from the factor's end to its start, a stream the hardware prefetchers follow
    // poorly (measured at h = 1/128: the backward pass 1.1–2.4× faster with it).
    for v in vals.iter().step_by(8) {
        prefetch(v);
    }
    let (size, r) = (cols.len(), rows.len());
    let g = &mut g[..r];
    for (gi, &row) in g.iter_mut().zip(rows) {
        *gi = y[row as usize];
    }
    let ys = &mut y[cols];
    let (mut end, mut j) = (0, 0);
    while j + 4 <= size {
        let mut c = [&vals[..0]; 4];
        for (k, ck) in c.iter_mut().enumerate() {
            end += size - (j + k) + r;
            *ck = &vals[end - r..end];
        }
        for (yj, d) in ys[j..j + 4].iter_mut().zip(dot4(c, g)) {
            *yj -= d;
        }
        j += 4;
    }
    for (j, yj) in ys.iter_mut().enumerate().skip(j) {
        end += size - j + r;
        *yj -= dot(&vals[end - r..end], g);
    }
    // L_ssᵀ⁻¹, the last column first (the block is in cache now).
    for j in (0..size).rev() {
        let col = &vals[end - (size - j + r)..end - r];
        end -= size - j + r;
        ys[j] = (ys[j] - dot(&col[1..], &ys[j + 1..])) / col[0];
    }
}

/// The smallest factor (stored values) whose solves are split in two groups: 2 MB, where a
/// pass takes about 0.2 ms and a thread's start and join are a small part of it.
const MIN_SPLIT: usize = 1 << 18;

/// The numeric factorization runs on faer's global parallelism (both cores) when its
/// supernodes hold at least this many flops (`factorization_flops`), else on one thread.
/// Measured side by side on the 2-core machine, one thread against two, full problem
/// (C last) unless said: 2D h = 1/128 (3.5e8) 47 against 101–105 ms, 1/256 (2.8e9) 220
/// against 373 ms, 1/512 (2.4e10) 1.07–1.12 against 1.71–1.78 s; 3D block h = 1/8 (2.4e8)
/// 15 against 24–39 ms, 1/16 (1.5e10) 0.38 against 0.41–0.44 s, 1/24 (1.7e11) 3.12–3.18
/// against 2.61–2.69 s (linear only, 1.2e11: 2.37–2.48 against 2.10–2.12 s); gmsh's
/// unstructured blocks of size 0.042 (1.2e11) 2.22 against 1.91 s (linear only, 7.0e10:
/// 1.44–1.46 against 1.36–1.40 s) and 0.035 (3.6e11) 6.7–7.2 against 4.9–5.0 s. Two
/// threads pay where a large share of the work is in the few widest supernodes of a 3D
/// factor (3 500–5 400 columns), not on the 2D factors of as many flops.
const PARALLEL_FLOPS: f64 = 5e10;

/// The flops of the numeric factorization, counted per supernode of k columns and r rows
/// below them: k³/3 for its diagonal block, k²r for the block below, k r² for its update
/// of the later columns (multiply-adds; a measure to compare factors, not a count of
/// instructions).
fn factorization_flops(sym: &SymbolicSupernodalCholesky<usize>) -> f64 {
    (0..sym.n_supernodes())
        .map(|s| {
            let k = (sym.supernode_end()[s] - sym.supernode_begin()[s]) as f64;
            let r = sym.supernode(s).pattern().len() as f64;
            k * k * k / 3.0 + k * k * r + k * r * r
        })
        .sum()
}

impl Factor {
    /// Factors `a`, with the dofs in `last` ordered last.
    pub fn new(a: &Sparse, last: &[usize]) -> Result<Self> {
        Self::with_split(a, last, MIN_SPLIT, |flops| {
            if flops >= PARALLEL_FLOPS {
                crate::threads::par()
            } else {
                Par::Seq
            }
        })
    }

    /// `new`, with the solves split in two groups (`Split`) if the factor stores at least
    /// `min_split` values, and the numeric factorization's parallelism chosen by `par` from
    /// its flops (`factorization_flops`).
    fn with_split(
        a: &Sparse,
        last: &[usize],
        min_split: usize,
        par: impl FnOnce(f64) -> Par,
    ) -> Result<Self> {
        let n = a.nrows();
        // Nested dissection of the other dofs, then C (ordering.rs).
        let fwd = super::ordering::constrained_last(a, last)?;
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
        .map_err(|e| {
            let why = match e {
                faer::sparse::FaerError::OutOfMemory => "not enough memory for the factor",
                _ => "the factor has more entries than its index type can count",
            };
            Error::solve(format!(
                "K_A ({n} free dofs) could not be factored: {why}; use a coarser mesh"
            ))
        })?;
        let mut values = vec![0.0; symbolic.len_val()];
        let par = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => par(factorization_flops(s)),
            SymbolicCholeskyRaw::Simplicial(_) => Par::Seq,
        };
        {
            let mut mem = MemBuffer::new(
                symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
            );
            symbolic
                .factorize_numeric_llt(
                    &mut values,
                    a.as_ref(),
                    Side::Lower,
                    LltRegularization::default(),
                    par,
                    MemStack::new(&mut mem),
                    Default::default(),
                )
                .map_err(|_| {
                    Error::solve(
                        "K_A (the viscosity stiffness on the free nodes) could not be \
                         factored: it is not positive definite to working precision. `check` \
                         refuses parts of the mesh that Γ1 does not hold; what is left is a \
                         matrix too ill-conditioned to factor: very distorted elements (see \
                         `viscontact mesh-info` for the quality) or viscosity coefficients θ, \
                         ζ many orders of magnitude apart",
                    )
                })?;
        }
        let layout = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => Layout::new(s, &mut values)?,
            SymbolicCholeskyRaw::Simplicial(_) => unreachable!("supernodal was forced"),
        };
        Ok(Factor {
            values,
            n,
            fwd,
            inv,
            last: last.len(),
            split: Split::new(&layout, min_split),
            forward_pair: Pair::default(),
            backward_pair: Pair::default(),
            layout,
        })
    }

    /// The number of dofs.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// The number of dofs ordered last.
    pub fn last(&self) -> usize {
        self.last
    }

    /// The number of stored values of L (amalgamated supernodes store some zeros).
    pub fn stored(&self) -> usize {
        self.values.len()
    }

    /// The number of stored values of L that are not exactly 0: nnz(L) without the zeros
    /// that amalgamation stores (and without entries of the pattern that happen to be 0).
    pub fn nonzeros(&self) -> usize {
        self.values.iter().filter(|v| **v != 0.0).count()
    }

    /// The position of an original dof in the factor's ordering.
    pub fn position(&self, dof: usize) -> usize {
        self.inv[dof]
    }

    /// `out[i] = x[fwd[i]]`: into the factor's ordering.
    pub fn permute(&self, x: &[f64], out: &mut [f64]) {
        for (o, &d) in out.iter_mut().zip(&self.fwd) {
            *o = x[d];
        }
    }

    /// `out[d] = x[inv[d]]`: back to the original ordering.
    pub fn unpermute(&self, x: &[f64], out: &mut [f64]) {
        for (o, &i) in out.iter_mut().zip(&self.inv) {
            *o = x[i];
        }
    }

    /// y ← L⁻¹ y in the factor's ordering: one pass over the supernodes in order. Supernode
    /// s (columns c₀..c₁, off-diagonal rows R) is the block [L_ss; L_Rs], its columns packed
    /// (`Layout`): y_s ← L_ss⁻¹ y_s, then y_R ← y_R − L_Rs y_s (`narrow_forward` for
    /// supernodes of at most four columns, `wide_forward` for the others). A factor with a
    /// `Split` runs its two groups on two threads when that pays (`Pair`).
    pub fn forward(&self, y: &mut [f64]) {
        let Some(split) = &self.split else {
            return self.forward_over(0..self.layout.n_supernodes(), y);
        };
        // The second group in a vector of its own: its columns, zeros elsewhere; it subtracts
        // its updates of `top` rows from those zeros.
        let mut z = vec![0.0; self.n];
        let cols = |s: usize| self.layout.begin[s]..self.layout.begin[s + 1];
        for &s in &split.groups[1] {
            z[cols(s)].copy_from_slice(&y[cols(s)]);
        }
        self.forward_pair.both(
            || self.forward_over(split.groups[0].iter().copied(), y),
            || self.forward_over(split.groups[1].iter().copied(), &mut z),
        );
        for &s in &split.groups[1] {
            y[cols(s)].copy_from_slice(&z[cols(s)]);
        }
        for &s in &split.top {
            for c in cols(s) {
                y[c] += z[c];
            }
        }
        self.forward_over(split.top.iter().copied(), y);
    }

    /// The forward pass over the supernodes `order` (increasing).
    fn forward_over(&self, order: impl Iterator<Item = usize>, y: &mut [f64]) {
        let layout = &self.layout;
        let mut t = vec![0.0; layout.widest_pattern];
        for s in order {
            let (cols, rows, vals) = layout.supernode(s, &self.values);
            match cols.len() {
                1 => narrow_forward::<1>(vals, rows, cols.start, y),
                2 => narrow_forward::<2>(vals, rows, cols.start, y),
                3 => narrow_forward::<3>(vals, rows, cols.start, y),
                4 => narrow_forward::<4>(vals, rows, cols.start, y),
                _ => wide_forward(vals, rows, cols, &mut t, y),
            }
        }
    }

    /// y ← L⁻ᵀ y in the factor's ordering: one pass over the supernodes in reverse. For
    /// supernode s, y_s ← L_ssᵀ⁻¹ (y_s − L_Rsᵀ y_R), the last column first
    /// (`narrow_backward` for supernodes of at most four columns, `wide_backward` for the
    /// others).
    pub fn backward(&self, y: &mut [f64]) {
        let Some(split) = &self.split else {
            return self.backward_over((0..self.layout.n_supernodes()).rev(), y);
        };
        self.backward_over(split.top.iter().rev().copied(), y);
        // The second group reads `top` rows from a copy and writes its own columns there.
        let mut z = y.to_vec();
        self.backward_pair.both(
            || self.backward_over(split.groups[0].iter().rev().copied(), y),
            || self.backward_over(split.groups[1].iter().rev().copied(), &mut z),
        );
        for &s in &split.groups[1] {
            let cols = self.layout.begin[s]..self.layout.begin[s + 1];
            y[cols.clone()].copy_from_slice(&z[cols]);
        }
    }

    /// The backward pass over the supernodes `order` (decreasing).
    fn backward_over(&self, order: impl Iterator<Item = usize>, y: &mut [f64]) {
        let layout = &self.layout;
        let mut g = vec![0.0; layout.widest_pattern];
        for s in order {
            let (cols, rows, vals) = layout.supernode(s, &self.values);
            match cols.len() {
                1 => narrow_backward::<1>(vals, rows, cols.start, y),
                2 => narrow_backward::<2>(vals, rows, cols.start, y),
                3 => narrow_backward::<3>(vals, rows, cols.start, y),
                4 => narrow_backward::<4>(vals, rows, cols.start, y),
                _ => wide_backward(vals, rows, cols, &mut g, y),
            }
        }
    }

    /// x ← K_A⁻¹ x (original ordering).
    pub fn solve(&self, x: &mut [f64]) {
        let mut y = vec![0.0; self.n];
        self.permute(x, &mut y);
        self.forward(&mut y);
        self.backward(&mut y);
        self.unpermute(&y, x);
    }

    /// The trailing block L_CC (last × last, lower triangular) of L.
    pub fn trailing_block(&self) -> Mat<f64> {
        let first = self.n - self.last;
        let mut out = Mat::zeros(self.last, self.last);
        let layout = &self.layout;
        for s in 0..layout.n_supernodes() {
            let (cols, rows, vals) = layout.supernode(s, &self.values);
            if cols.end <= first {
                continue;
            }
            let mut rest = vals;
            for col in cols.clone() {
                let (values, next) = rest.split_at(cols.end - col + rows.len());
                rest = next;
                if col < first {
                    continue;
                }
                // Rows of the diagonal block, then the pattern rows (all > col).
                let at = (col..cols.end).chain(rows.iter().map(|&r| r as usize));
                for (row, &v) in at.zip(values) {
                    out[(row - first, col - first)] = v;
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::solvers::{DenseSolveCore, Solve};
    use faer::sparse::{SparseColMat, Triplet};

    /// The SPD matrix Σ_edges w_ij (e_i − e_j)(e_i − e_j)ᵀ + diag(shift(i)) of a grid, with
    /// weights varying per edge: w_ij = 1 + ((31 i + 17 j) mod 11)/10.
    fn grid_matrix(
        n: usize,
        shift: impl Fn(usize) -> f64,
        edges: impl Iterator<Item = (usize, usize)>,
    ) -> SparseColMat<usize, f64> {
        let mut t: Vec<_> = (0..n).map(|i| Triplet::new(i, i, shift(i))).collect();
        for (i, j) in edges {
            let w = 1.0 + ((i * 31 + j * 17) % 11) as f64 / 10.0;
            t.extend([
                Triplet::new(i, i, w),
                Triplet::new(j, j, w),
                Triplet::new(i, j, -w),
                Triplet::new(j, i, -w),
            ]);
        }
        SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
    }

    /// The supernodal solves against a dense Cholesky solve of the same matrix: a 2D grid
    /// (5-point couplings, weights varying per edge, plus a diagonal shift) with a boundary
    /// row of dofs ordered last, big enough for supernodes of many widths.
    #[test]
    fn solve_matches_dense_cholesky() {
        let side = 30;
        let n = side * side;
        let edges = (0..n).flat_map(|i| {
            let (x, y) = (i % side, i / side);
            [(1, 0), (0, 1), (1, 1)]
                .into_iter()
                .filter(move |(dx, dy)| x + dx < side && y + dy < side)
                .map(move |(dx, dy)| (i, (y + dy) * side + x + dx))
        });
        let k = grid_matrix(n, |i| 0.01 + (i % 7) as f64 * 1e-3, edges);
        let last: Vec<usize> = (0..side).collect();
        let factor = Factor::new(&k, &last).unwrap();
        let b: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 101) as f64 / 50.0 - 1.0)
            .collect();
        let dense = k.to_dense().llt(Side::Lower).unwrap();
        let expected = dense.solve(faer::Mat::from_fn(n, 1, |i, _| b[i]));
        let scale = (0..n).fold(0.0f64, |a, i| a.max(expected[(i, 0)].abs()));
        // Unsplit (too small for MIN_SPLIT), then split in two groups, on one thread and two.
        let split = Factor::with_split(&k, &last, 0, |_| Par::Seq).unwrap();
        let groups = split
            .split
            .as_ref()
            .expect("the grid's tree splits")
            .groups
            .clone();
        assert!(groups.iter().all(|g| !g.is_empty()), "{groups:?}");
        let one_thread = Factor {
            forward_pair: Pair::one_thread(),
            backward_pair: Pair::one_thread(),
            ..Factor::with_split(&k, &last, 0, |_| Par::Seq).unwrap()
        };
        assert!(factor.split.is_none());
        // Every kernel is exercised: supernodes of one to four columns and wider ones.
        let layout = &factor.layout;
        let widths: std::collections::BTreeSet<usize> = (0..layout.n_supernodes())
            .map(|s| (layout.begin[s + 1] - layout.begin[s]).min(5))
            .collect();
        assert_eq!(widths, (1..=5).collect(), "supernode widths (5 = wider)");
        let solved = [&factor, &split, &one_thread].map(|f| {
            let mut x = b.clone();
            f.solve(&mut x);
            let err = (0..n).fold(0.0f64, |a, i| a.max((x[i] - expected[(i, 0)]).abs()));
            assert!(err <= 1e-12 * scale, "{err:e} vs {scale:e}");
            x
        });
        // The split's arithmetic does not depend on the threads.
        assert_eq!(solved[1], solved[2]);
        // The constrained dofs are the last ones and L_CC L_CCᵀ is their Schur complement:
        // its inverse is the C block of K⁻¹ (in the factor's order of C).
        let c = last.len();
        let l_cc = factor.trailing_block();
        let kinv = dense.inverse();
        let schur_inv = (l_cc.as_ref() * l_cc.transpose())
            .llt(Side::Lower)
            .unwrap()
            .inverse();
        let first = n - c;
        for &da in &last {
            for &db in &last {
                let (a, b) = (factor.position(da) - first, factor.position(db) - first);
                let (s, e) = (schur_inv[(a, b)], kinv[(da, db)]);
                assert!((s - e).abs() <= 1e-10 * e.abs().max(1.0), "{s} {e}");
            }
        }
        assert_eq!(c, factor.last());
    }

    /// The numeric factorization on several threads (`PARALLEL_FLOPS`: large 3D factors)
    /// gives the same values as on one, whatever the number of threads, so that the results
    /// do not depend on `--threads` and a resumed run factors K_A to the bits of the
    /// uninterrupted one. A 3D grid (7-point couplings, weights varying per edge) with one
    /// face ordered last, as the Γ3 dofs are: supernodes of hundreds of columns, where faer's
    /// parallel kernels split the work.
    #[test]
    fn parallel_factorization_is_identical_for_every_thread_count() {
        let side = 20;
        let n = side * side * side;
        let edges = (0..n).flat_map(|i| {
            let (x, y, z) = (i % side, (i / side) % side, i / (side * side));
            [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
                .into_iter()
                .filter(move |(dx, dy, dz)| x + dx < side && y + dy < side && z + dz < side)
                .map(move |(dx, dy, dz)| (i, ((z + dz) * side + y + dy) * side + x + dx))
        });
        let k = grid_matrix(n, |_| 0.01, edges);
        let last: Vec<usize> = (0..side * side).collect();
        let one = Factor::with_split(&k, &last, MIN_SPLIT, |_| Par::Seq).unwrap();
        for threads in [2, 3, 4] {
            let many = Factor::with_split(&k, &last, MIN_SPLIT, |_| Par::rayon(threads)).unwrap();
            assert!(many.values == one.values, "{threads} threads");
        }
    }
}
