//! The two history sums of (3.1), by the left endpoint rule:
//!
//!   u_n = u_0 + k Σ_{j<n} w_j                    (displacement, "first sum")
//!   m_n = k Σ_{j<n} r(t_n − t_j) u_j             (memory, "second sum"; R(s) = r(s)·I)
//!
//! u_n is accumulated with Neumaier's compensated summation, so that it does not drift over
//! 10^5..10^6 steps. For a Prony kernel r(s) = Σ a_i e^{−b_i s} each term keeps its own state
//! m^(i)_n = k Σ_{j<n} e^{−b_i (t_n − t_j)} u_j, updated exactly in O(1) per step by
//! m^(i)_{n+1} = e^{−b_i k} (m^(i)_n + k u_n); m_n = Σ a_i m^(i)_n. Any other kernel (an
//! expression or a table) is by default compressed to a certified sum of exponentials
//! (`kernel_fit`) and then runs the same recursion; with `memory = "exact"`, or when it
//! cannot be fitted within its tolerance and the run has at most `kernel_fit::EXACT_STEPS`
//! steps, it keeps u_0..u_{n−1} and evaluates the direct sum, O(n) per step. A longer run
//! whose kernel misses its tolerance is refused (bad input naming the tolerance the fit
//! reached), never silently run in O(N²). t_n − t_j is taken as (n − j)·k exactly.
//!
//! A body whose `[[material.region]]` entries have kernels of their own has one memory sum
//! per kernel, its *memory group* g (0: `[material.relaxation]`):
//!
//!   m^(g)_n = k Σ_{j<n} r_g(t_n − t_j) u_j,   memory force Σ_g K_R^(g) m^(g)_n,
//!
//! K_R^(g) assembled on the elements of group g. Every kernel of such a body runs by the
//! recursion ([`Plans`]): its memory is one list of Prony terms, each tagged with its group,
//! and m_n is the groups' sums one after the other.

use crate::kernel::Kernel;
use crate::kernel_fit::{self, Fit, Lags};
use crate::scene::{self, Scene};
use crate::Result;

/// One Prony term a e^{−b s}: its weight, its one-step decay e^{−b k}, its state m^(i)_n,
/// and the memory group whose kernel it is a term of (0: the body's).
#[derive(Clone, Debug)]
pub struct PronyTerm {
    pub a: f64,
    pub decay: f64,
    pub m: Vec<f64>,
    pub group: usize,
}

/// The memory state of the scheme.
#[derive(Clone, Debug)]
pub enum Memory {
    /// No relaxation term (Remark 2.5: no memory state at all).
    None,
    Prony(Vec<PronyTerm>),
    /// r(l·k) for l = 1, 2, … (grown as needed) and the past displacements u_0..u_{n−1},
    /// each at the dofs the history holds.
    Direct {
        r_lag: Vec<f64>,
        past: Vec<Vec<f64>>,
    },
}

/// The bytes of the memory's vectors gathered for a checkpoint that may wait for its
/// writer (at least one vector: `History::gathered` sends them one at a time, and the
/// writer takes them as it writes them: `checkpoint::Feed`).
pub const QUEUE_BYTES: usize = 16 << 20;

/// The vectors of `width` values that may wait for the checkpoint writer.
pub fn queue_len(width: usize) -> usize {
    (QUEUE_BYTES / (8 * width.max(1))).max(1)
}

/// The bytes of `count` vectors of `width` values (Prony states, a direct sum's past rows)
/// that the process writing a checkpoint holds at most: those waiting, the one the writer
/// is writing and the one being gathered.
pub fn held_bytes(width: usize, count: usize) -> f64 {
    (8 * width) as f64 * count.min(queue_len(width) + 2) as f64
}

/// The memory a checkpoint holds, as [`Plan::resumed`] needs it.
pub enum Stored {
    /// The Prony terms (a_i, b_i) the run's recursion used.
    Terms(Vec<(f64, f64)>),
    /// The past displacements of the direct sum (or no memory at all).
    Direct,
}

/// How a run computes its memory sum, decided at setup from the scene (before any step).
#[derive(Clone, Debug)]
pub enum Plan {
    None,
    /// The scene's own Prony series.
    Prony(Vec<(f64, f64)>),
    /// An expression or table compressed to a certified Prony series.
    Compressed(Fit),
    /// The direct sum over r on the lags; `fallback` says why compression was not used when
    /// it was asked for (None: `memory = "exact"`).
    Exact {
        lags: Lags,
        fallback: Option<String>,
    },
}

/// One kernel of a scene as its plan needs it: r (None: no relaxation), how its memory sum
/// is run, and the table its keys are in.
#[derive(Clone, Copy)]
pub struct Spec<'s> {
    pub kernel: Option<&'s Kernel>,
    pub compression: Option<f64>,
    pub horizon: Option<f64>,
    pub prefix: &'s str,
}

impl<'s> Spec<'s> {
    /// `[material.relaxation]`, the body's kernel (memory group 0).
    pub fn body(scene: &'s Scene) -> Self {
        let p = &scene.physics;
        Spec {
            kernel: p.relaxation.as_ref(),
            compression: p.compression,
            horizon: p.horizon,
            prefix: scene::BODY_KERNEL,
        }
    }

    /// A region's own kernel (`Physics::region_kernels`).
    pub fn region(prefix: &'s str, r: &'s scene::Relaxation) -> Self {
        Spec {
            kernel: r.kernel.as_ref(),
            compression: r.compression,
            horizon: r.horizon,
            prefix,
        }
    }
}

impl Plan {
    /// The plan of the body's kernel, `[material.relaxation]` ([`Plan::of`]).
    pub fn new(scene: &Scene) -> Result<Plan> {
        Self::of(Spec::body(scene), scene)
    }

    /// Evaluates an expression or table kernel on every lag the run reads (r(k)..r(Nk), and
    /// r(0) for the implicit variant; a compressed kernel up to its horizon) — a non-finite
    /// value is bad input naming the key — and fits it when the scene asks for compression.
    pub fn of(spec: Spec, scene: &Scene) -> Result<Plan> {
        let Some((lags, tolerance)) = Self::lags(spec, scene)? else {
            return Ok(Self::fixed(spec));
        };
        Ok(match tolerance {
            None => Self::exact(lags, scene, None),
            Some(tolerance) => match kernel_fit::fit(&lags, tolerance) {
                Ok(fit) => Plan::Compressed(fit),
                Err(why) if scene.time.steps > kernel_fit::EXACT_STEPS => {
                    return Err(crate::Error::input(format!(
                        "{}: key '{}.tolerance': the kernel cannot be compressed within \
                         {tolerance:e}: {why}. It is not run by the direct sum instead: its \
                         time.steps = {} exceed {} (the direct sum keeps every step's \
                         displacement, 8·dofs·N bytes, and takes O(N²·dofs) time); memory = \
                         \"exact\" runs it anyway",
                        scene.path.display(),
                        spec.prefix,
                        scene.time.steps,
                        kernel_fit::EXACT_STEPS
                    )))
                }
                Err(why) => Self::exact(lags, scene, Some(why)),
            },
        })
    }

    /// The plan of a run resumed from a checkpoint whose memory is `stored`: the memory the
    /// run started with, whatever the end time now. A compressed run continues with its own
    /// fit (the term states belong to it; nothing is stored to refit from), certified again on
    /// every lag up to the scene's end — the same lags without `--set time.end`, more with it.
    /// Where the fit leaves the tolerance on the new lags the resume is refused, naming the
    /// latest end time it still covers. A run that kept its past displacements continues the
    /// direct sum.
    pub fn resumed(spec: Spec, scene: &Scene, stored: Stored) -> Result<Plan> {
        let Some((lags, tolerance)) = Self::lags(spec, scene)? else {
            return Ok(Self::fixed(spec));
        };
        Ok(match (tolerance, stored) {
            (Some(tolerance), Stored::Terms(terms)) => {
                let start = std::time::Instant::now();
                let (error, within) = kernel_fit::certify(&lags, &terms, tolerance);
                if error > tolerance {
                    let t_ok = within.map_or(0.0, |l| l as f64 * lags.k);
                    return Err(crate::Error::input(format!(
                        "cannot continue this compressed run to T = {}: its kernel fit ({} \
                         terms, fitted on the lags of the run as it started) is off by {error:.2e} \
                         (relative) on the lags up to T, above the tolerance {tolerance:e}, and \
                         the checkpoint keeps no past displacements to fit again from. The fit \
                         holds up to t = {t_ok}: resume with --set time.end ≤ {t_ok}, or run \
                         the scene again from the start with [{}] horizon = {} (the latest \
                         end time its fit must cover)",
                        scene.time.end,
                        terms.len(),
                        spec.prefix,
                        scene.time.end
                    )));
                }
                Plan::Compressed(Fit {
                    terms,
                    error,
                    last_lag: lags.last(),
                    seconds: start.elapsed().as_secs_f64(),
                })
            }
            (Some(_), Stored::Direct) => Self::exact(
                lags,
                scene,
                Some(
                    "the run used the direct sum from its start (its kernel was not fitted \
                     within the tolerance then); it continues with the stored past \
                     displacements"
                        .into(),
                ),
            ),
            // memory = "exact"; a checkpoint whose memory kind differs is refused when it
            // is restored.
            _ => Self::exact(lags, scene, None),
        })
    }

    /// The direct sum on the run's own lags (`lags` may reach further, to a fit's horizon).
    fn exact(mut lags: Lags, scene: &Scene, fallback: Option<String>) -> Plan {
        lags.truncate(scene.time.steps);
        Plan::Exact { lags, fallback }
    }

    /// The plan of a kernel that is absent or a Prony series.
    fn fixed(spec: Spec) -> Plan {
        match spec.kernel {
            Some(Kernel::Prony(terms)) => Plan::Prony(terms.clone()),
            _ => Plan::None,
        }
    }

    /// For an expression or table kernel: r on every lag the run reads, and the tolerance of
    /// its compression (None: `memory = "exact"`); None for the other kernels.
    fn lags(spec: Spec, scene: &Scene) -> Result<Option<(Lags, Option<f64>)>> {
        let kernel = match spec.kernel {
            None | Some(Kernel::Prony(_)) => return Ok(None),
            Some(kernel) => kernel,
        };
        let key = match kernel {
            Kernel::Table(..) => format!("{}.table", spec.prefix),
            _ => format!("{}.expr", spec.prefix),
        };
        let implicit = scene.solver.history == scene::History::Implicit;
        // A compressed kernel is fitted up to its horizon, which a resume may extend the run
        // to (the scene checks horizon ≥ time.end).
        let steps = match (spec.compression, spec.horizon) {
            (Some(_), Some(h)) => scene
                .time
                .steps
                .max((h / scene.time.k() - 1e-9).ceil() as usize),
            _ => scene.time.steps,
        };
        let lags = Lags::new(kernel, scene.time.k(), steps, implicit, &key)
            .map_err(|e| crate::Error::input(format!("{}: {e}", scene.path.display())))?;
        Ok(Some((lags, spec.compression)))
    }

    /// The Prony series the recursion runs, if any.
    pub fn prony(&self) -> Option<&[(f64, f64)]> {
        match self {
            Plan::Prony(terms) => Some(terms),
            Plan::Compressed(fit) => Some(&fit.terms),
            _ => None,
        }
    }

    /// r(0) as the run uses it (the implicit variant's newest memory weight).
    pub fn r0(&self, kernel: Option<&Kernel>) -> Option<f64> {
        match self {
            Plan::None => None,
            Plan::Compressed(fit) => Some(fit.terms.iter().map(|t| t.0).sum()),
            _ => kernel.map(|k| k.eval(0.0)),
        }
    }
}

/// How a run computes the memory sums of its memory groups: the body's kernel (group 0,
/// `[material.relaxation]`) and each region's own (group g ≥ 1, `Physics::region_kernels`).
/// A body with region kernels runs every kernel by the O(1) recursion (Prony or
/// compressed): all its memory is one list of Prony terms, each tagged with its group.
#[derive(Clone, Debug)]
pub struct Plans {
    pub body: Plan,
    pub regions: Vec<Plan>,
}

impl Plans {
    /// The plans of `scene`'s kernels ([`Plan::of`]); a kernel run by the direct sum in a body
    /// with region kernels is refused.
    pub fn new(scene: &Scene) -> Result<Plans> {
        let body = Plan::new(scene)?;
        let regions = (scene.physics.region_kernels().iter())
            .map(|(prefix, r)| Plan::of(Spec::region(prefix, r), scene))
            .collect::<Result<Vec<_>>>()?;
        Self::checked(scene, body, regions)
    }

    /// The plans of a resumed run, from the Prony terms `stored` of each group (or the
    /// direct sum's memory, for the body alone): [`Plan::resumed`] for each kernel.
    pub fn resumed(scene: &Scene, mut stored: Vec<Stored>) -> Result<Plans> {
        let kernels = scene.physics.region_kernels();
        stored.resize_with(1 + kernels.len(), || Stored::Terms(Vec::new()));
        let mut stored = stored.into_iter();
        let body = Plan::resumed(Spec::body(scene), scene, stored.next().expect("group 0"))?;
        let regions = (kernels.iter().zip(stored))
            .map(|((prefix, r), s)| Plan::resumed(Spec::region(prefix, r), scene, s))
            .collect::<Result<Vec<_>>>()?;
        Self::checked(scene, body, regions)
    }

    /// Refuses a direct sum beside region kernels: the memory of several kernels is kept as
    /// Prony terms only (the direct sum's past displacements are one history file).
    fn checked(scene: &Scene, body: Plan, regions: Vec<Plan>) -> Result<Plans> {
        let direct = std::iter::once(&body)
            .chain(&regions)
            .position(|p| matches!(p, Plan::Exact { .. }));
        match direct {
            Some(g) if !regions.is_empty() => {
                let kernels = scene.physics.region_kernels();
                let prefix = match g {
                    0 => scene::BODY_KERNEL.to_string(),
                    g => kernels[g - 1].0.clone(),
                };
                Err(crate::Error::input(format!(
                    "{}: key '{prefix}.memory': this kernel would run by the direct sum, but a \
                     body whose regions have kernels of their own runs each by the O(1) \
                     recursion: give a Prony series, or an 'expr' or 'table' compressed \
                     (memory = \"compressed\", the default) within its tolerance",
                    scene.path.display()
                )))
            }
            _ => Ok(Plans { body, regions }),
        }
    }

    /// The plan of memory group g.
    pub fn group(&self, g: usize) -> &Plan {
        match g {
            0 => &self.body,
            g => &self.regions[g - 1],
        }
    }

    /// The number of memory groups.
    pub fn groups(&self) -> usize {
        1 + self.regions.len()
    }

    /// The Prony terms of every group, each of which keeps a state at every dof.
    pub fn terms(&self) -> usize {
        (0..self.groups())
            .map(|g| self.group(g).prony().map_or(0, <[_]>::len))
            .sum()
    }

    /// Whether the body's memory is the direct sum, which keeps every step's displacement.
    pub fn direct(&self) -> bool {
        matches!(self.body, Plan::Exact { .. })
    }

    /// r_g(0) of each group as the run uses it (None: a group without memory).
    pub fn r0(&self, scene: &Scene) -> Vec<Option<f64>> {
        let kernels = scene.physics.region_kernels();
        let body = self.body.r0(scene.physics.relaxation.as_ref());
        let regions =
            (self.regions.iter().zip(&kernels)).map(|(p, (_, r))| p.r0(r.kernel.as_ref()));
        std::iter::once(body).chain(regions).collect()
    }
}

/// A time loop at t_n, before step n is solved: its history and the last solved step's w
/// and multipliers (the next solve's warm start). What a checkpoint saves
/// (`TimeLoop::state`); everything else of the loop is rebuilt from the scene.
pub struct LoopState<'a> {
    /// n, k and the memory's kind; its values come one vector at a time
    /// (`TimeLoop::gather_memory`).
    pub history: &'a History,
    /// u_n, its compensated sum (`History::u_sum`, `u_comp`) and w_n, at every dof.
    pub u: Vec<f64>,
    pub u_sum: Vec<f64>,
    pub u_comp: Vec<f64>,
    pub w: Vec<f64>,
    /// The multipliers of the last solved step and of the step before it.
    pub z: &'a [f64],
    pub z_before: &'a [f64],
}

/// A [`LoopState`] as a checkpoint gives it back (`TimeLoop::restore`).
#[derive(Debug)]
pub struct SavedLoop {
    pub history: SavedHistory,
    pub w: Vec<f64>,
    pub z: Vec<f64>,
    pub z_before: Vec<f64>,
}

/// Where a rank holds each vector of a loop's state, each at the dofs given (increasing;
/// None: at every dof): what a resume reads of a checkpoint (`Checkpoint::saved`), so that
/// a follower rank never holds the whole of one of them.
#[derive(Clone, Copy, Debug, Default)]
pub struct HeldAt<'a> {
    /// u_n and its compensated sum.
    pub u: Option<&'a [usize]>,
    /// The memory: the Prony states, the direct sum's past displacements.
    pub memory: Option<&'a [usize]>,
    /// w_n.
    pub w: Option<&'a [usize]>,
}

/// A history as a checkpoint saved it, each vector at the dofs the history holds it
/// ([`History::held_at`]), for [`History::restore`].
#[derive(Debug)]
pub struct SavedHistory {
    pub n: usize,
    pub k: f64,
    pub u: Vec<f64>,
    pub u_sum: Vec<f64>,
    pub u_comp: Vec<f64>,
    pub memory: SavedMemory,
}

/// The memory state a checkpoint saved.
#[derive(Debug)]
pub enum SavedMemory {
    None,
    /// The Prony terms with their weights, one-step decays and states.
    Prony(Vec<PronyTerm>),
    /// The past displacements u_0..u_{n−1} of the direct sum.
    Direct(Vec<Vec<f64>>),
}

/// Why a checkpoint's stored memory (`what` it is) cannot continue this scene's.
pub fn memory_mismatch(what: &str) -> String {
    format!(
        "the stored memory is {what}, which the scene's relaxation kernel does not match: \
         the checkpoint does not belong to this scene"
    )
}

/// The state carried from step to step: n, u_n (compensated) and the memory.
///
/// On a rank of several (docs/cluster.md) the history holds some dofs alone ([`Holds`]):
/// the memory those that the rank's rows of Σ_g K_R^(g) m^(g)_n and its piece of a frame
/// read (on rank 0, history.csv's reactions too), and where the rank's matrices number
/// their rows over its own dofs' neighbours, u_n and its compensated sum those too. Each
/// value there is updated by the same arithmetic dof by dof, so it has the bits of the
/// whole history's. Rank 0 holds every dof where the frames are not in pieces (it computes
/// every cell's stress then); a checkpoint gathers each rank's values at its own rows
/// into the whole vectors (`TimeLoop::state`, [`History::gathered`]).
#[derive(Clone, Debug)]
pub struct History {
    pub k: f64,
    /// The current step index n: `u` holds u_n and `memory` gives m_n.
    pub n: usize,
    /// u_n = sum + compensation.
    pub u: Vec<f64>,
    /// Neumaier compensation of the running sum (the rounding error not yet in `u_sum`).
    pub u_comp: Vec<f64>,
    pub u_sum: Vec<f64>,
    pub memory: Memory,
    /// The dofs this history holds.
    pub holds: Holds,
}

/// The dofs whose values a [`History`] holds, in increasing order where not every one.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Holds {
    /// Every dof: one process, and rank 0 of several whose frames are not in pieces.
    #[default]
    Every,
    /// The memory at these dofs alone and u_n at every one: a follower whose rows of K_B
    /// and K_R read u_n by the whole numbering (`Discretization::memory_reach`).
    Memory(Vec<usize>),
    /// u_n, its compensated sum and the memory at these dofs alone, in their order: a
    /// follower whose rows of K_B and K_R number their columns over them
    /// (`Discretization::number_rows_over`).
    Local(Vec<usize>),
}

impl Holds {
    /// The dofs the memory holds (None: every one).
    pub fn dofs(&self) -> Option<&[usize]> {
        match self {
            Holds::Every => None,
            Holds::Memory(dofs) | Holds::Local(dofs) => Some(dofs),
        }
    }

    /// The dofs of u_n at which the memory's values lie, where u_n holds others too.
    fn memory_in_u(&self) -> Option<&[usize]> {
        match self {
            Holds::Memory(dofs) => Some(dofs),
            Holds::Every | Holds::Local(_) => None,
        }
    }

    /// The dofs at which u_n is held, where not at every one.
    pub fn local(&self) -> Option<&[usize]> {
        match self {
            Holds::Local(dofs) => Some(dofs),
            Holds::Every | Holds::Memory(_) => None,
        }
    }
}

impl History {
    /// The state at n = 0: u_0 = 0 (the paper's example; the initial displacement is zero)
    /// and m_0 = 0, for the memory groups of `plans`.
    pub fn new(n_free: usize, k: f64, plans: &Plans) -> Self {
        Self::holding(n_free, k, plans, Holds::Every)
    }

    /// [`History::new`] holding the dofs `holds` says.
    pub fn holding(n_free: usize, k: f64, plans: &Plans, holds: Holds) -> Self {
        let n_kept = holds.dofs().map_or(n_free, <[usize]>::len);
        let n_u = holds.local().map_or(n_free, <[usize]>::len);
        let terms: Vec<PronyTerm> = (0..plans.groups())
            .flat_map(|g| {
                plans
                    .group(g)
                    .prony()
                    .unwrap_or(&[])
                    .iter()
                    .map(move |t| (g, t))
            })
            .map(|(group, &(a, b))| PronyTerm {
                a,
                decay: (-b * k).exp(),
                m: vec![0.0; n_kept],
                group,
            })
            .collect();
        let memory = match plans.body {
            Plan::Exact { .. } => Memory::Direct {
                r_lag: Vec::new(),
                past: Vec::new(),
            },
            _ if terms.is_empty() => Memory::None,
            _ => Memory::Prony(terms),
        };
        History {
            k,
            n: 0,
            u: vec![0.0; n_u],
            u_comp: vec![0.0; n_u],
            u_sum: vec![0.0; n_u],
            memory,
            holds,
        }
    }

    pub fn has_memory(&self) -> bool {
        !matches!(self.memory, Memory::None)
    }

    /// The dofs at which u_n and the memory (the Prony states, the direct sum's past rows)
    /// are held (None: every one): a resume reads them there alone (`Checkpoint::saved`).
    pub fn held_at(&self) -> HeldAt<'_> {
        HeldAt {
            u: self.holds.local(),
            memory: self.holds.dofs(),
            w: None,
        }
    }

    /// The memory as a checkpoint saves it, every dof's, one vector at a time into `each`
    /// (in the file's order: the Prony states term by term, or a direct sum's past rows
    /// `from..`, those the checkpoints hold not yet), on one process and on rank 0 of
    /// several whose ranks hold their parts of it (`each` is never called on the others):
    /// `whole` makes the every-dof vector there of a vector held at some dofs
    /// (`TimeLoop::gathered`, collective: every rank calls this at every checkpoint).
    /// One vector at a time, so that the process that writes the checkpoint never holds the
    /// whole memory twice (`checkpoint::Feed`).
    pub fn gathered(
        &self,
        from: usize,
        whole: impl Fn(&[f64], Option<&[usize]>) -> Result<Option<Vec<f64>>>,
        each: &mut dyn FnMut(Vec<f64>),
    ) -> Result<()> {
        let mut send = |held: &[f64]| -> Result<()> {
            if let Some(v) = whole(held, self.holds.dofs())? {
                each(v);
            }
            Ok(())
        };
        match &self.memory {
            Memory::None => Ok(()),
            Memory::Prony(terms) => terms.iter().try_for_each(|t| send(&t.m)),
            Memory::Direct { past, .. } => past[from.min(past.len())..]
                .iter()
                .try_for_each(|row| send(row)),
        }
    }

    /// m_n of every memory group into `out` (overwritten), group g's at g·len(u_n), at the
    /// dofs of u_n (the body's kernel `kernel` is the direct sum's). Returns false (and
    /// leaves `out` alone) without memory.
    pub fn memory_into(&mut self, kernel: Option<&Kernel>, out: &mut [f64]) -> bool {
        match &mut self.memory {
            Memory::None => false,
            Memory::Prony(terms) => {
                out.fill(0.0);
                let n = self.u.len();
                for term in terms.iter() {
                    let out = &mut out[term.group * n..][..n];
                    add_at(out, self.holds.memory_in_u(), term.a, &term.m);
                }
                true
            }
            Memory::Direct { r_lag, past } => {
                let kernel = kernel.expect("a direct-sum memory has a kernel");
                let n = self.n;
                while r_lag.len() < n {
                    let l = r_lag.len() + 1;
                    r_lag.push(kernel.eval(l as f64 * self.k));
                }
                out.fill(0.0);
                // m_n = k Σ_{j<n} r((n − j) k) u_j, at every dof a row holds.
                let dofs = self.holds.memory_in_u();
                for (j, uj) in past.iter().enumerate() {
                    add_at(out, dofs, self.k * r_lag[n - j - 1], uj);
                }
                true
            }
        }
    }

    /// Takes back a saved history into this one, freshly built from the same scene (a
    /// resume): the memory must be of the kind this one plans, with the same Prony weights
    /// and, up to the rounding of e^{−b k}, the same decays. Its vectors are this history's
    /// dofs' ([`History::held_at`]: the checkpoint read them there).
    pub fn restore(&mut self, saved: SavedHistory) -> Result<()> {
        let mismatch = |what: &str| crate::Error::input(memory_mismatch(what));
        let u = [&saved.u, &saved.u_sum, &saved.u_comp];
        if u.iter().any(|v| v.len() != self.u.len()) {
            return Err(mismatch("held at other dofs than this rank's"));
        }
        match (&mut self.memory, saved.memory) {
            (Memory::None, SavedMemory::None) => {}
            (Memory::Prony(terms), SavedMemory::Prony(stored)) => {
                if terms.len() != stored.len() {
                    return Err(mismatch(&format!("{} Prony terms", stored.len())));
                }
                for (i, (t, s)) in terms.iter_mut().zip(stored).enumerate() {
                    // decay = exp(−b k) is recomputed by History::new from the scene's b and
                    // the same k: equal bits unless the kernel changed.
                    let expected = (t.decay.ln() / self.k) * saved.k;
                    if t.a.to_bits() != s.a.to_bits()
                        || t.group != s.group
                        || (expected.exp() - s.decay).abs() > 1e-12 * s.decay.abs()
                    {
                        return Err(mismatch(&format!(
                            "term {i}: a = {}, exp(-b k) = {}",
                            s.a, s.decay
                        )));
                    }
                    if s.m.len() != t.m.len() {
                        return Err(mismatch(&format!("term {i} of the wrong size")));
                    }
                    *t = s;
                }
            }
            (Memory::Direct { past, r_lag }, SavedMemory::Direct(rows)) => {
                let n_kept = self.holds.dofs().map_or(self.u.len(), <[usize]>::len);
                if rows.iter().any(|row| row.len() != n_kept) {
                    return Err(mismatch("a past row of the wrong size"));
                }
                *past = rows;
                r_lag.clear();
            }
            (_, SavedMemory::None) => return Err(mismatch("absent (no relaxation)")),
            (_, SavedMemory::Prony(_)) => return Err(mismatch("a Prony series")),
            (_, SavedMemory::Direct(_)) => return Err(mismatch("a general kernel's direct sum")),
        }
        self.k = saved.k;
        self.n = saved.n;
        self.u = saved.u;
        self.u_sum = saved.u_sum;
        self.u_comp = saved.u_comp;
        Ok(())
    }

    /// n → n + 1 with the velocity w_n, held at the dofs `held` alone where given
    /// (increasing, among which u_n's are: a follower's, `time_loop`), else whole:
    /// u_{n+1} = u_n + k w_n, and the memory update.
    pub fn advance(&mut self, w: &[f64], held: Option<&[usize]>) {
        let k = self.k;
        // The memory of step n + 1 uses u_n, so update it before u.
        match &mut self.memory {
            Memory::None => {}
            Memory::Prony(terms) => {
                for term in terms.iter_mut() {
                    // m^(i)_{n+1} = e^{−b_i k} (m^(i)_n + k u_n)
                    let decay = term.decay;
                    let next = |m: &mut f64, u: f64| *m = decay * (*m + k * u);
                    match self.holds.memory_in_u() {
                        None => (term.m.iter_mut().zip(&self.u)).for_each(|(m, &u)| next(m, u)),
                        Some(dofs) => {
                            (term.m.iter_mut().zip(dofs)).for_each(|(m, &i)| next(m, self.u[i]))
                        }
                    }
                }
            }
            Memory::Direct { past, .. } => past.push(at(self.holds.memory_in_u(), &self.u)),
        }
        let u = (&mut self.u[..], &mut self.u_sum[..], &mut self.u_comp[..]);
        match self.holds.local() {
            None => add_compensated(k, u, w.iter().copied()),
            Some(dofs) => add_compensated(k, u, places(dofs, held).map(|p| w[p])),
        }
        self.n += 1;
    }
}

/// The places of the dofs `dofs` (increasing) in a vector held at the dofs `held` alone
/// (increasing, among which they are), or in a whole one: one walk along both.
fn places<'a>(dofs: &'a [usize], held: Option<&'a [usize]>) -> impl Iterator<Item = usize> + 'a {
    let mut at = 0;
    dofs.iter().map(move |&i| match held {
        None => i,
        Some(held) => {
            at += held[at..].partition_point(|&d| d < i);
            at
        }
    })
}

/// (sum, comp) += k w and u = sum + comp, entry by entry, by Neumaier's compensated sum:
/// the rounding error not yet in `sum` goes on in `comp`.
fn add_compensated(
    k: f64,
    (u, sum, comp): (&mut [f64], &mut [f64], &mut [f64]),
    w: impl Iterator<Item = f64>,
) {
    let state = u.iter_mut().zip(sum.iter_mut().zip(comp));
    for ((u, (sum, comp)), wi) in state.zip(w) {
        let x = k * wi;
        let t = *sum + x;
        *comp += if sum.abs() >= x.abs() {
            (*sum - t) + x
        } else {
            (x - t) + *sum
        };
        *sum = t;
        *u = t + *comp;
    }
}

/// The values of the whole vector `v` at the dofs `kept` (all of it without).
pub(crate) fn at(kept: Option<&[usize]>, v: &[f64]) -> Vec<f64> {
    match kept {
        None => v.to_vec(),
        Some(kept) => kept.iter().map(|&i| v[i]).collect(),
    }
}

/// out_i += c v_i, where v holds the values at the dofs `kept` in their order (all of
/// `out` without).
fn add_at(out: &mut [f64], kept: Option<&[usize]>, c: f64, v: &[f64]) {
    match kept {
        None => (out.iter_mut().zip(v)).for_each(|(o, v)| *o += c * v),
        Some(kept) => (kept.iter().zip(v)).for_each(|(&i, v)| out[i] += c * v),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The plans of a body without region kernels.
    fn alone(body: Plan) -> Plans {
        Plans {
            body,
            regions: Vec::new(),
        }
    }

    /// A kernel r(s) = 1/(1+s) and two plans at step k: a recursion of two memory groups
    /// (the body's two terms, a region's one) and r's direct sum over 60 lags.
    fn two_groups_and_direct(k: f64) -> (Kernel, [Plans; 2]) {
        let two = Plans {
            body: Plan::Prony(vec![(1.0, 10.0), (0.5, 3.0)]),
            regions: vec![Plan::Prony(vec![(2.0, 1.0)])],
        };
        let kernel = Kernel::Expr(Box::new(
            crate::expr::Expr::parse("1/(1+s)", &["s"], "r").unwrap(),
        ));
        let exact = alone(Plan::Exact {
            lags: Lags::new(&kernel, k, 60, false, "r").unwrap(),
            fallback: None,
        });
        (kernel, [two, exact])
    }

    /// The state a checkpoint saves of the whole history `h`, as a resume reads it at the
    /// dofs `held` (`Checkpoint::saved`).
    fn saved(h: &History, held: HeldAt) -> SavedHistory {
        let memory = |v: &[f64]| at(held.memory, v);
        SavedHistory {
            n: h.n,
            k: h.k,
            u: at(held.u, &h.u),
            u_sum: at(held.u, &h.u_sum),
            u_comp: at(held.u, &h.u_comp),
            memory: match &h.memory {
                Memory::None => SavedMemory::None,
                Memory::Prony(terms) => SavedMemory::Prony(
                    (terms.iter())
                        .map(|t| PronyTerm {
                            m: memory(&t.m),
                            ..t.clone()
                        })
                        .collect(),
                ),
                Memory::Direct { past, .. } => {
                    SavedMemory::Direct(past.iter().map(|row| memory(row)).collect())
                }
            },
        }
    }

    #[test]
    fn each_group_sums_its_own_kernel() {
        // Group 0: r = e^{−10s}; group 1: r = 0.5 e^{−3s} + 2 e^{−s}; each against the
        // history of its kernel alone.
        let k = 0.01;
        let one = vec![(1.0, 10.0)];
        let two = vec![(0.5, 3.0), (2.0, 1.0)];
        let both = Plans {
            body: Plan::Prony(one.clone()),
            regions: vec![Plan::Compressed(Fit {
                terms: two.clone(),
                error: 0.0,
                last_lag: 0,
                seconds: 0.0,
            })],
        };
        let mut h = History::new(2, k, &both);
        let mut h0 = History::new(2, k, &alone(Plan::Prony(one)));
        let mut h1 = History::new(2, k, &alone(Plan::Prony(two)));
        let (mut m, mut m0, mut m1) = (vec![0.0; 4], vec![0.0; 2], vec![0.0; 2]);
        for n in 0..50 {
            let w = [(n as f64 * 0.3).cos(), 0.1 * n as f64];
            assert!(h.memory_into(None, &mut m));
            assert!(h0.memory_into(None, &mut m0) && h1.memory_into(None, &mut m1));
            assert_eq!(m, [m0.clone(), m1.clone()].concat(), "n = {n}");
            for h in [&mut h, &mut h0, &mut h1] {
                h.advance(&w, None);
            }
        }
        assert!(m[2..].iter().all(|&x| x != 0.0) && m[..2] != m[2..]);
    }

    #[test]
    fn prony_recursion_equals_direct_sum() {
        let k = 0.01;
        let prony = Kernel::Prony(vec![(1.0, 10.0), (0.5, 3.0)]);
        let table_like = Kernel::Expr(Box::new(
            crate::expr::Expr::parse("exp(-10*s) + 0.5*exp(-3*s)", &["s"], "r").unwrap(),
        ));
        let mut hp = History::new(3, k, &alone(Plan::Prony(vec![(1.0, 10.0), (0.5, 3.0)])));
        let exact = Plan::Exact {
            lags: Lags::new(&table_like, k, 200, false, "r").unwrap(),
            fallback: None,
        };
        let mut hd = History::new(3, k, &alone(exact));
        let (mut mp, mut md) = (vec![0.0; 3], vec![0.0; 3]);
        for n in 0..200 {
            let w = [(n as f64 * 0.1).sin(), 1.0, -0.5 * n as f64];
            assert!(hp.memory_into(Some(&prony), &mut mp));
            assert!(hd.memory_into(Some(&table_like), &mut md));
            for i in 0..3 {
                let scale = md[i].abs().max(1e-300);
                assert!(
                    (mp[i] - md[i]).abs() <= 1e-12 * scale.max(1e-12),
                    "n={n} {mp:?} {md:?}"
                );
            }
            hp.advance(&w, None);
            hd.advance(&w, None);
        }
    }

    #[test]
    fn a_history_holding_some_dofs_has_their_bits_of_the_whole_one() {
        // A follower rank's history (`Holds`) against the whole one, step after step and
        // across a restore from the whole history's saved state, for the recursion (two
        // groups) and the direct sum: holding the memory alone, the same m_n bits at its
        // dofs and 0 elsewhere; holding u_n too, the same u_n and m_n bits at its dofs.
        let k = 0.01;
        let (kernel, [two, exact]) = two_groups_and_direct(k);
        let dofs = vec![0, 2, 3];
        for plans in [two, exact] {
            let groups = plans.groups();
            for holds in [Holds::Memory(dofs.clone()), Holds::Local(dofs.clone())] {
                let local = holds.local().is_some();
                let mut whole = History::new(4, k, &plans);
                let mut part = History::holding(4, k, &plans, holds.clone());
                let mut m = vec![0.0; 4 * groups];
                let mut mp = vec![0.0; if local { 3 } else { 4 } * groups];
                for n in 0..60 {
                    if n == 30 {
                        part = History::holding(4, k, &plans, holds.clone());
                        part.restore(saved(&whole, part.held_at())).unwrap();
                    }
                    assert!(whole.memory_into(Some(&kernel), &mut m));
                    assert!(part.memory_into(Some(&kernel), &mut mp));
                    let (expected_m, expected_u): (Vec<f64>, Vec<f64>) = match local {
                        true => (
                            (0..groups)
                                .flat_map(|g| dofs.iter().map(move |&i| 4 * g + i))
                                .map(|i| m[i])
                                .collect(),
                            dofs.iter().map(|&i| whole.u[i]).collect(),
                        ),
                        false => (
                            (m.iter().enumerate())
                                .map(|(i, &a)| if i % 4 == 1 { 0.0 } else { a })
                                .collect(),
                            whole.u.clone(),
                        ),
                    };
                    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&mp), bits(&expected_m), "n = {n}, {holds:?}");
                    assert_eq!(bits(&part.u), bits(&expected_u), "n = {n}, {holds:?}");
                    let w = [(n as f64 * 0.3).cos(), 1.0, -0.5 * n as f64, 0.25];
                    whole.advance(&w, None);
                    // A follower's w_n is held at its u_n's dofs, and maybe others' too.
                    let held: &[usize] = if n % 2 == 0 { &dofs } else { &[0, 1, 2, 3] };
                    let w_held: Vec<f64> = held.iter().map(|&i| w[i]).collect();
                    part.advance(if local { &w_held } else { &w }, local.then_some(held));
                }
                assert!(m.iter().all(|&x| x != 0.0));
            }
        }
    }

    #[test]
    fn the_ranks_parts_gathered_are_the_whole_memory_with_its_bits() {
        // Two ranks' histories holding the memory at their reach alone (`Holds::Memory`),
        // rank 0 the prescribed dof 5 too, against one process's, for the recursion (two
        // groups) and the direct sum: what a checkpoint gathers at irregular steps (each
        // rank's values at its own rows, `History::gathered`) has the whole memory's bits,
        // of a direct sum the rows after the last checkpoint's alone, and a restore from it
        // goes on with the same bits.
        let k = 0.01;
        let (_, [two, exact]) = two_groups_and_direct(k);
        // Five unknowns and a prescribed dof; rank 0 owns 0, 3 and 4, rank 1 owns 1 and 2.
        let (own, reach) = (
            [vec![0, 3, 4], vec![1, 2]],
            [vec![0, 1, 3, 4, 5], vec![1, 2, 3]],
        );
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for plans in [two, exact] {
            let holding =
                |r: usize| History::holding(6, k, &plans, Holds::Memory(reach[r].clone()));
            let mut whole = History::new(6, k, &plans);
            let mut ranks = [holding(0), holding(1)];
            let mut from = 0;
            for n in 0..40 {
                let w = [(n as f64 * 0.3).cos(), 1.0, -0.5 * n as f64, 0.25, 0.1, 2.0];
                for h in ranks.iter_mut().chain([&mut whole]) {
                    h.advance(&w, None);
                }
                if ![3, 10, 11, 25, 30].contains(&n) {
                    continue;
                }
                // Rank 1's values at its own rows, then rank 0's and the whole vector.
                let sent = std::cell::RefCell::new(std::collections::VecDeque::new());
                // What `TimeLoop::gathered` reads of a rank's vector: its values at its own
                // rows' places, and rank 0's at the prescribed dof.
                let place =
                    |at: Option<&[usize]>, i| at.map_or(i, |at| at.binary_search(&i).unwrap());
                let value = |held: &[f64], at: Option<&[usize]>, i| held[place(at, i)];
                let of_1 = |held: &[f64], at: Option<&[usize]>| {
                    let mine = own[1].iter().map(|&i| value(held, at, i)).collect();
                    sent.borrow_mut().push_back(mine);
                    Ok(None)
                };
                let none = &mut |_: Vec<f64>| unreachable!("rank 1 gets no vector");
                ranks[1].gathered(from, of_1, none).unwrap();
                let of_0 = |held: &[f64], at: Option<&[usize]>| {
                    let theirs: Vec<f64> = sent.borrow_mut().pop_front().unwrap();
                    let mut v = vec![0.0; 6];
                    own[0]
                        .iter()
                        .chain([&5])
                        .for_each(|&i| v[i] = value(held, at, i));
                    own[1].iter().zip(theirs).for_each(|(&i, x)| v[i] = x);
                    Ok(Some(v))
                };
                let mut got = Vec::new();
                ranks[0].gathered(from, of_0, &mut |v| got.push(v)).unwrap();
                let expected: Vec<Vec<f64>> = match &whole.memory {
                    Memory::Prony(terms) => terms.iter().map(|t| t.m.clone()).collect(),
                    Memory::Direct { past, .. } => past[from..].to_vec(),
                    Memory::None => unreachable!("both plans have memory"),
                };
                assert_eq!(got.len(), expected.len(), "n = {n}");
                for (g, e) in got.iter().zip(&expected) {
                    assert_eq!(bits(g), bits(e), "n = {n}");
                }
                from = whole.n;
                if n == 25 {
                    // A resume on rank 1 from the whole saved state goes on as before.
                    ranks[1] = holding(1);
                    ranks[1].restore(saved(&whole, ranks[1].held_at())).unwrap();
                }
            }
        }
    }

    #[test]
    fn compensated_sum_is_exact_for_constant_velocity() {
        // k = 0.1 is not a binary fraction: plain summation of 10^5 terms drifts visibly.
        let (k, n) = (0.1, 100_000);
        let mut h = History::new(1, k, &alone(Plan::None));
        let mut plain = 0.0f64;
        for _ in 0..n {
            h.advance(&[1.0], None);
            plain += k;
        }
        let exact = 10_000.0;
        assert!(
            (h.u[0] - exact).abs() <= 2.0 * f64::EPSILON * exact,
            "{}",
            h.u[0]
        );
        assert!(
            (plain - exact).abs() > 1e3 * f64::EPSILON * exact,
            "{plain}"
        );
    }
}
