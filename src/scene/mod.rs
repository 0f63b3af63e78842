//! The scene file (TOML, docs/scene.md): what the user asks for. Reading it is
//! two steps: `SceneFile` mirrors the TOML exactly (unknown keys are errors, named by their
//! dotted path), then `Scene::from_file` checks every value and compiles the expressions.
//! `--set KEY=VALUE` overrides are applied to the TOML tree before either step, so an
//! override is checked exactly like a key written in the file.
//!
//! A checked [`Scene`] is made of typed parts, each converted from its section(s) and
//! checked there: [`MeshChoice`] (`[mesh]`), [`TimeGrid`] (`[time]`), [`Physics`]
//! (`[material]`, `[contact]`, `[friction]`, `[load]`), [`SolverChoice`] (`[solver]`,
//! `[scheme]`), [`OutputPlan`] (`[output]`) and [`CheckpointPlan`] (`[checkpoint]`).
//! A study or a resume changes a scene through its typed methods ([`Scene::with_time`],
//! [`Scene::with_mesh`], …), which check the new values as the file's would be and keep
//! [`Scene::text`] the TOML of the scene that runs.

mod conditions;
pub mod file;
mod parts;
mod physics;
mod read;
mod values;

pub use conditions::{Components, Dirichlet};
pub use file::{
    ActiveSetSection, ContactSolver, Groups, History, LinearSolver, MemoryMode, Model, SceneFile,
};
pub use parts::{CheckpointPlan, MeshChoice, OutputPlan, SolverChoice, TimeGrid};
pub use physics::{Friction, Material, Physics, Region, Relaxation, Traction, BODY_KERNEL};
pub use read::{apply_override, name_set_key, parse_scene_text, read_scene_file};

use crate::Result;
use std::path::{Path, PathBuf};

/// A checked scene: every number in range, every expression compiled, paths resolved.
#[derive(Debug)]
pub struct Scene {
    pub name: String,
    /// The path the scene was read from.
    pub path: PathBuf,
    /// The TOML text that runs (after `--set` overrides and the typed changes).
    pub text: String,
    pub mesh: MeshChoice,
    pub time: TimeGrid,
    pub physics: Physics,
    pub solver: SolverChoice,
    pub output: OutputPlan,
    pub checkpoint: CheckpointPlan,
}

impl Scene {
    /// Reads, overrides and checks a scene file.
    pub fn load(path: &Path, overrides: &[String]) -> Result<Scene> {
        let (text, file) = read_scene_file(path, overrides)?;
        Scene::from_file(path, text, &file).map_err(|e| name_set_key(e, path, overrides))
    }

    /// Checks every section of a schema-checked scene file read from `path` (`text` is its
    /// TOML after overrides); the memory of a compressed kernel is checked against the time
    /// grid.
    pub fn from_file(path: &Path, text: String, f: &SceneFile) -> Result<Scene> {
        let time = TimeGrid::from_section(&f.time, path)?;
        let physics = Physics::from_file(f, &time, path)?;
        let solver = SolverChoice::from_sections(&f.solver, &f.scheme, &physics, path)?;
        let output = OutputPlan::from_section(&f.output, path)?;
        let checkpoint = CheckpointPlan::from_section(f.checkpoint.as_ref(), path)?;
        let name = f.name.clone().unwrap_or_else(|| {
            path.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "scene".into())
        });
        Ok(Scene {
            name,
            path: path.to_path_buf(),
            text,
            mesh: MeshChoice::from_section(&f.mesh, path),
            time,
            physics,
            solver,
            output,
            checkpoint,
        })
    }

    /// The scene on the mesh `file`, written as `mesh.file` is: relative to the scene
    /// file's directory, or absolute.
    pub fn with_mesh(mut self, file: &Path) -> Result<Scene> {
        self.mesh.file = parts::resolve(&self.path, file);
        let value = toml::Value::String(file.display().to_string());
        self.text = read::set_key(&self.text, &["mesh", "file"], value, &self.path)?;
        Ok(self)
    }

    /// The scene run to `end` in `steps` steps, checked as `time.end` and `time.steps` in
    /// the file are (the memory of a compressed kernel too).
    pub fn with_time(mut self, end: f64, steps: usize) -> Result<Scene> {
        let time = TimeGrid::new(end, steps, &self.path)?;
        self.physics.check_memory(&time, &self.path)?;
        self.time = time;
        let steps = toml::Value::Integer(steps as i64);
        self.text = read::set_key(&self.text, &["time", "end"], end.into(), &self.path)?;
        self.text = read::set_key(&self.text, &["time", "steps"], steps, &self.path)?;
        Ok(self)
    }

    /// The scene with its kernel's memory sum run directly
    /// (`material.relaxation.memory = "exact"`).
    pub fn with_exact_memory(mut self) -> Result<Scene> {
        self.physics.set_exact_memory(&self.time, &self.path)?;
        let key = ["material", "relaxation", "memory"];
        self.text = read::set_key(&self.text, &key, "exact".into(), &self.path)?;
        Ok(self)
    }

    /// The scene with `material.relaxation.tolerance = tolerance` (a compressed kernel is
    /// fitted to it; one run exactly stays exact).
    pub fn with_tolerance(mut self, tolerance: f64) -> Result<Scene> {
        let physics = &mut self.physics;
        physics.set_tolerance(tolerance, &self.time, &self.path)?;
        let key = ["material", "relaxation", "tolerance"];
        self.text = read::set_key(&self.text, &key, tolerance.into(), &self.path)?;
        Ok(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "[mesh]\nfile = \"rect_008.msh\"\n[time]\nend = 1.0\nsteps = 8\n\
                        [material.viscosity]\ntheta = 1.0\n\
                        [material.relaxation]\nexpr = \"exp(-s)\"\nhorizon = 4.0\n";

    fn scene() -> Scene {
        let path = Path::new("scenes/paper.toml");
        let (text, file) = parse_scene_text(path, TEXT.into(), &[]).unwrap();
        Scene::from_file(path, text, &file).unwrap()
    }

    #[test]
    fn typed_changes_are_checked_and_kept_in_the_text() {
        let s = scene().with_time(2.0, 16).unwrap();
        assert_eq!((s.time.end, s.time.steps, s.time.k()), (2.0, 16, 0.125));
        let s = s.with_mesh(Path::new("rect_016.msh")).unwrap();
        assert_eq!(s.mesh.file, Path::new("scenes/rect_016.msh"));
        let s = s.with_tolerance(1e-6).unwrap();
        assert_eq!(s.physics.compression, Some(1e-6));
        let stored: toml::Table = s.text.parse().unwrap();
        assert_eq!(stored["time"]["steps"].as_integer(), Some(16));
        assert_eq!(stored["time"]["end"].as_float(), Some(2.0));
        assert_eq!(stored["mesh"]["file"].as_str(), Some("rect_016.msh"));
        let reread = parse_scene_text(&s.path, s.text.clone(), &[]).unwrap();
        assert_eq!(
            Scene::from_file(&s.path, reread.0, &reread.1)
                .unwrap()
                .time
                .steps,
            16
        );
    }

    #[test]
    fn typed_changes_refuse_what_the_file_would() {
        let e = scene().with_time(1.0, 0).unwrap_err().to_string();
        assert!(e.contains("time.steps"), "{e}");
        // A horizon needs a compressed kernel.
        let e = scene().with_exact_memory().unwrap_err().to_string();
        assert!(e.contains("material.relaxation.horizon"), "{e}");
        let e = scene().with_tolerance(2.0).unwrap_err().to_string();
        assert!(e.contains("material.relaxation.tolerance"), "{e}");
    }
}
