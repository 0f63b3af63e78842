//! The facets of a mesh's cells (the edges of triangles, the faces of tetrahedra) and how
//! the cells use them: a boundary facet once, an inner one twice in opposite orientations.
//!
//! Every use is one record (the facet's sorted nodes, and the cell with the ordering of
//! those nodes that is the facet's orientation in the cell), and the records are sorted, so
//! that the uses of a facet stand side by side and a facet is found by bisection. Not a
//! hash map: on the plate of 684 325 tetrahedra the map held 273 MB at the peak of reading
//! the mesh, the records 44 MB (docs/performance.md), and the read is rank 0's peak on many
//! MPI ranks.
//!
//! The read asks two things of the uses ([`survey`]): the misuse the earliest cell shows,
//! and where the boundary groups' facets lie. Both are answered a range of lowest nodes at
//! a time: a pass holds the records of the facets whose lowest node lies in its range, at
//! most [`PASS_USES`] but for one range's own, since a facet's uses all have its lowest
//! node. The answers are those of one pass over every record, and the records held at once
//! are at most a few million however large the mesh.

use std::ops::Range;

use super::groups::Words;
use crate::Error;

/// A use of a facet: its nodes sorted (`key`), and the cell's index times 8 plus the
/// number of the ordering of `key` that is the facet in the cell's orientation
/// ([`orderings`]: at most 3! = 6 for F ≤ 3). 16 bytes a use of a face, where the nodes in
/// the cell's orientation took 12 more.
#[derive(Clone, Copy)]
struct Use<const F: usize> {
    key: [u32; F],
    cell_and_order: u32,
}

/// The bits of [`Use::cell_and_order`] that number the ordering.
const ORDER_BITS: u32 = 3;

impl<const F: usize> Use<F> {
    fn cell(&self) -> usize {
        (self.cell_and_order >> ORDER_BITS) as usize
    }

    /// The facet's nodes in the cell's orientation.
    fn dir(&self, orders: &[[usize; F]]) -> [u32; F] {
        let order = orders[(self.cell_and_order & ((1 << ORDER_BITS) - 1)) as usize];
        order.map(|i| self.key[i])
    }
}

/// The orderings of F things (every permutation of 0..F), in one fixed order.
fn orderings<const F: usize>() -> Vec<[usize; F]> {
    let all = (0..F.pow(F as u32)).map(|k| std::array::from_fn(|i| k / F.pow(i as u32) % F));
    all.filter(|o: &[usize; F]| (0..F).all(|i| o.contains(&i)))
        .collect()
}

/// The uses of the facets (every facet, or those of one pass), sorted by facet and then by
/// cell.
struct Facets<const F: usize> {
    uses: Vec<Use<F>>,
    /// [`orderings`] of F.
    orders: Vec<[usize; F]>,
}

/// A facet that the cells misuse: two on the same side of it (a fold), or three or more.
/// The cells are the first that has it and the one that shows the misuse (the second or
/// the third), in the cells' order; `nodes`, the facet's.
pub(super) enum Misuse<const F: usize> {
    Fold {
        nodes: [usize; F],
        first: usize,
        second: usize,
    },
    Shared {
        nodes: [usize; F],
        first: usize,
        third: usize,
    },
}

impl<const F: usize> Misuse<F> {
    /// The cell that shows the misuse (the second or the third).
    fn shown_by(&self) -> usize {
        match *self {
            Misuse::Fold { second, .. } => second,
            Misuse::Shared { third, .. } => third,
        }
    }

    /// The refusal of a mesh `file` whose cells misuse a facet, in the mesh's `words`, with
    /// a cell's gmsh tag (`tag`) and a facet's place (`at`).
    pub(super) fn error(
        &self,
        file: &impl std::fmt::Display,
        words: &Words,
        tag: impl Fn(usize) -> u64,
        at: impl Fn([usize; F]) -> String,
    ) -> Error {
        let (cells, facet) = (words.cells, words.facet);
        Error::input(match *self {
            Misuse::Fold {
                nodes,
                first,
                second,
            } => format!(
                "mesh file '{file}' folds over itself: {cells} {} and {} (gmsh element tags) \
                 overlap at the {facet} {}; an inverted element in the middle of the mesh \
                 cannot be repaired by reorienting it: fix the geometry or remesh",
                tag(first),
                tag(second),
                at(nodes)
            ),
            Misuse::Shared {
                nodes,
                first,
                third,
            } => format!(
                "mesh file '{file}': the {facet} {} is shared by three or more {cells} (e.g. {} \
                 and {}, gmsh element tags); the mesh is not a valid {F}D domain (overlapping \
                 {}?): fix the geometry or remesh",
                at(nodes),
                tag(first),
                tag(third),
                if F == 2 { "surfaces" } else { "volumes" }
            ),
        })
    }
}

impl<const F: usize> Facets<F> {
    /// The facets of the cells, each cell's facets in its orientation (`facets`: the cell
    /// and the facet's nodes, `count` of them); None where a node's index does not fit 32
    /// bits, or a cell's 29 (beside its facet's ordering).
    fn new(facets: impl Iterator<Item = (usize, [usize; F])>, count: usize) -> Option<Facets<F>> {
        let orders = orderings::<F>();
        let mut uses = Vec::with_capacity(count);
        for (cell, dir) in facets {
            let dir = try_u32(dir)?;
            let mut key = dir;
            key.sort_unstable();
            let order = orders.iter().position(|o| o.map(|i| key[i]) == dir)?;
            let cell = u32::try_from(cell)
                .ok()
                .filter(|&c| c < 1 << (32 - ORDER_BITS))?;
            let cell_and_order = cell << ORDER_BITS | order as u32;
            uses.push(Use {
                key,
                cell_and_order,
            });
        }
        // By facet, then by cell (the ordering, below the cell's bits, never decides: a
        // cell's facets differ).
        uses.sort_unstable_by_key(|u| (u.key, u.cell_and_order));
        Some(Facets { uses, orders })
    }

    /// The misuse that the earliest cell shows (None: every facet is used once, or twice
    /// with `same_side` false for its two orientations).
    fn misuse(&self, same_side: impl Fn([u32; F], [u32; F]) -> bool) -> Option<Misuse<F>> {
        let mut worst: Option<(usize, Misuse<F>)> = None;
        for run in self.uses.chunk_by(|a, b| a.key == b.key) {
            let nodes = run[0].key.map(|n| n as usize);
            let first = run[0].cell();
            let found = match run {
                [a, b, ..] if same_side(a.dir(&self.orders), b.dir(&self.orders)) => {
                    let second = b.cell();
                    (
                        second,
                        Misuse::Fold {
                            nodes,
                            first,
                            second,
                        },
                    )
                }
                [_, _, c, ..] => {
                    let third = c.cell();
                    (
                        third,
                        Misuse::Shared {
                            nodes,
                            first,
                            third,
                        },
                    )
                }
                _ => continue,
            };
            if worst.as_ref().is_none_or(|(at, _)| found.0 < *at) {
                worst = Some(found);
            }
        }
        worst.map(|(_, m)| m)
    }

    /// The facet with the nodes `f` (in any order): its orientation in the first cell that
    /// has it and how many cells have it; None where no cell has it.
    fn lookup(&self, f: [usize; F]) -> Option<([usize; F], u32)> {
        let mut key = try_u32(f)?;
        key.sort_unstable();
        let at = self.uses.partition_point(|u| u.key < key);
        let count = self.uses[at..].iter().take_while(|u| u.key == key).count();
        let first = self.uses.get(at).filter(|_| count > 0)?;
        Some((first.dir(&self.orders).map(|n| n as usize), count as u32))
    }
}

/// The most records one pass of [`survey`] holds (32 MiB of a tetrahedron's faces'), but
/// where one range of lowest nodes has more.
const PASS_USES: usize = 1 << 21;

/// What the read asks of the cells' facets: the misuse the earliest cell shows, and the
/// facets that were asked about, each with its orientation in the first cell that has it
/// and how many cells have it.
pub(super) struct Survey<const F: usize> {
    pub(super) misuse: Option<Misuse<F>>,
    /// The asked facets that a cell has, by their sorted nodes: (sorted, orientation, count).
    found: Vec<([usize; F], [usize; F], u32)>,
}

impl<const F: usize> Survey<F> {
    /// The facet with the nodes `f` (in any order), where it was asked about: its
    /// orientation in the first cell that has it and how many cells have it; None where
    /// no cell has it.
    pub(super) fn lookup(&self, mut f: [usize; F]) -> Option<([usize; F], u32)> {
        f.sort_unstable();
        let at = self.found.binary_search_by_key(&f, |r| r.0).ok()?;
        Some((self.found[at].1, self.found[at].2))
    }
}

/// The survey of the facets that `uses` lists (the cell and the facet's nodes in its
/// orientation, every time it is called the same), over nodes numbered below `n_nodes`:
/// the misuse (where `same_side` says two orientations are the same side) and the facets
/// of `asked`; None where a node's index does not fit 32 bits, or a cell's 29.
pub(super) fn survey<const F: usize, I: Iterator<Item = (usize, [usize; F])>>(
    uses: impl Fn() -> I,
    n_nodes: usize,
    asked: impl Iterator<Item = [usize; F]>,
    same_side: impl Fn([u32; F], [u32; F]) -> bool + Copy,
) -> Option<Survey<F>> {
    survey_in_passes(uses, n_nodes, asked, same_side, PASS_USES)
}

/// [`survey`] in passes of at most `most` records (but where a bucket alone has more).
fn survey_in_passes<const F: usize, I: Iterator<Item = (usize, [usize; F])>>(
    uses: impl Fn() -> I,
    n_nodes: usize,
    asked: impl Iterator<Item = [usize; F]>,
    same_side: impl Fn([u32; F], [u32; F]) -> bool + Copy,
    most: usize,
) -> Option<Survey<F>> {
    let lowest = |f: &[usize; F]| f.iter().copied().min().unwrap_or(0);
    let mut asked: Vec<[usize; F]> = (asked.filter(|f| try_u32(*f).is_some()))
        .map(|mut f| {
            f.sort_unstable();
            f
        })
        .collect();
    asked.sort_unstable();
    asked.dedup();
    let mut survey = Survey {
        misuse: None,
        found: Vec::with_capacity(asked.len()),
    };
    let mut asked = asked.into_iter().peekable();
    for (range, count) in pass_ranges(uses().map(|(_, f)| lowest(&f)), n_nodes, most) {
        let pass = Facets::new(uses().filter(|(_, f)| range.contains(&lowest(f))), count)?;
        // The passes go up in the facets' order, so a tie keeps the earlier facet, as one
        // pass over every record does.
        if let Some(m) = pass.misuse(same_side) {
            let earlier = |old: &Misuse<F>| old.shown_by() <= m.shown_by();
            if !survey.misuse.as_ref().is_some_and(earlier) {
                survey.misuse = Some(m);
            }
        }
        while let Some(f) = asked.next_if(|f| f[0] < range.end) {
            if let Some((dir, count)) = pass.lookup(f) {
                survey.found.push((f, dir, count));
            }
        }
    }
    Some(survey)
}

/// The ranges of lowest nodes of the passes, in order and together every node, each with
/// its count of records: at most `most` but where a bucket of consecutive nodes alone has
/// more (the `lowest` nodes of the uses counted in up to 2^16 buckets below `n_nodes`,
/// the last bucket taking those at or above it).
fn pass_ranges(
    lowest: impl Iterator<Item = usize>,
    n_nodes: usize,
    most: usize,
) -> Vec<(Range<usize>, usize)> {
    let width = n_nodes.div_ceil(1 << 16).max(1);
    let mut counts = vec![0_usize; n_nodes.div_ceil(width).max(1)];
    let last = counts.len() - 1;
    for n in lowest {
        counts[(n / width).min(last)] += 1;
    }
    let mut ranges = Vec::new();
    let (mut start, mut held) = (0, 0);
    for (b, &c) in counts.iter().enumerate() {
        if held + c > most && held > 0 {
            ranges.push((start..b * width, held));
            (start, held) = (b * width, 0);
        }
        held += c;
    }
    ranges.push((start..usize::MAX, held));
    ranges
}

/// The nodes as u32, or None where one does not fit.
fn try_u32<const F: usize>(f: [usize; F]) -> Option<[u32; F]> {
    let mut out = [0; F];
    for (o, n) in out.iter_mut().zip(f) {
        *o = u32::try_from(n).ok()?;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The edges of triangles (node triples) in their orientation.
    fn edges(triangles: &[[usize; 3]]) -> Facets<2> {
        let uses = (triangles.iter().enumerate())
            .flat_map(|(k, t)| [0, 1, 2].map(|i| (k, [t[i], t[(i + 1) % 3]])));
        Facets::new(uses, 3 * triangles.len()).unwrap()
    }

    #[test]
    fn an_inner_edge_is_used_twice_and_a_boundary_edge_once_in_its_orientation() {
        let e = edges(&[[0, 1, 2], [2, 1, 3]]);
        assert!(e.misuse(|a, b| a == b).is_none());
        assert_eq!(e.lookup([2, 1]), Some(([1, 2], 2)));
        assert_eq!(e.lookup([3, 2]), Some(([3, 2], 1)));
        assert_eq!(e.lookup([0, 3]), None);
        assert_eq!(e.lookup([usize::MAX, 0]), None);
    }

    /// The survey of the triangles' edges in passes of at most `most` records, every edge
    /// of theirs and one of no triangle asked.
    fn surveyed(triangles: &[[usize; 3]], most: usize) -> Survey<2> {
        let uses = || {
            (triangles.iter().enumerate())
                .flat_map(|(k, t)| [0, 1, 2].map(|i| (k, [t[i], t[(i + 1) % 3]])))
        };
        let n = triangles.iter().flatten().max().map_or(0, |&n| n + 1);
        let asked = uses().map(|(_, e)| e).chain([[0, n + 7]]);
        survey_in_passes(uses, n, asked, |a, b| a == b, most).unwrap()
    }

    /// The misuse as (facet, first, shower, a fold).
    fn seen(m: &Option<Misuse<2>>) -> Option<([usize; 2], usize, usize, bool)> {
        m.as_ref().map(|m| match *m {
            Misuse::Fold {
                nodes,
                first,
                second,
            } => (nodes, first, second, true),
            Misuse::Shared {
                nodes,
                first,
                third,
            } => (nodes, first, third, false),
        })
    }

    #[test]
    fn a_survey_in_passes_answers_as_one_pass_over_every_use() {
        // A grid of 12 × 9 squares, each cut into two triangles, then two misuses: a fold
        // over an inner edge and a third triangle on a boundary edge.
        let node = |i: usize, j: usize| j * 13 + i;
        let mut triangles = Vec::new();
        for j in 0..9 {
            for i in 0..12 {
                let [a, b, c, d] = [
                    node(i, j),
                    node(i + 1, j),
                    node(i + 1, j + 1),
                    node(i, j + 1),
                ];
                triangles.extend([[a, b, c], [a, c, d]]);
            }
        }
        let whole = |t: &[[usize; 3]]| surveyed(t, usize::MAX);
        let passes = [1, 2, 5, 40];
        for t in [
            &triangles[..],
            &[&triangles[..], &[[node(5, 5), node(6, 6), node(9, 2)]]].concat(),
            &[&triangles[..], &[[node(0, 0), node(1, 0), node(3, 3)]]].concat(),
        ] {
            let one = whole(t);
            assert!(one.found.len() > 200);
            for most in passes {
                let s = surveyed(t, most);
                assert_eq!(s.found, one.found, "passes of {most}");
                assert_eq!(seen(&s.misuse), seen(&one.misuse), "passes of {most}");
            }
        }
        assert_eq!(seen(&whole(&triangles).misuse), None);
        // The diagonal 70–84 of square (5, 5) in triangles 130, 131 and the new one, 216.
        let shared = [&triangles[..], &[[node(5, 5), node(6, 6), node(9, 2)]]].concat();
        assert_eq!(
            seen(&whole(&shared).misuse),
            Some(([70, 84], 130, 216, false))
        );
        // The boundary edge 0–1 of triangle 0, used again in its direction.
        let fold = [&triangles[..], &[[node(0, 0), node(1, 0), node(3, 3)]]].concat();
        assert_eq!(seen(&whole(&fold).misuse), Some(([0, 1], 0, 216, true)));
        assert_eq!(
            whole(&triangles).lookup([node(1, 0), node(0, 0)]),
            Some(([0, 1], 1))
        );
        assert_eq!(
            whole(&triangles).lookup([node(1, 1), node(0, 0)]),
            Some(([14, 0], 2))
        );
        assert_eq!(whole(&triangles).lookup([node(0, 1), node(1, 0)]), None);
    }

    #[test]
    fn the_earliest_cell_that_misuses_a_facet_is_named_in_any_passes() {
        // The examples of the test below, surveyed in passes of 1 to 4 records: the
        // shared edge 0–1 and the fold over 5–6 fall in different passes.
        let shared = [[0, 1, 2], [1, 0, 3], [0, 1, 4], [5, 6, 7], [5, 6, 8]];
        let fold = [[5, 6, 7], [5, 6, 8], [0, 1, 2], [1, 0, 3], [0, 1, 4]];
        for most in [1, 2, 3, 4, usize::MAX] {
            assert_eq!(
                seen(&surveyed(&shared, most).misuse),
                Some(([0, 1], 0, 2, false))
            );
            assert_eq!(
                seen(&surveyed(&fold, most).misuse),
                Some(([5, 6], 0, 1, true))
            );
        }
    }

    #[test]
    fn the_earliest_cell_that_misuses_a_facet_is_named() {
        // Triangles 3 and 4 fold over edge 5–6; triangles 0, 1 and 2 share edge 0–1, which
        // the third of them (2) shows first: before the fold's second triangle (4).
        let e = edges(&[[0, 1, 2], [1, 0, 3], [0, 1, 4], [5, 6, 7], [5, 6, 8]]);
        match e.misuse(|a, b| a == b) {
            Some(Misuse::Fold {
                nodes,
                first,
                second,
            }) => {
                panic!("fold {nodes:?} {first} {second}, not the shared edge")
            }
            Some(Misuse::Shared {
                nodes,
                first,
                third,
            }) => {
                assert_eq!((nodes, first, third), ([0, 1], 0, 2))
            }
            None => panic!("no misuse found"),
        }
        let e = edges(&[[5, 6, 7], [5, 6, 8], [0, 1, 2], [1, 0, 3], [0, 1, 4]]);
        assert!(matches!(
            e.misuse(|a, b| a == b),
            Some(Misuse::Fold {
                nodes: [5, 6],
                first: 0,
                second: 1
            })
        ));
    }
}
