//! The multiplier groups and their sets Z_j: projection, the rim of a disc, the stopping
//! residual; and the Newton coordinates (columns of Q) built from them.

use crate::solver::Rows;
use std::ops::Range;

/// The set Z_j of a group of multipliers.
#[derive(Clone, Copy, Debug)]
pub(in crate::solver) enum Set {
    /// λ ≥ 0: a contact row.
    HalfLine,
    /// |γ| ≤ c: a friction node's block (an interval in 2D, a disc in 3D).
    Ball(f64),
}

/// One group of multipliers: a contact row or a friction node's block of rows.
#[derive(Clone, Copy, Debug)]
pub(in crate::solver) struct Group {
    pub(in crate::solver) start: usize,
    pub(in crate::solver) len: usize,
    pub(in crate::solver) set: Set,
    /// δ_j: the mean of diag(D) over the group's rows.
    pub(in crate::solver) scale: f64,
    /// The Newton shift ρ δ_j of a group at a node with dependent rows, else 0.
    pub(in crate::solver) shift: f64,
}

/// The groups of the rows, in row order: each contact row, then each friction node's block;
/// δ_j the mean of `diag` (D's diagonal, or an estimate of it) over the group's rows, and
/// the Newton shift ρ δ_j (ρ = `dependent_shift`) at the nodes with dependent rows.
pub(in crate::solver) fn groups(rows: &Rows, diag: &[f64], dependent_shift: f64) -> Vec<Group> {
    debug_assert!(rows.block <= 2, "friction blocks span a tangent plane");
    let contact = (0..rows.n_contact).map(|i| (i..i + 1, Set::HalfLine));
    let dependent = rows.dependent_nodes();
    let friction = (0..rows.n_friction_nodes()).map(|j| {
        let r = rows.friction_block(j);
        let c = rows.rows[r.start].bound;
        (r, Set::Ball(c))
    });
    contact
        .chain(friction)
        .map(|(r, set)| {
            let scale = r.clone().map(|i| diag[i]).sum::<f64>() / r.len() as f64;
            let at_dependent = dependent.contains(&rows.rows[r.start].node);
            Group {
                start: r.start,
                len: r.len(),
                set,
                scale,
                shift: if at_dependent {
                    dependent_shift * scale
                } else {
                    0.0
                },
            }
        })
        .collect()
}

pub(in crate::solver) fn norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, x| a.hypot(*x))
}

pub(in crate::solver) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

impl Group {
    pub(in crate::solver) fn rows(&self) -> Range<usize> {
        self.start..self.start + self.len
    }

    /// Projects v (the group's entries) onto Z_j in place. Returns None if v was in Z_j,
    /// otherwise Some(ρ): 0 for a contact row set to 0, c/|v| for a friction block scaled
    /// onto the rim.
    pub(in crate::solver) fn project(&self, v: &mut [f64]) -> Option<f64> {
        match self.set {
            Set::HalfLine => (v[0] < 0.0).then(|| {
                v[0] = 0.0;
                0.0
            }),
            Set::Ball(c) => {
                let nv = norm(v);
                (nv > c).then(|| {
                    // v/|v| first: exactly ±1 in 2D, so the 2D multiplier is exactly ±c.
                    for x in v.iter_mut() {
                        *x = *x / nv * c;
                    }
                    c / nv
                })
            }
        }
    }

    /// True when v lies on the boundary of Z_j or outside.
    pub(in crate::solver) fn not_interior(&self, v: &[f64]) -> bool {
        match self.set {
            Set::HalfLine => v[0] <= 0.0,
            Set::Ball(c) => norm(v) >= c,
        }
    }

    /// The unit tangent t̂ ⊥ n of a disc block (the rim's direction at n ≠ 0) as a Newton
    /// coordinate with diagonal shift κ; None for 1-row groups (their rim is two points).
    pub(in crate::solver) fn tangent(&self, n: &[f64], kappa: f64) -> Option<Coord> {
        (self.len == 2).then(|| {
            let nn = norm(n);
            Coord {
                start: self.start,
                len: 2,
                dir: [-n[1] / nn, n[0] / nn],
                shift: kappa + self.shift,
            }
        })
    }

    /// For a 3D disc multiplier z on its rim (|z| ≥ `rim` c, z ≠ 0): the point c ẑ held on
    /// the rim and the shift κ = max(μ, 0)/c of its tangent, μ = −g·ẑ the radial multiplier
    /// (`DualSettings::held_rims`); None for a contact row, a 2D friction row or z off the
    /// rim. In 2D the rim is two points, so holding would fix the multiplier outright
    /// instead of letting its tangent follow the loads (measured: the bracket 180 → 193
    /// iterations, the paper's scenes ±2; 2D runs keep their bits without it).
    pub(in crate::solver) fn held_on_rim(
        &self,
        z: &[f64],
        g: &[f64],
        rim: f64,
    ) -> Option<([f64; 2], f64)> {
        let (Set::Ball(c), 2) = (self.set, self.len) else {
            return None;
        };
        let nz = norm(z);
        (nz > 0.0 && nz >= rim * c).then(|| {
            let mut z0 = [0.0; 2];
            for (o, x) in z0.iter_mut().zip(z) {
                *o = x / nz * c;
            }
            (z0, (-dot(g, z) / nz).max(0.0) / c)
        })
    }

    /// The group's rows as free Newton coordinates.
    pub(in crate::solver) fn free(&self) -> impl Iterator<Item = Coord> + '_ {
        self.rows().map(|i| Coord {
            start: i,
            len: 1,
            dir: [1.0, 0.0],
            shift: self.shift,
        })
    }

    /// The group's part of the optimality residual (see the module doc); z in Z_j, a disc
    /// multiplier on the rim where |z| ≥ `rim` c (`DualSettings::rim`).
    pub(in crate::solver) fn residual(&self, z: &[f64], g: &[f64], rim: f64) -> f64 {
        match self.set {
            Set::HalfLine if z[0] > 0.0 => g[0].abs(),
            Set::HalfLine => (-g[0]).max(0.0),
            Set::Ball(c) => {
                let nz = norm(z);
                if nz < rim * c {
                    norm(g)
                } else if nz == 0.0 {
                    0.0 // c = 0: Z_j = {0}, every g is balanced
                } else {
                    // g·γ̂ and |T g| = |g − (g·γ̂) γ̂|, computed without cancellation.
                    let gn = dot(g, z) / nz;
                    let tangential = g
                        .iter()
                        .zip(z)
                        .fold(0.0f64, |a, (g, z)| a.hypot(g - gn * z / nz));
                    tangential + gn.max(0.0)
                }
            }
        }
    }
}

/// A column of Q in the Newton systems: a unit vector in the rows of one group (a free
/// multiplier, or the tangent of a disc multiplier on its rim) and its diagonal shift κ.
#[derive(Clone, Copy, Debug)]
pub(in crate::solver) struct Coord {
    pub(in crate::solver) start: usize,
    pub(in crate::solver) len: usize,
    pub(in crate::solver) dir: [f64; 2],
    pub(in crate::solver) shift: f64,
}

impl Coord {
    pub(in crate::solver) fn entries(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        (self.start..self.start + self.len).zip(self.dir.iter().copied())
    }

    /// qᵀ v.
    pub(in crate::solver) fn dot(&self, v: &[f64]) -> f64 {
        self.entries().map(|(i, x)| x * v[i]).sum()
    }
}
