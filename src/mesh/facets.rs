//! The facets of a mesh's cells (the edges of triangles, the faces of tetrahedra) and how
//! the cells use them: a boundary facet once, an inner one twice in opposite orientations.
//!
//! Every use is one record (the facet's sorted nodes, its orientation in the cell, the
//! cell), and the records are sorted, so that the uses of a facet stand side by side and a
//! facet is found by bisection. Not a hash map: on the plate of 684 325 tetrahedra the map
//! held 273 MB at the peak of reading the mesh, the records 77 MB (docs/performance.md),
//! and every MPI rank reads the whole mesh.

use super::groups::Words;
use crate::Error;

/// A use of a facet: its nodes sorted (`key`), in the cell's orientation (`dir`), and the
/// cell's index.
#[derive(Clone, Copy)]
struct Use<const F: usize> {
    key: [u32; F],
    dir: [u32; F],
    cell: u32,
}

/// The uses of every facet, sorted by facet and then by cell.
pub(super) struct Facets<const F: usize> {
    uses: Vec<Use<F>>,
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
    /// and the facet's nodes); None where a node's index does not fit 32 bits.
    pub(super) fn new(facets: impl Iterator<Item = (usize, [usize; F])>) -> Option<Facets<F>> {
        let mut uses = Vec::with_capacity(facets.size_hint().0);
        for (cell, dir) in facets {
            let dir = try_u32(dir)?;
            let mut key = dir;
            key.sort_unstable();
            let cell = u32::try_from(cell).ok()?;
            uses.push(Use { key, dir, cell });
        }
        uses.sort_unstable_by_key(|u| (u.key, u.cell));
        Some(Facets { uses })
    }

    /// The misuse that the earliest cell shows (None: every facet is used once, or twice
    /// with `same_side` false for its two orientations).
    pub(super) fn misuse(
        &self,
        same_side: impl Fn([u32; F], [u32; F]) -> bool,
    ) -> Option<Misuse<F>> {
        let mut worst: Option<(u32, Misuse<F>)> = None;
        for run in self.uses.chunk_by(|a, b| a.key == b.key) {
            let nodes = run[0].key.map(|n| n as usize);
            let first = run[0].cell as usize;
            let found = match run {
                [a, b, ..] if same_side(a.dir, b.dir) => {
                    let second = b.cell as usize;
                    (
                        b.cell,
                        Misuse::Fold {
                            nodes,
                            first,
                            second,
                        },
                    )
                }
                [_, _, c, ..] => {
                    let third = c.cell as usize;
                    (
                        c.cell,
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
        Some((first.dir.map(|n| n as usize), count as u32))
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
