//! How the step's solves run on several threads: independent subtrees of the supernodal
//! elimination tree on different threads, the rest after them (its wide supernodes with
//! their rows shared out, `shared`), with arithmetic that depends on the matrix alone.
//!
//! A subtree's supernodes update only rows of the subtree and of its ancestors, so
//! disjoint subtrees ("units") can run their forward and backward passes at the same time,
//! each in its own slice of y when its columns are contiguous. Two things fix the bits:
//!
//! - **The arithmetic** is that of the serial pass, except where the factor is split in
//!   two groups (`two_groups`, decided by the matrix as the solves have always done): the
//!   forward pass then sums the second group's updates of the rows above both groups
//!   (`top`) in a vector z of their own, from zero, and adds z to y before `top` runs.
//! - **The units** (`Schedule`), dealt to as many bins as the process has threads (16 at
//!   most), run their supernodes on their own rows and *record* each update of a row
//!   outside the unit, the value L_Rs y_s it would subtract, instead of subtracting it.
//!   After the parallel part the records are subtracted (into y, or into z for the second
//!   group's updates of `top`) in increasing supernode order, interleaved with the
//!   supernodes outside every unit ("upper": opened to make the units smaller), which
//!   run then. Every row therefore receives the same updates in the same order as in the
//!   reference pass, whatever the units and however many threads run them.
//! - **Where to cut** is a search over frontiers of the tree (`Tree::search`) for the
//!   shortest longest path: the supernodes above the units plus the heaviest bin, in stored
//!   values, a wide supernode above the units (`shared`) counted as a bin's share of its
//!   values. Counted whole, the nested dissection's top separators kept the search from
//!   opening them: on the block at h = 1/24 with 16 bins it stopped at 4 units and a path
//!   of 34.0 M of 76.3 M values; counted shared, 14 units and a path of 6.4 M.
//!
//! The backward pass reads only ancestors: `top` and the upper supernodes run first (in
//! reverse order), the units' rows outside themselves are gathered into the record, then
//! the units run in parallel. Its arithmetic is the serial pass's in any case.

use super::Layout;
use std::ops::Range;

/// The most bins: each is a thread's share of a pass's units.
pub(super) const MAX_BINS: usize = 16;

/// The supernodal elimination tree of a factor (a parent's index exceeds its children's).
struct Tree {
    children: Vec<Vec<usize>>,
    roots: Vec<usize>,
    /// The stored values of each supernode, and of its subtree.
    own: Vec<usize>,
    weight: Vec<usize>,
    /// The lowest supernode of each subtree, and the number of supernodes in it: its
    /// supernodes are first..=s exactly when the count is s + 1 − first.
    first: Vec<usize>,
    count: Vec<usize>,
    /// The supernode of each column.
    owner: Vec<usize>,
}

impl Tree {
    fn new(layout: &Layout) -> Tree {
        let ns = layout.n_supernodes();
        let mut owner = vec![0; layout.begin[ns]];
        for s in 0..ns {
            owner[layout.begin[s]..layout.begin[s + 1]].fill(s);
        }
        let own: Vec<usize> = (0..ns)
            .map(|s| layout.val_ptr[s + 1] - layout.val_ptr[s])
            .collect();
        let mut tree = Tree {
            children: vec![Vec::new(); ns],
            roots: Vec::new(),
            weight: own.clone(),
            own,
            first: (0..ns).collect(),
            count: vec![1; ns],
            owner,
        };
        for s in 0..ns {
            match layout.parent(s) {
                Some(p) => {
                    tree.children[p].push(s);
                    tree.weight[p] += tree.weight[s];
                    tree.first[p] = tree.first[p].min(tree.first[s]);
                    tree.count[p] += tree.count[s];
                }
                None => tree.roots.push(s),
            }
        }
        tree
    }

    /// Whether the subtree of s holds the supernodes first..=s (then also a contiguous
    /// range of columns).
    fn contiguous(&self, s: usize) -> bool {
        s + 1 - self.first[s] == self.count[s]
    }

    /// The supernodes of the subtree of `root`.
    fn subtree(&self, root: usize) -> Vec<usize> {
        let mut stack = vec![root];
        let mut out = Vec::new();
        while let Some(s) = stack.pop() {
            out.push(s);
            stack.extend_from_slice(&self.children[s]);
        }
        out
    }

    /// `frontier`'s subtrees dealt to `bins` bins, heaviest first, each into the lightest
    /// bin so far (the first of equals): each bin's weight and subtrees.
    fn deal(&self, frontier: &[usize], bins: usize) -> Vec<(usize, Vec<usize>)> {
        let mut sorted = frontier.to_vec();
        sorted.sort_by_key(|&s| std::cmp::Reverse(self.weight[s]));
        let mut out = vec![(0, Vec::new()); bins];
        for s in sorted {
            let b = (0..bins).min_by_key(|&b| out[b].0).unwrap_or(0);
            out[b].0 += self.weight[s];
            out[b].1.push(s);
        }
        out
    }

    /// Opens the heaviest subtree of `frontier` into its children, one at a time (256 at
    /// most), first every one that `must_open` names; each frontier is dealt to `bins`
    /// bins. Returns the frontier whose longest path, the opened supernodes (`opened`
    /// to start with, each supernode counted as `cost` says) plus the heaviest bin, is
    /// shortest, and that path.
    fn search(
        &self,
        mut frontier: Vec<usize>,
        mut opened: usize,
        bins: usize,
        must_open: impl Fn(usize) -> bool,
        cost: impl Fn(usize) -> usize,
    ) -> Option<(usize, Vec<usize>)> {
        let open = |frontier: &mut Vec<usize>, s: usize| {
            frontier.retain(|&f| f != s);
            frontier.extend_from_slice(&self.children[s]);
            cost(s)
        };
        // Opens every supernode of the frontier that must open, and those of its children
        // that must, in one pass over a queue, linear in what it visits. It leaves the
        // frontier (the kept supernodes in order, then the opened ones' children in the
        // order they were opened) and the cost of opening the first one found, one at a
        // time, until none is left.
        let open_all = |frontier: &mut Vec<usize>| {
            let (mut queue, mut cost_sum) = (std::mem::take(frontier), 0);
            let mut i = 0;
            while i < queue.len() {
                let s = queue[i];
                if must_open(s) {
                    cost_sum += cost(s);
                    queue.extend_from_slice(&self.children[s]);
                } else {
                    frontier.push(s);
                }
                i += 1;
            }
            cost_sum
        };
        let mut best: Option<(usize, Vec<usize>)> = None;
        for _ in 0..256 {
            opened += open_all(&mut frontier);
            let heaviest_bin = self.deal(&frontier, bins).iter().map(|b| b.0).max();
            let path = opened + heaviest_bin.unwrap_or(0);
            if best.as_ref().is_none_or(|b| path < b.0) {
                best = Some((path, frontier.clone()));
            }
            let Some(heaviest) = frontier.iter().copied().max_by_key(|&s| self.weight[s]) else {
                break;
            };
            opened += open(&mut frontier, heaviest);
        }
        best
    }
}

/// The group of a supernode in the forward pass's arithmetic.
const TOP: u8 = 2;

/// The arithmetic's two groups of subtrees (labels 0 and 1, each subtree of the returned
/// frontier in one of them) and `top` (label `TOP`, every ancestor of both): the split
/// whose longest path, top + max(group), is shortest, counted in stored values; None when
/// it would not save a fifth of a pass or the factor is smaller than `min`.
fn two_groups(tree: &Tree, total: usize, min: usize) -> Option<(Vec<u8>, Vec<usize>)> {
    let ns = tree.own.len();
    if total < min || ns < 2 {
        return None;
    }
    let plain = |s: usize| tree.own[s];
    let (path, frontier) = tree.search(tree.roots.clone(), 0, 2, |_| false, plain)?;
    if path * 5 > total * 4 {
        return None;
    }
    let mut label = vec![TOP; ns];
    for (b, (_, subtrees)) in tree.deal(&frontier, 2).into_iter().enumerate() {
        for root in subtrees {
            for s in tree.subtree(root) {
                label[s] = b as u8;
            }
        }
    }
    Some((label, frontier))
}

/// A subtree run by one thread: its supernodes, its columns and its part of the record.
pub(super) struct Unit {
    pub(super) supernodes: Range<usize>,
    pub(super) cols: Range<usize>,
    pub(super) record: Range<usize>,
    bin: usize,
}

/// The units of a factor's solves, the bins that deal them to threads, and what runs on
/// one thread (the module doc).
pub(super) struct Schedule {
    /// The units, in increasing order of their supernodes (so of their columns).
    pub(super) units: Vec<Unit>,
    bins: usize,
    /// For each supernode: its pattern's rows from `from[s]` on are recorded (a unit's
    /// rows outside it; the second group's rows in `top` for its upper supernodes), and
    /// of those the rows from `to_z[s]` on go to z (the second group's rows in `top`).
    from: Vec<u32>,
    to_z: Vec<u32>,
    /// Supernode s's records are record[rec[s]..rec[s + 1]].
    rec: Vec<usize>,
    /// The supernodes of both groups that are upper (true) or have records, increasing.
    pub(super) replay: Vec<(usize, bool)>,
    /// The supernodes above both groups, increasing; they run after the records.
    pub(super) top: Vec<usize>,
    /// z holds the rows z_from.. (`top` lies there); n when there are no two groups.
    pub(super) z_from: usize,
}

/// The rows of a unit's y and record that one thread works on.
pub(super) type Piece<'a> = (&'a Unit, &'a mut [f64], &'a mut [f64]);

impl Schedule {
    /// The schedule for `bins` threads of a factor storing at least `min_units` values
    /// (the arithmetic's two groups from `min_two` values, `two_groups`); None where one
    /// thread runs the serial pass: the factor is smaller, or there are no two groups and
    /// one bin, or the units would not save a fifth of a pass.
    pub(super) fn new(
        layout: &Layout,
        min_two: usize,
        min_units: usize,
        bins: usize,
        shared: impl Fn(usize) -> bool,
    ) -> Option<Self> {
        let (ns, total) = (layout.n_supernodes(), *layout.val_ptr.last()?);
        if total < min_units || ns < 2 {
            return None;
        }
        let tree = Tree::new(layout);
        let two = two_groups(&tree, total, min_two);
        let split = two.is_some();
        if !split && bins < 2 {
            return None;
        }
        let (label, frontier) = two.unwrap_or_else(|| (vec![0; ns], tree.roots.clone()));
        // A supernode outside the units costs its values, or a bin's share of them where
        // its passes share them out (`shared`).
        let cost = |s: usize| match shared(s) {
            true => tree.own[s].div_ceil(bins),
            false => tree.own[s],
        };
        let top = (0..ns).filter(|&s| label[s] == TOP).map(cost).sum();
        let must_open = |s| !tree.contiguous(s);
        let (path, frontier) = tree.search(frontier, top, bins, must_open, cost)?;
        if !split && path * 5 > total * 4 {
            return None;
        }
        let (mut units, unit_of) = units(layout, &tree, &frontier, bins);
        let mut schedule = Schedule {
            units: Vec::new(),
            bins,
            from: Vec::with_capacity(ns),
            to_z: Vec::with_capacity(ns),
            rec: vec![0],
            replay: Vec::new(),
            top: (0..ns).filter(|&s| label[s] == TOP).collect(),
            z_from: layout.begin[ns],
        };
        if let Some(&first_top) = schedule.top.first() {
            schedule.z_from = layout.begin[first_top];
        }
        for s in 0..ns {
            let rows = layout.pattern(s);
            let outside_top = |&r: &u32| label[tree.owner[r as usize]] != TOP;
            let to_z = match label[s] {
                1 => rows.partition_point(outside_top),
                _ => rows.len(),
            };
            let from = match unit_of[s] {
                usize::MAX => to_z,
                u => rows.partition_point(|&r| (r as usize) < units[u].cols.end),
            };
            let upper = unit_of[s] == usize::MAX && label[s] != TOP;
            if upper || from < rows.len() {
                schedule.replay.push((s, upper));
            }
            schedule.from.push(from as u32);
            schedule.to_z.push(to_z as u32);
            schedule.rec.push(schedule.rec[s] + rows.len() - from);
        }
        units.sort_by_key(|u| u.supernodes.start);
        for u in &mut units {
            u.record = schedule.rec[u.supernodes.start]..schedule.rec[u.supernodes.end];
        }
        schedule.units = units;
        Some(schedule)
    }

    /// The length of the record.
    pub(super) fn record_len(&self) -> usize {
        *self.rec.last().unwrap_or(&0)
    }

    /// Supernode s's records in `record`, and the first of them (counted in its pattern)
    /// that goes to z.
    pub(super) fn records<'a>(&self, s: usize, record: &'a mut [f64]) -> (&'a mut [f64], usize) {
        let at = self.rec[s]..self.rec[s + 1];
        let to_z = (self.to_z[s] - self.from[s]) as usize;
        (&mut record[at], to_z)
    }

    /// The units' rows of `y` and parts of `record`, dealt to the bins (the bins that hold
    /// units).
    pub(super) fn pieces<'a>(
        &'a self,
        y: &'a mut [f64],
        record: &'a mut [f64],
    ) -> Vec<Vec<Piece<'a>>> {
        let mut bins: Vec<Vec<Piece>> = (0..self.bins).map(|_| Vec::new()).collect();
        let (mut y, mut y_at, mut rec, mut rec_at) = (y, 0, record, 0);
        for unit in &self.units {
            let (_, rest) = std::mem::take(&mut y).split_at_mut(unit.cols.start - y_at);
            let (ys, rest) = rest.split_at_mut(unit.cols.len());
            (y, y_at) = (rest, unit.cols.end);
            let (_, rest) = std::mem::take(&mut rec).split_at_mut(unit.record.start - rec_at);
            let (rs, rest) = rest.split_at_mut(unit.record.len());
            (rec, rec_at) = (rest, unit.record.end);
            bins[unit.bin].push((unit, ys, rs));
        }
        // A bin without units (more threads than units) would only wake a thread.
        bins.retain(|units| !units.is_empty());
        bins
    }

    /// Supernode s's part of its unit's record (`unit.record`'s slice).
    pub(super) fn unit_records<'a>(
        &self,
        unit: &Unit,
        s: usize,
        rs: &'a mut [f64],
    ) -> &'a mut [f64] {
        &mut rs[self.rec[s] - unit.record.start..self.rec[s + 1] - unit.record.start]
    }
}

/// The units: the subtrees under `frontier` dealt to `bins` threads (`Tree::deal`), each
/// with its supernodes and columns (its record is set later); and the unit of each
/// supernode (usize::MAX outside them).
fn units(layout: &Layout, tree: &Tree, frontier: &[usize], bins: usize) -> (Vec<Unit>, Vec<usize>) {
    let mut unit_of = vec![usize::MAX; layout.n_supernodes()];
    let mut units: Vec<Unit> = Vec::new();
    for (bin, (_, roots)) in tree.deal(frontier, bins).into_iter().enumerate() {
        for root in roots {
            let supernodes = tree.first[root]..root + 1;
            unit_of[supernodes.clone()].fill(units.len());
            let cols = layout.begin[supernodes.start]..layout.begin[root + 1];
            units.push(Unit {
                supernodes,
                cols,
                record: 0..0,
                bin,
            });
        }
    }
    (units, unit_of)
}
