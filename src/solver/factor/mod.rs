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
//! passes run on all the process's threads: disjoint subtrees of the elimination tree on
//! different threads (`split`), the wide supernodes above them with their rows or columns
//! shared out (`shared`), with the same arithmetic for every thread count.
//! faer's default amalgamation may merge a supernode across the boundary between the
//! interior dofs and C; L_CC is read column by column (`trailing`).

mod shared;
mod split;
mod trailing;

use crate::fem::Sparse;
use crate::threads::team::Team;
use crate::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::{Par, Side};
use split::{Schedule, MAX_BINS};

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
    /// The solves' units of subtrees, for factors big enough to gain from them.
    schedule: Option<Schedule>,
    /// The forward and the backward pass's units, on all threads when that pays.
    forward_team: Team,
    backward_team: Team,
    /// The columns of L_CC and the threads of its passes (`trailing`).
    trailing: trailing::Trailing,
    /// The wide supernodes' threshold and the threads of their passes (`shared`).
    shared: shared::Shared,
}

/// A set of supernodes closed under taking parents (`Factor::reach`): one flag each.
pub struct Reach(Vec<bool>);

impl Reach {
    /// Whether a pass over `reach` (every supernode for None) runs supernode s.
    fn keeps(reach: Option<&Reach>) -> impl Fn(&usize) -> bool + Copy + '_ {
        move |s| reach.is_none_or(|r| r.0[*s])
    }
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

    /// Supernode s's off-diagonal rows.
    fn pattern(&self, s: usize) -> &[u32] {
        &self.rows[self.row_ptr[s]..self.row_ptr[s + 1]]
    }

    /// The supernode that holds column c.
    fn owner(&self, c: usize) -> usize {
        self.begin.partition_point(|&b| b <= c) - 1
    }

    /// Supernode s's parent in the elimination tree (the owner of its first off-diagonal
    /// row), None for a root.
    fn parent(&self, s: usize) -> Option<usize> {
        self.pattern(s).first().map(|&r| self.owner(r as usize))
    }

    /// Supernode s: its columns, its off-diagonal rows and its packed values.
    fn supernode<'a>(
        &'a self,
        s: usize,
        values: &'a [f64],
    ) -> (std::ops::Range<usize>, &'a [u32], &'a [f64]) {
        (
            self.begin[s]..self.begin[s + 1],
            self.pattern(s),
            &values[self.val_ptr[s]..self.val_ptr[s + 1]],
        )
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
/// buffer: the sums stay in registers. `y[i]` holds row base + i; the sums of the last
/// `ext.len()` rows of the pattern are stored in `ext` instead (`split`'s records).
#[inline(always)]
fn narrow_forward<const K: usize>(
    vals: &[f64],
    rows: &[u32],
    c0: usize,
    y: &mut [f64],
    base: usize,
    ext: &mut [f64],
) {
    let r = rows.len();
    let cols = columns::<K>(vals, r);
    let c0 = c0 - base;
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
    let sum = |i: usize| {
        let mut t = 0.0;
        for j in 0..K {
            t += below[j][i] * x[j];
        }
        t
    };
    let own = r - ext.len();
    for (i, &row) in rows[..own].iter().enumerate() {
        y[row as usize - base] -= sum(i);
    }
    for (i, e) in ext.iter_mut().enumerate() {
        *e = sum(own + i);
    }
}

/// The forward pass over a wider supernode: y_s ← L_ss⁻¹ y_s column by column, L_Rs y_s
/// accumulated in the contiguous buffer `t` and subtracted from y_R once. (Accumulating four
/// or eight columns per sweep of `t` measured 10–30% slower.) `y`, `base` and `ext` as in
/// `narrow_forward`.
fn wide_forward(
    vals: &[f64],
    rows: &[u32],
    cols: std::ops::Range<usize>,
    t: &mut [f64],
    y: &mut [f64],
    base: usize,
    ext: &mut [f64],
) {
    let size = cols.len();
    let t = &mut t[..rows.len()];
    t.fill(0.0);
    let ys = &mut y[cols.start - base..cols.end - base];
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
    subtract_below(rows, t, y, base, ext);
}

/// y_R ← y_R − t for the rows R of a supernode's pattern held in `y` (`y[i]` is row
/// base + i), the last `ext.len()` of t stored in `ext` instead (`split`'s records).
fn subtract_below(rows: &[u32], t: &[f64], y: &mut [f64], base: usize, ext: &mut [f64]) {
    let own = rows.len() - ext.len();
    for (&r, ti) in rows[..own].iter().zip(t) {
        y[r as usize - base] -= ti;
    }
    ext.copy_from_slice(&t[own..]);
}

/// g ← y_R for the rows R of a supernode's pattern, the last `ext.len()` read from `ext`
/// (`split`'s records); `y[i]` is row base + i.
fn gather_below(rows: &[u32], y: &[f64], base: usize, ext: &[f64], g: &mut [f64]) {
    let own = rows.len() - ext.len();
    for (gi, &row) in g[..own].iter_mut().zip(rows) {
        *gi = y[row as usize - base];
    }
    g[own..].copy_from_slice(ext);
}

/// The backward pass over a supernode of K ≤ 4 columns starting at column c0: y_s ←
/// L_ssᵀ⁻¹ (y_s − L_Rsᵀ y_R), y_R read as it is used, two partial sums per column (one
/// sum per column would wait on its additions). `y[i]` holds row base + i; the last
/// `ext.len()` rows of the pattern are read from `ext` (`split`'s records).
#[inline(always)]
fn narrow_backward<const K: usize>(
    vals: &[f64],
    rows: &[u32],
    c0: usize,
    y: &mut [f64],
    base: usize,
    ext: &[f64],
) {
    let r = rows.len();
    let cols = columns::<K>(vals, r);
    let below: [&[f64]; K] = std::array::from_fn(|j| &cols[j][K - j..]);
    let own = r - ext.len();
    // Without records (most supernodes) y_R is read without asking where each row is.
    let acc = if ext.is_empty() {
        below_sums(&below, r, |i| y[rows[i] as usize - base])
    } else {
        below_sums(&below, r, |i| match i < own {
            true => y[rows[i] as usize - base],
            false => ext[i - own],
        })
    };
    let c0 = c0 - base;
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

/// (Σ_i below_j[i] value(i))_j for K columns over r rows, in two partial sums per column
/// (even and odd rows): `narrow_backward`'s L_Rsᵀ y_R.
#[inline(always)]
fn below_sums<const K: usize>(
    below: &[&[f64]; K],
    r: usize,
    value: impl Fn(usize) -> f64,
) -> [[f64; K]; 2] {
    let mut acc = [[0.0; K]; 2];
    for p in 0..r / 2 {
        let (g0, g1) = (value(2 * p), value(2 * p + 1));
        for j in 0..K {
            acc[0][j] += below[j][2 * p] * g0;
            acc[1][j] += below[j][2 * p + 1] * g1;
        }
    }
    if r % 2 == 1 {
        let g = value(r - 1);
        for j in 0..K {
            acc[0][j] += below[j][r - 1] * g;
        }
    }
    acc
}

/// The backward pass over a wider supernode: y_R gathered once into `g`, y_s − L_Rsᵀ y_R
/// four columns at a time in memory order, then L_ssᵀ⁻¹, the last column first. `y`,
/// `base` and `ext` as in `narrow_backward`.
fn wide_backward(
    vals: &[f64],
    rows: &[u32],
    cols: std::ops::Range<usize>,
    g: &mut [f64],
    y: &mut [f64],
    base: usize,
    ext: &[f64],
) {
    // All loads of the block at once, before the dependent arithmetic needs them: the pass
    // runs from the factor's end to its start, a stream the hardware prefetchers follow
    // poorly (measured at h = 1/128: the backward pass 1.1–2.4× faster with it).
    for v in vals.iter().step_by(8) {
        prefetch(v);
    }
    let (size, r) = (cols.len(), rows.len());
    let g = &mut g[..r];
    gather_below(rows, y, base, ext, g);
    let ys = &mut y[cols.start - base..cols.end - base];
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

/// The smallest factor (stored values) whose solves are split in units (and whose
/// arithmetic may take two groups, `split`): 2 MB, where a pass takes about 0.2 ms and a
/// thread's start and join are a small part of it.
const MIN_SPLIT: usize = 1 << 18;

/// The numeric factorization runs on faer's global parallelism (both cores) when its
/// supernodes hold at least this many flops (`factorization_flops`), else on one thread.
/// Two threads pay where a large share of the work is in the few widest supernodes of a 3D
/// factor (3 500–5 400 columns), not on the 2D factors of as many flops: every factor
/// measured up to 2.4e10 flops was faster on one thread, every one from 7.0e10 on two
/// (docs/performance.md, "The measurements behind the code's constants").
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

/// The order of `a`'s dofs (nested dissection of the others, then `last`: ordering.rs), its
/// inverse, and the symbolic analysis in it.
type Analysis = (Vec<usize>, Vec<usize>, SymbolicCholesky<usize>);

fn analysis(a: &Sparse, last: &[usize]) -> Result<Analysis> {
    let fwd = super::ordering::constrained_last(a, last)?;
    let mut inv = vec![0; a.nrows()];
    for (i, &d) in fwd.iter().enumerate() {
        inv[d] = i;
    }
    let symbolic = symbolic(a, &fwd, &inv)?;
    Ok((fwd, inv, symbolic))
}

/// The bytes of the values of L (faer's numeric factorization holds them all at once).
fn values_bytes(symbolic: &SymbolicCholesky<usize>) -> f64 {
    8.0 * symbolic.len_val() as f64
}

/// The bytes of the values of the factor of `a` with the dofs in `last` ordered last, from
/// its ordering and symbolic analysis alone (no numbers: seconds where the factorization
/// takes minutes): what `check` prints, and what a run checks before it factors.
pub fn predicted_bytes(a: &Sparse, last: &[usize]) -> Result<f64> {
    let (_, _, symbolic) = analysis(a, last)?;
    Ok(values_bytes(&symbolic))
}

/// The symbolic analysis of `a` in the ordering `fwd` (`inv` its inverse), supernodal.
fn symbolic(a: &Sparse, fwd: &[usize], inv: &[usize]) -> Result<SymbolicCholesky<usize>> {
    let n = a.nrows();
    let params = CholeskySymbolicParams {
        supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
        ..Default::default()
    };
    let perm = PermRef::new_checked(fwd, inv, n);
    factorize_symbolic_cholesky(
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
    })
}

/// The values of L for `symbolic`, by faer's numeric factorization with parallelism `par`.
fn numeric(a: &Sparse, symbolic: &SymbolicCholesky<usize>, par: Par) -> Result<Vec<f64>> {
    let mut values = vec![0.0; symbolic.len_val()];
    let mut mem =
        MemBuffer::new(symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()));
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
    Ok(values)
}

#[derive(Clone, Copy)]
struct Splits {
    /// The smallest factor (stored values) whose forward pass may take two groups.
    two_groups: usize,
    /// The smallest factor whose solves run in units, and the bins they are dealt to.
    units: usize,
    bins: usize,
    /// The fewest values of a supernode whose passes share out its rows (`shared`).
    shared: usize,
}

impl Factor {
    /// Factors `a`, with the dofs in `last` ordered last.
    pub fn new(a: &Sparse, last: &[usize]) -> Result<Self> {
        let split = Splits {
            two_groups: MIN_SPLIT,
            units: MIN_SPLIT,
            bins: crate::threads::count().min(MAX_BINS),
            shared: shared::SHARED_MIN,
        };
        Self::with_split(a, last, split, |flops| {
            if flops >= PARALLEL_FLOPS {
                crate::threads::par()
            } else {
                Par::Seq
            }
        })
    }

    /// `new`, with the solves' schedule from `split`, and the numeric factorization's
    /// parallelism chosen by `par` from its flops (`factorization_flops`).
    fn with_split(
        a: &Sparse,
        last: &[usize],
        split: Splits,
        par: impl FnOnce(f64) -> Par,
    ) -> Result<Self> {
        let n = a.nrows();
        let (fwd, inv, symbolic) = analysis(a, last)?;
        crate::resources::check_factor(values_bytes(&symbolic), n)?;
        let par = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => par(factorization_flops(s)),
            SymbolicCholeskyRaw::Simplicial(_) => Par::Seq,
        };
        let mut values = numeric(a, &symbolic, par)?;
        let layout = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => Layout::new(s, &mut values)?,
            SymbolicCholeskyRaw::Simplicial(_) => unreachable!("supernodal was forced"),
        };
        let mut factor = Factor {
            values,
            n,
            fwd,
            inv,
            last: last.len(),
            schedule: None,
            forward_team: Team::default(),
            backward_team: Team::default(),
            layout,
            trailing: trailing::Trailing::default(),
            shared: shared::Shared {
                min: split.shared,
                ..Default::default()
            },
        };
        factor.schedule = Schedule::new(
            &factor.layout,
            split.two_groups,
            split.units,
            split.bins,
            |s| factor.is_shared(s),
        );
        factor.trailing = trailing::Trailing::new(&factor);
        Ok(factor)
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
    /// `Schedule` runs its units on all threads when that pays (`Team`), then the rest
    /// (`split`).
    pub fn forward(&self, y: &mut [f64]) {
        self.forward_in(y, None);
    }

    /// `forward` over the supernodes of `reach` alone (all of them for None): y must be 0
    /// outside the reach's columns, and stays so.
    fn forward_in(&self, y: &mut [f64], reach: Option<&Reach>) {
        let kept = Reach::keeps(reach);
        let Some(schedule) = &self.schedule else {
            return self.forward_over((0..self.layout.n_supernodes()).filter(kept), y);
        };
        let widest = self.layout.widest_pattern;
        let mut record = vec![0.0; schedule.record_len()];
        self.forward_team
            .each(schedule.pieces(y, &mut record), |units| {
                let mut t = vec![0.0; widest];
                for (unit, ys, rs) in units {
                    for s in unit.supernodes.clone().filter(kept) {
                        let ext = schedule.unit_records(unit, s, rs);
                        self.forward_step(s, ys, unit.cols.start, ext, &mut t, false);
                    }
                }
            });
        // The records and the upper supernodes in supernode order, then `top`.
        let z_from = schedule.z_from;
        let mut z = vec![0.0; self.n - z_from];
        let mut t = vec![0.0; widest];
        for &(s, upper) in schedule.replay.iter().filter(|r| kept(&r.0)) {
            let (ext, to_z) = schedule.records(s, &mut record);
            if upper {
                self.forward_step(s, y, 0, ext, &mut t, true);
            }
            let rows = self.layout.pattern(s);
            let rows = &rows[rows.len() - ext.len()..];
            for (i, (&r, v)) in rows.iter().zip(&*ext).enumerate() {
                match i < to_z {
                    true => y[r as usize] -= v,
                    false => z[r as usize - z_from] -= v,
                }
            }
        }
        for &s in schedule.top.iter().filter(|s| kept(s)) {
            for c in self.layout.begin[s]..self.layout.begin[s + 1] {
                y[c] += z[c - z_from];
            }
        }
        self.forward_over(schedule.top.iter().copied().filter(kept), y);
    }

    /// The forward pass over supernode s, `y[i]` holding row base + i, the updates of the
    /// last `ext.len()` rows of its pattern stored in `ext`; `t` a buffer of
    /// `widest_pattern` values; a wide supernode's rows shared out over the threads when
    /// `share` (`shared`: outside the units).
    fn forward_step(
        &self,
        s: usize,
        y: &mut [f64],
        base: usize,
        ext: &mut [f64],
        t: &mut [f64],
        share: bool,
    ) {
        // Inside a unit (`share` false) a wide supernode's forward pass is `wide_forward`:
        // the shared pass has its bits.
        if share && self.is_shared(s) {
            return self.shared_forward(s, y, base, ext, t);
        }
        let (cols, rows, vals) = self.layout.supernode(s, &self.values);
        match cols.len() {
            1 => narrow_forward::<1>(vals, rows, cols.start, y, base, ext),
            2 => narrow_forward::<2>(vals, rows, cols.start, y, base, ext),
            3 => narrow_forward::<3>(vals, rows, cols.start, y, base, ext),
            4 => narrow_forward::<4>(vals, rows, cols.start, y, base, ext),
            _ => wide_forward(vals, rows, cols, t, y, base, ext),
        }
    }

    /// The forward pass over the supernodes `order` (increasing) on the whole of y.
    fn forward_over(&self, order: impl Iterator<Item = usize>, y: &mut [f64]) {
        let mut t = vec![0.0; self.layout.widest_pattern];
        for s in order {
            self.forward_step(s, y, 0, &mut [], &mut t, true);
        }
    }

    /// y ← L⁻ᵀ y in the factor's ordering: one pass over the supernodes in reverse. For
    /// supernode s, y_s ← L_ssᵀ⁻¹ (y_s − L_Rsᵀ y_R), the last column first
    /// (`narrow_backward` for supernodes of at most four columns, `wide_backward` for the
    /// others). With a `Schedule`: `top` and the upper supernodes, then the units on all
    /// threads when that pays, each reading the rows outside it from the record.
    pub fn backward(&self, y: &mut [f64]) {
        self.backward_in(y, None);
    }

    /// `backward` over the supernodes of `reach` alone (all of them for None): y is right
    /// on the reach's columns only.
    fn backward_in(&self, y: &mut [f64], reach: Option<&Reach>) {
        let kept = Reach::keeps(reach);
        let Some(schedule) = &self.schedule else {
            return self.backward_over((0..self.layout.n_supernodes()).rev().filter(kept), y);
        };
        self.backward_over(schedule.top.iter().rev().copied().filter(kept), y);
        let replay = schedule.replay.iter().rev().filter(|r| kept(&r.0));
        self.backward_over(replay.clone().filter(|r| r.1).map(|r| r.0), y);
        let mut record = vec![0.0; schedule.record_len()];
        for &(s, _) in replay.filter(|r| !r.1) {
            let (ext, _) = schedule.records(s, &mut record);
            let rows = self.layout.pattern(s);
            let rows = &rows[rows.len() - ext.len()..];
            for (v, &r) in ext.iter_mut().zip(rows) {
                *v = y[r as usize];
            }
        }
        let widest = self.layout.widest_pattern;
        self.backward_team
            .each(schedule.pieces(y, &mut record), |units| {
                let mut g = vec![0.0; widest];
                for (unit, ys, rs) in units {
                    for s in unit.supernodes.clone().rev().filter(kept) {
                        let ext = schedule.unit_records(unit, s, rs);
                        self.backward_step(s, ys, unit.cols.start, ext, &mut g, false);
                    }
                }
            });
    }

    /// The backward pass over supernode s, `y[i]` holding row base + i, the last
    /// `ext.len()` rows of its pattern read from `ext`; `g` a buffer of `widest_pattern`
    /// values; a wide supernode's columns shared out over the threads when `share`
    /// (`shared`: outside the units).
    fn backward_step(
        &self,
        s: usize,
        y: &mut [f64],
        base: usize,
        ext: &[f64],
        g: &mut [f64],
        share: bool,
    ) {
        if self.is_shared(s) {
            return self.shared_backward(s, y, base, ext, g, share);
        }
        let (cols, rows, vals) = self.layout.supernode(s, &self.values);
        match cols.len() {
            1 => narrow_backward::<1>(vals, rows, cols.start, y, base, ext),
            2 => narrow_backward::<2>(vals, rows, cols.start, y, base, ext),
            3 => narrow_backward::<3>(vals, rows, cols.start, y, base, ext),
            4 => narrow_backward::<4>(vals, rows, cols.start, y, base, ext),
            _ => wide_backward(vals, rows, cols, g, y, base, ext),
        }
    }

    /// The backward pass over the supernodes `order` (decreasing) on the whole of y.
    fn backward_over(&self, order: impl Iterator<Item = usize>, y: &mut [f64]) {
        let mut g = vec![0.0; self.layout.widest_pattern];
        for s in order {
            self.backward_step(s, y, 0, &[], &mut g, true);
        }
    }

    /// The supernodes that hold one of the positions `at` (the factor's ordering) and
    /// their ancestors in the elimination tree.
    pub fn reach(&self, at: impl IntoIterator<Item = usize>) -> Reach {
        let layout = &self.layout;
        let mut kept = vec![false; layout.n_supernodes()];
        for p in at {
            let mut s = Some(layout.owner(p));
            while let Some(t) = s.filter(|&t| !kept[t]) {
                kept[t] = true;
                s = layout.parent(t);
            }
        }
        Reach(kept)
    }

    /// y ← (L Lᵀ)⁻¹ y on the positions of `reach` (`Factor::reach` of them), y holding 0
    /// elsewhere: the forward and backward passes over the reach's supernodes alone. The
    /// others' columns of y hold 0 in the forward pass, so their updates are zeros, and
    /// the backward pass reads only ancestors; so the reach's entries are those of the
    /// whole solve, and a product through the factor (the sparse dual's D v) skips the
    /// supernodes that touch neither its right side nor its answer.
    pub fn solve_within(&self, reach: &Reach, y: &mut [f64]) {
        self.forward_in(y, Some(reach));
        self.backward_in(y, Some(reach));
    }

    /// x ← K_A⁻¹ x (original ordering).
    pub fn solve(&self, x: &mut [f64]) {
        let mut y = vec![0.0; self.n];
        self.permute(x, &mut y);
        self.forward(&mut y);
        self.backward(&mut y);
        self.unpermute(&y, x);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::solvers::{DenseSolveCore, Solve};
    use faer::sparse::{SparseColMat, Triplet};
    use faer::Mat;

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

    /// A 2D grid's matrix (5-point couplings and one diagonal, weights varying per edge,
    /// plus a diagonal shift), its first row of dofs (to order last) and a right side: big
    /// enough for supernodes of many widths.
    fn grid_2d() -> (SparseColMat<usize, f64>, Vec<usize>, Vec<f64>) {
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
        let b = (0..n)
            .map(|i| ((i * 7919) % 101) as f64 / 50.0 - 1.0)
            .collect();
        (k, (0..side).collect(), b)
    }

    /// The 2D grid's matrix and its dofs ordered last.
    fn grid_2d_with_last() -> (SparseColMat<usize, f64>, Vec<usize>) {
        let (k, last, _) = grid_2d();
        (k, last)
    }

    /// A 3D grid of side³ dofs (7-point couplings, weights varying per edge) and one face
    /// to order last, as the Γ3 dofs are.
    fn grid_3d_with_last(side: usize) -> (SparseColMat<usize, f64>, Vec<usize>) {
        let n = side * side * side;
        let edges = (0..n).flat_map(move |i| {
            let (x, y, z) = (i % side, (i / side) % side, i / (side * side));
            [(1, 0, 0), (0, 1, 0), (0, 0, 1)]
                .into_iter()
                .filter(move |(dx, dy, dz)| x + dx < side && y + dy < side && z + dz < side)
                .map(move |(dx, dy, dz)| (i, ((z + dz) * side + y + dy) * side + x + dx))
        });
        (grid_matrix(n, |_| 0.01, edges), (0..side * side).collect())
    }

    /// K⁻¹ b by a dense Cholesky solve.
    fn dense_solve(k: &SparseColMat<usize, f64>, b: &[f64]) -> Vec<f64> {
        let rhs = Mat::from_fn(b.len(), 1, |i, _| b[i]);
        let x = k.to_dense().llt(Side::Lower).unwrap().solve(rhs);
        (0..b.len()).map(|i| x[(i, 0)]).collect()
    }

    /// `f.solve(b)`, checked against `expected` (`dense_solve`): its bits.
    fn solve_checked(f: &Factor, b: &[f64], expected: &[f64]) -> Vec<u64> {
        let scale = expected.iter().fold(0.0f64, |a, e| a.max(e.abs()));
        let mut x = b.to_vec();
        f.solve(&mut x);
        let err = x
            .iter()
            .zip(expected)
            .fold(0.0f64, |a, (x, e)| a.max((x - e).abs()));
        assert!(err <= 1e-12 * scale, "{err:e} vs {scale:e}");
        x.iter().map(|v| v.to_bits()).collect()
    }

    /// The split solves give the same bits for 1 to 8 threads (as many bins of units) and
    /// on one thread or several, with the serial pass's arithmetic (then they equal the
    /// serial pass) and with two groups.
    #[test]
    fn split_solves_are_identical_for_every_thread_count() {
        let (k, last, b) = grid_2d();
        let expected = dense_solve(&k, &b);
        let serial = solve_checked(&Factor::new(&k, &last).unwrap(), &b, &expected);
        for two_groups in [usize::MAX, 0] {
            let mut reference = None;
            for bins in 1..=8 {
                let split = Splits {
                    two_groups,
                    units: 0,
                    bins,
                    shared: usize::MAX,
                };
                let f = Factor {
                    forward_team: Team::of(bins),
                    backward_team: Team::of(bins),
                    ..Factor::with_split(&k, &last, split, |_| Par::Seq).unwrap()
                };
                if bins >= 3 {
                    let units = f.schedule.as_ref().map_or(0, |s| s.units.len());
                    assert!(units >= 3, "{bins} bins: {units} units");
                }
                // `Team` probes both ways: several solves.
                for _ in 0..3 {
                    let x = solve_checked(&f, &b, &expected);
                    let reference = reference.get_or_insert_with(|| x.clone());
                    assert!(x == *reference, "{bins} bins, two groups from {two_groups}");
                }
            }
            if two_groups == usize::MAX {
                assert!(
                    reference == Some(serial.clone()),
                    "not the serial pass's bits"
                );
            }
        }
    }

    /// The wide supernodes' passes (`shared`) on a 3D grid with a face ordered last, every
    /// supernode of 20 000 values or more taking them, with panels shared out from 64 rows:
    /// the forward pass has the bits of the serial pass, and the solves have the same bits
    /// for 1 to 4 threads (as many bins of units), whichever supernodes run inside the
    /// units, and agree with the serial pass's solve (`solve_matches_dense_cholesky` checks
    /// that one) to 1e-12.
    #[test]
    fn shared_supernodes_are_identical_for_every_thread_count() {
        let (k, last) = grid_3d_with_last(20);
        let n = k.nrows();
        let b: Vec<f64> = (0..n)
            .map(|i| ((i * 37) % 23) as f64 / 11.0 - 1.0)
            .collect();
        let factor = |bins: usize, shared: usize| {
            let split = Splits {
                two_groups: MIN_SPLIT,
                units: 0,
                bins,
                shared,
            };
            let mut f = Factor {
                forward_team: Team::of(bins),
                backward_team: Team::of(bins),
                ..Factor::with_split(&k, &last, split, |_| Par::Seq).unwrap()
            };
            f.shared.share_rows = 64;
            f.shared.forward_team = Team::of(bins);
            f.shared.backward_team = Team::of(bins);
            f
        };
        let serial = factor(1, usize::MAX);
        let mut y = b.clone();
        serial.forward(&mut y);
        let serial_forward: Vec<u64> = y.iter().map(|v| v.to_bits()).collect();
        let mut expected = b.clone();
        serial.solve(&mut expected);
        let mut reference = None;
        for bins in 1..=4 {
            let f = factor(bins, 20_000);
            let ns = f.layout.n_supernodes();
            let shared: Vec<usize> = (0..ns).filter(|&s| f.is_shared(s)).collect();
            let widest = shared
                .iter()
                .map(|&s| f.layout.begin[s + 1] - f.layout.begin[s]);
            assert!(
                shared.len() >= 3 && widest.max() > Some(2 * 128),
                "{shared:?}"
            );
            // `Team` probes both ways: several solves.
            for _ in 0..3 {
                let mut y = b.clone();
                f.forward(&mut y);
                let bits: Vec<u64> = y.iter().map(|v| v.to_bits()).collect();
                assert!(bits == serial_forward, "forward, {bins} bins");
                let x = solve_checked(&f, &b, &expected);
                assert!(
                    *reference.get_or_insert_with(|| x.clone()) == x,
                    "{bins} bins"
                );
            }
        }
    }

    /// `solve_within` on the reach of one face of a 3D grid in a linear run's order (the
    /// sparse dual's products): on the face it gives the whole solve's values, with the
    /// serial arithmetic and with two groups and units on 1 to 4 threads, and it skips
    /// supernodes.
    #[test]
    fn solves_within_a_reach_match_the_whole_solve() {
        let (k, face) = grid_3d_with_last(20);
        for (two_groups, bins) in [(usize::MAX, 1), (0, 1), (0, 2), (0, 3), (0, 4)] {
            let split = Splits {
                two_groups,
                units: 0,
                bins,
                shared: 20_000,
            };
            let f = Factor {
                forward_team: Team::of(bins),
                backward_team: Team::of(bins),
                ..Factor::with_split(&k, &[], split, |_| Par::Seq).unwrap()
            };
            let at: Vec<usize> = face.iter().map(|&d| f.position(d)).collect();
            let reach = f.reach(at.iter().copied());
            let kept = reach.0.iter().filter(|&&k| k).count();
            assert!(kept < f.layout.n_supernodes() / 2, "{kept} kept");
            let mut rhs = vec![0.0; f.dim()];
            for (i, &p) in at.iter().enumerate() {
                rhs[p] = ((i * 37) % 23) as f64 / 11.0 - 1.0;
            }
            let mut whole = rhs.clone();
            f.forward(&mut whole);
            f.backward(&mut whole);
            // Several solves: `Team` probes both ways.
            for _ in 0..3 {
                let mut y = rhs.clone();
                f.solve_within(&reach, &mut y);
                for &p in &at {
                    assert!(y[p] == whole[p] && y[p] != 0.0, "{two_groups} {bins}: {p}");
                }
            }
        }
    }

    /// The supernodal solves against a dense Cholesky solve of the same matrix, with a
    /// boundary row of dofs ordered last, and its trailing block.
    #[test]
    fn solve_matches_dense_cholesky() {
        let (k, last, b) = grid_2d();
        let n = b.len();
        let factor = Factor::new(&k, &last).unwrap();
        assert!(factor.schedule.is_none(), "too small for MIN_SPLIT");
        // Every kernel is exercised: supernodes of one to four columns and wider ones.
        let layout = &factor.layout;
        let widths: std::collections::BTreeSet<usize> = (0..layout.n_supernodes())
            .map(|s| (layout.begin[s + 1] - layout.begin[s]).min(5))
            .collect();
        assert_eq!(widths, (1..=5).collect(), "supernode widths (5 = wider)");
        solve_checked(&factor, &b, &dense_solve(&k, &b));
        // The constrained dofs are the last ones and L_CC L_CCᵀ is their Schur complement:
        // its inverse is the C block of K⁻¹ (in the factor's order of C).
        let c = last.len();
        let l_cc = factor.trailing_block();
        let kinv = k.to_dense().llt(Side::Lower).unwrap().inverse();
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

    /// The passes over L_CC alone (`trailing`) against the dense block: (K_A⁻¹)_CC v by
    /// `trailing_solve` equals the C part of a whole solve, and `trailing_product` is
    /// L_CC L_CCᵀ v. On the 2D grid, whose root supernode straddles the start of C, and on
    /// a 3D grid with a face ordered last.
    #[test]
    fn trailing_passes_match_the_dense_block() {
        for (k, last) in [grid_2d_with_last(), grid_3d_with_last(12)] {
            let factor = Factor::new(&k, &last).unwrap();
            let (n, c) = (factor.dim(), factor.last());
            let first = n - c;
            let v: Vec<f64> = (0..c)
                .map(|i| ((i * 37) % 23) as f64 / 11.0 - 1.0)
                .collect();
            let mut whole = vec![0.0; n];
            whole[first..].copy_from_slice(&v);
            factor.forward(&mut whole);
            factor.backward(&mut whole);
            let mut y = v.clone();
            factor.trailing_solve(&mut y);
            let scale = whole.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            for (a, b) in y.iter().zip(&whole[first..]) {
                assert!((a - b).abs() <= 1e-13 * scale, "{a} {b}");
            }
            let l = factor.trailing_block();
            let expected = &l * (l.transpose() * Mat::from_fn(c, 1, |i, _| v[i]));
            let mut out = vec![1.0; c];
            factor.trailing_product(&v, &mut out);
            let scale = expected.norm_max();
            for (i, o) in out.iter().enumerate() {
                assert!((o - expected[(i, 0)]).abs() <= 1e-13 * scale, "{o}");
            }
            // The two are inverse to each other.
            let mut back = vec![0.0; c];
            factor.trailing_product(&y, &mut back);
            for (a, b) in back.iter().zip(&v) {
                assert!((a - b).abs() <= 1e-11, "{a} {b}");
            }
        }
    }

    /// `trailing_solve` gives the same bits on 1 to 4 threads, its rows and columns shared
    /// out below every panel (a face of 400 dofs: four panels).
    #[test]
    fn trailing_solve_is_identical_for_every_thread_count() {
        let (k, last) = grid_3d_with_last(20);
        let mut factor = Factor::new(&k, &last).unwrap();
        let c = factor.last();
        let v: Vec<f64> = (0..c)
            .map(|i| ((i * 37) % 23) as f64 / 11.0 - 1.0)
            .collect();
        let mut reference = None;
        for threads in 1..=4 {
            factor.trailing.forward_team = Team::of(threads);
            factor.trailing.backward_team = Team::of(threads);
            factor.trailing.share_rows = 0;
            // `Team` probes both ways: several solves.
            for _ in 0..20 {
                let mut y = v.clone();
                factor.trailing_solve(&mut y);
                let bits: Vec<u64> = y.iter().map(|x| x.to_bits()).collect();
                assert!(
                    *reference.get_or_insert(bits.clone()) == bits,
                    "{threads} threads"
                );
            }
        }
    }

    /// The numeric factorization on several threads (`PARALLEL_FLOPS`: large 3D factors)
    /// gives the same values as on one, whatever the number of threads, so that the results
    /// do not depend on `--threads` and a resumed run factors K_A to the bits of the
    /// uninterrupted one. A 3D grid with one face ordered last (`grid_3d_with_last`):
    /// supernodes of hundreds of columns, where faer's parallel kernels split the work.
    #[test]
    fn parallel_factorization_is_identical_for_every_thread_count() {
        let (k, last) = grid_3d_with_last(20);
        let split = Splits {
            two_groups: MIN_SPLIT,
            units: MIN_SPLIT,
            bins: 2,
            shared: usize::MAX,
        };
        let one = Factor::with_split(&k, &last, split, |_| Par::Seq).unwrap();
        for threads in [2, 3, 4] {
            let many = Factor::with_split(&k, &last, split, |_| Par::rayon(threads)).unwrap();
            assert!(many.values == one.values, "{threads} threads");
        }
    }
}
