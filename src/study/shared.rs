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

#[cfg(test)]
mod tests {
    use super::*;

    /// The paper scene on the mesh `rect_NNN.msh` of level n with `steps` steps.
    fn prepare(discs: &mut Discs, n: usize, steps: usize) -> (Scene, Discretized) {
        let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/paper.toml");
        let mesh = format!("../meshes/paper/rect_{n:03}.msh");
        discs
            .prepare(&scene, &[], |s| {
                let end = s.time.end;
                s.with_mesh(Path::new(&mesh))?.with_time(end, steps)
            })
            .unwrap()
    }

    /// Cases on one mesh share its discretization whatever their steps; another mesh gets
    /// its own. The transfers are those made directly, one per pair of meshes, the target
    /// counted: two references give two transfers.
    #[test]
    fn discretizations_by_mesh_and_transfers_by_pair() {
        let mut discs = Discs::default();
        let (s8, a) = prepare(&mut discs, 8, 8);
        let (s64, b) = prepare(&mut discs, 8, 64);
        assert_eq!((s8.time.steps, s64.time.steps), (8, 64));
        assert!(Arc::ptr_eq(&a.disc, &b.disc));
        let (_, fine) = prepare(&mut discs, 16, 8);
        let (_, finer) = prepare(&mut discs, 32, 8);
        assert!(!Arc::ptr_eq(&a.disc, &fine.disc));
        assert_eq!(discs.0.len(), 3);

        let mut transfers = Transfers::default();
        for target in [&fine, &finer, &fine] {
            let t = transfers.between((&a.mesh, &a.disc), (&target.mesh, &target.disc));
            let direct = Transfer::between(&a.disc, &target.disc);
            assert_eq!(t.weights, direct.weights);
            assert_eq!(t.weights.len(), target.disc.nodes.len());
        }
        assert_eq!(transfers.0.len(), 2);
        assert!(transfers.has(&a.mesh, &fine.mesh) && !transfers.has(&fine.mesh, &a.mesh));
    }
}
