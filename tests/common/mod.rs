//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use viscontact::fem::Discretization;
use viscontact::mesh::Mesh;
use viscontact::scene::Scene;
use viscontact::time_loop::TimeLoop;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A shipped mesh by its path below meshes/.
pub fn mesh_path(rel: &str) -> String {
    repo().join("meshes").join(rel).display().to_string()
}

/// Writes `text` as `name` into `dir` and returns its path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Loads a scene with overrides, its mesh and discretization.
pub fn load(scene: &Path, overrides: &[&str]) -> (Scene, Mesh, Discretization) {
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    viscontact::run::setup(scene, &o).unwrap()
}

/// Result of running a scene through the library: per step (u_n, w_n, z_n), and u_N.
pub struct Trace {
    pub u: Vec<Vec<f64>>,
    pub w: Vec<Vec<f64>>,
    pub z: Vec<Vec<f64>>,
    pub u_final: Vec<f64>,
    pub effects: Vec<&'static str>,
    pub solver: &'static str,
}

/// Runs all steps n = 0..=N and records them.
pub fn trace(scene: &Scene, disc: &Discretization) -> Trace {
    let mut tl = TimeLoop::new(scene, disc).unwrap();
    let (mut u, mut w, mut z) = (Vec::new(), Vec::new(), Vec::new());
    loop {
        let n = tl.n();
        let step = tl.solve_step().unwrap();
        u.push(step.u.to_vec());
        w.push(step.w.to_vec());
        z.push(step.z.to_vec());
        if n == scene.steps {
            break;
        }
        tl.advance();
    }
    Trace {
        u,
        w,
        z,
        u_final: tl.history.u.clone(),
        effects: tl.effects.names(),
        solver: tl.solver.name(),
    }
}

pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

/// max|a − b| / max|b|.
pub fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let d = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    d / max_abs(b).max(f64::MIN_POSITIVE)
}

/// Options of a library run into `out` with `--set` overrides, no progress bar.
pub fn run_options(
    out: &Path,
    set: &[&str],
    stop_after: Option<usize>,
) -> viscontact::run::RunOptions {
    viscontact::run::RunOptions {
        out: Some(out.to_path_buf()),
        overrides: set.iter().map(|s| s.to_string()).collect(),
        progress: false,
        stop_after,
        force: false,
    }
}

/// The summary of a run that must have finished.
pub fn finished(o: viscontact::run::Outcome) -> viscontact::run::Summary {
    match o {
        viscontact::run::Outcome::Finished(s) => *s,
        viscontact::run::Outcome::Stopped { step, .. } => panic!("run stopped at step {step}"),
    }
}
