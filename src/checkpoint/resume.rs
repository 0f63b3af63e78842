//! Resuming: the scene of a resumed run, the checks that it continues the same physics on
//! the same mesh, and the saved state of the loop.

use super::history_file::read_history;
use super::{groups_fingerprint, mesh_fingerprint, physics_signature, Checkpoint, StoredMemory};
use crate::fem::Discretization;
use crate::history::{
    memory_mismatch, HeldAt, Plans, PronyTerm, SavedHistory, SavedLoop, SavedMemory, Stored,
};
use crate::mesh::Mesh;
use crate::scene::{self, Scene};
use crate::{Error, Result};
use std::path::PathBuf;

/// Keys a resume may override: the end time (the step size stays), output, checkpoints, and
/// where the mesh is now (a run moved to another machine; the mesh itself must be the same,
/// checked by its fingerprint).
pub(super) fn overridable(key: &str) -> bool {
    key == "time.end"
        || key == "mesh.file"
        || key.starts_with("output.")
        || key.starts_with("checkpoint.")
}

impl Checkpoint {
    /// The scene of a resumed run: the stored scene text with `overrides` applied. Only
    /// `time.end`, `mesh.file`, `output.*` and `checkpoint.*` may be overridden;
    /// `time.end = T2` keeps the step size k and sets `time.steps` = T2/k, which must be an
    /// integer (within 1e-9) not below the checkpoint's step. The stored `mesh.file` is
    /// resolved against the stored scene path; an overriding one (a run moved to another
    /// place) against the working directory, and [`Checkpoint::check`] then requires the
    /// recorded fingerprints.
    pub fn scene(&self, overrides: &[String]) -> Result<Scene> {
        let shown = self.path.display();
        let (mut plain, mut mesh, mut time) = (Vec::new(), None, None);
        for o in overrides {
            let (key, value) = o.split_once('=').ok_or_else(|| {
                Error::input(format!(
                    "--set {o:?}: expected KEY=VALUE, e.g. --set time.end=2.0"
                ))
            })?;
            let key = key.trim();
            if !overridable(key) {
                return Err(Error::input(format!(
                    "--set {key}: a resume continues the physics of {shown} and may only \
                     change time.end, mesh.file (the same mesh in a new place), output.* and \
                     checkpoint.*; to change {key}, start a new run with `viscontact run`"
                )));
            }
            match key {
                "mesh.file" => mesh = Some(Self::moved_mesh(value)?),
                "time.end" => time = Some(self.new_end(value)?),
                _ => plain.push(o.clone()),
            }
        }
        let stored = |e: Error| Error::input(format!("{shown}: the stored scene: {e}"));
        let scene_path = self.scene_path();
        let text = self.id.scene_text.clone();
        let (text, file) = scene::parse_scene_text(&scene_path, text, &plain).map_err(stored)?;
        let mut scene = Scene::from_file(&scene_path, text, &file).map_err(stored)?;
        if let Some(mesh) = mesh {
            scene = scene.with_mesh(&mesh).map_err(stored)?;
        }
        if let Some((end, steps)) = time {
            scene = scene.with_time(end, steps).map_err(stored)?;
        }
        // One run, one series: frames in two formats would split its time series.
        let stored_format = self
            .id
            .scene_text
            .parse::<toml::Table>()
            .ok()
            .and_then(|t| t.get("output")?.get("format")?.as_str().map(str::to_string))
            .unwrap_or_else(|| "vtu".into());
        let format = match scene.output.options.format {
            crate::output::Format::Vtu => "vtu",
            crate::output::Format::Vtkhdf => "vtkhdf",
        };
        if format != stored_format {
            return Err(Error::input(format!(
                "--set output.format={format}: the run of {shown} writes its frames as \
                 {stored_format}, and a resumed run continues that series (frames in two \
                 formats would split it): resume without changing output.format"
            )));
        }
        if scene.time.steps < self.n {
            return Err(Error::input(format!(
                "{shown}: the stored scene has {} steps but the checkpoint is at step {}: \
                 the file is inconsistent",
                scene.time.steps, self.n
            )));
        }
        Ok(scene)
    }

    /// `--set time.end=T2`: T2 and the number of steps T2/k of the run's step size k, a whole
    /// number not below the checkpoint's step.
    fn new_end(&self, value: &str) -> Result<(f64, usize)> {
        let shown = self.path.display();
        let end: f64 = value.trim().parse().map_err(|_| {
            Error::input(format!(
                "--set time.end={}: not a number; give the new end time T2 in seconds",
                value.trim()
            ))
        })?;
        let end = crate::ranges::scaled_sign(end, "time.end", &self.path, true)?;
        let ratio = end / self.k;
        let steps = ratio.round();
        if steps > crate::ranges::MAX_STEPS as f64 {
            let detail = format!(
                " (--set): {ratio:e} steps of the run's k = {}, more than time.steps may \
                 have",
                self.k
            );
            return Err(crate::ranges::refuse(&self.path, "time.end", end, &detail));
        }
        if !(ratio.is_finite() && (ratio - steps).abs() <= 1e-9 * steps.max(1.0)) {
            return Err(Error::input(format!(
                "--set time.end={end}: T2/k = {ratio} is not a whole number of steps of \
                 the run's step size k = {} ({shown}); choose T2 = N·k, e.g. {}",
                self.k,
                (ratio.ceil().max(1.0)) * self.k
            )));
        }
        let steps = steps as usize;
        if steps < self.n {
            return Err(Error::input(format!(
                "--set time.end={end}: ends before the checkpoint's time t = {} (step \
                 {}) of {shown}; choose T2 ≥ {}",
                self.time, self.n, self.time
            )));
        }
        Ok((end, steps))
    }

    /// `--set mesh.file=PATH`: the mesh's new place. Given on the command line, so relative to the
    /// working directory (not to the stored scene's directory, which may not exist on this
    /// machine).
    fn moved_mesh(value: &str) -> Result<PathBuf> {
        let value = value.trim();
        let value = value
            .strip_prefix('"')
            .and_then(|v| v.strip_suffix('"'))
            .unwrap_or(value);
        let new = std::path::absolute(value).map_err(|e| {
            Error::input(format!(
                "--set mesh.file={value}: {e}; give the mesh's path"
            ))
        })?;
        Ok(new)
    }

    /// The scene path to use: the path as the run was given it when that still names the
    /// same file from here (so summary.json says the same), else the absolute one.
    fn scene_path(&self) -> PathBuf {
        let given = PathBuf::from(&self.id.scene_path);
        match std::fs::canonicalize(&given) {
            Ok(p) if p.display().to_string() == self.id.scene_path_absolute => given,
            _ => PathBuf::from(&self.id.scene_path_absolute),
        }
    }

    /// Refuses a mesh, physics or step size that differ from the checkpoint's, naming what.
    pub fn check(&self, scene: &Scene, mesh: &Mesh, disc: &Discretization) -> Result<()> {
        let shown = self.path.display();
        let mut diffs = Vec::new();
        if mesh_fingerprint(mesh) != self.id.mesh_fingerprint {
            diffs.push(format!(
                "the mesh {} is not the one the run used, {} (now {} nodes, {} cells; the run \
                 had {} nodes, {} cells; node coordinates or connectivity differ): restore \
                 that mesh file",
                mesh.path.display(),
                self.id.mesh_path,
                mesh.nodes.len(),
                mesh.n_cells(),
                self.id.nodes,
                self.id.triangles
            ));
        } else if groups_fingerprint(mesh) != self.id.groups_fingerprint {
            diffs.push(format!(
                "the physical groups of the mesh {} differ from those of the run's mesh {}: \
                 restore that mesh file",
                mesh.path.display(),
                self.id.mesh_path
            ));
        }
        // The mesh is compared by its fingerprint above, not by where its file is.
        let moved = |k: &str| k == "mesh.file";
        let now: Vec<_> = physics_signature(&scene.text)
            .into_iter()
            .filter(|(k, _)| !moved(k))
            .collect();
        let stored: Vec<_> = self.id.physics.iter().filter(|(k, _)| !moved(k)).collect();
        for (k, v) in stored.iter().copied() {
            match now.iter().find(|(k2, _)| k2 == k) {
                Some((_, v2)) if v2 == v => {}
                Some((_, v2)) => diffs.push(format!("{k}: the run had {v}, the scene says {v2}")),
                None => diffs.push(format!("{k}: the run had {v}, the scene has no such key")),
            }
        }
        for (k, v) in &now {
            if !stored.iter().any(|(k2, _)| k2 == k) {
                diffs.push(format!("{k}: the run had no such key, the scene says {v}"));
            }
        }
        let k_scene = scene.time.k();
        if (k_scene - self.k).abs() > 1e-9 * self.k {
            diffs.push(format!(
                "step size: the run had k = {}, the scene gives k = {} / {} = {k_scene}",
                self.k, scene.time.end, scene.time.steps
            ));
        }
        let dof_of: Vec<i64> = disc.free.signed().collect();
        if diffs.is_empty() && dof_of != self.id.dof_of {
            diffs.push(
                "the held dofs differ from the run's (clamped groups or [[dirichlet]] \
                 components): check mesh.groups.fixed and the [[dirichlet]] entries"
                    .into(),
            );
        }
        if diffs.is_empty() {
            return Ok(());
        }
        Err(Error::input(format!(
            "{shown}: cannot resume, the checkpoint does not match its scene:\n  - {}",
            diffs.join("\n  - ")
        )))
    }

    /// The memory plans the resumed run continues with ([`Plans::resumed`]): a compressed
    /// run's own fits, each group's terms (a_i, b_i) read back from the stored a_i and
    /// e^{−b_i k}.
    pub fn plans(&self, scene: &Scene) -> Result<Plans> {
        let stored = match &self.memory {
            StoredMemory::Prony {
                a, decay, group, ..
            } => {
                let groups = group.iter().max().map_or(1, |g| g + 1);
                let mut terms = vec![Vec::new(); groups];
                for ((&a, &d), &g) in a.iter().zip(decay).zip(group) {
                    terms[g].push((a, -d.ln() / self.k));
                }
                terms.into_iter().map(Stored::Terms).collect()
            }
            StoredMemory::None | StoredMemory::Direct { .. } => vec![Stored::Direct],
        };
        Plans::resumed(scene, stored)
            .map_err(|e| Error::input(format!("{}: {e}", self.path.display())))
    }

    /// The saved state of the loop, checked against the sizes of the scene's discretization
    /// (`n_free` dofs, `n_rows` contact and friction rows), each vector read from the file
    /// now at the dofs the loop holds it (`held`, `TimeLoop::held_at`): u_n, its sums and
    /// w_n, and the memory, the Prony states from this file a term at a time, or a general
    /// kernel's past displacements from the history file, their hash checked. z and
    /// z_before are handed over.
    pub fn saved(&mut self, n_free: usize, n_rows: usize, held: HeldAt) -> Result<SavedLoop> {
        let shown = self.path.display();
        let sizes = [
            ("state/u", self.n_dofs, n_free),
            ("state/z", self.z.len(), n_rows),
            ("state/z_before", self.z_before.len(), n_rows),
        ];
        for (name, have, want) in sizes {
            if have != want {
                return Err(Error::input(format!(
                    "{shown}: {name} has {have} values but the scene's discretization needs \
                     {want}: the checkpoint does not belong to this scene and mesh"
                )));
            }
        }
        let memory = match &self.memory {
            StoredMemory::None => SavedMemory::None,
            StoredMemory::Prony {
                a,
                decay,
                group,
                width,
            } => {
                if *width != n_free {
                    let what = format!("states of {width} dofs");
                    return Err(Error::input(format!("{shown}: {}", memory_mismatch(&what))));
                }
                let states = self.prony_states_at(held.memory)?;
                let term = |(i, m)| PronyTerm {
                    a: a[i],
                    decay: decay[i],
                    m,
                    group: group[i],
                };
                SavedMemory::Prony(states.into_iter().enumerate().map(term).collect())
            }
            StoredMemory::Direct {
                file, rows, hash, ..
            } => {
                if *rows != self.n {
                    let what = format!("{rows} history rows at step {}", self.n);
                    return Err(Error::input(format!("{shown}: {}", memory_mismatch(&what))));
                }
                let path = self.dir().join(file);
                let past = read_history(&path, (*rows, *hash), n_free, &self.id, held.memory)?;
                SavedMemory::Direct(past)
            }
        };
        let [u, u_sum, u_comp, w] = self.state_at(&held)?;
        let take = std::mem::take;
        Ok(SavedLoop {
            history: SavedHistory {
                n: self.n,
                k: self.k,
                u,
                u_sum,
                u_comp,
                memory,
            },
            w,
            z: take(&mut self.z),
            z_before: take(&mut self.z_before),
        })
    }
}
