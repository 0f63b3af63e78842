//! Fingerprints: the 64-bit running hash of meshes, physical groups and history rows, and
//! the physics signature of a scene, which resume compares with the checkpoint's.

use crate::mesh::Mesh;

/// A 64-bit running hash over 64-bit words (FNV-1a style multiply, with an xor-shift so that
/// high bits feed back into low ones). Not cryptographic: it tells a changed mesh or a
/// foreign history file from the right one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hash64(pub u64);

impl Default for Hash64 {
    fn default() -> Self {
        Hash64(0xcbf2_9ce4_8422_2325)
    }
}

impl Hash64 {
    pub fn word(&mut self, w: u64) {
        let h = (self.0 ^ w).wrapping_mul(0x0000_0100_0000_01b3);
        self.0 = h ^ (h >> 32);
    }

    /// The bits of every value (so −0.0 ≠ 0.0 and NaNs are told apart).
    pub fn f64s(&mut self, v: &[f64]) {
        for x in v {
            self.word(x.to_bits());
        }
    }

    pub fn str(&mut self, s: &str) {
        self.word(s.len() as u64);
        for chunk in s.as_bytes().chunks(8) {
            let mut b = [0u8; 8];
            b[..chunk.len()].copy_from_slice(chunk);
            self.word(u64::from_le_bytes(b));
        }
    }
}

/// Hash of the node coordinates (their bits) and the triangles' connectivity.
pub fn mesh_fingerprint(mesh: &Mesh) -> u64 {
    let mut h = Hash64::default();
    h.word(mesh.nodes.len() as u64);
    for p in mesh.nodes.all() {
        h.f64s(p);
    }
    h.word(mesh.triangles.len() as u64);
    for t in &mesh.triangles {
        for &i in t {
            h.word(i as u64);
        }
    }
    // 3D meshes only, so that 2D fingerprints stay what they were.
    if !mesh.tetrahedra.is_empty() {
        h.word(mesh.tetrahedra.len() as u64);
        for t in &mesh.tetrahedra {
            for &i in t {
                h.word(i as u64);
            }
        }
    }
    h.0
}

/// Hash of the physical groups: name, tag, dimension, facets and cells of each.
pub fn groups_fingerprint(mesh: &Mesh) -> u64 {
    let mut h = Hash64::default();
    h.word(mesh.groups.len() as u64);
    for g in &mesh.groups {
        h.word(g.dim as u64);
        h.word(g.tag as i64 as u64);
        h.str(g.name.as_deref().unwrap_or(""));
        h.word(g.facets.len() as u64);
        for f in &g.facets {
            h.word(f[0] as u64);
            h.word(f[1] as u64);
        }
        if !g.faces.is_empty() {
            h.word(g.faces.len() as u64);
            for f in &g.faces {
                for &i in f {
                    h.word(i as u64);
                }
            }
        }
        h.word(g.cells.len() as u64);
        for &c in &g.cells {
            h.word(c as u64);
        }
    }
    h.0
}

/// The physics of a scene as `(dotted key, TOML value)` pairs: every key except the ones a
/// resume may change (`name`, `time.*`, `output.*`, `checkpoint.*`). The step size is
/// compared on its own (`step_size`).
pub fn physics_signature(scene_text: &str) -> Vec<(String, String)> {
    fn flatten(prefix: &str, v: &toml::Value, out: &mut Vec<(String, String)>) {
        match v {
            toml::Value::Table(t) => {
                for (k, v) in t {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    if matches!(key.as_str(), "name" | "time" | "output" | "checkpoint") {
                        continue;
                    }
                    flatten(&key, v, out);
                }
            }
            toml::Value::Array(a) if a.iter().any(|x| x.is_table()) => {
                for (i, x) in a.iter().enumerate() {
                    flatten(&format!("{prefix}[{i}]"), x, out);
                }
            }
            other => out.push((prefix.to_string(), other.to_string())),
        }
    }
    let mut out = Vec::new();
    if let Ok(root) = scene_text.parse::<toml::Table>() {
        flatten("", &toml::Value::Table(root), &mut out);
    }
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn physics_signature_skips_resumable_keys() {
        let text = "name = \"a\"\n[time]\nend = 1.0\nsteps = 4\n[output]\nevery = 2\n\
                    [material.viscosity]\ntheta = 0.1\n[[load.traction]]\non = \"top\"\n\
                    value = [\"0\", \"1\"]\n";
        let sig = physics_signature(text);
        assert_eq!(
            sig,
            vec![
                ("load.traction[0].on".to_string(), "\"top\"".to_string()),
                (
                    "load.traction[0].value".to_string(),
                    "[\"0\", \"1\"]".to_string()
                ),
                ("material.viscosity.theta".to_string(), "0.1".to_string()),
            ]
        );
    }

    #[test]
    fn hash_tells_bits_apart() {
        let (mut a, mut b) = (Hash64::default(), Hash64::default());
        a.f64s(&[0.0, 1.0]);
        b.f64s(&[-0.0, 1.0]);
        assert_ne!(a, b);
        let mut c = Hash64::default();
        c.f64s(&[0.0]);
        c.f64s(&[1.0]);
        assert_eq!(
            a, c,
            "a running hash does not depend on how rows are grouped"
        );
    }
}
