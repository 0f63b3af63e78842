//! The primal active-set contact solver (`solver.contact = "active_set"`): a semismooth
//! Newton method on the step's optimality conditions whose linear systems are the sparse
//! primal system itself, solved by a Krylov method with algebraic multigrid (PETSc's,
//! through `ConstrainedSystem`). No factor of K, no m × m matrix:
//! memory and cost grow like a linear run's.
//!
//! # The equations
//!
//! The step problem (`solver` module doc) with multipliers λ_i ≥ 0 on the contact rows n_i
//! and γ_i on the friction blocks (|γ_i| ≤ c_i) is, with K the step matrix,
//!
//!   K w + Σ λ_i n_i + Σ γ_ik τ_ik = b,
//!   λ_i = max(0, λ_i + ρ_i n_i·w)                     (Γ3,1: n·w ≤ 0, λ ≥ 0, λ n·w = 0),
//!   γ_i = Π_{|·|≤c_i}(γ_i + ρ_i w_τ,i)                (Γ3,2: the friction disc, 2D: segment),
//!
//! with ρ_i > 0 any constants, one per node (here a tenth of the diagonal of K along the
//! row, the mean over a friction node's tangents, so that both arguments are forces: K's
//! diagonal itself is far stiffer than a thin body's boundary, `RHO_START`). Given the iterate (w, z), the sets are: a contact row is *active* where
//! λ_i + ρ_i n_i·w > 0, a friction node *sticks* where g_i = γ_i + ρ_i w_τ,i lies in the
//! disc, and *slips* otherwise. The semismooth Newton step (Hintermüller–Ito–Kunisch's
//! primal–dual active set; Hüeber–Stadler–Wohlmuth for the disc) sets
//!
//! - active: n_i·w⁺ = 0; inactive: λ⁺_i = 0;
//! - sticking: w⁺_τ,i = 0;
//! - slipping: γ⁺_i = c_i ĝ_i + β_i T_i w⁺_τ,i, the linearization of c g/|g| at g_i
//!   (ĝ = g/|g|, T = I − ĝĝᵀ) solved for γ⁺: β_i = c_i ρ_i / (|g_i| − c_i) > 0. In 2D T = 0
//!   and γ⁺ = c_i sign(g_i). At a fixed point T_i w_τ,i = 0 and γ_i = c_i ĝ_i whatever β_i
//!   is, so β changes only the rate, not the solution.
//!
//! w⁺ then minimizes ½wᵀ(K + S)w − (b − f_slip)ᵀw over the w with the active and sticking
//! directions at zero, S = Σ_slip β_i τ_iᵀ T_i τ_i (symmetric positive semidefinite, zero in
//! 2D) and f_slip = Σ_slip c_i τ_iᵀ ĝ_i: with Π the orthogonal projection that removes
//! those directions node by node (`Terms`),
//!
//!   Π(K + S)Π w⁺ + (I − Π) w⁺ = Π(b − f_slip),
//!
//! an SPD system of the size of K whatever the sets. It is solved as N w⁺ = Π(b − f_slip)
//! with N = Π(K + S)Π + α(I − Π)(K + S)(I − Π), α = 0.1 (`shim.c`, `DECOUPLED`), which has
//! the same solution ((I − Π)w⁺ = 0) and K's sparsity and graph: N is assembled, and its
//! algebraic multigrid has aggregates and an interpolation P made once from K and the
//! coarse operators of N, Pᵀ N P level by level: made at the first system of a step from
//! K's as PᵀKP + Pᵀ(N − K)P, and updated by the difference wherever the sets changed
//! (`Preconditioner`; N − K lives near the contact boundary, so an update costs a fraction
//! of a solve); where only the slip stiffness moved, and by less than a tenth of K's
//! diagonal at every node (`STIFFNESS_MOVED`), the last one serves. A multigrid of K
//! alone, projected, was a weak preconditioner where much of the face is active
//! (docs/performance.md). The multipliers of the removed directions follow from the
//! residual r = b − f_slip − (K + S)w⁺ node by node, r_i = Σ z_k a_k over the node's
//! removed rows a_k (least squares on at most three vectors; a row dependent on the node's
//! others, as at a corner where Γ3,1 meets Γ3,2, gets none).
//!
//! # Stopping, accuracy and forcing
//!
//! A Newton iterate whose sets reproduce themselves satisfies the complementarity
//! conditions exactly (2D) or up to the slip direction's convergence (3D); the iteration
//! stops there once the KKT residual (`kkt_residual`, relative to max|w| and max|z|) is at
//! most `tolerance` and the last system was solved to `krylov_tolerance` of its right
//! side (`ActiveSetSettings`, the scene's `[solver.active_set]`). Until then the systems are
//! solved inexactly, with a constant forcing term: each Krylov solve reduces the residual it
//! starts from (that of the current iterate) by `forcing`, η = 10⁻² (`Tolerance::OfStart`).
//! A system whose sets are still changing need not be accurate, and measured from its own
//! start every solve makes progress, where a tolerance relative to the right side is met
//! by a warm start without an iteration. Eisenstat–Walker's forcing (their choice 2,
//! relative to the right side and at most a tenth of the last term so that it could not
//! stall) took 1.7× the Krylov iterations on the plate 0.03 (docs/performance.md). The step starts from the previous step's w and multipliers, so
//! its first sets are the previous step's.
//!
//! # Globalization
//!
//! The primal–dual active set converges in finitely many steps where K is an M-matrix;
//! P1 elasticity is not one, and the sets can cycle. Three safeguards, none of which moves
//! the solution (ρ and the order of the changes only steer the iteration):
//!
//! - a slipping node whose test turns it the other way sticks first (a reversal passes
//!   through sticking; where the body slides, ρ (from K's diagonal) is far stiffer than the
//!   boundary, and the test would swing between the two directions);
//! - when the sets an iteration proposes, or those it keeps of them (below), were met
//!   before in the step (a cycle), every later system is solved to `krylov_tolerance`, ρ
//!   is divided by 10 (the test then weighs the multipliers more, the velocities less),
//!   and an iteration makes at most half as many changes of the sets as the last cycle
//!   proposed, the largest violations first (down to one at a time). The kept sets count:
//!   limited to two changes, the bracket's onset once went round four sets for good;
//! - `max_iterations` iterations end the step with `StepStatus::MaxIterations`.
//!
//! On the golden scenes, the corners and a rotating traction (tests/petsc) every step
//! converges; the bracket's sliding onset is the hardest (31 iterations in one step).

use super::{kkt_residual, Rows, StepReport, StepStatus};
use crate::fem::NodalRow;
use crate::scene::ActiveSetSection;
use crate::Result;

/// ρ at the start of a step, in units of K's diagonal along the row (`Iterate::rho`): K's
/// diagonal is far stiffer than the boundary of a thin body, and on the thin slab
/// (tests/data/3d/slab_t0008.msh) the sets wandered without converging with it
/// (docs/performance.md, "The thin slab: ρ at a tenth of K's diagonal").
const RHO_START: f64 = 0.1;

/// How far a slipping node's stiffness β may move, in units of K's diagonal, before the Newton
/// system's preconditioner is updated rather than kept (`Sets::stiffness_moved`): a tenth
/// of K's diagonal leaves the kept multigrid close to the system's. Without the bound, a
/// multigrid made where β reached 17 times the diagonal served systems where it was 10⁻⁴ of it
/// (docs/performance.md, "Updating the multigrid where the slip stiffness moves").
const STIFFNESS_MOVED: f64 = 0.1;

/// What a linear solve of the Newton system did.
#[derive(Clone, Copy, Debug, Default)]
pub struct LinearSolve {
    pub iterations: usize,
    /// The final residual norm.
    pub residual: f64,
    /// Why the Krylov method stopped without converging (PETSc's reason), if it did.
    pub failed: Option<&'static str>,
    /// What to try where it did.
    pub remedy: &'static str,
    /// The solve was given up on request (the run's stop: `solver::abandon`).
    pub given_up: bool,
}

/// The systems of the Newton iteration: products with K and solves of the constrained
/// system Π(K + S)Π w + (I − Π) w = Π b with the terms of `Terms`.
pub trait ConstrainedSystem {
    /// y ← (K x) at `dofs`, `y[k]` at `dofs[k]` (0 where it is −1).
    fn mult_at(&mut self, x: &[f64], dofs: &[i32], y: &mut [f64]) -> Result<()>;
    /// max|w_i| (NaN skipped) over every unknown, w a solution of `solve`: the scale of
    /// the KKT residual, which a system spread over ranks takes from each rank's rows.
    fn largest_abs(&mut self, w: &[f64]) -> Result<f64>;
    /// w ← the constrained system's solution, from the guess in w, to `tolerance`, with the
    /// preconditioner `pc` says. Its right side Π(b − f_slip) is b but at Γ3's nodes, where
    /// it is `rhs`.
    fn solve(
        &mut self,
        terms: &Terms,
        rhs: RightSide<'_>,
        w: &mut [f64],
        tolerance: Tolerance,
        pc: Preconditioner,
    ) -> Result<LinearSolve>;
}

/// Where a Newton system's Krylov solve stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    /// ‖r‖ ≤ rtol ‖b‖: the last system of a step.
    OfRhs(f64),
    /// ‖r‖ ≤ η ‖r₀‖, r₀ the residual of the initial guess: the systems before it.
    OfStart(f64),
}

/// The preconditioner of a Newton system, where the backend builds one from the systems.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Preconditioner {
    /// The last system's.
    Last,
    /// Rebuilt from this system, on what depends on K alone (GAMG's aggregates and
    /// interpolation): at the first system of a step, so that a step depends only on what
    /// a checkpoint holds.
    Rebuilt,
    /// This system's, by an update of the last one: where the sets changed within a step.
    Updated,
}

/// The nodal terms of a Newton system, flat as PETSc's shim reads them: the removed
/// directions (three dofs, −1 for none, and three coefficients each; orthonormal within a
/// node, so that applying them one after the other is Π) and the slip stiffness blocks S_i
/// (three dofs and a row-major 3 × 3 block each).
#[derive(Clone, Debug, Default)]
pub struct Terms {
    pub removed_dofs: Vec<i32>,
    pub removed: Vec<f64>,
    pub stiffness_dofs: Vec<i32>,
    pub stiffness: Vec<f64>,
}

impl Terms {
    fn clear(&mut self) {
        self.removed_dofs.clear();
        self.removed.clear();
        self.stiffness_dofs.clear();
        self.stiffness.clear();
    }

    /// a ← Π a.
    pub fn project(&self, a: &mut [f64]) {
        for (d, v) in self.removed_dofs.chunks(3).zip(self.removed.chunks(3)) {
            remove(d, v, a, |c| d[c] as usize);
        }
    }

    /// S x block by block: each block's dofs and its product with x there (0 where a dof
    /// is −1).
    pub fn stiffness_products<'a>(
        &'a self,
        x: &'a [f64],
    ) -> impl Iterator<Item = (&'a [i32], [f64; 3])> + 'a {
        let blocks = self.stiffness_dofs.chunks(3).zip(self.stiffness.chunks(9));
        blocks.map(|(d, m)| {
            let row = |r: usize| -> f64 {
                (0..3)
                    .filter(|&c| d[c] >= 0)
                    .map(|c| m[3 * r + c] * x[d[c] as usize])
                    .sum()
            };
            (
                d,
                std::array::from_fn(|r| if d[r] >= 0 { row(r) } else { 0.0 }),
            )
        })
    }
}

/// A Newton system's right side Π(b − f_slip): b, but at the dofs of Γ3's nodes (three a
/// node, −1 where a node has none), where Π and f_slip act and it is `values`.
#[derive(Clone, Copy, Debug)]
pub struct RightSide<'a> {
    pub b: &'a [f64],
    pub dofs: &'a [i32],
    pub values: &'a [f64],
}

/// The settings of the active-set solver (`[solver.active_set]`), with their defaults.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActiveSetSettings {
    /// The KKT residual at which a step is solved (default 1e-10): u_N agrees with the
    /// dense dual's to 1e-8 relative (tests/petsc).
    pub tolerance: f64,
    /// Newton iterations before a step fails (default 50).
    pub max_iterations: usize,
    /// The forcing term of the systems before the last: the reduction of the residual each
    /// solves for, from the one it starts at (default 1e-2; 1e-3 and 1e-4 took 5 % and
    /// 14 % more time on the plate 0.03, docs/performance.md).
    pub forcing: f64,
    /// The Krylov tolerance of a step's last system (default 1e-12, as the linear backend;
    /// 1e-10 took 8 % less time on the fine plate, docs/performance.md).
    pub krylov_tolerance: f64,
}

impl Default for ActiveSetSettings {
    fn default() -> Self {
        ActiveSetSettings {
            tolerance: 1e-10,
            max_iterations: 50,
            forcing: 1e-2,
            krylov_tolerance: 1e-12,
        }
    }
}

impl ActiveSetSettings {
    /// The scene's keys, each over its default (their ranges are checked where the scene
    /// is read).
    pub fn from_keys(keys: &ActiveSetSection) -> Self {
        let d = ActiveSetSettings::default();
        ActiveSetSettings {
            tolerance: keys.tolerance.unwrap_or(d.tolerance),
            max_iterations: keys.max_iterations.unwrap_or(d.max_iterations),
            forcing: keys.forcing.unwrap_or(d.forcing),
            krylov_tolerance: keys.krylov_tolerance.unwrap_or(d.krylov_tolerance),
        }
    }
}

/// A friction node's state in an iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Friction {
    Stick,
    /// ĝ (its d − 1 components in the node's tangent frame) and β.
    Slip {
        g: [f64; 2],
        beta: f64,
    },
}

/// The sets of an iterate: which contact rows are active, how each friction node behaves.
#[derive(Clone, Debug, Default, PartialEq)]
struct Sets {
    active: Vec<bool>,
    friction: Vec<Friction>,
}

impl Friction {
    /// What a set tells apart: sticking, or slipping; in 2D, slipping which way (a 3D
    /// direction turns continuously, and the Newton iteration follows it).
    fn kind(&self) -> i8 {
        match *self {
            Friction::Stick => 0,
            Friction::Slip { g: [x, 0.0], .. } if x.abs() == 1.0 => x.signum() as i8,
            Friction::Slip { .. } => 2,
        }
    }
}

impl Sets {
    /// A hash of the sets (deterministic: fixed keys).
    fn signature(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        self.active.hash(&mut h);
        for f in &self.friction {
            f.kind().hash(&mut h);
        }
        h.finish()
    }

    /// The changes from `self` to `next` (a contact row, or a friction node numbered after
    /// them), each with its size at the iterate (w, z): the force by which the condition of
    /// the old set is violated (ρ n·w or −λ for a contact row, ||g| − c| for a node).
    fn changes(&self, next: &Sets, at: Iterate) -> Vec<(usize, f64)> {
        let rows = at.rows;
        let contact = (0..self.active.len())
            .filter(|&i| self.active[i] != next.active[i])
            .map(|i| (i, at.force(i).abs()));
        let friction = (0..self.friction.len())
            .filter(|&j| self.friction[j].kind() != next.friction[j].kind())
            .map(|j| {
                let block = rows.friction_block(j);
                let c = rows.rows[block.start].bound;
                let g = block.fold(0.0f64, |a, i| a.hypot(at.force(i)));
                (self.active.len() + j, (g - c).abs())
            });
        contact.chain(friction).collect()
    }

    /// Keeps the `allowed` largest of the changes from `old` (`changes`; ties by index) and
    /// takes back the others: a cycle of the sets is broken by changing fewer at a time.
    fn keep_changes(&mut self, old: &Sets, at: Iterate, allowed: usize) {
        let mut changes = old.changes(self, at);
        changes.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        for &(k, _) in changes.iter().skip(allowed) {
            match k.checked_sub(self.active.len()) {
                None => self.active[k] = old.active[k],
                Some(j) => self.friction[j] = old.friction[j],
            }
        }
    }

    /// Whether a node slipping in both `self` and `other` has a slip stiffness β that
    /// differs by more than `STIFFNESS_MOVED` times K's diagonal along the node's tangents
    /// (`diagonal`, per row): then a preconditioner made from one is not one for the other.
    /// Only in 3D: a 2D node's slip adds no stiffness (T = 0).
    fn stiffness_moved(&self, other: &Sets, rows: &Rows, diagonal: &[f64]) -> bool {
        let mut pairs = self.friction.iter().zip(&other.friction).enumerate();
        pairs.any(|(j, pair)| match pair {
            (Friction::Slip { beta: a, .. }, Friction::Slip { beta: b, .. }) => {
                let block = rows.friction_block(j);
                block.len() == 2 && (a - b).abs() > STIFFNESS_MOVED * diagonal[block.start]
            }
            _ => false,
        })
    }

    /// Whether `other` has the same active rows and the same sticking and slipping nodes
    /// (`Friction::kind`).
    fn same_as(&self, other: &Sets) -> bool {
        self.active == other.active
            && (self.friction.iter().map(Friction::kind))
                .eq(other.friction.iter().map(Friction::kind))
    }
}

/// What the sets are judged at: the rows, their ρ (K's diagonal times `soften`:
/// `RHO_START`, divided by 10 at each cycle of the sets in the step) and the iterate (w, z).
#[derive(Clone, Copy)]
struct Iterate<'a> {
    rows: &'a Rows,
    rho: &'a [f64],
    soften: f64,
    w: &'a [f64],
    z: &'a [f64],
}

impl Iterate<'_> {
    /// ρ of row i.
    fn rho(&self, i: usize) -> f64 {
        self.soften * self.rho[i]
    }

    /// The argument of row i's complementarity function or projection: z_i + ρ_i (P w)_i.
    fn force(&self, i: usize) -> f64 {
        self.z[i] + self.rho(i) * self.rows.rows[i].apply(self.w)
    }

    /// The sets of the iterate; `before`, the sets it was solved with.
    fn sets(&self, before: Option<&Sets>) -> Sets {
        let rows = self.rows;
        let active = (0..rows.n_contact).map(|i| self.force(i) > 0.0).collect();
        let friction = (0..rows.n_friction_nodes())
            .map(|j| {
                let block = rows.friction_block(j);
                let (c, rho) = (rows.rows[block.start].bound, self.rho(block.start));
                let mut g = [0.0; 2];
                for (k, i) in block.enumerate() {
                    g[k] = self.force(i);
                }
                let norm = g[0].hypot(g[1]);
                let g = [g[0] / norm, g[1] / norm];
                // A node that would turn back sticks first: ρ (K's diagonal) can be far
                // stiffer than the boundary is where the body slides, and the test would
                // swing between the two directions past the sticking state between them.
                let reverses = match before.map(|b| b.friction[j]) {
                    Some(Friction::Slip { g: old, .. }) => old[0] * g[0] + old[1] * g[1] < 0.0,
                    _ => false,
                };
                if norm <= c || reverses {
                    return Friction::Stick;
                }
                Friction::Slip {
                    g,
                    beta: (c * rho / (norm - c)).min(1e12 * rho),
                }
            })
            .collect();
        Sets { active, friction }
    }
}

/// The rows of one node: its contact row and friction block, if any.
#[derive(Clone, Debug)]
struct Node {
    contact: Option<usize>,
    friction: Option<usize>,
}

/// Counts over a run (the summary's iteration statistics).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ActiveSetCounts {
    pub steps: usize,
    pub newton: usize,
    pub krylov: usize,
    /// The most Newton iterations and Krylov iterations of one system.
    pub max_newton: usize,
    pub max_krylov: usize,
}

/// The active-set solver of a run.
pub struct ActiveSetSolver {
    settings: ActiveSetSettings,
    nodes: Vec<Node>,
    /// The diagonal of K along each row, ρ's unit (ρ itself is `Iterate::rho`).
    rho: Vec<f64>,
    terms: Terms,
    /// At each node's dofs (`dofs`, three a node, −1 where it has none; the values there 0):
    /// b − f_slip, what the multipliers read of it; its projection Π(b − f_slip), where the
    /// system's right side is not b; and (K + S) w. No n-vector: Π, f_slip and the
    /// multipliers act at Γ3's nodes alone.
    dofs: Vec<[i32; 3]>,
    force: Vec<[f64; 3]>,
    rhs: Vec<[f64; 3]>,
    r: Vec<[f64; 3]>,
    counts: ActiveSetCounts,
}

impl ActiveSetSolver {
    /// The solver for `rows` of the step matrix whose diagonal is `diagonal`.
    pub fn new(rows: &Rows, diagonal: &[f64], settings: ActiveSetSettings) -> Self {
        let mut rho: Vec<f64> = (rows.rows.iter())
            .map(|r| r.entries().map(|(d, c)| c * c * diagonal[d]).sum())
            .collect();
        // One ρ per friction node, the mean of its rows': with ρ_ik different along the
        // tangents a fixed point would not align γ_i with w_τ,i (the module doc).
        for j in 0..rows.n_friction_nodes() {
            let block = rows.friction_block(j);
            let mean = rho[block.clone()].iter().sum::<f64>() / block.len() as f64;
            rho[block].fill(mean);
        }
        let (nodes, dofs) = nodes(rows);
        ActiveSetSolver {
            settings,
            dofs,
            force: vec![[0.0; 3]; nodes.len()],
            rhs: vec![[0.0; 3]; nodes.len()],
            r: vec![[0.0; 3]; nodes.len()],
            nodes,
            rho,
            terms: Terms::default(),
            counts: ActiveSetCounts::default(),
        }
    }

    pub fn settings(&self) -> ActiveSetSettings {
        self.settings
    }

    pub fn counts(&self) -> ActiveSetCounts {
        self.counts
    }

    /// Solves the step: `w` in, the previous step's w; out, w_n. `z` in, the previous
    /// multipliers; out, the step's. A step whose Krylov solve is given up (the system's
    /// request: `solver::abandon`) ends `Abandoned` with an iterate in w, which the time loop
    /// puts back.
    pub fn solve(
        &mut self,
        system: &mut impl ConstrainedSystem,
        rows: &Rows,
        b: &[f64],
        w: &mut [f64],
        z: &mut [f64],
    ) -> Result<StepReport> {
        let s = self.settings;
        let mut soften = RHO_START;
        let mut sets = self.at(rows, soften, w, z).sets(None);
        let mut kkt_before = f64::NAN;
        let (mut exact, mut krylov) = (false, 0);
        // The sets met in this step (their hashes), and how many changes of the sets an
        // iteration may make: all until the sets cycle, then half as many at each cycle, and
        // ρ a tenth of what it was.
        let mut seen = vec![sets.signature()];
        let mut allowed = usize::MAX;
        let mut built: Option<Sets> = None;
        for newton in 1..=s.max_iterations {
            let tolerance = match exact {
                true => Tolerance::OfRhs(s.krylov_tolerance),
                false => Tolerance::OfStart(s.forcing),
            };
            self.assemble(rows, &sets, b);
            self.terms.project(w);
            // The preconditioner is rebuilt at the start of the step and where the sets or
            // the slip stiffness have changed; where the stiffness moved a little, the last
            // one serves.
            let pc = match &built {
                None => Preconditioner::Rebuilt,
                Some(b) if b.same_as(&sets) && !b.stiffness_moved(&sets, rows, &self.rho) => {
                    Preconditioner::Last
                }
                Some(_) => Preconditioner::Updated,
            };
            if pc != Preconditioner::Last {
                built = Some(sets.clone());
            }
            let rhs = RightSide {
                b,
                dofs: self.dofs.as_flattened(),
                values: self.rhs.as_flattened(),
            };
            let lin = system.solve(&self.terms, rhs, w, tolerance, pc)?;
            krylov += lin.iterations;
            self.count_system(lin.iterations);
            if lin.given_up {
                return Ok(report(StepStatus::Abandoned, newton, kkt_before));
            }
            if let Some(reason) = lin.failed {
                let status = StepStatus::Stopped {
                    solver: "the Krylov solve of a Newton system of the active-set solver",
                    reason,
                    iterations: lin.iterations,
                    residual: lin.residual,
                    remedy: lin.remedy,
                };
                return Ok(report(status, newton, kkt_before));
            }
            self.multipliers(system, rows, &sets, w, z)?;
            let kkt = kkt_residual(rows, w, z, system.largest_abs(w)?, max_abs(z));
            let at = self.at(rows, soften, w, z);
            let proposed = at.sets(Some(&sets));
            let same = proposed.same_as(&sets);
            if same && exact && kkt <= s.tolerance {
                self.count_step(newton);
                return Ok(StepReport {
                    status: StepStatus::Solved,
                    iterations: newton,
                    residual: kkt,
                    krylov,
                });
            }
            let kept = |allowed: usize| {
                let mut next = proposed.clone();
                if allowed < usize::MAX {
                    next.keep_changes(&sets, at, allowed);
                }
                next
            };
            // A cycle: the sets proposed, or those that the limit on changes keeps of them,
            // were met before in the step.
            let mut next = kept(allowed);
            let cycled = !same
                && [&proposed, &next]
                    .iter()
                    .any(|t| seen.contains(&t.signature()));
            if cycled {
                allowed = allowed.min(sets.changes(&proposed, at).len()).div_ceil(2);
                next = kept(allowed);
                soften *= 0.1;
            }
            seen.push(next.signature());
            // The next system is the last one where the sets stand and the KKT residual is
            // small, or once the sets have cycled: it is solved to `krylov_tolerance`.
            exact = (same && kkt <= s.tolerance.sqrt()) || allowed < usize::MAX;
            kkt_before = kkt;
            sets = next;
        }
        self.count_step(s.max_iterations);
        let status = StepStatus::MaxIterations {
            limit: s.max_iterations,
            residual: kkt_before,
            scale: 1.0,
        };
        Ok(report(status, s.max_iterations, kkt_before))
    }

    fn count_system(&mut self, krylov: usize) {
        self.counts.newton += 1;
        self.counts.krylov += krylov;
        self.counts.max_krylov = self.counts.max_krylov.max(krylov);
    }

    fn count_step(&mut self, newton: usize) {
        self.counts.steps += 1;
        self.counts.max_newton = self.counts.max_newton.max(newton);
    }

    /// The iterate (w, z) of the rows, judged with ρ times `soften`.
    fn at<'a>(&'a self, rows: &'a Rows, soften: f64, w: &'a [f64], z: &'a [f64]) -> Iterate<'a> {
        Iterate {
            rows,
            rho: &self.rho,
            soften,
            w,
            z,
        }
    }

    /// The Newton system's terms, and at Γ3's nodes b − f_slip and its projection Π(b −
    /// f_slip) for `sets`.
    fn assemble(&mut self, rows: &Rows, sets: &Sets, b: &[f64]) {
        self.terms.clear();
        for (k, node) in self.nodes.iter().enumerate() {
            let (dofs, force) = (self.dofs[k], &mut self.force[k]);
            *force = dofs.map(|d| if d < 0 { 0.0 } else { b[d as usize] });
            let mut removed: Vec<[f64; 3]> = Vec::new();
            if let Some(i) = node.contact.filter(|&i| sets.active[i]) {
                removed.push(rows.rows[i].dir);
            }
            if let Some(j) = node.friction {
                let block = rows.friction_block(j);
                match sets.friction[j] {
                    Friction::Stick => removed.extend(block.map(|i| rows.rows[i].dir)),
                    Friction::Slip { g, beta } => {
                        let c = rows.rows[block.start].bound;
                        for (k, i) in block.clone().enumerate() {
                            add_at_node(&rows.rows[i], -c * g[k], force);
                        }
                        if block.len() == 2 {
                            let tau = [rows.rows[block.start].dir, rows.rows[block.start + 1].dir];
                            self.terms.stiffness_dofs.extend(dofs);
                            self.terms.stiffness.extend(slip_block(&tau, g, beta));
                        }
                    }
                }
            }
            self.rhs[k] = *force;
            for v in orthonormal(&removed).0 {
                remove(&dofs, &v, &mut self.rhs[k], |c| c);
                self.terms.removed_dofs.extend(dofs);
                self.terms.removed.extend(v);
            }
        }
    }

    /// The multipliers of the iterate w: λ = 0 on inactive rows, γ = c ĝ + β T w_τ on
    /// slipping nodes, and on each node's removed rows the least-squares split of the
    /// residual r = b − f_slip − (K + S) w there (`force` holds b − f_slip there).
    fn multipliers(
        &mut self,
        system: &mut impl ConstrainedSystem,
        rows: &Rows,
        sets: &Sets,
        w: &[f64],
        z: &mut [f64],
    ) -> Result<()> {
        system.mult_at(w, self.dofs.as_flattened(), self.r.as_flattened_mut())?;
        // S w, block by block in the nodes' order (a block is a slipping node's).
        let mut blocks = self.terms.stiffness_products(w).peekable();
        for (r, dofs) in self.r.iter_mut().zip(&self.dofs) {
            if let Some((_, s)) = blocks.next_if(|(d, _)| d == dofs) {
                (0..3).filter(|&c| dofs[c] >= 0).for_each(|c| r[c] += s[c]);
            }
        }
        for (k, node) in self.nodes.iter().enumerate() {
            let mut removed: Vec<usize> = Vec::new();
            if let Some(i) = node.contact {
                z[i] = 0.0;
                if sets.active[i] {
                    removed.push(i);
                }
            }
            if let Some(j) = node.friction {
                let block = rows.friction_block(j);
                match sets.friction[j] {
                    Friction::Stick => removed.extend(block),
                    Friction::Slip { g, beta } => slip_multipliers(rows, j, g, beta, w, z),
                }
            }
            let local: [f64; 3] = std::array::from_fn(|c| match self.dofs[k][c] {
                -1 => 0.0,
                _ => self.force[k][c] - self.r[k][c],
            });
            let dirs: Vec<[f64; 3]> = removed.iter().map(|&i| rows.rows[i].dir).collect();
            for (i, zi) in removed.iter().zip(split(&dirs, local)) {
                z[*i] = zi;
            }
        }
        Ok(())
    }
}

/// a += z · the row's direction, a at its node's components: `NodalRow::add_transpose` on
/// the node's dofs alone.
fn add_at_node(row: &NodalRow, z: f64, a: &mut [f64; 3]) {
    for c in (0..row.dim).filter(|&c| row.dir[c] != 0.0) {
        a[c] += z * row.dir[c];
    }
}

/// a ← a − (v·a) v over the dofs d that exist, a's value at the c-th of them a[at(c)]: the
/// removal of one direction of a node (`Terms::project`).
fn remove(d: &[i32], v: &[f64], a: &mut [f64], at: impl Fn(usize) -> usize) {
    let p: f64 = (0..3).filter(|&c| d[c] >= 0).map(|c| v[c] * a[at(c)]).sum();
    for c in (0..3).filter(|&c| d[c] >= 0) {
        a[at(c)] -= p * v[c];
    }
}

/// The coefficients z with Σ z_k a_k = r in the least-squares sense, a_k = `dirs`: by the
/// QR factors of Gram–Schmidt (`orthonormal`); a vector dependent on those before it gets 0.
fn split(dirs: &[[f64; 3]], r: [f64; 3]) -> Vec<f64> {
    let (q, index) = orthonormal(dirs);
    let kept: Vec<usize> = (0..dirs.len()).filter(|&k| index[k].is_some()).collect();
    // R y = Qᵀ r with R_jl = q_j·a_{kept_l} (upper triangular), back substitution.
    let mut y: Vec<f64> = q.iter().map(|e| crate::mesh::dot(*e, r)).collect();
    for j in (0..kept.len()).rev() {
        for l in j + 1..kept.len() {
            y[j] -= crate::mesh::dot(q[j], dirs[kept[l]]) * y[l];
        }
        y[j] /= crate::mesh::dot(q[j], dirs[kept[j]]);
    }
    let mut z = vec![0.0; dirs.len()];
    for (j, &k) in kept.iter().enumerate() {
        z[k] = y[j];
    }
    z
}

/// PETSc's KSP as the Newton systems' solver: K in its matrix, the constrained system in an
/// assembled matrix of K's pattern with a multigrid of its own
/// (`petsc::Krylov::solve_constrained`).
#[cfg(feature = "petsc")]
impl ConstrainedSystem for crate::petsc::Krylov {
    fn mult_at(&mut self, x: &[f64], dofs: &[i32], y: &mut [f64]) -> Result<()> {
        crate::petsc::Krylov::mult_at(self, x, dofs, y)
    }

    fn largest_abs(&mut self, w: &[f64]) -> Result<f64> {
        crate::petsc::Krylov::largest_abs(self, w)
    }

    fn solve(
        &mut self,
        terms: &Terms,
        rhs: RightSide<'_>,
        w: &mut [f64],
        tolerance: Tolerance,
        pc: Preconditioner,
    ) -> Result<LinearSolve> {
        let view = crate::petsc::NodalTerms {
            removed_dofs: &terms.removed_dofs,
            removed: &terms.removed,
            stiffness_dofs: &terms.stiffness_dofs,
            stiffness: &terms.stiffness,
        };
        let hierarchy = match pc {
            Preconditioner::Last => crate::petsc::Hierarchy::Last,
            Preconditioner::Rebuilt => crate::petsc::Hierarchy::FromK,
            Preconditioner::Updated => crate::petsc::Hierarchy::Updated,
        };
        let tolerance = match tolerance {
            Tolerance::OfRhs(rtol) => crate::petsc::Tolerance::OfRhs(rtol),
            Tolerance::OfStart(eta) => crate::petsc::Tolerance::OfStart(eta),
        };
        let b = (rhs.b, rhs.dofs, rhs.values);
        let s = self.solve_constrained(view, b, w, tolerance, hierarchy)?;
        Ok(LinearSolve {
            iterations: s.iterations,
            residual: s.residual,
            failed: s.failed,
            remedy: crate::petsc::REMEDY,
            given_up: s.given_up,
        })
    }
}

fn report(status: StepStatus, iterations: usize, residual: f64) -> StepReport {
    StepReport {
        status,
        iterations,
        residual,
        krylov: 0,
    }
}

/// γ_i = c ĝ + β T w_τ on a slipping node j.
fn slip_multipliers(rows: &Rows, j: usize, g: [f64; 2], beta: f64, w: &[f64], z: &mut [f64]) {
    let block = rows.friction_block(j);
    let c = rows.rows[block.start].bound;
    let wt: Vec<f64> = block.clone().map(|i| rows.rows[i].apply(w)).collect();
    let gw: f64 = wt.iter().zip(g).map(|(a, b)| a * b).sum();
    for (k, i) in block.enumerate() {
        let tangential = if wt.len() == 2 {
            wt[k] - g[k] * gw
        } else {
            0.0
        };
        z[i] = c * g[k] + beta * tangential;
    }
}

/// S_i = β Σ_kl T_kl τ_k τ_lᵀ (3 × 3, row-major) on a node's dofs, T = I − ĝĝᵀ.
fn slip_block(tau: &[[f64; 3]; 2], g: [f64; 2], beta: f64) -> [f64; 9] {
    let mut m = [0.0; 9];
    for k in 0..2 {
        for l in 0..2 {
            let t = beta * (f64::from(u8::from(k == l)) - g[k] * g[l]);
            for r in 0..3 {
                for c in 0..3 {
                    m[3 * r + c] += t * tau[k][r] * tau[l][c];
                }
            }
        }
    }
    m
}

/// Modified Gram–Schmidt on a node's vectors: the orthonormal ones and, for each input,
/// its index among them (None for a vector dependent on those before it).
fn orthonormal(vs: &[[f64; 3]]) -> (Vec<[f64; 3]>, Vec<Option<usize>>) {
    let (mut q, mut index): (Vec<[f64; 3]>, Vec<Option<usize>>) = (Vec::new(), Vec::new());
    for v in vs {
        let mut u = *v;
        for _ in 0..2 {
            for e in &q {
                let p = crate::mesh::dot(u, *e);
                for c in 0..3 {
                    u[c] -= p * e[c];
                }
            }
        }
        let norm = crate::mesh::dot(u, u).sqrt();
        let scale = crate::mesh::dot(*v, *v).sqrt();
        if norm > 1e-8 * scale {
            index.push(Some(q.len()));
            q.push(u.map(|x| x / norm));
        } else {
            index.push(None);
        }
    }
    (q, index)
}

/// The nodes of the rows, in the order of their first row, and each node's dofs (the union
/// over its rows: −1 where no row touches the component).
fn nodes(rows: &Rows) -> (Vec<Node>, Vec<[i32; 3]>) {
    let mut index = std::collections::HashMap::new();
    let (mut nodes, mut dofs) = (Vec::new(), Vec::new());
    for (i, row) in rows.rows.iter().enumerate() {
        let k = *index.entry(row.node).or_insert_with(|| {
            nodes.push(Node {
                contact: None,
                friction: None,
            });
            dofs.push([-1; 3]);
            nodes.len() - 1
        });
        for c in (0..row.dim).filter(|&c| row.dir[c] != 0.0) {
            dofs[k][c] = row.dofs[c] as i32;
        }
        match i < rows.n_contact {
            true => nodes[k].contact = Some(i),
            false => nodes[k].friction = Some((i - rows.n_contact) / rows.block),
        }
    }
    (nodes, dofs)
}

fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |a, x| a.max(x.abs()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The least-squares split recovers the coefficients of independent directions exactly,
    /// and gives a direction dependent on those before it nothing (the 90° corner).
    #[test]
    fn split_recovers_the_coefficients_of_a_node() {
        let dirs = [[0.0, -1.0, 0.0], [0.6, 0.8, 0.0], [0.0, 0.0, 1.0]];
        let z = [0.3, -1.2, 2.5];
        let r: [f64; 3] = std::array::from_fn(|c| (0..3).map(|k| z[k] * dirs[k][c]).sum());
        let got = split(&dirs, r);
        for (a, b) in got.iter().zip(z) {
            assert!((a - b).abs() <= 1e-14, "{got:?}");
        }
        let corner = [[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]];
        assert_eq!(split(&corner, [0.0, -0.7, 0.0]), vec![0.7, 0.0]);
    }

    /// A slipping node's block β τᵀ(I − ĝĝᵀ)τ is symmetric, positive semidefinite, zero along
    /// the slip direction τᵀĝ and β across it.
    #[test]
    fn the_slip_block_acts_across_the_slip_only() {
        let (s, c) = 0.3f64.sin_cos();
        let tau = [[c, s, 0.0], [-s, c, 0.0]];
        let (g, beta) = ([0.8, -0.6], 2.5);
        let m = slip_block(&tau, g, beta);
        let apply = |x: [f64; 3]| -> [f64; 3] {
            std::array::from_fn(|r| (0..3).map(|k| m[3 * r + k] * x[k]).sum())
        };
        let along: [f64; 3] = std::array::from_fn(|k| g[0] * tau[0][k] + g[1] * tau[1][k]);
        let across: [f64; 3] = std::array::from_fn(|k| -g[1] * tau[0][k] + g[0] * tau[1][k]);
        for r in 0..3 {
            for k in 0..3 {
                assert!((m[3 * r + k] - m[3 * k + r]).abs() <= 1e-15);
            }
        }
        assert!(apply(along).iter().all(|v| v.abs() <= 1e-15));
        let a = apply(across);
        assert!(
            (0..3).all(|k| (a[k] - beta * across[k]).abs() <= 1e-14),
            "{a:?}"
        );
        assert!(apply([0.0, 0.0, 1.0]).iter().all(|v| *v == 0.0));
    }

    /// A slipping node whose β moved by more than a tenth of its ρ asks for a new
    /// preconditioner, in 3D only (a 2D slip adds no stiffness); a node that sticks in
    /// either set is the sets' business (`same_as`), not the stiffness's.
    #[test]
    fn only_a_3d_slip_stiffness_that_moved_far_calls_for_a_new_preconditioner() {
        let row = |node: usize, dir: [f64; 3], dim: usize| NodalRow {
            node,
            dofs: [3 * node, 3 * node + 1, 3 * node + 2],
            dir,
            dim,
            bound: 1.0,
            area: 1.0,
        };
        let tangents = [row(0, [1.0, 0.0, 0.0], 3), row(0, [0.0, 1.0, 0.0], 3)];
        let rows_3d = Rows::new(&[], &tangents, 2);
        let rows_2d = Rows::new(&[], &[row(0, [1.0, 0.0, 0.0], 2)], 1);
        let rho = [4.0, 4.0];
        let slip = |beta: f64| Sets {
            active: vec![],
            friction: vec![Friction::Slip {
                g: [1.0, 0.0],
                beta,
            }],
        };
        let stick = Sets {
            active: vec![],
            friction: vec![Friction::Stick],
        };
        assert!(slip(50.0).stiffness_moved(&slip(1e-3), &rows_3d, &rho));
        assert!(!slip(1.0).stiffness_moved(&slip(1.3), &rows_3d, &rho));
        assert!(!slip(50.0).stiffness_moved(&slip(1e-3), &rows_2d, &rho));
        assert!(!stick.stiffness_moved(&slip(50.0), &rows_3d, &rho));
    }

    /// Π removes the directions of a node and keeps the rest; S multiplies by its block.
    #[test]
    fn terms_project_and_add_their_stiffness() {
        let n = [0.6, 0.0, 0.8];
        let terms = Terms {
            removed_dofs: vec![3, -1, 5],
            removed: n.to_vec(),
            stiffness_dofs: vec![0, 1, -1],
            stiffness: vec![2.0, 1.0, 0.0, 1.0, 3.0, 0.0, 0.0, 0.0, 0.0],
        };
        let mut a = vec![1.0, 1.0, 1.0, 0.6, 7.0, 0.8];
        terms.project(&mut a);
        assert!(a[3].abs() <= 1e-15 && a[5].abs() <= 1e-15, "{a:?}");
        assert_eq!(a[4], 7.0);
        let x = [1.0, 2.0, 9.0, 9.0, 9.0, 9.0];
        let products: Vec<_> = terms.stiffness_products(&x).collect();
        assert_eq!(products, [(&[0, 1, -1][..], [4.0, 7.0, 0.0])]);
    }
}
