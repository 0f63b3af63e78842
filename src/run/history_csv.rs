//! `DIR/history.csv`: the forces on the body at every solved step, one row per step
//! n = 0, …, N, made from a copy of the step on a writer thread (`output::Lines`) and
//! written with one `write` each; a checkpoint of step n + 1 waits until the rows up to
//! step n are written (docs/output.md).
//!
//! A row describes the equilibrium of step n: t_n, the state (u_n, w_n, m_n) and the
//! multipliers z_n of the step problem (3.1) solved at t_n. Each force is the force on the
//! body, summed over its group: the reactions r_n of each condition group (`fem::reactions`
//! says how they are computed from the rows of the step's matrices at the held dofs), the
//! resultant of each traction group's ⟨f_n, φ⟩ and of the body forces, the contact force
//! −Σ_{Γ3,1} λ_i n_i, the friction force −Σ g_F − Σ_{Γ3,2} γ_i τ_i (the given normal stress
//! F with the friction multipliers), and in 3D the moment Σ x_i × r_i of each condition
//! group about the origin. The balance Σ r + Σ f − Σ g_F − Σ Pᵀz = 0 holds per component to
//! the precision of the step's solve.
//!
//! A group's columns carry its name as the scene writes it, every character other than a
//! letter, a digit, `_`, `-` or `.` replaced by `_`; conditions (or tractions) that name one
//! group share its columns; a name that an earlier group's already took gets `_2`, `_3`, …
//! (the first that is free). A dof held by two conditions reports its reaction in the
//! first condition's group (the clamped groups in order, then the `[[dirichlet]]` entries).
//!
//! Numbers are Rust's shortest text that reads back as the same f64, so the file holds the
//! exact bits; a resumed run keeps the rows before its checkpoint's step and writes the
//! others again: its file equals the uninterrupted run's byte for byte.

use crate::fem::loads::Source;
use crate::fem::reactions::{Reactions, StateRead, StepForces};
use crate::fem::{Discretization, StressCells};
use crate::mesh::{cross, Mesh};
use crate::output::Lines;
use crate::scene::{self, Scene};
use crate::solver::Rows;
use crate::time_loop::{Solved, TimeLoop};
use crate::{Error, Result};
use std::fmt::Write as _;
use std::fs::{File, OpenOptions};
use std::io::Write as _;
use std::path::Path;
use std::sync::mpsc::Receiver;
use std::sync::Arc;

/// The file's name in the run directory.
pub const FILE_NAME: &str = "history.csv";

/// The groups of a scene's columns: which condition group each held dof reports to and
/// which traction group each load does.
struct Layout {
    dim: usize,
    /// Column names of the condition groups, and the group of each held dof.
    conditions: Vec<String>,
    condition_of: Vec<usize>,
    /// Column names of the traction groups, and the group of each load (None: a body force).
    tractions: Vec<String>,
    traction_of: Vec<Option<usize>>,
    body: bool,
}

impl Layout {
    fn new(scene: &Scene, disc: &Discretization) -> Layout {
        let (conditions, condition_of) =
            column_groups(disc.held.iter().map(|(_, source)| source.group(scene)));
        let sources: Vec<Source> = disc.loads.sources().collect();
        let traction_names = sources.iter().filter_map(|s| match s {
            Source::Traction(i) => Some(scene.physics.tractions[*i].on.as_str()),
            Source::Body(_) => None,
        });
        let (tractions, mut of_traction) = column_groups(traction_names);
        of_traction.reverse();
        let traction_of = sources
            .iter()
            .map(|s| match s {
                Source::Traction(_) => of_traction.pop(),
                Source::Body(_) => None,
            })
            .collect();
        Layout {
            dim: disc.dim,
            conditions,
            condition_of,
            tractions,
            traction_of,
            body: sources.iter().any(|s| matches!(s, Source::Body(_))),
        }
    }

    /// The header's names, in the order of a row.
    fn columns(&self) -> Vec<String> {
        let axes = &["x", "y", "z"][..self.dim];
        let vector =
            |name: &str| -> Vec<String> { axes.iter().map(|a| format!("{name}_{a}")).collect() };
        let mut names: Vec<String> = vec!["step".into(), "t".into()];
        for g in &self.conditions {
            names.extend(vector(&format!("reaction_{g}")));
        }
        for g in &self.tractions {
            names.extend(vector(&format!("load_{g}")));
        }
        if self.body {
            names.extend(vector("body"));
        }
        names.extend(vector("contact"));
        names.extend(vector("friction"));
        if self.dim == 3 {
            for g in &self.conditions {
                names.extend(vector(&format!("moment_{g}")));
            }
        }
        names.extend(["active", "stick", "slip", "max_von_mises", "iterations"].map(String::from));
        names
    }
}

/// The column names of the scene's groups as a run writes them (`viscontact check`).
pub fn columns(scene: &Scene, disc: &Discretization) -> Vec<String> {
    Layout::new(scene, disc).columns()
}

/// A group name as a column name: every character but a letter, a digit, `_`, `-`, `.`
/// becomes `_` (commas, quotes, spaces and the like have no place in a CSV header).
fn column_name(written: &str) -> String {
    written
        .chars()
        .map(
            |c| match c.is_alphanumeric() || matches!(c, '_' | '-' | '.') {
                true => c,
                false => '_',
            },
        )
        .collect()
}

/// The distinct groups of `names` (as written, in order of first appearance) as unique
/// column names, and the group of each name: a column name taken already gets `_2`, `_3`, ….
fn column_groups<'a>(names: impl Iterator<Item = &'a str>) -> (Vec<String>, Vec<usize>) {
    let (mut written, mut columns): (Vec<&str>, Vec<String>) = (Vec::new(), Vec::new());
    let of = names
        .map(|name| {
            if let Some(i) = written.iter().position(|w| *w == name) {
                return i;
            }
            let base = column_name(name);
            let column = std::iter::once(base.clone())
                .chain((2..).map(|k| format!("{base}_{k}")))
                .find(|c| !columns.contains(c))
                .expect("an unused suffix exists");
            written.push(name);
            columns.push(column);
            columns.len() - 1
        })
        .collect();
    (columns, of)
}

/// The history file of a run. A solved step's row is made on the thread of
/// `output::Lines` from a copy of the step's state: its forces, and its largest von Mises
/// stress, which the step's frame hands over when it has that field (else the row computes
/// the stress); the time loop only copies w_n, u_n, m_n and z_n.
pub(super) struct HistoryCsv {
    lines: Lines,
    rows: Arc<RowMaker>,
}

/// What a row is made of besides the step's state, shared with the writer thread.
struct RowMaker {
    layout: Layout,
    reactions: Reactions,
    disc: Arc<Discretization>,
    scene: Arc<Scene>,
    rows: Rows,
}

/// A solved step as its row needs it: copies of its state and multipliers.
struct StepCopy {
    n: usize,
    t: f64,
    /// What the reactions read of the state (`Reactions::read`).
    read: StateRead,
    von_mises: VonMises,
    z: Vec<f64>,
    iterations: usize,
}

/// Where a step's largest von Mises stress comes from.
enum VonMises {
    /// The step's frame, or the ranks' pieces, which compute it.
    Handed(Receiver<f64>),
    /// The row's writer, from w, u and m whole (a step without a frame on one process):
    /// only then copied whole, 8 bytes a dof of each.
    Computed {
        w: Vec<f64>,
        u: Vec<f64>,
        m: Option<Vec<f64>>,
    },
}

/// The held rows and the constant forces that history.csv's reactions are computed from
/// (`fem::reactions`), for the run's step matrix: K_A, or with `solver.history =
/// "implicit"` K_A + k K_B + k² r_g(0) K_R^(g) (`plans`' r_g). Made during setup, so that
/// the mesh goes before the step solver's setup (PETSc's or the factor's), the largest of a
/// run's peaks.
pub(super) fn reactions(
    scene: &Scene,
    mesh: &Mesh,
    disc: &Discretization,
    plans: &crate::history::Plans,
) -> Result<Reactions> {
    let k = scene.time.k();
    let (k_b, k_r) = match scene.solver.history {
        scene::History::Left => (0.0, Vec::new()),
        scene::History::Implicit => {
            let r0 = plans.r0(scene);
            (k, r0.iter().map(|r0| k * k * r0.unwrap_or(0.0)).collect())
        }
    };
    Reactions::new(mesh, scene, disc, k_b, &k_r)
}

impl HistoryCsv {
    /// `DIR/history.csv` of a new run (from step 0), or of a run resumed at step `from`:
    /// the rows of steps before `from` are kept, those after cut off (a run killed after its
    /// last checkpoint wrote them); a file that lacks them is started again with a warning.
    /// `reactions`: the held rows made during setup ([`reactions`]).
    pub fn open(
        out: &Path,
        scene: &Arc<Scene>,
        reactions: Reactions,
        disc: &Arc<Discretization>,
        tl: &TimeLoop,
        from: Option<usize>,
    ) -> Result<Self> {
        let layout = Layout::new(scene, disc);
        let header = layout.columns().join(",") + "\n";
        let path = out.join(FILE_NAME);
        let file = open_file(&path, &header, from)?;
        let rows = RowMaker {
            layout,
            reactions,
            disc: Arc::clone(disc),
            scene: Arc::clone(scene),
            rows: tl.rows().clone(),
        };
        Ok(HistoryCsv {
            lines: Lines::new(file, path),
            rows: Arc::new(rows),
        })
    }

    /// Hands the row of a solved step to the writer thread; `counts` are its (active,
    /// stick, slip) nodes, `frame_von_mises` the receiver of its frame's largest von Mises
    /// stress, if the frame has it.
    pub fn solved(
        &mut self,
        s: &Solved,
        counts: [usize; 3],
        frame_von_mises: Option<Receiver<f64>>,
    ) -> Result<()> {
        let step = &s.step;
        let copy = StepCopy {
            n: step.n,
            t: step.t,
            read: (self.rows.reactions).read([step.w, step.u], step.m, [step.local, step.held]),
            von_mises: match frame_von_mises {
                Some(rx) => VonMises::Handed(rx),
                None => VonMises::Computed {
                    w: step.w.to_vec(),
                    u: step.u.to_vec(),
                    m: step.m.map(<[f64]>::to_vec),
                },
            },
            z: step.z.to_vec(),
            iterations: step.report.iterations,
        };
        let rows = Arc::clone(&self.rows);
        (self.lines).send(move || rows.row(&copy, counts))
    }

    /// Waits until every row handed over is written (before a checkpoint, at the end).
    pub fn finish(&mut self) -> Result<()> {
        self.lines.finish()
    }
}

impl RowMaker {
    /// The row of a step, its line ended.
    fn row(&self, s: &StepCopy, counts: [usize; 3]) -> Result<String> {
        let (disc, scene) = (&self.disc, &self.scene);
        let forces = (self.reactions).forces(disc, scene, s.t, &s.read)?;
        let von_mises = match &s.von_mises {
            VonMises::Handed(rx) => rx.recv().map_err(|_| {
                Error::solve(format!(
                    "step {}: its frame's writer stopped before it computed the largest von \
                     Mises stress for history.csv",
                    s.n
                ))
            })?,
            VonMises::Computed { w, u, m } => {
                let (wu, m) = ([&w[..], u], (m.as_deref(), [None; 2]));
                disc.max_von_mises(wu, m, scene.mesh.model, StressCells::All)
            }
        };
        let mut line = s.n.to_string();
        put_number(&mut line, s.t);
        for v in self.forces(&s.z, &forces) {
            put_number(&mut line, v);
        }
        let [active, stick, slip] = counts;
        let _ = write!(line, ",{active},{stick},{slip}");
        put_number(&mut line, von_mises);
        let _ = writeln!(line, ",{}", s.iterations);
        Ok(line)
    }

    /// The force (and moment) columns of a row, in the header's order; `z` the step's
    /// multipliers.
    fn forces(&self, z: &[f64], f: &StepForces) -> Vec<f64> {
        let (layout, d) = (&self.layout, self.layout.dim);
        let mut reaction = vec![[0.0; 3]; layout.conditions.len()];
        let mut moment = vec![[0.0; 3]; layout.conditions.len()];
        for ((&(dof, _), &g), &r) in (self.reactions.held.iter())
            .zip(&layout.condition_of)
            .zip(&f.reactions)
        {
            let (node, mut r_vec) = (dof / d, [0.0; 3]);
            r_vec[dof % d] = r;
            let r_vec = self.disc.frames.to_space(node, r_vec);
            (0..3).for_each(|c| reaction[g][c] += r_vec[c]);
            let arm = cross(self.disc.nodes[node], r_vec);
            (0..3).for_each(|c| moment[g][c] += arm[c]);
        }
        let mut traction = vec![[0.0; 3]; layout.tractions.len()];
        let mut body = [0.0; 3];
        for (load, of) in f.loads.iter().zip(&layout.traction_of) {
            let sum = match of {
                Some(g) => &mut traction[*g],
                None => &mut body,
            };
            (0..3).for_each(|c| sum[c] += load[c]);
        }
        let (contact, friction) = self.multiplier_forces(z);
        let mut columns = Vec::new();
        let mut put = |v: &[f64; 3]| columns.extend_from_slice(&v[..d]);
        reaction.iter().for_each(&mut put);
        traction.iter().for_each(&mut put);
        if layout.body {
            put(&body);
        }
        put(&contact);
        put(&friction);
        if d == 3 {
            moment.iter().for_each(&mut put);
        }
        columns
    }

    /// −Σ λ_i n_i over Γ3,1 and −Σ g_F − Σ γ_i τ_i over Γ3,2.
    fn multiplier_forces(&self, z: &[f64]) -> ([f64; 3], [f64; 3]) {
        let rows = &self.rows;
        let (mut contact, mut friction) = ([0.0; 3], self.reactions.normal_stress);
        for (i, (row, z)) in rows.rows.iter().zip(z).enumerate() {
            let sum = match i < rows.n_contact {
                true => &mut contact,
                false => &mut friction,
            };
            let dir = self.disc.frames.to_space(row.node, row.dir);
            (0..3).for_each(|c| sum[c] -= z * dir[c]);
        }
        (contact, friction)
    }
}

/// `path` ready for the rows of a run from step 0 (`from` None: the header alone), or of a
/// run resumed at step n: its header and rows of steps < n kept (`kept_bytes`), else
/// started again with a warning.
fn open_file(path: &Path, header: &str, from: Option<usize>) -> Result<File> {
    let io = |e| Error::io(path, e);
    if let Some(len) = from.and_then(|n| kept_bytes(path, header, n)) {
        let mut file = OpenOptions::new().write(true).open(path).map_err(io)?;
        file.set_len(len).map_err(io)?;
        std::io::Seek::seek(&mut file, std::io::SeekFrom::End(0)).map_err(io)?;
        return Ok(file);
    }
    if let Some(n) = from.filter(|&n| n > 0) {
        crate::errln!(
            "warning: {} does not hold the rows of steps 0 to {} of this run; it starts \
             again at step {n}",
            path.display(),
            n - 1
        );
    }
    let mut file = File::create(path).map_err(io)?;
    file.write_all(header.as_bytes()).map_err(io)?;
    Ok(file)
}

/// `,v` with v as the shortest text that reads back as the same f64: plain for 0 and
/// 1e-4 ≤ |v| < 1e16, else with an exponent (`1.5e-7`; plain, it would be
/// `0.00000015`).
fn put_number(line: &mut String, v: f64) {
    let _ = match v == 0.0 || (1e-4..1e16).contains(&v.abs()) || !v.is_finite() {
        true => write!(line, ",{v}"),
        false => write!(line, ",{v:e}"),
    };
}

/// The length of `path`'s header and rows of steps 0..n, when the file has the header
/// `header` and those rows in order (else None).
fn kept_bytes(path: &Path, header: &str, n: usize) -> Option<u64> {
    let text = std::fs::read(path).ok()?;
    let body = text.strip_prefix(header.as_bytes())?;
    let mut len = header.len();
    for step in 0..n {
        let end = body[len - header.len()..]
            .iter()
            .position(|&b| b == b'\n')?;
        let row = &body[len - header.len()..][..end];
        let first = row.split(|&b| b == b',').next()?;
        if first != step.to_string().as_bytes() {
            return None;
        }
        len += end + 1;
    }
    Some(len as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn group_names_become_unique_column_names() {
        let names = ["Γ1", "a b", "a_b", "Γ1", "x,\"y\"", "a_b_2"];
        let (columns, of) = column_groups(names.into_iter());
        assert_eq!(columns, ["Γ1", "a_b", "a_b_2", "x__y_", "a_b_2_2"]);
        assert_eq!(of, [0, 1, 2, 0, 3, 4]);
    }

    #[test]
    fn numbers_read_back_exactly() {
        let mut line = String::new();
        for v in [
            0.0,
            -0.0,
            0.125,
            1e-4,
            7.4e-5,
            -1.0 / 3.0,
            2.5e16,
            1e300,
            5e-324,
        ] {
            line.clear();
            put_number(&mut line, v);
            let back: f64 = line[1..].parse().unwrap();
            assert_eq!(back.to_bits(), v.to_bits(), "{line}");
        }
        put_number(&mut line, 7.4e-5);
        assert!(line.ends_with(",7.4e-5"), "{line}");
    }

    #[test]
    fn a_resume_keeps_the_rows_before_its_step() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(FILE_NAME);
        let header = "step,t\n";
        std::fs::write(&path, "step,t\n0,0\n1,0.5\n2,1\n3,1.").unwrap();
        assert_eq!(kept_bytes(&path, header, 2), Some(17));
        assert_eq!(kept_bytes(&path, header, 0), Some(7));
        assert_eq!(kept_bytes(&path, header, 4), None, "a half row is no row");
        assert_eq!(kept_bytes(&path, "step,t,x\n", 1), None);
        std::fs::write(&path, "step,t\n0,0\n2,1\n").unwrap();
        assert_eq!(kept_bytes(&path, header, 2), None);
    }
}
