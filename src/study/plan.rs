//! What a study runs: its distinct cases, and which of them make each family's reference
//! and rows. Planning comes first so that the cases can be solved in any order, one after
//! another or side by side ([`super::jobs`]), and the report is assembled from their
//! solutions alone.

use super::meshes::Meshes;
use super::{KernelForm, StudyOptions, Vary};
use crate::Result;

/// One run of a study: the scene on `mesh` (written as `mesh.file` is, relative to the
/// scene file) in `steps` steps to its end time, the kernel handed over in `form`, the wall
/// time the median of `repeat` runs (None: 3 when one run takes under a second, else 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Case {
    pub mesh: String,
    pub steps: usize,
    pub form: KernelForm,
    pub repeat: Option<usize>,
}

impl std::fmt::Display for Case {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}, N = {}", self.mesh, self.steps)?;
        match self.form {
            KernelForm::AsGiven => Ok(()),
            KernelForm::Expression => write!(f, ", the kernel as an expression"),
        }
    }
}

/// A level of a family: its level n, the level of its mesh and its case in [`Plan::cases`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Level {
    pub n: usize,
    pub mesh_n: usize,
    pub case: usize,
}

/// One `--vary` family: its reference and, per kernel form, its levels.
#[derive(Clone, Debug)]
pub(super) struct VaryPlan {
    pub vary: Vary,
    pub reference: Level,
    pub forms: Vec<(KernelForm, Vec<Level>)>,
}

/// The cases of a study, each once, in the order a study solves them one after another
/// (each family's reference, then its levels), and the families made of them.
#[derive(Clone, Debug)]
pub(super) struct Plan {
    pub cases: Vec<Case>,
    pub varies: Vec<VaryPlan>,
}

impl Plan {
    /// The plan of a study whose levels are checked and whose meshes exist. The reference
    /// keeps the fixed parameter at its fixed value (module docs of `study`); families that
    /// share a reference share its case.
    pub fn new(opts: &StudyOptions, meshes: &Meshes) -> Result<Plan> {
        let fixed = opts.fixed.unwrap_or(opts.reference);
        let forms: &[KernelForm] = if opts.kernel_compare {
            &[KernelForm::AsGiven, KernelForm::Expression]
        } else {
            &[KernelForm::AsGiven]
        };
        let mut plan = Plan {
            cases: Vec::new(),
            varies: Vec::new(),
        };
        for &vary in &opts.vary {
            let (mesh, steps, mesh_n) = meshes.case(vary, opts.reference, None, fixed)?;
            let reference = Level {
                n: opts.reference,
                mesh_n,
                case: plan.add(Case {
                    mesh,
                    steps,
                    form: KernelForm::AsGiven,
                    repeat: Some(1),
                }),
            };
            let mut by_form = Vec::new();
            for &form in forms {
                let mut levels = Vec::new();
                for (i, &n) in opts.levels.iter().enumerate() {
                    let (mesh, steps, mesh_n) = meshes.case(vary, n, Some(i), fixed)?;
                    let repeat = opts.repeat;
                    let case = plan.add(Case {
                        mesh,
                        steps,
                        form,
                        repeat,
                    });
                    levels.push(Level { n, mesh_n, case });
                }
                by_form.push((form, levels));
            }
            plan.varies.push(VaryPlan {
                vary,
                reference,
                forms: by_form,
            });
        }
        Ok(plan)
    }

    /// The pairs (level's case, its reference's case) whose error the report measures: each
    /// needs the transfer from the first's mesh to the second's.
    pub fn errors(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.varies.iter().flat_map(|v| {
            v.forms
                .iter()
                .flat_map(|(_, levels)| levels.iter().map(|l| (l.case, v.reference.case)))
        })
    }

    /// The index of `case`, added unless an equal one is there.
    fn add(&mut self, case: Case) -> usize {
        match self.cases.iter().position(|c| *c == case) {
            Some(i) => i,
            None => {
                self.cases.push(case);
                self.cases.len() - 1
            }
        }
    }
}
