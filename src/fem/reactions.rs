//! The forces on the body at a solved step: the reactions of the Dirichlet conditions and the
//! resultants of the loads (`DIR/history.csv`, written by `run/history_csv.rs`).
//!
//! # The balance
//!
//! Step n's equation holds on every dof of the mesh (free, prescribed and held at zero alike)
//! once the conditions' forces r_n are added:
//!
//!   M w_n + K_B u_n + K_R m_n = f_n − g_F − Pᵀz_n + r_n,
//!
//! M the step matrix (K_A, or K_A + k K_B + k² r(0) K_R for the implicit variant, see
//! `time_loop`), f_n the loads, g_F the given normal stress F on Γ3,2, z_n the contact and
//! friction multipliers. At a free dof r_n is zero: there the equation is the step problem's
//! (3.1). At a held dof h (clamped, held at zero, or prescribed) it is the reaction
//!
//!   r_{n,h} = (M w_n + K_B u_n + K_R m_n)_h − f_{n,h} + g_{F,h},
//!
//! the force the condition exerts on the body (Pᵀz has no entry at a held dof: a `NodalRow`
//! drops the components a condition holds). A translation has no strain, so the rows of
//! each matrix sum to zero over the dofs of one component, and summing the equation over
//! them gives
//!
//!   Σ r_n + Σ f_n − Σ g_F − Σ Pᵀz_n = 0:
//!
//! reactions, loads, the normal stress and the contact and friction forces, each the force
//! on the body, balance to the precision of the step's solve.
//!
//! # What is assembled
//!
//! `Discretization` assembles the matrices on the dofs with an index only (free and
//! prescribed): the rows of the dofs held at zero are dropped. [`Reactions::new`] assembles
//! the rows of K_A, K_B and K_R at every held dof, over the columns with an index (u, w and
//! m vanish at the others), from the cells that touch a held node, with the element entries
//! of the global assembly (`Cell::parts`, `Cell::entry`), and integrates g_F once more on
//! every dof. Only a run that writes history.csv builds it, once; a step then costs the
//! products of these few rows and one more evaluation of the loads (`Loads::visit`), which
//! splits ⟨f_n, φ⟩ by load and keeps its values at the held dofs.

use std::collections::HashMap;

use super::{constraints::Source, group, place, Discretization};
use crate::mesh::Mesh;
use crate::scene::Scene;
use crate::Result;

/// The held dofs' rows of the step's matrices and what is constant of the step's forces.
pub struct Reactions {
    /// Every held global dof d·node + c with its condition (`Discretization::held`): row i.
    pub held: Vec<(usize, Source)>,
    /// Global dof → its row, at the dofs a condition holds alone (a boundary's: an array of
    /// every dof had held 8 bytes a dof of the whole on rank 0 and one process).
    row_of: HashMap<usize, u32>,
    /// The rows, compressed: columns (places in `reads` and in `m_reads`) and the values
    /// of M, K_B, K_R.
    ptr: Vec<usize>,
    cols: Vec<[u32; 2]>,
    values: Vec<[f64; 3]>,
    /// The dofs of u and w the rows read, increasing, and the indices of m (in its memory
    /// group's part): all that a step's reactions read of the state ([`Reactions::read`]).
    reads: Vec<usize>,
    m_reads: Vec<usize>,
    /// The dofs' count, of which `m_reads` count each memory group's.
    n_dofs: usize,
    /// g_F at the held dofs.
    g_f: Vec<f64>,
    /// −Σ g_F per component: the force of the normal stress F on the body.
    pub normal_stress: [f64; 3],
}

/// What the held rows read of a step's state: w, u and m (None without memory) at
/// [`Reactions`]' `reads` and `m_reads`, a few times the held dofs' count where the state
/// has n values each.
pub struct StateRead {
    w: Vec<f64>,
    u: Vec<f64>,
    m: Option<Vec<f64>>,
}

/// The forces on the body at one step.
pub struct StepForces {
    /// r_{n,h} at every held dof, in the order of [`Reactions::held`].
    pub reactions: Vec<f64>,
    /// The resultant of each load (x, y, z), in the order of `Loads::sources`.
    pub loads: Vec<[f64; 3]>,
}

impl Reactions {
    /// The held rows of M = K_A + `k_b` K_B + Σ_g `k_r[g]` K_R^(g) (`k_b` = `k_r` = 0 for
    /// the paper's scheme, k and k² r_g(0) for the implicit variant), K_B and K_R^(g).
    pub fn new(
        mesh: &Mesh,
        scene: &Scene,
        disc: &Discretization,
        k_b: f64,
        k_r: &[f64],
    ) -> Result<Self> {
        let row_of: HashMap<usize, u32> = (disc.held.iter().enumerate())
            .map(|(i, &(dof, _))| (dof, i as u32))
            .collect();
        let (ptr, whole_cols, values) = held_rows(disc, &row_of, k_b, k_r);
        let listed = |c: usize| {
            let mut read: Vec<usize> = whole_cols.iter().map(|col| col[c]).collect();
            read.sort_unstable();
            read.dedup();
            read
        };
        let (reads, m_reads) = (listed(0), listed(1));
        let place = |read: &[usize], i: usize| read.binary_search(&i).expect("listed") as u32;
        let cols = (whole_cols.iter())
            .map(|&[col, at]| [place(&reads, col), place(&m_reads, at)])
            .collect();
        let d = disc.dim;
        let g_f_all = normal_stress_load(mesh, scene)?;
        let mut normal_stress = [0.0; 3];
        for (g, v) in g_f_all.iter().enumerate() {
            normal_stress[g % d] -= v;
        }
        // g_F at a held dof: the node's spatial g_F in its dof components.
        let at_held = |g: usize| {
            let node = g / d;
            let v = std::array::from_fn(|c| if c < d { g_f_all[d * node + c] } else { 0.0 });
            disc.frames.to_dofs(node, v)[g % d]
        };
        let g_f = match g_f_all.is_empty() {
            true => vec![0.0; disc.held.len()],
            false => disc.held.iter().map(|&(g, _)| at_held(g)).collect(),
        };
        Ok(Reactions {
            held: disc.held.clone(),
            row_of,
            ptr,
            cols,
            values,
            reads,
            m_reads,
            n_dofs: disc.n_dofs,
            g_f,
            normal_stress,
        })
    }

    /// The dofs whose u, w and m the held rows read, increasing.
    pub fn dofs_read(&self) -> &[usize] {
        &self.reads
    }

    /// What the held rows read of the state `[w, u]`, `m` (None without memory): all that
    /// [`Reactions::forces`] needs of it. On a rank whose vectors hold some dofs alone, u
    /// and m (each memory group's part after the other's) at `local`, w at `held`
    /// (`time_loop::Step`; `fem::place`).
    pub fn read(
        &self,
        [w, u]: [&[f64]; 2],
        m: Option<&[f64]>,
        [local, held]: [Option<&[usize]>; 2],
    ) -> StateRead {
        let at =
            |v: &[f64], at| -> Vec<f64> { self.reads.iter().map(|&i| v[place(at, i)]).collect() };
        // m_reads are g·n_dofs + dof; a group's part holds u's dofs.
        let in_m = |i: usize| (i / self.n_dofs) * u.len() + place(local, i % self.n_dofs);
        StateRead {
            w: at(w, held),
            u: at(u, local),
            m: m.map(|m| self.m_reads.iter().map(|&i| m[in_m(i)]).collect()),
        }
    }

    /// The reactions r_{n,h} = (M w + K_B u + K_R m)_h − f_h + g_F,h of the state `read`
    /// ([`Reactions::read`]) at time `t`, and the loads' resultants.
    pub fn forces(
        &self,
        disc: &Discretization,
        scene: &Scene,
        t: f64,
        read: &StateRead,
    ) -> Result<StepForces> {
        let (w, u, m) = (&read.w, &read.u, read.m.as_deref());
        let mut reactions: Vec<f64> = (0..self.held.len())
            .map(|h| {
                let range = self.ptr[h]..self.ptr[h + 1];
                let mut s = 0.0;
                for (&[col, at], v) in self.cols[range.clone()].iter().zip(&self.values[range]) {
                    let (col, at) = (col as usize, at as usize);
                    s += v[0] * w[col] + v[1] * u[col] + m.map_or(0.0, |m| v[2] * m[at]);
                }
                s + self.g_f[h]
            })
            .collect();
        let d = disc.dim;
        let mut loads = vec![[0.0; 3]; disc.loads.sources().count()];
        disc.visit_every_load(t, scene, |l, dof, v| {
            loads[l][dof % d] += v;
            disc.frames.spread(d, dof, v, |g, v| {
                if let Some(&h) = self.row_of.get(&g) {
                    reactions[h as usize] -= v;
                }
            });
        })?;
        Ok(StepForces { reactions, loads })
    }
}

/// The rows `row_of` numbers (held dofs) of M = K_A + `k_b` K_B + Σ_g `k_r[g]` K_R^(g), K_B
/// and K_R over the dofs with an index, compressed: (row starts, columns of u and w and of
/// m, the three values). An entry is kept per memory group: its K_R value multiplies that
/// group's m.
fn held_rows(
    disc: &Discretization,
    row_of: &HashMap<usize, u32>,
    k_b: f64,
    k_r: &[f64],
) -> (Vec<usize>, Vec<[usize; 2]>, Vec<[f64; 3]>) {
    let d = disc.dim;
    let mut entries: Vec<(u32, [usize; 2], [f64; 3])> = Vec::new();
    disc.cell_source().each(|c, t| {
        let s = disc.materials.of(c);
        let (a, b) = (s.a, s.b_or_zero());
        let (r, g) = match s.memory {
            Some(g) => (disc.r, g),
            None => (crate::fem::Isotropic { a: 0.0, b: 0.0 }, 0),
        };
        let k_r = k_r.get(g).copied().unwrap_or(0.0);
        let nodes = t.vertices();
        let frame = |i: usize| disc.frames.of(nodes[i]);
        for (i, &q) in nodes.iter().enumerate() {
            for al in 0..d {
                let Some(&row) = row_of.get(&(d * q + al)) else {
                    continue;
                };
                for (j, &p) in nodes.iter().enumerate() {
                    for (be, col) in (0..d).filter_map(|be| Some((be, disc.free.get(d * p + be)?)))
                    {
                        let parts = t.parts_in([i, j], [al, be], [frame(i), frame(j)]);
                        let [ka, kb, kr] = [a, b, r].map(|c| t.entry(c, parts));
                        let at = g * disc.n_dofs + col;
                        entries.push((row, [col, at], [ka + k_b * kb + k_r * kr, kb, kr]));
                    }
                }
            }
        }
    });
    // Stable: the entries of one position are added in the cells' order.
    entries.sort_by_key(|&(row, col, _)| (row, col));
    let mut ptr = vec![0; disc.held.len() + 1];
    let (mut cols, mut values): (Vec<[usize; 2]>, Vec<[f64; 3]>) = (Vec::new(), Vec::new());
    let mut last = None;
    for (row, col, v) in entries {
        match values.last_mut() {
            Some(sum) if last == Some((row, col)) => (0..3).for_each(|c| sum[c] += v[c]),
            _ => {
                cols.push(col);
                values.push(v);
                ptr[row as usize + 1] = cols.len();
                last = Some((row, col));
            }
        }
    }
    // Rows without entries end where the row before them ends.
    for i in 1..ptr.len() {
        ptr[i] = ptr[i].max(ptr[i - 1]);
    }
    (ptr, cols, values)
}

/// g_F = ∫_{Γ3,2} F φ ν da on every global dof d·node + c (empty without friction).
fn normal_stress_load(mesh: &Mesh, scene: &Scene) -> Result<Vec<f64>> {
    let Some(fr) = &scene.physics.friction else {
        return Ok(Vec::new());
    };
    let name = &scene.mesh.groups.friction;
    let g = group(mesh, scene, "mesh.groups.friction", name)?;
    // Every global dof its own index, no frame: g_F in x, y, z at every node.
    let all = super::DofIndices::each(mesh.dim * mesh.nodes.len());
    let dofs = (&all, &super::Frames::default());
    let (at, _) = super::friction_integrals(mesh, scene, fr, g, dofs)?;
    let mut g_f = vec![0.0; all.dofs()];
    at.into_iter().for_each(|(dof, v)| g_f[dof] = v);
    Ok(g_f)
}
