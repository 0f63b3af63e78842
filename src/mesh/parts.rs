//! Is the mesh one body held by Γ1? Two checks that the element checks cannot see.
//!
//! **Parts.** A part is a connected component of the cells, two cells being connected when
//! they share a node (union–find over the nodes of every cell, O(n α(n))). A part that holds
//! no facet of the clamped group Γ1 can move as a rigid body: its block of K_A is singular and
//! no step can be solved. Such a part is always refused (`check`/`run`, exit 2). A Γ1 facet
//! is an edge or face of one cell, so its nodes lie in one part; a part that holds one holds
//! at least two distinct points (2D) or three non-collinear ones (3D), which fix its rigid
//! motions.
//!
//! **Coincident nodes.** Two mesh nodes at the same place, each used by cells, are never both
//! used by one cell (that cell would be degenerate, refused earlier): the cells on either side
//! are not connected there. That is the mark of touching geometry that was not fragmented
//! (OpenCASCADE `BooleanFragments`, built-in kernel `Coherence`) or of a mesh merged from
//! pieces without `Coherence Mesh;`. Two nodes coincide when each coordinate differs by at
//! most tol = 1e-10 × the diagonal of the mesh's bounding box (cells smaller than that are
//! refused as degenerate anyway). They are found in O(n) expected time with a hash of the
//! coordinates rounded to a grid of spacing tol: a node is compared with the nodes of its own
//! and the 3^d − 1 neighbouring grid cells only. Coincident nodes are refused unless the
//! scene says the parts are separate bodies that only touch (`[mesh] separate_parts = true`);
//! even then every part needs Γ1.

use std::collections::{BTreeSet, HashMap};

use super::{fmt_point, Mesh};
use crate::{Error, Result};

/// Coordinates closer than this times the bounding-box diagonal are one place.
pub const COINCIDENT_TOLERANCE: f64 = 1e-10;

/// A connected component of the cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// Indices of its cells (triangles or tetrahedra), increasing.
    pub cells: Vec<usize>,
    /// Its nodes, increasing.
    pub nodes: Vec<usize>,
    /// The gmsh entities (surfaces in 2D, volumes in 3D) its cells belong to.
    pub entities: Vec<i32>,
    /// Its bounding box: lowest and highest coordinates.
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// Nodes at one place: two or more mesh nodes within the tolerance of each other.
#[derive(Debug, Clone, PartialEq)]
pub struct Coincident {
    /// The nodes, increasing.
    pub nodes: Vec<usize>,
    /// The gmsh entities of the cells that use them.
    pub entities: Vec<i32>,
}

/// Union–find with path halving.
struct Sets(Vec<usize>);

impl Sets {
    fn new(n: usize) -> Self {
        Sets((0..n).collect())
    }

    fn find(&mut self, mut i: usize) -> usize {
        while self.0[i] != i {
            self.0[i] = self.0[self.0[i]];
            i = self.0[i];
        }
        i
    }

    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        self.0[ra.max(rb)] = ra.min(rb);
    }

    /// The sets with at least `min_len` members, each increasing, ordered by their first.
    fn classes(&mut self, min_len: usize) -> Vec<Vec<usize>> {
        let mut by_root: HashMap<usize, Vec<usize>> = HashMap::new();
        for i in 0..self.0.len() {
            let r = self.find(i);
            by_root.entry(r).or_default().push(i);
        }
        let mut out: Vec<Vec<usize>> = by_root
            .into_values()
            .filter(|c| c.len() >= min_len)
            .collect();
        out.sort_unstable_by_key(|c| c[0]);
        out
    }
}

impl Mesh {
    fn cell(&self, c: usize) -> &[usize] {
        match self.dim {
            2 => &self.triangles[c],
            _ => &self.tetrahedra[c],
        }
    }

    /// The gmsh entities of the cells using each node, sorted, unique.
    fn node_entities(&self) -> Vec<Vec<i32>> {
        let mut out = vec![Vec::new(); self.nodes.len()];
        for (c, &e) in self.cell_entity.iter().enumerate() {
            for &n in self.cell(c) {
                if !out[n].contains(&e) {
                    out[n].push(e);
                }
            }
        }
        out.iter_mut().for_each(|v| v.sort_unstable());
        out
    }

    /// The connected components of the cells (through shared nodes), in the order of their
    /// first cell. One part for a mesh that is one body.
    pub fn parts(&self) -> Vec<Part> {
        let mut sets = Sets::new(self.nodes.len());
        for c in 0..self.n_cells() {
            let cell = self.cell(c);
            for &n in &cell[1..] {
                sets.union(cell[0], n);
            }
        }
        let classes = sets.classes(1);
        let mut part_of = vec![0; self.nodes.len()];
        for (k, nodes) in classes.iter().enumerate() {
            nodes.iter().for_each(|&n| part_of[n] = k);
        }
        let mut parts: Vec<Part> = classes
            .into_iter()
            .map(|nodes| {
                let (mut min, mut max) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                for &n in &nodes {
                    for k in 0..3 {
                        min[k] = min[k].min(self.nodes[n][k]);
                        max[k] = max[k].max(self.nodes[n][k]);
                    }
                }
                Part {
                    cells: Vec::new(),
                    nodes,
                    entities: Vec::new(),
                    min,
                    max,
                }
            })
            .collect();
        for c in 0..self.n_cells() {
            let p = &mut parts[part_of[self.cell(c)[0]]];
            p.cells.push(c);
            if !p.entities.contains(&self.cell_entity[c]) {
                p.entities.push(self.cell_entity[c]);
            }
        }
        parts.sort_by_key(|p| p.cells[0]);
        parts.iter_mut().for_each(|p| p.entities.sort_unstable());
        parts
    }

    /// Places where two or more nodes coincide (see the module doc for the tolerance), in the
    /// order of their first node.
    pub fn coincident_nodes(&self) -> Vec<Coincident> {
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in self.nodes.all() {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let tol = COINCIDENT_TOLERANCE * diag;
        // Grid keys are at most 1e10 (the diagonal over tol): they fit an i64.
        let key = |p: &[f64; 3]| [0, 1, 2].map(|k| ((p[k] - lo[k]) / tol).floor() as i64);
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::with_capacity(self.nodes.len());
        for (i, p) in self.nodes.all().iter().enumerate() {
            grid.entry(key(p)).or_default().push(i);
        }
        let span = |k: usize| if k < self.dim { -1..=1 } else { 0..=0 };
        let mut sets = Sets::new(self.nodes.len());
        for (i, p) in self.nodes.all().iter().enumerate() {
            let g = key(p);
            for dx in span(0) {
                for dy in span(1) {
                    for dz in span(2) {
                        let near = grid.get(&[g[0] + dx, g[1] + dy, g[2] + dz]);
                        for &j in near.into_iter().flatten().filter(|&&j| j > i) {
                            let q = self.nodes[j];
                            if (0..3).all(|k| (p[k] - q[k]).abs() <= tol) {
                                sets.union(i, j);
                            }
                        }
                    }
                }
            }
        }
        let entities = self.node_entities();
        sets.classes(2)
            .into_iter()
            .map(|nodes| {
                let set: BTreeSet<i32> = nodes.iter().flat_map(|&n| entities[n].clone()).collect();
                Coincident {
                    nodes,
                    entities: set.into_iter().collect(),
                }
            })
            .collect()
    }

    /// `check`/`run`: refuses coincident nodes (unless `separate_parts`) and any part that
    /// holds no node of the conditions (`held` per node; `what` names them: "the clamped
    /// group 'Γ1'"), naming where and what fixes it.
    pub fn check_parts(&self, held: &[bool], what: &str, separate_parts: bool) -> Result<()> {
        let file = self.path.display();
        if !separate_parts {
            let places = self.coincident_nodes();
            if !places.is_empty() {
                return Err(Error::input(format!(
                    "mesh '{file}': {}; the cells on either side are not connected there, as \
                     when touching {} were not fragmented. In gmsh, fragment them \
                     (OpenCASCADE: `BooleanFragments{{ {} {{:}}; Delete; }}{{}}`; built-in \
                     kernel: `Coherence;`) or merge the duplicate nodes (`Coherence Mesh;`) \
                     and save the mesh again; if they are separate bodies that only touch, \
                     set `separate_parts = true` in [mesh]",
                    self.describe_coincident(&places),
                    self.entity_words().1,
                    self.entity_words().2,
                )));
            }
        }
        let parts = self.parts();
        let free: Vec<(usize, &Part)> = parts
            .iter()
            .enumerate()
            .filter(|(_, p)| !p.nodes.iter().any(|&n| held[n]))
            .collect();
        let Some(&(k, first)) = free.first() else {
            return Ok(());
        };
        let more = match free.len() {
            1 => String::new(),
            n => format!(" ({} more parts hold none either)", n - 1),
        };
        Err(Error::input(format!(
            "mesh '{file}' has {} parts (sets of cells connected through shared nodes), and \
             part {} ({}) holds no {} of {what}{more}: it could move as a rigid \
             body, so K_A is singular. Put part of its boundary into a clamped group, connect it to the \
             body (gmsh: BooleanFragments in OpenCASCADE, Coherence in the built-in kernel), \
             or remove it{}",
            parts.len(),
            k + 1,
            self.describe_part(first),
            if self.dim == 2 { "edge" } else { "face" },
            if separate_parts {
                "; `separate_parts = true` allows parts that only touch, not parts without Γ1"
            } else {
                ""
            }
        )))
    }

    /// ("triangles", "surfaces", "Surface", "surface") or the 3D words.
    fn entity_words(&self) -> (&'static str, &'static str, &'static str, &'static str) {
        match self.dim {
            2 => ("triangles", "surfaces", "Surface", "surface"),
            _ => ("tetrahedra", "volumes", "Volume", "volume"),
        }
    }

    /// "162 triangles, 99 nodes, gmsh surface 2, spanning (1, 0)–(2, 1)".
    pub fn describe_part(&self, p: &Part) -> String {
        let (cells, entities, _, one) = self.entity_words();
        format!(
            "{} {cells}, {} nodes, gmsh {} {}, spanning {}–{}",
            p.cells.len(),
            p.nodes.len(),
            if p.entities.len() == 1 { one } else { entities },
            join(&p.entities),
            fmt_point(p.min, self.dim),
            fmt_point(p.max, self.dim)
        )
    }

    /// "18 nodes at 9 places coincide with another node that no cell shares (the first at
    /// (1, 0), where gmsh surfaces 1, 2 meet)".
    pub fn describe_coincident(&self, places: &[Coincident]) -> String {
        let n: usize = places.iter().map(|c| c.nodes.len()).sum();
        let first = &places[0];
        format!(
            "{n} nodes at {} place{} coincide with another node that no cell shares (the first \
             at {}, {})",
            places.len(),
            if places.len() == 1 { "" } else { "s" },
            fmt_point(self.nodes[first.nodes[0]], self.dim),
            match first.entities.len() {
                1 => format!("in gmsh {} {}", self.entity_words().3, first.entities[0]),
                _ => format!(
                    "where gmsh {} {} meet",
                    self.entity_words().1,
                    join(&first.entities)
                ),
            }
        )
    }
}

fn join(tags: &[i32]) -> String {
    let list: Vec<String> = tags.iter().map(|t| t.to_string()).collect();
    list.join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles on the unit square's diagonal: sharing nodes 1 and 2, or each with its
    /// own copy shifted by `gap` (relative to the diagonal √2).
    fn square(gap: Option<f64>) -> Mesh {
        let mut nodes = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let mut second = [1, 3, 2];
        if let Some(g) = gap {
            let d = g * 2f64.sqrt();
            nodes.push([1.0 + d, 0.0, 0.0]);
            nodes.push([0.0, 1.0 - d, 0.0]);
            second = [4, 3, 5];
        }
        Mesh {
            path: "square.msh".into(),
            dim: 2,
            nodes: crate::mesh::Places::every(nodes),
            triangles: vec![[0, 1, 2], second],
            tetrahedra: Vec::new(),
            groups: Vec::new(),
            flipped: 0,
            other_groups: Vec::new(),
            cell_entity: vec![1, 2],
        }
    }

    #[test]
    fn coincident_within_the_tolerance_and_parts() {
        let one = square(None);
        assert_eq!(one.parts().len(), 1);
        assert!(one.coincident_nodes().is_empty());
        // Within the tolerance (and on either side of a grid line): two places.
        for gap in [0.0, 0.3 * COINCIDENT_TOLERANCE, -0.9 * COINCIDENT_TOLERANCE] {
            let m = square(Some(gap));
            let places = m.coincident_nodes();
            let nodes: Vec<Vec<usize>> = places.iter().map(|c| c.nodes.clone()).collect();
            assert_eq!(nodes, vec![vec![1, 4], vec![2, 5]], "gap {gap:e}");
            assert_eq!(places[0].entities, vec![1, 2]);
            let parts = m.parts();
            assert_eq!(parts.len(), 2);
            assert_eq!(
                (parts[1].cells.clone(), parts[1].entities.clone()),
                (vec![1], vec![2])
            );
        }
        // Beyond it: separate nodes, still two parts.
        let m = square(Some(3.0 * COINCIDENT_TOLERANCE));
        assert!(m.coincident_nodes().is_empty());
        assert_eq!(m.parts().len(), 2);
    }
}
