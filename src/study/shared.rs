//! What a study's cases share: one discretization per mesh and one transfer per pair of
//! meshes.
//!
//! - A discretization depends on the mesh and the scene's physics, not on the number of
//!   steps (`fem` never reads `scene.time`), and every case of a study has the same physics
//!   (the scene and its overrides): cases on one mesh share it. Only the cases' own runs
//!   discretize again, as a run does, because their wall times count it.
//! - A transfer depends on the two meshes alone: the paper's Tables 1 and 2 have their
//!   levels on the same four meshes, and Table 3's levels are all on the reference mesh, so
//!   the 12 rows of the three tables need 5 transfers.
//!
//! The numbers are those of a case that discretizes and transfers on its own, bit for bit:
//! the same function of the same input.

use super::transfer::Transfer;
use crate::fem::Discretization;
use crate::run::{discretize, load_scene};
use crate::scene::Scene;
use crate::Result;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// A mesh read and discretized: the file as the mesh names it, and its discretization.
#[derive(Clone)]
pub(crate) struct Discretized {
    pub mesh: String,
    pub disc: Arc<Discretization>,
}

/// The discretizations of the meshes seen so far, by the scene's `mesh.file` of the case.
#[derive(Default)]
pub(crate) struct Discs(HashMap<String, Discretized>);

impl Discs {
    /// The scene (with the overrides) as `case` changes it, and the discretization of its
    /// mesh, made once per mesh.
    pub fn prepare(
        &mut self,
        scene_path: &Path,
        overrides: &[String],
        case: impl FnOnce(Scene) -> Result<Scene>,
    ) -> Result<(Scene, Discretized)> {
        let scene = case(load_scene(scene_path, overrides)?)?;
        let key = scene.mesh.file.display().to_string();
        if let Some(d) = self.0.get(&key) {
            return Ok((scene, d.clone()));
        }
        let (scene, mesh, disc) = discretize(scene)?;
        let d = Discretized {
            mesh: mesh.path.display().to_string(),
            disc: Arc::new(disc),
        };
        self.0.insert(key, d.clone());
        Ok((scene, d))
    }
}

/// The transfers made so far, by (source mesh, target mesh) as [`Discretized::mesh`]
/// names them.
#[derive(Default)]
pub(crate) struct Transfers(HashMap<(String, String), Transfer>);

impl Transfers {
    /// The transfer from the mesh `source` to the mesh `target`, made once per pair.
    pub fn between(
        &mut self,
        (source, source_disc): (&str, &Discretization),
        (target, target_disc): (&str, &Discretization),
    ) -> &Transfer {
        self.0
            .entry((source.to_string(), target.to_string()))
            .or_insert_with(|| Transfer::between(source_disc, target_disc))
    }

    /// Whether the transfer between these meshes is made.
    pub fn has(&self, source: &str, target: &str) -> bool {
        self.0
            .contains_key(&(source.to_string(), target.to_string()))
    }
}
