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

/// Copies the files of `from` (not recursive) into a new directory `to`.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_file() {
            std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
        }
    }
}

/// A seeded pseudo-random sequence (splitmix64), for reproducible random trials.
pub struct SplitMix(pub u64);

impl SplitMix {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in 0..n.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}
