//! The facets of a mesh's cells (the edges of triangles, the faces of tetrahedra) and how
//! the cells use them: a boundary facet once, an inner one twice in opposite orientations.
//!
//! Every use is one record (the facet's sorted nodes, and the cell with the ordering of
//! those nodes that is the facet's orientation in the cell), and the records are sorted, so
//! that the uses of a facet stand side by side and a facet is found by bisection. Not a
//! hash map: on the plate of 684 325 tetrahedra the map held 273 MB at the peak of reading
//! the mesh, the records 44 MB (docs/performance.md), and the read is rank 0's peak on many
//! MPI ranks.

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

/// The uses of every facet, sorted by facet and then by cell.
pub(super) struct Facets<const F: usize> {
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
    /// and the facet's nodes); None where a node's index does not fit 32 bits, or a cell's
    /// 29 (beside its facet's ordering).
    pub(super) fn new(facets: impl Iterator<Item = (usize, [usize; F])>) -> Option<Facets<F>> {
        let orders = orderings::<F>();
        let mut uses = Vec::with_capacity(facets.size_hint().0);
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
    pub(super) fn misuse(
        &self,
        same_side: impl Fn([u32; F], [u32; F]) -> bool,
    ) -> Option<Misuse<F>> {
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
    pub(super) fn lookup(&self, f: [usize; F]) -> Option<([usize; F], u32)> {
        let mut key = try_u32(f)?;
        key.sort_unstable();
        let at = self.uses.partition_point(|u| u.key < key);
        let count = self.uses[at..].iter().take_while(|u| u.key == key).count();
        let first = self.uses.get(at).filter(|_| count > 0)?;
        Some((first.dir(&self.orders).map(|n| n as usize), count as u32))
    }
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
        Facets::new(uses).unwrap()
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
