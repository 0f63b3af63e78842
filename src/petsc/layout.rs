//! How the ranks hold K_A's unknowns (docs/cluster.md): each rank a contiguous block of
//! PETSc's rows, whole nodes (the active set's frames and slip stiffness act on a node's own
//! rows: `shim.c`).
//!
//! On one rank the rows are the unknowns themselves, in their order. On several, METIS's
//! k-way partition of the nodes' graph (two nodes adjacent where K_A couples them) says which
//! rank holds a node, and the rows number the nodes part by part, in their own order within
//! a part, each node's unknowns one after the other. The mesh's numbering cut into blocks
//! instead made a rank's product with K_A fetch more values of other ranks' rows than it
//! holds rows, six times as many on 16 ranks of the fine plate (docs/cluster.md, "Planning").
//! Rank 0 alone builds the nodes' graph and runs METIS, and sends the rows' order to the
//! others ([`Layout::of_first`]: 4 bytes an unknown, once), where every rank had made the
//! same partition itself from the whole graph, the work and memory of one process on each
//! (docs/cluster.md, "Memory per rank"). A follower whose vectors hold its own unknowns
//! and their neighbours' alone gets the rows of those and of Γ3's alone, with its part of
//! the cells ([`Layout::keep_rows_of_first`]), and finds one by binary search. A rank's vectors cross to PETSc's order at its
//! own rows alone, at every PETSc call, and a solved step's rows come back whole to rank 0
//! in that order once a step ([`Layout::to_unknowns_order`]).

use super::PetscInt;
use crate::fem::{CellSource, Discretization, Sparse};
use crate::{Error, Result};

/// Where each unknown stands among PETSc's rows, and each rank's rows.
#[derive(Clone, Debug)]
pub struct Layout {
    /// The row of each unknown, in 4 bytes as the numbering holds its index
    /// (`fem::DofIndex`), or of each place of a rank's vectors where it holds some unknowns
    /// alone ([`Layout::placed`]); None on one rank, where they are the same.
    row: Option<Vec<u32>>,
    /// The unknowns whose rows `row` holds, increasing, where a follower holds those it
    /// reads alone ([`Layout::keep_rows_of_first`]); None where `row` is every unknown's.
    kept: Option<Vec<u32>>,
    /// Rank r holds the rows `blocks[r]..blocks[r + 1]` (size + 1 values, the last n_free).
    pub blocks: Vec<usize>,
}

impl Layout {
    /// The layout of `disc`'s unknowns over `size` ranks, its nodes' graph read from
    /// `cells` (`disc`'s own, or the mesh's where it holds none).
    pub fn new(disc: &Discretization, cells: CellSource, size: usize) -> Result<Layout> {
        match size {
            0 | 1 => Ok(Layout {
                row: None,
                kept: None,
                blocks: vec![0, disc.n_free],
            }),
            _ => Ok(Layout::partition(disc, cells, size)?.0),
        }
    }

    /// The layout of `disc`'s unknowns over `size` ranks (METIS's partition; one part on
    /// one rank) and each rank's share of K_A, both from one nodes' graph read from `cells`.
    pub fn partition(
        disc: &Discretization,
        cells: CellSource,
        size: usize,
    ) -> Result<(Layout, Vec<RankShare>)> {
        let nodes = nodes(disc);
        let mut graph = Graph::new(disc, cells, &nodes).for_metis()?;
        let part = match size {
            0 | 1 => vec![0; nodes.len()],
            _ => partition(&mut graph, size)?,
        };
        let shares = shares(&graph, &nodes, &part, size.max(1));
        drop(graph);
        let mut order: Vec<usize> = (0..nodes.len()).collect();
        order.sort_by_key(|&v| (part[v], v));
        let (mut row, mut blocks) = (vec![0; disc.n_free], vec![0; size.max(1) + 1]);
        let mut next = 0;
        for v in order {
            for &i in &nodes[v] {
                row[i] = next as u32;
                next += 1;
            }
            blocks[part[v] + 1] += nodes[v].len();
        }
        for r in 0..size.max(1) {
            blocks[r + 1] += blocks[r];
        }
        let row = (size > 1).then_some(row);
        let kept = None;
        Ok((Layout { row, kept, blocks }, shares))
    }

    /// The partition that rank 0 makes (`make`, called there alone) on every rank of
    /// several (collective: every rank calls it, `first` on rank 0), so that no other rank
    /// builds the nodes' graph or runs METIS: rank 0 sends its error's text, or the blocks,
    /// the shares and, where `every_row`, the rows' order as bytes. Else a follower's
    /// layout holds no row until it keeps those it reads ([`Layout::keep_rows_of_first`]).
    pub fn of_first(
        (first, every_row): (bool, bool),
        make: impl FnOnce() -> Result<(Layout, Vec<RankShare>)>,
    ) -> Result<(Layout, Vec<RankShare>)> {
        let made = if first { Some(make()) } else { None };
        // What follows: the error's bytes (0 where there is none), the rows, the ranks.
        let mut head = [0u64; 3];
        match &made {
            Some(Err(e)) => head[0] = text_of(e).len() as u64,
            Some(Ok((layout, _))) => {
                let rows = (layout.row.as_ref().filter(|_| every_row)).map_or(0, Vec::len);
                head = [0, rows as u64, (layout.blocks.len() - 1) as u64];
            }
            None => {}
        }
        super::from_rank0_bytes(bytemuck::cast_slice_mut(&mut head))?;
        if head[0] > 0 {
            let mut text = match &made {
                Some(Err(e)) => text_of(e),
                _ => vec![0; head[0] as usize],
            };
            super::from_rank0_bytes(&mut text)?;
            return match made {
                Some(Err(e)) => Err(e),
                _ => Err(Error::solve(String::from_utf8_lossy(&text).into_owned())),
            };
        }
        let (rows, size) = (head[1] as usize, head[2] as usize);
        let made = match made {
            Some(made) => made?,
            None => (
                Layout {
                    row: Some(vec![0; rows]),
                    kept: (!every_row).then(Vec::new),
                    blocks: vec![0; size + 1],
                },
                vec![RankShare::default(); size],
            ),
        };
        Layout::sent(made, every_row)
    }

    /// Rank 0's layout and shares in `made` on every rank (collective), each rank's of the
    /// sizes of rank 0's.
    fn sent(
        (mut layout, shares): (Layout, Vec<RankShare>),
        every_row: bool,
    ) -> Result<(Layout, Vec<RankShare>)> {
        let size = shares.len();
        let mut flat: Vec<u64> = (shares.iter())
            .flat_map(|s| [s.rows, s.entries, s.ghosts].map(|c| c as u64))
            .chain(layout.blocks.iter().map(|&b| b as u64))
            .collect();
        super::from_rank0_bytes(bytemuck::cast_slice_mut(&mut flat))?;
        if let Some(row) = layout.row.as_mut().filter(|_| every_row) {
            super::from_rank0_bytes(bytemuck::cast_slice_mut(row))?;
        }
        let (counts, blocks) = flat.split_at(3 * size);
        layout.blocks = blocks.iter().map(|&b| b as usize).collect();
        let shares = (counts.chunks(3))
            .map(|c| RankShare {
                rows: c[0] as usize,
                entries: c[1] as usize,
                ghosts: c[2] as usize,
            })
            .collect();
        Ok((layout, shares))
    }

    /// This layout read at the places of a rank's vectors that hold the unknowns `places`
    /// alone (increasing; `petsc::Reads::held`): [`Layout::row`] of place k is then the row
    /// of unknown `places[k]`, 4 bytes a place and not an unknown of the whole on a
    /// follower. What reads every unknown (`own`,
    /// `unknowns_of`, `rows_of`) is the setup's, done before. A place past the unknowns (a
    /// prescribed dof's) has no row.
    pub fn placed(self, places: &[usize]) -> Layout {
        let n = self.n_unknowns();
        let at = |&i: &usize| if i < n { self.row(i) as u32 } else { u32::MAX };
        let row = self.row.is_some().then(|| places.iter().map(at).collect());
        let kept = None;
        Layout { row, kept, ..self }
    }

    /// Of a follower's layout made without the rows' order ([`Layout::of_first`]), the
    /// rows of the unknowns `kept` that it reads (increasing: its part's cells' and Γ3's,
    /// [`part_unknowns`]), which rank 0 sends, knowing each rank r's as `kept_of(r)`
    /// (collective; `first` on rank 0, whose layout, every unknown's, stays as it is): 4
    /// bytes an unknown the follower reads, not of every unknown.
    pub fn keep_rows_of_first(
        &mut self,
        (first, kept): (bool, Vec<u32>),
        kept_of: impl Fn(usize) -> Vec<u32>,
    ) -> Result<()> {
        let size = self.blocks.len() - 1;
        let rows_of = |r: usize| match r {
            0 => Vec::new(),
            r => kept_of(r)
                .iter()
                .map(|&i| self.row(i as usize) as u32)
                .collect(),
        };
        let parts = first.then(|| (0..size).map(rows_of).collect::<Vec<_>>());
        let rows = super::scatter_from_first(parts.as_deref())?;
        if !first {
            assert_eq!(
                kept.len(),
                rows.len(),
                "a row for each unknown a follower reads"
            );
            (self.row, self.kept) = (Some(rows), Some(kept));
        }
        Ok(())
    }

    /// The row of unknown i (of place i where [`Layout::placed`]).
    ///
    /// # Panics
    /// Where a follower keeps the rows it reads alone and i is not among them: which
    /// unknowns a rank reads is the code's invariant, not the user's input.
    pub fn row(&self, i: usize) -> usize {
        match (&self.row, &self.kept) {
            (None, _) => i,
            (Some(row), None) => row[i] as usize,
            (Some(row), Some(kept)) => {
                let at = kept.binary_search(&(i as u32));
                row[at.expect("the row of an unknown this rank reads")] as usize
            }
        }
    }

    /// The unknowns whose rows this layout says: every one, or those a follower keeps.
    fn unknowns(&self) -> Box<dyn Iterator<Item = usize> + '_> {
        match &self.kept {
            None => Box::new(0..self.n_unknowns()),
            Some(kept) => Box::new(kept.iter().map(|&i| i as usize)),
        }
    }

    /// The number of unknowns, which the rows number: the last block's end.
    pub fn n_unknowns(&self) -> usize {
        *self.blocks.last().unwrap_or(&0)
    }

    /// The rank that holds row r.
    pub fn rank_of_row(&self, r: usize) -> usize {
        self.blocks.partition_point(|&b| b <= r) - 1
    }

    /// The unknowns whose rows rank `rank` holds, increasing.
    pub fn own(&self, rank: usize) -> Vec<usize> {
        let block = self.blocks[rank]..self.blocks[rank + 1];
        self.unknowns()
            .filter(|&i| block.contains(&self.row(i)))
            .collect()
    }

    /// The unknown of each of rank `rank`'s rows, in the rows' order: the inverse of
    /// [`Layout::row`] there (4 bytes a row of its own, not of every rank's).
    pub fn unknowns_of(&self, rank: usize) -> Vec<u32> {
        let block = self.blocks[rank]..self.blocks[rank + 1];
        let mut unknown = vec![0u32; block.len()];
        for i in self.unknowns().filter(|&i| block.contains(&self.row(i))) {
            unknown[self.row(i) - block.start] = i as u32;
        }
        unknown
    }

    /// Whether the rows are the unknowns in another order.
    pub fn permutes(&self) -> bool {
        self.row.is_some()
    }

    /// x ← x from the rows' order to the unknowns', in place: x holds every row (a solved
    /// step's, gathered), and x_i ← x_row(i) along each cycle of the permutation, a bit a
    /// value marking those done, where a copy in the rows' order held 8 bytes an unknown
    /// of the whole (docs/cluster.md, "Memory per rank", 51.).
    pub fn to_unknowns_order(&self, x: &mut [f64]) {
        assert!(self.kept.is_none(), "every unknown's row, not kept");
        let Some(row) = &self.row else {
            return;
        };
        assert_eq!(x.len(), row.len(), "every row, not placed");
        let mut done = vec![0_u64; x.len().div_ceil(64)];
        let is_done = |done: &[u64], i: usize| done[i / 64] >> (i % 64) & 1 == 1;
        for start in 0..x.len() {
            if is_done(&done, start) {
                continue;
            }
            let first = x[start];
            let mut i = start;
            loop {
                done[i / 64] |= 1 << (i % 64);
                let r = row[i] as usize;
                if r == start {
                    x[i] = first;
                    break;
                }
                assert!(
                    !is_done(&done, r),
                    "the rows are a permutation of the unknowns"
                );
                x[i] = x[r];
                i = r;
            }
        }
    }

    /// Rank `rank`'s rows of the symmetric `matrix` in the rows' order, as CSR (its CSC)
    /// with the row pointers of those rows alone (m + 1, from 0): what the shim keeps of it.
    /// On one rank the matrix's own arrays, its values not copied. A matrix with fewer
    /// columns than rows holds the rank's own columns alone, in the unknowns' order
    /// (`Discretization::own`).
    pub fn rows_of<'a>(&self, matrix: &'a Sparse, rank: usize) -> Result<Csr<'a>> {
        let m = matrix.as_ref();
        let (ptr, idx, val) = (m.symbolic().col_ptr(), m.symbolic().row_idx(), m.val());
        if self.row.is_none() {
            return Ok(Csr {
                rowptr: petsc_ints(ptr)?,
                cols: petsc_ints(idx)?,
                vals: std::borrow::Cow::Borrowed(val),
            });
        };
        let own = self.unknowns_of(rank);
        // Sized once: grown by doubling, the values could hold up to twice their length.
        let own = || own.iter().map(|&i| i as usize);
        let sorted = (m.ncols() < m.nrows()).then(|| {
            let mut sorted: Vec<usize> = own().collect();
            sorted.sort_unstable();
            sorted
        });
        let column = |i: usize| match &sorted {
            Some(sorted) => sorted.binary_search(&i).expect("an own column"),
            None => i,
        };
        let entries: usize = own().map(|i| ptr[column(i) + 1] - ptr[column(i)]).sum();
        let (mut cols, mut vals) = (Vec::with_capacity(entries), Vec::with_capacity(entries));
        let mut rowptr = Vec::with_capacity(self.blocks[rank + 1] - self.blocks[rank] + 1);
        rowptr.push(0);
        let mut by_row: Vec<(usize, f64)> = Vec::new();
        for i in own().map(column) {
            by_row.clear();
            by_row.extend((ptr[i]..ptr[i + 1]).map(|p| (self.row(idx[p]), val[p])));
            by_row.sort_by_key(|&(c, _)| c);
            for &(c, v) in &by_row {
                cols.push(petsc_int(c)?);
                vals.push(v);
            }
            rowptr.push(petsc_int(cols.len())?);
        }
        Ok(Csr {
            rowptr,
            cols,
            vals: std::borrow::Cow::Owned(vals),
        })
    }

    /// The rank that holds mesh node v's unknowns, None for a node without any: a rank
    /// holds whole nodes, so a node's first unknown says whose it is.
    fn rank_of_node(&self, disc: &Discretization, v: usize) -> Option<u32> {
        let g = v * disc.dim;
        let first = (g..g + disc.dim).find_map(|g| disc.free.unknown(g))?;
        Some(self.rank_of_row(self.row(first)) as u32)
    }

    /// The piece of each cell (`cells`: `nodes_per_cell` mesh nodes each) in the `.pvtu`
    /// frames of a run over these ranks (`output`'s `pvtu.rs`): the lowest rank among those
    /// that hold the cell's nodes with unknowns, so that piece r is rank r's part of the
    /// mesh; 0 for a cell whose nodes are all clamped.
    pub fn cell_pieces(
        &self,
        disc: &Discretization,
        cells: &[usize],
        nodes_per_cell: usize,
    ) -> Vec<u32> {
        // Node by node, not from an array of every node's: a follower's cells are its part's.
        let of_node = |&v: &usize| self.rank_of_node(disc, v);
        (cells.chunks(nodes_per_cell.max(1)))
            .map(|c| c.iter().filter_map(of_node).min().unwrap_or(0))
            .collect()
    }

    /// The rank that holds each mesh node's unknowns; `u32::MAX` for a node without any.
    fn rank_of_nodes(&self, disc: &Discretization) -> Vec<u32> {
        let rank_of = |v| self.rank_of_node(disc, v).unwrap_or(u32::MAX);
        (0..disc.free.dofs() / disc.dim).map(rank_of).collect()
    }

    /// Each follower's part of the mesh (`cells`, in their order): the cells its assembly
    /// reads, those with one of its own nodes, as indices increasing; for a scene whose
    /// ranks keep every column (`Discretization::keeps_own_columns`), every cell. Rank 0's
    /// (the first) is empty: it holds the mesh. One pass over the cells.
    pub fn cell_parts(&self, disc: &Discretization, cells: CellSource) -> Vec<Vec<u32>> {
        let size = self.blocks.len() - 1;
        let of_node = self.rank_of_nodes(disc);
        let whole = !disc.keeps_own_columns();
        let mut parts = vec![Vec::new(); size];
        let mut c = 0u32;
        cells.each_vertices(|v| {
            if whole {
                parts[1..].iter_mut().for_each(|part| part.push(c));
            } else {
                // Each rank of the cell's nodes once (a cell has at most four).
                let mut ranks = [u32::MAX; 4];
                v.iter().zip(&mut ranks).for_each(|(&p, r)| *r = of_node[p]);
                ranks.sort_unstable();
                for (i, &r) in ranks.iter().enumerate() {
                    if r != 0 && r != u32::MAX && (i == 0 || ranks[i - 1] != r) {
                        parts[r as usize].push(c);
                    }
                }
            }
            c += 1;
        });
        parts
    }
}

/// A rank's share of K_A (`Layout`): its rows, its stored entries, and the values of other
/// ranks' rows that a product with K_A fetches (its rows' distinct columns outside them): a
/// Krylov iteration's work and messages on that rank.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RankShare {
    pub rows: usize,
    pub entries: usize,
    pub ghosts: usize,
}

/// A matrix's rows as the shim takes them (`Layout::rows_of`).
pub struct Csr<'a> {
    pub rowptr: Vec<PetscInt>,
    pub cols: Vec<PetscInt>,
    pub vals: std::borrow::Cow<'a, [f64]>,
}

impl Csr<'_> {
    /// The rows with their values of their own (copied where they were borrowed).
    pub fn into_owned(self) -> Csr<'static> {
        Csr {
            rowptr: self.rowptr,
            cols: self.cols,
            vals: std::borrow::Cow::Owned(self.vals.into_owned()),
        }
    }
}

/// `v` as PETSc's indices, or the error that they do not fit (32 bits).
pub fn petsc_ints(v: &[usize]) -> Result<Vec<PetscInt>> {
    v.iter().map(|&i| petsc_int(i)).collect()
}

/// `i` as a PETSc index, or the error that it does not fit (32 bits).
fn petsc_int(i: usize) -> Result<PetscInt> {
    PetscInt::try_from(i)
        .map_err(|_| Error::solve("K_A is too large for PETSc's 32-bit indices".to_string()))
}

/// The unknowns of each node that has any, node by node.
fn nodes(disc: &Discretization) -> Vec<Vec<usize>> {
    (0..disc.free.dofs() / disc.dim)
        .map(|v| node_unknowns(disc, v))
        .filter(|u| !u.is_empty())
        .collect()
}

/// The unknowns of the nodes that `vertices` name and of Γ3's rows, increasing: those a
/// follower reads where its vectors hold its own unknowns and their neighbours' alone
/// ([`Layout::keep_rows_of_first`]; the cells with one of its own nodes are its part).
pub fn part_unknowns(disc: &Discretization, vertices: &[u32]) -> Vec<u32> {
    let gamma3 = (disc.contact.iter().chain(&disc.friction)).map(|row| row.node as u32);
    let of_node = |v: u32| (disc.free.of_node(disc.dim, v as usize)).map(|i| i as u32);
    let nodes = vertices.iter().copied().chain(gamma3);
    crate::mesh::increasing(nodes.flat_map(of_node).collect())
}

/// The unknowns of mesh node `v`.
fn node_unknowns(disc: &Discretization, v: usize) -> Vec<usize> {
    let g = v * disc.dim;
    (g..g + disc.dim)
        .filter_map(|g| disc.free.unknown(g))
        .collect()
}

/// The nodes' graph on the nodes with unknowns (`nodes`, in their order): for each, the
/// others that one of `cells` holds with it (where K_A couples them: P1), increasing, in
/// compressed rows. Made from the cells' vertices (4 bytes each) and the cells at each
/// node, each neighbour once, so that it holds no more than it says (docs/performance.md,
/// "The nodes' graph at its size"). Node and cell numbers fit 32 bits (the mesh's reader
/// refuses more: `mesh::facets`).
struct Graph {
    /// The neighbours of node v are `adjacent[start[v]..start[v + 1]]`.
    start: Vec<usize>,
    adjacent: Vec<u32>,
}

impl Graph {
    fn new(disc: &Discretization, cells: CellSource, nodes: &[Vec<usize>]) -> Graph {
        const NONE: u32 = u32::MAX;
        let mut vertex = vec![NONE; disc.free.dofs() / disc.dim];
        let with_unknowns = (0..vertex.len()).filter(|&p| !node_unknowns(disc, p).is_empty());
        for (v, p) in with_unknowns.enumerate() {
            vertex[p] = v as u32;
        }
        // Each cell's vertices in the graph (NONE: a node without unknowns).
        let (mut corners, mut per) = (Vec::new(), 1);
        cells.each_vertices(|vertices| {
            per = vertices.len().max(1);
            corners.extend(vertices.iter().map(|&p| vertex[p]));
        });
        // The cells at each node, by counting.
        let n = nodes.len();
        let mut at = vec![0; n + 1];
        let held = || (corners.iter().enumerate()).filter(|(_, &v)| v != NONE);
        held().for_each(|(_, &v)| at[v as usize + 1] += 1);
        for v in 0..n {
            at[v + 1] += at[v];
        }
        let (mut cell_at, mut next) = (vec![0u32; at[n]], at.clone());
        for (k, &v) in held() {
            cell_at[next[v as usize]] = (k / per) as u32;
            next[v as usize] += 1;
        }
        // Each node's neighbours: the other vertices of its cells, each once.
        let mut seen = vec![NONE; n];
        let (mut start, mut adjacent) = (Vec::with_capacity(n + 1), Vec::new());
        start.push(0);
        for v in 0..n {
            let first = adjacent.len();
            for &c in &cell_at[at[v]..at[v + 1]] {
                for &w in &corners[c as usize * per..][..per] {
                    if w != NONE && w as usize != v && seen[w as usize] != v as u32 {
                        seen[w as usize] = v as u32;
                        adjacent.push(w);
                    }
                }
            }
            adjacent[first..].sort_unstable();
            start.push(adjacent.len());
        }
        Graph { start, adjacent }
    }
}

/// An error's text as rank 0 sends it to the others ([`Layout::of_first`]): never empty,
/// since its length says that there is one.
fn text_of(e: &Error) -> Vec<u8> {
    let mut text = e.to_string().into_bytes();
    text.resize(text.len().max(1), b' ');
    text
}

/// The nodes' graph in METIS's integers: the neighbours of node v are
/// `adjncy[xadj[v]..xadj[v + 1]]`.
struct MetisGraph {
    xadj: Vec<metis_sys::idx_t>,
    adjncy: Vec<metis_sys::idx_t>,
}

impl MetisGraph {
    /// The neighbours of node v, increasing.
    fn of(&self, v: usize) -> impl Iterator<Item = usize> + Clone + '_ {
        let (a, b) = (self.xadj[v] as usize, self.xadj[v + 1] as usize);
        self.adjncy[a..b].iter().map(|&w| w as usize)
    }
}

impl Graph {
    /// The graph in METIS's integers, the graph's own arrays let go of as they are copied.
    fn for_metis(self) -> Result<MetisGraph> {
        let too_large = |_| Error::solve("K_A is too large for METIS's indices".to_string());
        let idx = |v: usize| metis_sys::idx_t::try_from(v).map_err(too_large);
        let xadj = self.start.iter().map(|&i| idx(i)).collect::<Result<_>>()?;
        drop(self.start);
        let adjncy = self.adjacent.iter().map(|&w| idx(w as usize));
        Ok(MetisGraph {
            xadj,
            adjncy: adjncy.collect::<Result<_>>()?,
        })
    }
}

/// Each rank's share of K_A over the partition `part` of the nodes' graph (each node's
/// rank): its rows, entries and the values of other ranks' rows that a product fetches.
/// Counted on the graph, whose pattern K_A's is (the unknowns of a node couple with those
/// of the node and of its neighbours), so that a rank that assembled only its own columns
/// (`Ranks::discretize`) counts every rank's share.
fn shares(graph: &MetisGraph, nodes: &[Vec<usize>], part: &[usize], size: usize) -> Vec<RankShare> {
    let mut order: Vec<usize> = (0..nodes.len()).collect();
    order.sort_by_key(|&v| part[v]);
    let mut shares = vec![RankShare::default(); size];
    let mut seen = vec![usize::MAX; nodes.len()];
    for v in order {
        let (r, unknowns) = (part[v], nodes[v].len());
        let share = &mut shares[r];
        let adjacent = graph.of(v);
        let coupled: usize = adjacent.clone().map(|w| nodes[w].len()).sum();
        share.rows += unknowns;
        share.entries += unknowns * (unknowns + coupled);
        for w in adjacent.filter(|&w| part[w] != r) {
            if seen[w] != r {
                seen[w] = r;
                share.ghosts += nodes[w].len();
            }
        }
    }
    shares
}

/// METIS's k-way partition of the nodes' graph into `size` parts: each node's part. Two
/// nodes are adjacent where a cell holds both (where K_A couples them: P1), so that the
/// partition needs no matrix: rank 0 makes it before it assembles its own columns of K_A
/// alone (`fem::Discretization::assembled`), and hands it to the others
/// ([`Layout::of_first`]).
fn partition(graph: &mut MetisGraph, size: usize) -> Result<Vec<usize>> {
    let too_large = |_| Error::solve("K_A is too large for METIS's indices".to_string());
    let idx = |v: usize| metis_sys::idx_t::try_from(v).map_err(too_large);
    let nodes = graph.xadj.len() - 1;
    let (mut nvtxs, mut ncon, mut nparts) = (idx(nodes)?, 1, idx(size)?);
    let (mut cut, mut part) = (0, vec![0; nodes]);
    // SAFETY: xadj (nvtxs + 1 entries) and adjncy describe a graph without self loops,
    // symmetric (a cell makes both arrows); part holds nvtxs entries; null weights, targets
    // and options mean unit weights, even parts and METIS's defaults (a fixed seed). METIS
    // reads the graph and writes cut and part. The runs that partition (under a launcher)
    // order nothing with METIS at the same time (`solver::ordering` serializes its own).
    let status = unsafe {
        metis_sys::METIS_PartGraphKway(
            &mut nvtxs,
            &mut ncon,
            graph.xadj.as_mut_ptr(),
            graph.adjncy.as_mut_ptr(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            &mut nparts,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            &mut cut,
            part.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return Err(Error::solve(format!(
            "METIS could not partition the mesh's {nodes} nodes among {size} ranks (status \
             {status})"
        )));
    }
    Ok(part.iter().map(|&p| p as usize).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::SplitMix;

    /// A layout of `n` unknowns in a random order over `size` ranks of random sizes.
    fn shuffled(n: usize, size: usize, rng: &mut SplitMix) -> Layout {
        let mut order: Vec<u32> = (0..n as u32).collect();
        for i in (1..n).rev() {
            order.swap(i, rng.next() as usize % (i + 1));
        }
        let mut row = vec![0; n];
        order
            .iter()
            .enumerate()
            .for_each(|(r, &i)| row[i as usize] = r as u32);
        let mut cuts: Vec<usize> = (1..size).map(|_| rng.next() as usize % (n + 1)).collect();
        cuts.sort_unstable();
        let blocks = [vec![0], cuts, vec![n]].concat();
        Layout {
            row: Some(row),
            kept: None,
            blocks,
        }
    }

    #[test]
    fn each_rank_makes_the_unknowns_of_its_own_rows_alone() {
        let mut rng = SplitMix(52);
        let layout = shuffled(40, 4, &mut rng);
        for rank in 0..4 {
            let unknowns = layout.unknowns_of(rank);
            let block = layout.blocks[rank]..layout.blocks[rank + 1];
            assert_eq!(unknowns.len(), block.len());
            for (k, &i) in unknowns.iter().enumerate() {
                assert_eq!(layout.row(i as usize), block.start + k);
            }
            let mut own: Vec<usize> = unknowns.iter().map(|&i| i as usize).collect();
            own.sort_unstable();
            assert_eq!(own, layout.own(rank));
        }
    }

    /// A vector in the rows' order goes to the unknowns' order in place as a copy read
    /// at each unknown's row would put it, for permutations of one long cycle, many short
    /// ones and none.
    #[test]
    fn rows_go_to_the_unknowns_order_in_place() {
        let mut rng = SplitMix(51);
        let n = 1000;
        let mut layouts = vec![shuffled(n, 4, &mut rng), shuffled(1, 1, &mut rng)];
        let one_cycle: Vec<u32> = (0..n as u32).map(|i| (i + 1) % n as u32).collect();
        let swaps: Vec<u32> = (0..n as u32).map(|i| i ^ 1).collect();
        for row in [one_cycle, swaps, (0..n as u32).collect()] {
            layouts.push(Layout {
                row: Some(row),
                ..layouts[0].clone()
            });
        }
        for layout in &layouts {
            let m = layout.n_unknowns();
            let rows: Vec<f64> = (0..m).map(|_| rng.next() as f64).collect();
            let mut x = rows.clone();
            layout.to_unknowns_order(&mut x);
            for (i, v) in x.iter().enumerate() {
                assert_eq!(v.to_bits(), rows[layout.row(i)].to_bits(), "unknown {i}");
            }
        }
    }

    #[test]
    fn a_placed_layout_reads_the_rows_of_its_places() {
        let mut rng = SplitMix(38);
        let layout = shuffled(30, 3, &mut rng);
        // Increasing places, and one past the unknowns (a prescribed dof's: no row).
        let places: Vec<usize> = (0..30)
            .filter(|_| rng.next().is_multiple_of(3))
            .chain([31])
            .collect();
        let placed = layout.clone().placed(&places);
        for (k, &i) in places[..places.len() - 1].iter().enumerate() {
            assert_eq!(placed.row(k), layout.row(i));
        }
        assert_eq!(placed.row(places.len() - 1), u32::MAX as usize);
        assert!(placed.permutes());
    }

    /// A layout that keeps the rows of some unknowns alone (a rank's own among them) reads
    /// the same rows, own unknowns and places as the whole, and no row of another unknown.
    #[test]
    fn a_layout_of_some_rows_reads_them_as_the_whole_does() {
        let mut rng = SplitMix(44);
        let whole = shuffled(50, 4, &mut rng);
        for rank in 0..4 {
            let mut kept: Vec<u32> = (0..50).filter(|_| rng.next().is_multiple_of(2)).collect();
            kept.extend(whole.unknowns_of(rank));
            kept.sort_unstable();
            kept.dedup();
            let some = Layout {
                row: Some(kept.iter().map(|&i| whole.row(i as usize) as u32).collect()),
                kept: Some(kept.clone()),
                blocks: whole.blocks.clone(),
            };
            assert_eq!(some.own(rank), whole.own(rank));
            assert_eq!(some.unknowns_of(rank), whole.unknowns_of(rank));
            let places: Vec<usize> = (kept.iter().map(|&i| i as usize)).chain([57]).collect();
            let (a, b) = (some.clone().placed(&places), whole.clone().placed(&places));
            for k in 0..places.len() {
                assert_eq!(a.row(k), b.row(k));
            }
            if let Some(other) = (0..50).find(|i| kept.binary_search(i).is_err()) {
                let read = std::panic::catch_unwind(|| some.row(other as usize));
                assert!(read.is_err(), "the row of an unknown not kept");
            }
        }
    }
}
