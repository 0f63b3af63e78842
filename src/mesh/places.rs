//! The nodes' places that a mesh and a discretization hold: every node's, or on a rank of
//! several those of the nodes it reads.
//!
//! One process holds every node's, and so does rank 0 of several where it reads every cell
//! (a frame not in pieces, a body force's resultant in history.csv). Elsewhere rank 0 lets
//! go of them with its cells' vertices, past its setup, and keeps a follower's and those
//! that history.csv reads: its held nodes' (their moments) and the traction facets' nodes
//! (`Discretization::keep_places`). A follower of a run whose setup spreads never holds
//! every node's (24 bytes a node, 8 a dof of the whole problem): with the mesh it gets
//! those of the boundary groups' nodes, which its numbering, Γ3's rows and the tractions
//! read, and the centroid of every node as a number (GAMG's rigid-body modes turn about
//! it); with its part of the cells those of their vertices, which its assembly and its
//! piece of the frames read ([`Places::held`], [`Places::joined`]; `ranks::mesh`). Past
//! its setup it reads fewer:
//! its rows of K_B and K_R^(0), made after PETSc's setup (`Discretization::own_pair_made`),
//! read their cells' vertices; GAMG's rigid-body modes its own unknowns' nodes; its piece's
//! stresses its piece's points; a message Γ3's nodes; the prescribed values, at each step,
//! their nodes (`constraints::values`). So its discretization keeps those alone
//! ([`Places::some`], `Discretization::keep_places`). A node's place is found by binary
//! search in the increasing node numbers held; reading one not held panics, as does
//! reading every node's where some alone are held: which rank reads what is the code's
//! invariant, not the user's input.

use std::ops::Index;

/// The nodes' places of a mesh or a discretization: every node's, or some.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Places {
    /// The nodes of the mesh, held or not.
    n: usize,
    /// The nodes held, increasing; None where every node is.
    kept: Option<Vec<u32>>,
    /// Their places, or every node's.
    places: Vec<[f64; 3]>,
    /// The centroid of every node (GAMG's rigid-body modes turn about it:
    /// `petsc::rigid_body_modes`).
    centre: [f64; 3],
}

impl Places {
    /// Every node's place, `places[p]` node p's.
    pub fn every(places: Vec<[f64; 3]>) -> Places {
        Places {
            n: places.len(),
            kept: None,
            centre: centroid(&places),
            places,
        }
    }

    /// Of these places, those of `nodes` alone (increasing, no repeats; each held here),
    /// with the same centroid.
    pub fn some(&self, nodes: &[usize]) -> Places {
        Places {
            n: self.n,
            kept: Some(nodes.iter().map(|&p| p as u32).collect()),
            places: nodes.iter().map(|&p| self[p]).collect(),
            centre: self.centre,
        }
    }

    /// Of a mesh of `n` nodes whose centroid is `centre`, the places `places` of `nodes`
    /// alone (increasing, no repeats): a follower's, handed over by rank 0.
    pub fn held(n: usize, (nodes, places): (Vec<u32>, Vec<[f64; 3]>), centre: [f64; 3]) -> Places {
        assert_eq!(nodes.len(), places.len(), "a place for each node held");
        Places {
            n,
            kept: Some(nodes),
            places,
            centre,
        }
    }

    /// These places and those `places` of `nodes` (increasing, no repeats), the nodes held
    /// here or there; a node held in both keeps its place here.
    ///
    /// # Panics
    /// Where every node's is held here: there is nothing to join.
    pub fn joined(&self, nodes: &[u32], places: &[[f64; 3]]) -> Places {
        let mine = self.kept.as_deref().expect("some places, joined to others");
        let (mut kept, mut joined) = (Vec::new(), Vec::new());
        let (mut i, mut j) = (0, 0);
        while i < mine.len() || j < nodes.len() {
            let here = i < mine.len() && (j == nodes.len() || mine[i] <= nodes[j]);
            let (p, x) = match here {
                true => (mine[i], self.places[i]),
                false => (nodes[j], places[j]),
            };
            if here && j < nodes.len() && nodes[j] == p {
                j += 1;
            }
            (i, j) = if here { (i + 1, j) } else { (i, j + 1) };
            kept.push(p);
            joined.push(x);
        }
        Places::held(self.n, (kept, joined), self.centre)
    }

    /// Every node's place, in node order, given back to be sent (rank 0's, to the other
    /// ranks; [`Places::every`] makes them again).
    ///
    /// # Panics
    /// Where some alone are held.
    pub fn into_all(self) -> Vec<[f64; 3]> {
        assert!(
            self.kept.is_none(),
            "every node's place, where some are held"
        );
        self.places
    }

    /// The nodes of the mesh, held or not.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether the mesh has no nodes.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Every node's place, in node order.
    ///
    /// # Panics
    /// On a follower rank of several, which holds some alone ([`Places::some`]): only rank 0
    /// and one process read every node's.
    pub fn all(&self) -> &[[f64; 3]] {
        assert!(
            self.kept.is_none(),
            "every node's place, read where some alone are held"
        );
        &self.places
    }

    /// The centroid of every node.
    pub fn centre(&self) -> [f64; 3] {
        self.centre
    }

    /// A view of them, as cells made from their vertices read them
    /// (`fem::CellSource::Vertices`).
    pub fn points(&self) -> Points<'_> {
        match &self.kept {
            None => Points::Every(&self.places),
            Some(kept) => Points::Some(kept, &self.places),
        }
    }
}

/// `nodes` sorted, each once (node lists held by binary search).
pub fn increasing<T: Ord>(mut nodes: Vec<T>) -> Vec<T> {
    nodes.sort_unstable();
    nodes.dedup();
    nodes
}

/// The mean of `places`, each divided by their count and added in node order.
fn centroid(places: &[[f64; 3]]) -> [f64; 3] {
    let count = places.len().max(1) as f64;
    let mut centre = [0.0; 3];
    for x in places {
        for c in 0..3 {
            centre[c] += x[c] / count;
        }
    }
    centre
}

impl Index<usize> for Places {
    type Output = [f64; 3];

    /// Node p's place.
    ///
    /// # Panics
    /// Where p's is not held: a follower reads only the places it kept ([`Places::some`]).
    fn index(&self, p: usize) -> &[f64; 3] {
        match &self.kept {
            None => &self.places[p],
            Some(kept) => kept_at((kept, &self.places), p),
        }
    }
}

/// The places of the nodes, every node's (a mesh's, or [`Places::every`]) or some.
#[derive(Clone, Copy, Debug)]
pub enum Points<'a> {
    Every(&'a [[f64; 3]]),
    /// The nodes held (increasing) and their places.
    Some(&'a [u32], &'a [[f64; 3]]),
}

impl<'a> Points<'a> {
    /// Every node's place, in node order.
    ///
    /// # Panics
    /// Where some alone are held: only rank 0 and one process read every node's.
    pub fn whole(&self) -> &'a [[f64; 3]] {
        match *self {
            Points::Every(places) => places,
            Points::Some(..) => panic!("every node's place, read where some alone are held"),
        }
    }
}

impl Index<usize> for Points<'_> {
    type Output = [f64; 3];

    fn index(&self, p: usize) -> &[f64; 3] {
        match *self {
            Points::Every(places) => &places[p],
            Points::Some(nodes, places) => kept_at((nodes, places), p),
        }
    }
}

/// Node p's place among the places of `nodes` (increasing).
fn kept_at<'a>((nodes, places): (&[u32], &'a [[f64; 3]]), p: usize) -> &'a [f64; 3] {
    let at = nodes.binary_search(&(p as u32));
    &places[at.expect("a follower reads the places it kept alone")]
}

#[cfg(test)]
mod tests {
    use super::Places;

    /// The kept places are those of the whole at the same nodes, and the centroid is the
    /// whole's.
    #[test]
    fn kept_places_are_the_whole_ones() {
        let whole: Vec<[f64; 3]> = (0..8).map(|p| [p as f64, 0.5 * p as f64, -1.0]).collect();
        let every = Places::every(whole.clone());
        let kept = every.some(&[1, 4, 7]);
        assert_eq!((kept.len(), every.centre()), (8, kept.centre()));
        assert_eq!(every.centre(), [3.5, 1.75, -1.0]);
        for p in [1, 4, 7] {
            assert_eq!((kept[p], every[p]), (whole[p], whole[p]));
        }
        assert_eq!(every.all(), &whole[..]);
        let missing = std::panic::catch_unwind(|| kept[5]);
        assert!(missing.is_err());
    }

    /// Joining two sets of places holds each node of either once, in increasing order,
    /// with its place; the count and the centroid stay.
    #[test]
    fn joined_places_hold_each_node_of_either_once() {
        let whole: Vec<[f64; 3]> = (0..10).map(|p| [p as f64, -(p as f64), 0.25]).collect();
        let every = Places::every(whole.clone());
        for (a, b) in [
            (vec![1, 4, 7], vec![0, 4, 8, 9]),
            (vec![], vec![2, 3]),
            (vec![5], vec![]),
            (vec![0, 9], vec![0, 9]),
        ] {
            let b_places: Vec<[f64; 3]> = b.iter().map(|&p| whole[p]).collect();
            let b: Vec<u32> = b.iter().map(|&p| p as u32).collect();
            let joined = every.some(&a).joined(&b, &b_places);
            let mut both: Vec<usize> = a
                .iter()
                .copied()
                .chain(b.iter().map(|&p| p as usize))
                .collect();
            both.sort_unstable();
            both.dedup();
            assert_eq!(joined, every.some(&both), "{a:?} and {b:?}");
            assert_eq!((joined.len(), joined.centre()), (10, every.centre()));
        }
    }
}
