//! The mesh of each level of a study: a pattern with the level in it (given, or derived
//! from the scene's `mesh.file`) or a list; every mesh must exist before anything runs.

use super::{MeshFamily, StudyOptions, Vary};
use crate::scene::read_scene_file;
use crate::{Error, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Expands `{n}` and `{n:0W}` in a mesh pattern.
pub fn expand_pattern(pattern: &str, n: usize) -> std::result::Result<String, String> {
    let mut out = String::new();
    let mut rest = pattern;
    let mut found = false;
    while let Some(i) = rest.find('{') {
        out.push_str(&rest[..i]);
        let j = rest[i..]
            .find('}')
            .ok_or_else(|| format!("mesh pattern '{pattern}': unclosed '{{'"))?;
        let spec = &rest[i + 1..i + j];
        match spec {
            "n" => write!(out, "{n}").expect("string"),
            _ => {
                let width = spec
                    .strip_prefix("n:0")
                    .and_then(|w| w.parse::<usize>().ok())
                    .ok_or_else(|| {
                        format!(
                            "mesh pattern '{pattern}': '{{{spec}}}' is not {{n}} or {{n:0W}} \
                             (e.g. {{n:03}})"
                        )
                    })?;
                write!(out, "{n:0width$}").expect("string");
            }
        }
        found = true;
        rest = &rest[i + j + 1..];
    }
    out.push_str(rest);
    if !found {
        return Err(format!(
            "mesh pattern '{pattern}' has no {{n}} or {{n:03}} for the level"
        ));
    }
    Ok(out)
}

/// `dir/name_032.msh` → `dir/name_{n:03}.msh`.
pub fn derive_pattern(mesh_file: &str) -> Option<String> {
    let stem = mesh_file.strip_suffix(".msh")?;
    let digits = stem.len() - stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    let head = &stem[..stem.len() - digits];
    (digits > 0 && head.ends_with('_')).then(|| format!("{head}{{n:0{digits}}}.msh"))
}

/// The mesh of each level.
pub(super) struct Meshes {
    family: MeshFamily,
    /// The scene file's directory (a pattern is relative to it).
    dir: PathBuf,
    /// The scene's spatial dimension.
    dim: usize,
}

impl Meshes {
    /// The meshes of a study: from `--meshes`, `--mesh-pattern` or the pattern of the scene's
    /// `mesh.file`. Every mesh is there before anything runs: a missing mesh fails at once.
    pub(super) fn for_study(scene_path: &Path, opts: &StudyOptions) -> Result<Meshes> {
        let (_, file) = read_scene_file(scene_path, &opts.overrides)?;
        let meshes = Meshes {
            family: mesh_family(scene_path, opts, &file.mesh.file)?,
            dir: scene_path.parent().unwrap_or(Path::new("")).to_path_buf(),
            dim: file.mesh.model.dim(),
        };
        let reference = opts.reference;
        let fixed = opts.fixed.unwrap_or(reference);
        for &vary in &opts.vary {
            meshes.case(vary, reference, None, fixed)?;
            for (i, &n) in opts.levels.iter().enumerate() {
                meshes.case(vary, n, Some(i), fixed)?;
            }
        }
        Ok(meshes)
    }

    /// The mesh file of level `n` (a pattern) or of entry `index` of a list (None: the
    /// reference mesh, the last of the list); an input error when it does not exist.
    fn file(&self, n: usize, index: Option<usize>) -> Result<String> {
        let file = match &self.family {
            MeshFamily::Pattern(p) => expand_pattern(p, n).map_err(Error::input)?,
            MeshFamily::List(list) => {
                let p = match index {
                    Some(i) => &list[i],
                    None => list.last().expect("checked non-empty"),
                };
                let abs = std::path::absolute(p).map_err(|e| Error::io(p, e))?;
                abs.display().to_string()
            }
        };
        let path = self.dir.join(&file);
        if !path.exists() {
            let (what, make) = match self.family {
                MeshFamily::Pattern(_) => (
                    format!("the mesh of level {n}"),
                    how_to_make(&path, n, self.dim)
                        .map_or(String::new(), |m| format!("; make it with `{m}`")),
                ),
                MeshFamily::List(_) => ("a mesh of --meshes".into(), String::new()),
            };
            return Err(Error::input(format!(
                "study: {what}, {}, does not exist{make}",
                path.display()
            )));
        }
        Ok(file)
    }

    /// The mesh file, number of steps and mesh level of a run of family `vary` at level n
    /// (`index` in a list; None: the reference run at n = the reference level): the level
    /// sets what varies, `fixed` the other.
    pub(super) fn case(
        &self,
        vary: Vary,
        n: usize,
        index: Option<usize>,
        fixed: usize,
    ) -> Result<(String, usize, usize)> {
        Ok(match vary {
            Vary::Both => (self.file(n, index)?, n, n),
            Vary::H => (self.file(n, index)?, fixed, n),
            Vary::K => (self.file(fixed, None)?, n, fixed),
        })
    }

    pub(super) fn nominal_h(&self, n: usize, h_max: f64) -> f64 {
        match self.family {
            MeshFamily::Pattern(_) => 1.0 / n as f64,
            MeshFamily::List(_) => h_max,
        }
    }
}

/// Where a study's meshes come from: the options' list or pattern, else the pattern derived
/// from the scene's `mesh.file` (as written in the scene).
fn mesh_family(scene_path: &Path, opts: &StudyOptions, mesh_file: &str) -> Result<MeshFamily> {
    Ok(match &opts.meshes {
        Some(MeshFamily::List(list)) => {
            let needs_levels = opts.vary.iter().any(|v| *v != Vary::K);
            if list.is_empty() || (needs_levels && list.len() != opts.levels.len() + 1) {
                return Err(Error::input(format!(
                    "study: --meshes has {} files; give one mesh per level ({}) and then the \
                     reference mesh",
                    list.len(),
                    opts.levels.len()
                )));
            }
            if opts.fixed.is_some() && opts.vary.contains(&Vary::K) {
                return Err(Error::input(
                    "study: with --meshes, --vary k runs on the last (reference) mesh; \
                     --fixed picks a mesh level only with a pattern",
                ));
            }
            MeshFamily::List(list.clone())
        }
        Some(MeshFamily::Pattern(p)) => {
            expand_pattern(p, 1).map_err(Error::input)?;
            MeshFamily::Pattern(p.clone())
        }
        None => MeshFamily::Pattern(derive_pattern(mesh_file).ok_or_else(|| {
            Error::input(format!(
                "{}: key 'mesh.file' = '{}' has no level number (name_NNN.msh); give \
                 --mesh-pattern 'name_{{n:03}}.msh' or --meshes a.msh,b.msh,…,reference.msh",
                scene_path.display(),
                mesh_file
            ))
        })?),
    })
}

/// How to make the missing mesh `dir/NAME_NNN.msh` of level n: with the generator script
/// in `dir` or up to two directories above it when its text offers `generate.sh NAME N`
/// (meshes too big to commit, e.g. `meshes/generate.sh block 16`), else with gmsh from
/// `dir/NAME.geo` when there is one.
fn how_to_make(path: &Path, n: usize, dim: usize) -> Option<String> {
    let name = path.file_name()?.to_str()?.strip_suffix(".msh")?;
    let stem = name
        .trim_end_matches(|c: char| c.is_ascii_digit())
        .strip_suffix('_')?;
    let dir = path.parent()?.canonicalize().ok()?;
    let shown = |p: &Path| {
        let cwd = std::env::current_dir().and_then(|d| d.canonicalize());
        cwd.ok()
            .and_then(|cwd| p.strip_prefix(cwd).ok().map(Path::to_path_buf))
            .unwrap_or_else(|| p.to_path_buf())
            .display()
            .to_string()
    };
    let offer = format!("generate.sh {stem} N");
    for d in dir.ancestors().take(3) {
        let script = d.join("generate.sh");
        if std::fs::read_to_string(&script).is_ok_and(|text| text.contains(&offer)) {
            return Some(format!("{} {stem} {n}", shown(&script)));
        }
    }
    let geo = dir.join(format!("{stem}.geo"));
    geo.exists().then(|| {
        format!(
            "gmsh -{dim} {} -setnumber n {n} -format msh41 -o {}",
            shown(&geo),
            shown(&dir.join(format!("{name}.msh")))
        )
    })
}
