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
//! the others are busy, and the forward pass is `wide_forward` itself.

use super::{dot, dot4, gather_below, subtract_below, Factor};
use crate::threads::team::{blocks, Team};
use std::ops::Range;

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

/// A wide supernode's packed values: `size` columns, each holding the rows j..size of the
/// diagonal block and then the r rows below (`Layout`).
#[derive(Clone, Copy)]
struct Wide<'a> {
    vals: &'a [f64],
    size: usize,
    r: usize,
}

impl<'a> Wide<'a> {
    /// Column j: rows j..size of the diagonal block, then the rows below.
    fn column(&self, j: usize) -> &'a [f64] {
        // Column j starts after Σ_{i<j} (size − i + r) values.
        let start = |j: usize| j * (2 * (self.size + self.r) + 1 - j) / 2;
        &self.vals[start(j)..start(j + 1)]
    }
}

/// The threads a pass may hand its pieces to: the team, or none (inside a unit).
#[derive(Clone, Copy)]
struct Threads<'a> {
    team: Option<&'a Team>,
    share_rows: usize,
}

impl Threads<'_> {
    /// The pieces for work over `rows` rows (or sums): the team's size from `share_rows` on.
    fn pieces(&self, rows: usize) -> usize {
        self.team.map_or(1, |t| t.pieces(rows >= self.share_rows))
    }

    /// Runs the parts on the team's threads when there are several, else here.
    fn each<T: Send>(&self, parts: Vec<T>, work: impl Fn(T) + Sync) {
        match self.team {
            Some(team) if parts.len() > 1 => team.each(parts, work),
            _ => parts.into_iter().for_each(work),
        }
    }
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

impl Factor {
    /// Whether supernode s takes this module's passes.
    pub(super) fn is_shared(&self, s: usize) -> bool {
        let values = self.layout.val_ptr[s + 1] - self.layout.val_ptr[s];
        let size = self.layout.begin[s + 1] - self.layout.begin[s];
        values >= self.shared.min && size > 4
    }

    /// Supernode s's values, and the threads of a pass of `team` when `share`.
    fn wide_parts<'a>(&'a self, s: usize, team: &'a Team, share: bool) -> (Wide<'a>, Threads<'a>) {
        let (cols, rows, vals) = self.layout.supernode(s, &self.values);
        let wide = Wide {
            vals,
            size: cols.len(),
            r: rows.len(),
        };
        let threads = Threads {
            team: share.then_some(team),
            share_rows: self.shared.share_rows,
        };
        (wide, threads)
    }

    /// `wide_forward` over supernode s (the same bits), in panels whose rows below are
    /// shared out over the threads. `y`, `base`, `ext` and `t` as in `forward_step`.
    pub(super) fn shared_forward(
        &self,
        s: usize,
        y: &mut [f64],
        base: usize,
        ext: &mut [f64],
        t: &mut [f64],
    ) {
        let (w, threads) = self.wide_parts(s, &self.shared.forward_team, true);
        let (cols, rows, _) = self.layout.supernode(s, &self.values);
        let t = &mut t[..w.r];
        t.fill(0.0);
        let ys = &mut y[cols.start - base..cols.end - base];
        for p in (0..w.size).step_by(PANEL) {
            forward_panel(w, p..(p + PANEL).min(w.size), ys, t, threads);
        }
        subtract_below(rows, t, y, base, ext);
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
        let (w, threads) = self.wide_parts(s, &self.shared.backward_team, share);
        let (cols, rows, _) = self.layout.supernode(s, &self.values);
        let g = &mut g[..w.r];
        gather_below(rows, y, base, ext, g);
        let ys = &mut y[cols.start - base..cols.end - base];
        subtract_sums(w, g, ys, threads);
        let mut sums = vec![0.0; PANEL];
        let panels: Vec<usize> = (0..w.size).step_by(PANEL).collect();
        for &p in panels.iter().rev() {
            backward_panel(w, p..(p + PANEL).min(w.size), ys, &mut sums, threads);
        }
    }
}

/// The forward pass over the panel's columns p..q: their triangle here, then the rows
/// below the panel (of the diagonal block in `ys`, of R summed into `t`) in blocks over
/// the threads, each row's updates in column order.
fn forward_panel(w: Wide, panel: Range<usize>, ys: &mut [f64], t: &mut [f64], threads: Threads) {
    let (p, q) = (panel.start, panel.end);
    for j in panel.clone() {
        let col = w.column(j);
        let yj = ys[j] / col[0];
        ys[j] = yj;
        for (yi, l) in ys[j + 1..q].iter_mut().zip(&col[1..]) {
            *yi -= l * yj;
        }
    }
    let (head, low) = ys.split_at_mut(q);
    let solved = &head[p..];
    let pieces = threads.pieces(w.size - q + w.r);
    let parts: Vec<_> = cut(low, pieces).into_iter().zip(cut(t, pieces)).collect();
    threads.each(parts, |((low_at, low), (t_at, t))| {
        for (j, yj) in panel.clone().zip(solved) {
            let col = w.column(j);
            // Row q + low_at is entry q + low_at − j of column j; R's row t_at is entry
            // size − j + t_at.
            for (yi, l) in low.iter_mut().zip(&col[q + low_at - j..]) {
                *yi -= l * yj;
            }
            for (ti, l) in t.iter_mut().zip(&col[w.size - j + t_at..]) {
                *ti += l * yj;
            }
        }
    });
}

/// ys ← ys − L_Rsᵀ g: `wide_backward`'s sums, four columns at a time from the first, in
/// blocks of whole fours over the threads (the last block also takes the columns after the
/// last four).
fn subtract_sums(w: Wide, g: &[f64], ys: &mut [f64], threads: Threads) {
    let fours = w.size / 4;
    let mut parts = Vec::new();
    let mut rest = ys;
    for range in blocks(fours, threads.pieces(w.r)) {
        let end = if range.end == fours {
            w.size
        } else {
            4 * range.end
        };
        let (piece, tail) = std::mem::take(&mut rest).split_at_mut(end - 4 * range.start);
        parts.push((4 * range.start, piece));
        rest = tail;
    }
    threads.each(parts, |(j0, piece)| {
        let below = |j: usize| &w.column(j)[w.size - j..];
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
}

/// L_ssᵀ⁻¹ on the panel's columns p..q, the rows below the panel solved: their sums over
/// those rows in blocks of columns over the threads (into `sums`), then the panel's
/// triangle here, the last column first.
fn backward_panel(
    w: Wide,
    panel: Range<usize>,
    ys: &mut [f64],
    sums: &mut [f64],
    threads: Threads,
) {
    let (p, q, size) = (panel.start, panel.end, w.size);
    let (head, low) = ys.split_at_mut(q);
    let low = &*low;
    if q < size {
        let parts = cut(&mut sums[..q - p], threads.pieces(size - q));
        threads.each(parts, |(k0, piece)| {
            for (j, sum) in (p + k0..).zip(piece.iter_mut()) {
                *sum = dot(&w.column(j)[q - j..size - j], low);
            }
        });
    }
    for j in panel.rev() {
        let col = w.column(j);
        let within = dot(&col[1..q - j], &head[j + 1..q]);
        let sum = if q < size {
            sums[j - p] + within
        } else {
            within
        };
        head[j] = (head[j] - sum) / col[0];
    }
}
