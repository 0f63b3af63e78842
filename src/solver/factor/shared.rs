//! The passes over a wide supernode, its rows or its columns shared out over the threads.
//!
//! The supernodes above the units (`split`) run while the units' threads wait, and in 3D
//! they are the nested dissection's top separators, dense and large: on the block at
//! h = 1/24 the root alone (C and the top separator, 3 657 columns) holds 8.8 % of L's
//! values, and with 16 bins the three supernodes above the units hold 24 %. So a supernode
//! of at least `SHARED_MIN` stored values is done in panels of `PANEL` columns, counted
//! from its first column:
//!
//! - **forward**: the panel's triangle on one thread, then every row below the panel (the
//!   diagonal block's, and R's into the buffer t) receives the panel's columns' updates in
//!   column order, the rows in blocks over the threads. Each row's arithmetic is
//!   `wide_forward`'s, so the bits are those of the serial pass.
//! - **backward**: y_s − L_Rsᵀ y_R by blocks of columns, each column's sum whole as in
//!   `wide_backward`; then L_ssᵀ⁻¹ from the last panel up: the sums of the panel's columns
//!   over the rows below the panel, by blocks of columns over the threads, then the
//!   panel's triangle on one thread. Each column's sum is cut at its panel's end, a place
//!   fixed by the supernode: the bits are the same for every thread count, and whether the
//!   supernode runs here or inside a unit on one thread, but they differ in the last bits
//!   from `wide_backward`'s single sum. So every supernode this large takes this
//!   arithmetic, wherever it runs.
//!
//! The units' threads run their own supernodes on one thread each (`share` false): there
//! the others are busy.

use super::{dot, dot4, wide_forward, Factor};
use crate::solver::team::{blocks, Team};

/// The fewest stored values of a supernode that takes these passes: 8 MB, a pass of about
/// a millisecond, where a panel's hand-out to the threads (a few microseconds, one per
/// panel of `PANEL` columns) is a small part.
pub(super) const SHARED_MIN: usize = 1 << 20;

/// The columns of a panel.
const PANEL: usize = 128;

/// Rows below a panel (forward) or columns' sums (backward) from which the work is shared
/// out: fewer take less time than waking the threads.
const SHARE_ROWS: usize = 1024;

/// The thresholds and the threads of the wide supernodes' passes.
pub(super) struct Shared {
    /// `SHARED_MIN` and `SHARE_ROWS`, or other thresholds in the tests.
    pub(super) min: usize,
    pub(super) share_rows: usize,
    pub(super) forward_team: Team,
    pub(super) backward_team: Team,
}

impl Default for Shared {
    fn default() -> Self {
        Shared {
            min: SHARED_MIN,
            share_rows: SHARE_ROWS,
            forward_team: Team::default(),
            backward_team: Team::default(),
        }
    }
}

/// Where column j of a supernode of `size` columns and r rows below starts in its packed
/// values: Σ_{i<j} (size − i + r).
fn column_start(size: usize, r: usize, j: usize) -> usize {
    j * (2 * (size + r) + 1 - j) / 2
}

/// `v` cut into `pieces` consecutive blocks (some empty where `v` is shorter), each with
/// its first index.
fn cut(v: &mut [f64], pieces: usize) -> Vec<(usize, &mut [f64])> {
    let n = v.len();
    let mut rest = v;
    let mut out = Vec::with_capacity(pieces);
    for k in 0..pieces {
        let range = k * n / pieces..(k + 1) * n / pieces;
        let (piece, tail) = std::mem::take(&mut rest).split_at_mut(range.len());
        out.push((range.start, piece));
        rest = tail;
    }
    out
}

/// Runs the parts on the team's threads, else one after the other here.
fn each<T: Send>(team: Option<&Team>, parts: Vec<T>, work: impl Fn(T) + Sync) {
    match team {
        Some(team) => team.each(parts, work),
        None => parts.into_iter().for_each(work),
    }
}

impl Factor {
    /// Whether supernode s takes this module's passes.
    pub(super) fn is_shared(&self, s: usize) -> bool {
        let values = self.layout.val_ptr[s + 1] - self.layout.val_ptr[s];
        let size = self.layout.begin[s + 1] - self.layout.begin[s];
        values >= self.shared.min && size > 4
    }

    /// `wide_forward` over supernode s (the same bits), in panels whose rows below are
    /// shared out over the threads when `share`. `y`, `base`, `ext` and `t` as in
    /// `forward_step`.
    pub(super) fn shared_forward(
        &self,
        s: usize,
        y: &mut [f64],
        base: usize,
        ext: &mut [f64],
        t: &mut [f64],
        share: bool,
    ) {
        let (cols, rows, vals) = self.layout.supernode(s, &self.values);
        if !share {
            return wide_forward(vals, rows, cols, t, y, base, ext);
        }
        let (size, r) = (cols.len(), rows.len());
        let column = |j: usize| &vals[column_start(size, r, j)..column_start(size, r, j + 1)];
        let t = &mut t[..r];
        t.fill(0.0);
        let ys = &mut y[cols.start - base..cols.end - base];
        for p in (0..size).step_by(PANEL) {
            let q = (p + PANEL).min(size);
            for j in p..q {
                let col = column(j);
                let yj = ys[j] / col[0];
                ys[j] = yj;
                for (yi, l) in ys[j + 1..q].iter_mut().zip(&col[1..]) {
                    *yi -= l * yj;
                }
            }
            let (head, low) = ys.split_at_mut(q);
            let solved = &head[p..];
            let large = size - q + r >= self.shared.share_rows;
            let team = &self.shared.forward_team;
            let pieces = team.pieces(large);
            let parts: Vec<_> = cut(low, pieces).into_iter().zip(cut(t, pieces)).collect();
            each(
                large.then_some(team),
                parts,
                |((low_at, low), (t_at, t))| {
                    for (k, j) in (p..q).enumerate() {
                        let (col, yj) = (column(j), solved[k]);
                        // Row q + low_at is entry q + low_at − j of column j; R's row t_at is
                        // entry size − j + t_at.
                        for (yi, l) in low.iter_mut().zip(&col[q + low_at - j..]) {
                            *yi -= l * yj;
                        }
                        for (ti, l) in t.iter_mut().zip(&col[size - j + t_at..]) {
                            *ti += l * yj;
                        }
                    }
                },
            );
        }
        let own = r - ext.len();
        for (&row, ti) in rows[..own].iter().zip(t.iter()) {
            y[row as usize - base] -= ti;
        }
        ext.copy_from_slice(&t[own..]);
    }

    /// y_s ← L_ssᵀ⁻¹ (y_s − L_Rsᵀ y_R) over supernode s in this module's arithmetic, its
    /// columns' sums shared out over the threads when `share`. `y`, `base`, `ext` and `g` as
    /// in `backward_step`.
    pub(super) fn shared_backward(
        &self,
        s: usize,
        y: &mut [f64],
        base: usize,
        ext: &[f64],
        g: &mut [f64],
        share: bool,
    ) {
        let (cols, rows, vals) = self.layout.supernode(s, &self.values);
        let (size, r) = (cols.len(), rows.len());
        let column = |j: usize| &vals[column_start(size, r, j)..column_start(size, r, j + 1)];
        let team = share.then_some(&self.shared.backward_team);
        let pieces = |large: bool| team.map_or(1, |t| t.pieces(large));
        let g = &mut g[..r];
        let own = r - ext.len();
        for (gi, &row) in g[..own].iter_mut().zip(rows) {
            *gi = y[row as usize - base];
        }
        g[own..].copy_from_slice(ext);
        let g = &*g;
        let ys = &mut y[cols.start - base..cols.end - base];
        // y_s − L_Rsᵀ y_R: `wide_backward`'s sums, four columns at a time from the first
        // (blocks of whole fours, the last block with the columns after the last four).
        let fours = size / 4;
        let large = r >= self.shared.share_rows;
        let mut parts = Vec::new();
        let mut rest = &mut *ys;
        for range in blocks(fours, pieces(large)) {
            let end = if range.end == fours {
                size
            } else {
                4 * range.end
            };
            let (piece, tail) = std::mem::take(&mut rest).split_at_mut(end - 4 * range.start);
            parts.push((4 * range.start, piece));
            rest = tail;
        }
        each(team.filter(|_| large), parts, |(j0, piece)| {
            let below = |j: usize| &column(j)[size - j..];
            let mut k = 0;
            while k + 4 <= piece.len() && j0 + k + 4 <= 4 * fours {
                let c = std::array::from_fn(|i| below(j0 + k + i));
                for (yj, d) in piece[k..k + 4].iter_mut().zip(dot4(c, g)) {
                    *yj -= d;
                }
                k += 4;
            }
            for (k, yj) in piece.iter_mut().enumerate().skip(k) {
                *yj -= dot(below(j0 + k), g);
            }
        });
        // L_ssᵀ⁻¹ from the last panel up.
        let panels: Vec<usize> = (0..size).step_by(PANEL).collect();
        let mut sums = vec![0.0; PANEL];
        for &p in panels.iter().rev() {
            let q = (p + PANEL).min(size);
            let (head, low) = ys.split_at_mut(q);
            let low = &*low;
            if q < size {
                let large = size - q >= self.shared.share_rows;
                let parts = cut(&mut sums[..q - p], pieces(large));
                each(team.filter(|_| large), parts, |(k0, piece)| {
                    for (k, sum) in piece.iter_mut().enumerate() {
                        let j = p + k0 + k;
                        *sum = dot(&column(j)[q - j..size - j], low);
                    }
                });
            }
            for j in (p..q).rev() {
                let col = column(j);
                let within = dot(&col[1..q - j], &head[j + 1..q]);
                let sum = if q < size {
                    sums[j - p] + within
                } else {
                    within
                };
                head[j] = (head[j] - sum) / col[0];
            }
        }
    }
}
