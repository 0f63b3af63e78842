//! The MPI ranks of a run: `mpirun -n N viscontact run …` (or `srun`) in a build with the
//! `petsc` feature. Without a launcher, or with one process, a run is one rank and nothing
//! here calls MPI.
//!
//! # What spreads, and what each rank holds
//!
//! PETSc's Krylov solves spread, K_A's and the active set's Newton systems: their KSPs on
//! all the ranks, each holding the rows of the nodes METIS's partition gives it
//! (`petsc::Layout`), of which it makes the Newton matrix, its part of GAMG's hierarchy and
//! of every Krylov vector, and each getting the solution back where it reads it (its
//! rows' neighbours, Γ3's unknowns, a rank's history's reach: `petsc::Exchange`; the
//! whole once a step where a rank's history holds every dof), and of a product with K,
//! the active set's (K + S) w, its values at Γ3's nodes alone. Every rank reads the
//! scene; rank 0 alone reads the mesh file, and hands the mesh to the others during their
//! setup (`mesh.rs`: a follower never holds the file's bytes nor the reader's arrays),
//! and alone partitions the nodes among the ranks (`petsc::Layout::of_first`: a follower
//! never builds the nodes' graph nor runs METIS). Where the scene's keys take PETSc, the
//! followers get the mesh without its cells, and then each its part of them alone, those
//! its assembly reads (its own nodes'), with their materials
//! (`Ranks::cells_of_first`); what only the whole mesh shows (the body's parts, regions
//! that overlap) is rank 0's to check. Of
//! K_A, K_B and K_R a rank holds the columns of its own unknowns alone (a symmetric
//! matrix's column is its row): it assembles only those ([`Ranks::discretize`]) where the
//! scene's keys take PETSc, or keeps them of the whole matrices
//! (`Discretization::keep_columns`) where `auto`'s choice read the whole K_A. It computes
//! its entries of the right side's products from them and gets the others' where it
//! reads them (`Backend::share`), as of the step matrix's diagonal at Γ3's unknowns, which
//! the active set's ρ reads (`effects::step_solver`); where K_A is the step matrix its rows
//! go to PETSc ([`Own`]), and the rank keeps K_A's diagonal at its own of Γ3's unknowns
//! alone, and makes its rows of K_B and
//! K_R^(0), paired, only once PETSc's setup (where a rank of a few peaks) is done, from its cells
//! with one of its own nodes, where the scene has elasticity and one memory group
//! (`fem::PairWhen`). A follower's history holds the
//! dofs that its rows of K_B and K_R and its piece of a frame read alone
//! ([`Ranks::hold_history`], `history::Holds`): u_n, its compensated sum and the memory (the
//! Prony states, the direct sum's past displacements) where K_A is the step matrix, its
//! rows of K_B and K_R then numbering their columns in the order of those dofs; elsewhere
//! the memory alone (and at its own rows). The values it holds have the bits of the whole
//! history's. Where the frames are in pieces, rank 0's history holds what its steps, its
//! piece and history.csv's reactions read, as a follower's does, and where they are not,
//! every dof (`run::hold_history_of_first`); summary.json's u_max is then the ranks'
//! largest, taken with the norms (`run::consumers::of_pieces`).
//! At a checkpoint every rank sends its own rows of u_n, its compensated sum and w_n
//! (`TimeLoop::state`) and of the memory, one vector at a time (`TimeLoop::gather_memory`),
//! to rank 0: every rank knows the checkpoints' steps, rank 0's clock
//! reaching the others with the stop requests ([`Ranks::stop`]). Of the loads, a rank makes the
//! quadrature points that reach its own rows alone (its rows of f_n, with the same bits;
//! those of other rows it reads come with b_n's exchange), rank 0 every traction's facets
//! too, and it makes the other points again, a traction's facet by facet and a body
//! force's cell by cell, where history.csv reads every value
//! (`Discretization::visit_every_load`). The rest is replicated: every other n-vector,
//! and w_n and b_n where a rank reads them (its own rows, their neighbours', Γ3's), so
//! every rank holds the same right side b_n there, bit for bit, and the active set's
//! decisions (its sets, its KKT residual) are the same on every rank. Rank 0 (the *first*)
//! owns the output directory (lock, series, history.csv, checkpoints, summary.json) and
//! prints; the others *follow* (`run::follow`). Of each `.vtu` frame every rank writes its
//! own piece, its part of the mesh, and the ranks agree that all are on disk
//! ([`Ranks::written`]) before rank 0 lists them in the frame's `.pvtu`
//! (`run::frame::OwnFrames`). No rank keeps the mesh past its setup, and none holds the
//! cells where the scene's keys take PETSc: its setup makes each from the mesh as it reads
//! it (`fem::CellSource::Made`). Every rank keeps its piece's node numbers, from which it
//! makes each of the piece's cells when it reads it (`fem::StressCells::Of`); rank 0 keeps
//! each cell's vertices besides only where it reads every cell past its setup
//! ([`first_keeps_vertices`]). history.csv's largest von Mises stress is, at every
//! step, the largest of the ranks' pieces' (`run::frame::OwnFrames::solved`), and
//! summary.json's norms the sum of their pieces' parts, at the loop's start and after
//! every step (`run::consumers::of_pieces`), so that rank 0 knows them when its run
//! fails, where no collective call may stand. (Where `auto`'s choice assembled the whole,
//! rank 0 keeps every cell where it would keep their vertices, and a follower lets go of
//! them: `Discretization::forget_cells`.)
//!
//! So only the runs whose steps are PETSc solves spread (`solver.linear = "petsc"`: linear,
//! or with contact and friction through the active set: `Descriptor::spreads`); any other
//! run under a launcher with several processes is refused (exit 2), as is `study`. The
//! memory of each rank is the replicated part (the history, w_n and b_n of the whole on a
//! rank whose history holds every dof: rank 0 where the frames are not in pieces, a
//! follower where K_A is not the step matrix; rank 0's unknowns' row order, its every
//! dof's index while it holds the cells, and at a checkpoint the vectors it gathers;
//! during setup every node's place on every rank, and on rank 0 the whole mesh and its
//! reading), its columns of the matrices, its part of the history, of w_n, b_n, of the
//! mesh and of the nodes' places (`fem::Places`, those it reads past its setup alone; it
//! finds a dof's index by searching the held dofs: `fem::DofIndices`), and its share of
//! PETSc's; a follower's setup in a numbering of its own (so that it never receives every
//! node's place), and rank 0's unknowns' row order in parts, are the next steps
//! (docs/cluster.md, "Not built yet").
//!
//! # Planning
//!
//! `Plan` is what a rank of a run over N ranks holds and does (`check --ranks N`): its
//! share of K_A's rows, entries and of the values a product fetches from other ranks, and
//! its memory, its own part (the setup's peak, measured, less what of the matrices it
//! does not hold) and its share of PETSc's, and for `check` a step's expected time on this
//! machine (`Plan::timed`).
//! `check` and `run` refuse ranks that would not fit, naming how many would.
//!
//! # Agreement
//!
//! - **Setup.** Every rank's setup, failed or not, passes [`Ranks::agree`] twice: once
//!   its setup up to the mesh, before rank 0 hands the mesh over
//!   ([`Ranks::with_mesh_of_first`]), and once the whole, before the first collective call
//!   of PETSc: if any rank failed, all stop there. Where the followers get their parts of
//!   the mesh, the ranks also agree after the dofs' numbering (whose check of the body's
//!   parts is rank 0's), and rank 0's error in the cells' materials reaches the others as
//!   its exit status before it hands the parts over. Rank 0 reports
//!   its own error; a follower reports its own only where rank 0 had none, and is silent
//!   ([`Error::Elsewhere`]) otherwise. Rank 0 alone decides at a signal during setup and
//!   commits the directory ([`Ranks::first_says`] tells the others).
//! - **Stops.** After each step, [`Ranks::stop`] combines every rank's stop request (a
//!   signal that reached any rank, `--stop-after`), so that all stop after the same step,
//!   rank 0 with a checkpoint. During a step, the first signal gives it up: the Krylov
//!   solve's convergence test asks every rank at each iteration, in one reduction, so all
//!   leave it at the same iteration (`shim.c`; mpirun kills the ranks a second after it
//!   passes a Ctrl-C on). A follower is never ended by a second signal: only rank 0 may
//!   be, before it commits, when nothing on disk has changed.
//! - **Failures after setup.** A step that fails fails on every rank (the KSP's reason is
//!   collective); a rank that fails alone (a frame rank 0 cannot write) ends them all
//!   ([`Ranks::abort`], in `main`), so that none waits forever in a collective call.

mod mesh;

use crate::history::Holds;
use crate::{Error, Result};

/// The environment variables by which MPI launchers tell each process how many they
/// started: Open MPI's `mpirun` (and `srun` with Open MPI), and the PMI of MPICH's and
/// Intel MPI's launchers and of Slurm's `srun --mpi=pmi2`.
pub const LAUNCHER_SIZE: [&str; 2] = ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE"];

/// This process's rank among the run's `size`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ranks {
    pub rank: usize,
    pub size: usize,
}

/// The process count a launcher set in the environment, above 1, with its variable and
/// text. A value that is not a count is not ours to judge and is let be.
fn launched() -> Option<(&'static str, String, usize)> {
    LAUNCHER_SIZE.into_iter().find_map(|var| {
        let value = std::env::var(var).unwrap_or_default();
        let size = value.trim().parse::<usize>().ok().filter(|&n| n > 1)?;
        Some((var, value, size))
    })
}

/// This process's rank as the launcher says (Open MPI's variable, PMI's), 0 without one:
/// for the commands that only print (`check`, `mesh-info`, `plot`), which run on every rank
/// and print on rank 0 alone, without MPI.
pub fn launcher_rank() -> usize {
    ["OMPI_COMM_WORLD_RANK", "PMI_RANK"]
        .into_iter()
        .find_map(|var| std::env::var(var).ok()?.trim().parse().ok())
        .unwrap_or(0)
}

/// What spreads over ranks, for the refusals of a run that does not (`run`, `run --emit
/// slurm`).
pub const WHAT_SPREADS: &str = "only a run whose steps are PETSc solves spreads over MPI ranks \
     ([solver] linear = \"petsc\", and with contact or friction contact = \"active_set\"; \
     docs/cluster.md)";

impl Ranks {
    /// One process.
    pub const ONE: Ranks = Ranks { rank: 0, size: 1 };

    /// The ranks of this process for `command` (`run`, `resume`: `spreads`), before it reads
    /// anything. One without a launcher or with one process. With several, in a build with
    /// PETSc, MPI is initialized (with PETSc) and asked; a command that does not spread, or
    /// a build without PETSc, is refused (bad input, exit 2): every process would run the
    /// whole scene into the same directory.
    pub fn of_process(command: &str, spreads: bool) -> Result<Ranks> {
        let Some((var, value, size)) = launched() else {
            return Ok(Ranks::ONE);
        };
        if spreads && cfg!(feature = "petsc") {
            return world();
        }
        let how = if spreads {
            "this build has no MPI: build with `--features petsc` (docs/cluster.md), which \
             spreads a run whose steps are PETSc solves, or start one process"
        } else {
            "start one process"
        };
        Err(Error::input(format!(
            "{var}={value}: an MPI launcher (mpirun -n, srun) started viscontact {command} as \
             one of {size} processes, but it does not spread over MPI ranks here: each \
             process would run the whole scene into the same directory. {how}, without \
             mpirun or srun -n; give it the machine's cores with --threads N, and run many \
             scenes on a cluster with `study --emit slurm`"
        )))
    }

    /// Whether this is rank 0, which owns the output directory and prints.
    pub fn is_first(&self) -> bool {
        self.rank == 0
    }

    /// Every rank's setup outcome combined (collective on several ranks): `r` where every
    /// rank succeeded or this is rank 0; else the first failure's exit status, quietly
    /// ([`Error::Elsewhere`]) where rank 0 reports its own, or this follower's own error
    /// where only followers failed.
    pub fn agree<T>(&self, r: Result<T>) -> Result<T> {
        if self.size == 1 {
            return r;
        }
        let code = r.as_ref().err().map_or(0, Error::exit_code);
        let (worst, first) = (self.max(code)?, self.first_says(code)?);
        match r {
            Err(e) if self.is_first() || first == 0 => Err(e),
            Err(_) => Err(Error::Elsewhere(first)),
            Ok(_) if worst == 0 => r,
            Ok(_) if self.is_first() => Err(elsewhere_failed(worst)),
            Ok(_) => Err(Error::Elsewhere(if first == 0 { worst } else { first })),
        }
    }

    /// Whether the run stops after this step, by which signal, and whether rank 0's clock
    /// says a checkpoint is due: this rank's request (`signal`, `after`: `--stop-after`
    /// says so) combined with every other's, and rank 0's `clock` (a follower's is not
    /// read), the same answer on every rank (collective on several).
    pub fn stop(&self, signal: Option<i32>, after: bool, clock: bool) -> Result<AfterStep> {
        // One reduction, the largest of 4 s + 2 a + c: where no rank asks to stop, the
        // largest is rank 0's c; a stop makes a checkpoint due anyway.
        let mine = 4 * signal.unwrap_or(0) + 2 * i32::from(after);
        let all = self.max(mine + i32::from(clock && self.is_first()))?;
        let stop = all >= 2;
        Ok(AfterStep {
            signal: (all / 4 > 0).then_some(all / 4),
            stop,
            clock: all == 1,
        })
    }

    /// Every rank's part of a frame written (collective on several): the largest of the
    /// ranks' `r` (their pieces' largest von Mises stress) where every rank wrote its part.
    /// A rank that failed says why itself; the others fail quietly
    /// ([`Error::Elsewhere`]), rank 0 with an error that says another rank failed, which
    /// ends the run as a failed write does (exit 1).
    pub fn written(&self, r: Result<f64>) -> Result<f64> {
        if self.size == 1 {
            return r;
        }
        let code = r.as_ref().err().map_or(0, Error::exit_code);
        let worst = self.max(code)?;
        let largest = self.largest(*r.as_ref().unwrap_or(&0.0))?;
        match r {
            Err(e) if self.is_first() => Err(e),
            Err(e) => {
                crate::errln!("error: rank {}: {e}", self.rank);
                Err(Error::Elsewhere(code))
            }
            Ok(_) if worst == 0 => Ok(largest),
            Ok(_) if self.is_first() => Err(Error::solve(format!(
                "another rank could not write its piece of the frame (exit status {worst}; its \
                 message is above); the frames and the checkpoint before it are kept"
            ))),
            Ok(_) => Err(Error::Elsewhere(worst)),
        }
    }

    /// Rank 0's `text` on every rank (collective on several).
    pub fn first_says_text(&self, text: &str) -> Result<String> {
        if self.size == 1 {
            return Ok(text.to_string());
        }
        let len = self.first_says(i32::try_from(text.len()).unwrap_or(i32::MAX))?;
        let mut bytes = text.as_bytes().to_vec();
        bytes.resize(usize::try_from(len).unwrap_or(0), 0);
        mpi::from_rank0_bytes(&mut bytes)?;
        Ok(String::from_utf8_lossy(&bytes).into_owned())
    }

    /// The largest of every rank's `value` (collective on several).
    pub fn largest(&self, value: f64) -> Result<f64> {
        match self.size {
            1 => Ok(value),
            _ => mpi::max_real_over_ranks(value),
        }
    }

    /// The sums of every rank's `parts` on rank 0, rank by rank in their order (the same
    /// bits on as many ranks), `parts` elsewhere (collective on several).
    pub fn sum_at_first(&self, parts: [f64; 2]) -> Result<[f64; 2]> {
        match self.size {
            1 => Ok(parts),
            _ => Ok(mpi::sum_at_first(&parts)?.try_into().unwrap_or(parts)),
        }
    }

    /// Rank 0's `value` on every rank (collective on several).
    pub fn first_says(&self, value: i32) -> Result<i32> {
        match self.size {
            1 => Ok(value),
            _ => mpi::from_rank0(value),
        }
    }

    /// The largest of every rank's `value` (collective on several).
    fn max(&self, value: i32) -> Result<i32> {
        match self.size {
            1 => Ok(value),
            _ => mpi::max_over_ranks(value),
        }
    }

    /// Whether the setup of a run of `scene` spreads over the ranks: on several ranks, where
    /// the scene's keys take PETSc (`SolverChoice::takes_petsc`). Then rank 0 alone reads
    /// the mesh and partitions it, and each follower gets its part of the mesh's cells
    /// (`Ranks::cells_of_first`); elsewhere every rank gets the whole mesh.
    pub fn spreads_setup(&self, scene: &crate::scene::Scene) -> bool {
        cfg!(feature = "petsc") && self.size > 1 && scene.solver.takes_petsc()
    }

    /// The discretization of `scene` on `mesh` as this rank holds it. On one of several
    /// ranks of a run whose keys take PETSc (`SolverChoice::takes_petsc`), the rank
    /// assembles of K_A, K_B and K_R only the columns of the unknowns whose rows it holds
    /// in PETSc (`Discretization::assembled`, over `petsc::Layout`'s partition, made
    /// here once and handed on in [`Own`]), so that no rank holds the whole matrices. Else
    /// the whole: one rank, or `solver.linear = "auto"`, whose choice reads the whole K_A
    /// (the analysis of its factor) before a rank keeps its columns. A rank that assembles
    /// its columns alone holds no cell: rank 0 their vertices, a follower nothing (and,
    /// where it makes its rows of K_B and K_R^(0) after PETSc's setup, those of its cells
    /// with one of its own nodes: `fem::PairWhen::AfterKrylov`).
    pub fn discretize(
        &self,
        mesh: &mut crate::mesh::Mesh,
        scene: &crate::scene::Scene,
    ) -> Result<(crate::fem::Discretization, Option<Own>)> {
        #[cfg(feature = "petsc")]
        if self.spreads_setup(scene) {
            let hold = match self.is_first() {
                true => crate::fem::Hold::Vertices,
                false => crate::fem::Hold::Nothing,
            };
            // Rank 0 alone checks the body's parts, which read the cells: the ranks agree.
            let disc = self.agree(crate::fem::Discretization::numbered(mesh, scene, hold))?;
            let cells = crate::fem::CellSource::Made(mesh);
            let make = || crate::petsc::Layout::partition(&disc, cells, self.size);
            // A follower whose vectors will hold its own unknowns and their neighbours'
            // alone (`Holds::Local`) gets the rows of those with its part of the cells.
            let every_row = !hands_over_k_a(&disc, scene.solver.history);
            let first = (self.is_first(), every_row);
            let (mut layout, shares) = crate::petsc::Layout::of_first(first, make)?;
            let with = (&disc, &mut layout, every_row);
            let materials = self.cells_of_first(mesh, scene, with)?;
            let own = Some(layout.own(self.rank));
            let how = (hold, crate::fem::PairWhen::AfterKrylov);
            let disc = disc.assembled(mesh, scene, how, (materials, own))?;
            let own = Own {
                layout,
                shares,
                rows: None,
                holds: Holds::Every,
            };
            return Ok((disc, Some(own)));
        }
        Ok((crate::fem::Discretization::new(mesh, scene)?, None))
    }

    /// On one of several ranks, `disc` keeps the columns of K_A, K_B and K_R of the
    /// unknowns whose rows this rank holds in PETSc (`petsc::Layout`; `made`: the layout
    /// [`Ranks::discretize`] made, when it assembled those columns alone), and no others
    /// (`Discretization::keep_columns`). Where K_A is the step matrix (`solver.history =
    /// "left"`, no prescribed dofs), its rows go on in PETSc's numbering, and `disc` keeps
    /// K_A's diagonal at its own of Γ3's unknowns alone
    /// (`Discretization::keep_diagonal_of_k_a`), and
    /// K_B and K_R^(0) become the rank's rows of both, paired
    /// (`Discretization::pair_own_rows`; or made after PETSc's setup where
    /// [`Ranks::discretize`] put them off: `fem::PairWhen`). The heap the matrices held
    /// then goes back to the system (`resources::return_freed_memory`). A rank keeps the
    /// loads of its own rows alone (`Discretization::keep_own_loads`), rank 0 every
    /// traction's facets too: it makes the other points again (a body force's from its
    /// cells) for history.csv's resultants and reactions, and so sees any value that is not
    /// finite.
    /// What goes on to PETSc, the layout included, is [`Own`]; nothing on one rank.
    pub fn keep_own_columns(
        &self,
        disc: &mut crate::fem::Discretization,
        scene: &crate::scene::Scene,
        made: Option<Own>,
    ) -> Result<Option<Own>> {
        #[cfg(feature = "petsc")]
        if self.size > 1 {
            let (layout, shares) = match made {
                Some(own) => (own.layout, own.shares),
                None => crate::petsc::Layout::partition(disc, disc.cell_source(), self.size)?,
            };
            if disc.own.is_none() {
                disc.keep_columns(layout.own(self.rank));
            }
            let rows = if hands_over_k_a(disc, scene.solver.history) {
                let rows = layout.rows_of(&disc.k_a, self.rank)?.into_owned();
                disc.keep_diagonal_of_k_a();
                // The implicit variant's step matrix is made of the columns of all three.
                disc.pair_own_rows();
                Some(rows)
            } else {
                None
            };
            // A load not finite at t = 0, which a follower's own loads may not hold, stops
            // rank 0 here, before the ranks agree on the setup, not alone in its time loop.
            if self.is_first() {
                disc.loads_at_start(scene)?;
            }
            disc.keep_own_loads(self.is_first());
            crate::resources::return_freed_memory();
            return Ok(Some(Own {
                layout,
                shares,
                rows,
                holds: Holds::Every,
            }));
        }
        let _ = (disc, scene, made);
        Ok(None)
    }

    /// What a rank's history holds (`own.holds`; rank 0 calls this where its frames are in
    /// pieces, `run::hold_history_of_first`, and else holds every dof). Where it hands its
    /// rows of K_A to PETSc ([`Ranks::keep_own_columns`]: K_A the step matrix, no
    /// prescribed dofs), u_n and m_n at the dofs its rows of K_B and K_R read and `also`
    /// (what else it reads: its piece's points'; on rank 0 history.csv's too) alone
    /// (`Holds::Local`): `disc`'s matrices number their rows over them
    /// (`Discretization::number_rows_over`); its w_n and b_n are held there, at its own
    /// rows and at Γ3's unknowns (`time_loop`). Nothing else reads u_n or m_n on a
    /// follower: the active set reads b_n and w_n, and the checks' max|u_n| is the ranks'
    /// largest. Elsewhere (the implicit variant, whose step matrix the time loop makes of
    /// the three matrices' columns, and prescribed dofs), the memory alone at the dofs its
    /// rows of K_R read, its own rows and `also` (`Holds::Memory`,
    /// `Discretization::memory_reach`).
    pub fn hold_history(
        &self,
        disc: &mut crate::fem::Discretization,
        own: Option<&mut Own>,
        also: Vec<usize>,
    ) {
        #[cfg(feature = "petsc")]
        if let Some(own) = own {
            own.holds = match own.rows.is_some() {
                true => disc.local_reach(also).map(|local| {
                    disc.number_rows_over(&local);
                    Holds::Local(local)
                }),
                // Its own rows too, which it sends to rank 0's checkpoints.
                false => disc.memory_reach().map(|mut dofs| {
                    dofs.extend(disc.own.iter().flatten());
                    dofs.extend(also);
                    Holds::Memory(crate::mesh::increasing(dofs))
                }),
            }
            .unwrap_or(Holds::Every);
        }
        #[cfg(not(feature = "petsc"))]
        let _ = (disc, own, also);
    }

    /// Ends every rank of the run with exit status `code`: a rank that failed alone after
    /// setup, so that no other waits for it in a collective call.
    pub fn abort(&self, code: i32) {
        #[cfg(feature = "petsc")]
        if self.size > 1 {
            crate::petsc::abort(code);
        }
        let _ = code;
    }
}

/// What the ranks agreed after a step ([`Ranks::stop`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AfterStep {
    /// The signal that reached a rank, if one did.
    pub signal: Option<i32>,
    /// Whether the run stops after the step.
    pub stop: bool,
    /// Whether rank 0's clock says a checkpoint is due after it (where the run goes on).
    pub clock: bool,
}

/// On one of several ranks, what [`Ranks::keep_own_columns`] hands to the time loop's PETSc
/// backend (`petsc::Krylov`): which rank holds which rows (METIS's partition, made by rank
/// 0 and handed to the others: `petsc::Layout::of_first`) and each rank's share of them,
/// and where K_A is the step matrix, the rank's rows of K_A in PETSc's numbering, taken
/// out of the discretization: PETSc's matrices are made of them, and the Newton
/// systems read them as their copy of K, the rank's only one. On a follower, the dofs
/// its history holds ([`Ranks::hold_history`]).
pub struct Own {
    #[cfg(feature = "petsc")]
    pub(crate) layout: crate::petsc::Layout,
    /// Each rank's share of K_A over the layout, counted where the partition was made.
    #[cfg(feature = "petsc")]
    pub(crate) shares: Vec<crate::petsc::RankShare>,
    #[cfg(feature = "petsc")]
    pub(crate) rows: Option<crate::petsc::Csr<'static>>,
    /// What a rank's history holds: the memory of its `Discretization::memory_reach`, or
    /// u_n and m_n at its `Discretization::local_reach` ([`Ranks::hold_history`]); on rank
    /// 0, every dof where its frames are not in pieces (`run::hold_history_of_first`).
    pub(crate) holds: Holds,
}

/// Whether a rank of several hands its rows of K_A to PETSc ([`Ranks::keep_own_columns`]):
/// where K_A is the step matrix (the left endpoint history) and the rank keeps its columns
/// (no prescribed dofs, whose right side reads K_A whole: `Discretization::keeps_own_columns`,
/// which the numbered `disc` says already, before its assembly).
#[cfg(feature = "petsc")]
fn hands_over_k_a(disc: &crate::fem::Discretization, history: crate::scene::History) -> bool {
    history == crate::scene::History::Left && disc.keeps_own_columns()
}

/// What Open MPI adds to a rank's resident memory, which a process without a launcher (as
/// `check` is) does not hold and counts for several ranks: 8.6 MB measured on the 3D block
/// (a rank's setup peak under `mpirun -n 2` against one process's), doubled.
#[cfg(feature = "petsc")]
const MPI_RUNTIME: f64 = 16e6;

/// How a rank of several holds K_A, K_B and K_R, which its setup's peak depends on.
#[cfg(feature = "petsc")]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Holding {
    /// Its own columns alone, assembled so (`Ranks::discretize`: the scene names PETSc).
    Columns,
    /// The whole matrices assembled first, then its own columns kept (`solver.linear =
    /// "auto"`, whose choice reads the whole K_A).
    WholeFirst,
    /// The whole matrices, kept: prescribed dofs, whose velocities reach every row's right
    /// side through K_A.
    Whole,
}

#[cfg(feature = "petsc")]
impl Holding {
    /// How a rank of several holds the matrices of `disc` for `scene`.
    fn of(disc: &crate::fem::Discretization, scene: &crate::scene::Scene) -> Holding {
        match (disc.k_a_all.is_some(), scene.solver.takes_petsc()) {
            (true, _) => Holding::Whole,
            (false, true) => Holding::Columns,
            (false, false) => Holding::WholeFirst,
        }
    }
}

/// What each rank of a run over `size` ranks holds and does (`check --ranks N`, and the
/// refusal of a run whose ranks would not fit the memory available): its share of K_A
/// (the largest rank's, over `petsc::Layout`'s partition) and its memory: its own part
/// (this process's setup peak so far, measured, less what of the matrices and of the cells
/// it does not hold on a rank, and what the steps hold) and its share of PETSc's matrices and
/// multigrid. A rank of a run whose keys take PETSc assembles its own columns alone
/// (`Ranks::discretize`); one that assembles the whole matrices first (`solver.linear =
/// "auto"`) holds them at its setup's peak, a floor that no rank count lowers.
#[cfg(feature = "petsc")]
#[derive(Clone, Debug)]
pub struct Plan {
    size: usize,
    /// The rows of K_A.
    rows: usize,
    /// The largest rank's share.
    largest: crate::petsc::RankShare,
    /// The largest rank's own bytes, and its bytes of PETSc's.
    own: f64,
    spread: f64,
    /// What a rank of several holds whatever their count: the measured setup peak with
    /// MPI's runtime and what the steps hold, less the matrices and the cells this process
    /// holds and such a rank does not.
    base: f64,
    /// The bytes of K_A, K_B and K_R whole (`matrix_bytes`), of which a rank assembles its
    /// share or all first (`holding`), and keeps its share of `kept` (its rows of K_B and
    /// K_R, paired, and of K_A unless they go to PETSc: `Ranks::keep_own_columns`, which
    /// copies them, `rows_bytes` in all, beside its columns; none of the three where every
    /// rank holds them whole, in `base`); PETSc's bytes a rank on several ranks times their
    /// count.
    matrices: f64,
    kept: f64,
    rows_bytes: f64,
    spread_several: f64,
    holding: Holding,
    /// Whether rank 0 keeps every cell's vertices ([`first_keeps_vertices`]).
    vertices: bool,
    /// The largest rank's fraction of K_A's entries.
    share: f64,
    /// The memory sum's bytes at every dof (`resources::Estimate::largest_rank`), and the
    /// fraction of them that the largest rank holds: its reach, every dof where rank 0
    /// holds them all.
    memory: f64,
    reach: f64,
    /// Through the active set's Newton systems.
    newton: bool,
    /// A step's expected seconds on this machine ([`Plan::timed`]), once timed.
    step_s: Option<f64>,
}

#[cfg(feature = "petsc")]
impl Plan {
    /// The plan of `disc` (whole, or a rank's columns) for `scene` over `size` ranks (the
    /// partition `made` holds where this rank made one for them: `Ranks::discretize`; else
    /// made here), its steps through the active set's Newton systems where `newton` (else
    /// K_A's solves), holding what `steps` estimates besides the setup.
    pub fn new(
        disc: &crate::fem::Discretization,
        scene: &crate::scene::Scene,
        (size, made): (usize, Option<&Own>),
        newton: bool,
        steps: &crate::resources::Estimate,
    ) -> Result<Plan> {
        use crate::resources::{peak_memory, petsc_bytes};
        let made = made.filter(|own| own.shares.len() == size);
        let shares = match made {
            Some(own) => own.shares.clone(),
            None => crate::petsc::Layout::partition(disc, disc.cell_source(), size)?.1,
        };
        let largest = shares
            .iter()
            .copied()
            .max_by_key(|s| s.entries)
            .unwrap_or_default();
        let entries: usize = shares.iter().map(|s| s.entries).sum();
        // Under a launcher the peak holds MPI's runtime already.
        let launched = launched().is_some();
        let peak = peak_memory().unwrap_or(0.0);
        let holding = Holding::of(disc, scene);
        let hands_over = hands_over_k_a(disc, scene.solver.history);
        // With the matrices whole on every rank they are part of what every rank holds.
        let (held, matrices, kept) = match holding {
            Holding::Whole => (0.0, 0.0, 0.0),
            _ => (
                matrix_bytes(disc),
                whole_matrix_bytes(disc, entries),
                kept_per_entry(disc, hands_over) * entries as f64,
            ),
        };
        let (gathered, memory) = steps.largest_rank();
        let base = peak + gathered + if launched { 0.0 } else { MPI_RUNTIME }
            - held
            - cell_bytes(disc, holding, scene);
        let reach = memory_reach(disc, scene, holding, &largest);
        let rows_bytes = if hands_over {
            12.0 * entries as f64
        } else {
            0.0
        };
        let share = largest.entries as f64 / entries.max(1) as f64;
        Ok(Plan {
            size,
            rows: disc.n_free,
            largest,
            own: match size {
                1 => peak + steps.memory(),
                _ => base + share * kept + reach * memory,
            },
            spread: petsc_bytes(largest.entries, newton, size),
            base,
            matrices,
            kept,
            rows_bytes,
            spread_several: petsc_bytes(entries, newton, 2),
            holding,
            vertices: first_keeps_vertices(scene),
            share,
            memory,
            reach,
            newton,
            step_s: None,
        })
    }

    /// A rank's setup peak where it holds `share` of K_A's entries: what it holds whatever
    /// the rank count, and the matrices whole, or its share of them with its copy of its
    /// rows of K_A.
    fn setup_peak(&self, share: f64) -> f64 {
        match self.holding {
            Holding::Columns => self.base + share * (self.matrices + self.rows_bytes),
            Holding::WholeFirst => self.base + self.matrices,
            Holding::Whole => self.base,
        }
    }

    /// The plan with a step's expected time on this machine: the largest rank's share of a
    /// product with K_A, timed here (`product_seconds`), times a Krylov iteration's cost in
    /// such products and the iterations a step takes (`step_products`).
    pub fn timed(mut self, disc: &crate::fem::Discretization) -> Plan {
        let total = disc.k_a.as_ref().val().len().max(1);
        let share = self.largest.entries as f64 / total as f64;
        self.step_s = Some(product_seconds(disc) * share * step_products(self.rows, self.newton));
        self
    }

    /// A step's expected seconds, once [`Plan::timed`].
    pub fn step_s(&self) -> Option<f64> {
        self.step_s
    }

    /// The memory of the largest rank: its setup's peak, or what it holds with PETSc's
    /// share, whichever is more.
    pub fn per_rank(&self) -> f64 {
        let setup = match self.size {
            1 => 0.0,
            _ => self.setup_peak(self.share),
        };
        (self.own + self.spread).max(setup)
    }

    /// Refuses (exit 2) ranks that would need more than `resources::MARGIN` of the memory
    /// available (`VISCONTACT_MEMORY` is a rank's), naming how many ranks would fit, or
    /// that none would where what every rank holds does not fit.
    pub fn check(&self) -> Result<()> {
        use crate::resources::{available_memory, human, memory_phrase, MARGIN};
        let Some(avail) = available_memory()? else {
            return Ok(());
        };
        let budget = MARGIN * avail;
        if self.per_rank() <= budget {
            return Ok(());
        }
        // R ranks hold base + (M' + PETSc's + H)/R each, and at setup base + M, or base +
        // (M + rows)/R where a rank assembles its own columns alone (M: the matrices, M'
        // what a rank keeps of them, H the memory sum at every dof where rank 0 holds it
        // at its reach), evenly but for whole nodes: 5 % more for the largest.
        let history = if self.reach < 1.0 { self.memory } else { 0.0 };
        let left = budget - self.base - (self.memory - history);
        let split = self.kept + self.spread_several + history;
        let spreads = match self.holding {
            Holding::Columns => split.max(self.matrices + self.rows_bytes),
            _ => split,
        };
        let whole = match self.holding {
            Holding::Columns => "",
            Holding::WholeFirst => {
                ", and assembles the whole matrices before it keeps its own columns: \
                 `solver.linear = \"auto\"`"
            }
            Holding::Whole => ", and the whole matrices: prescribed dofs",
        };
        let remedy = match left > 0.0 && budget >= self.setup_peak(0.0) {
            true => format!(
                "≈ {} ranks would fit (mpirun -n {0} or srun -n {0}, each rank with the \
                 memory this one has)",
                (1.05 * spreads / left).ceil().max(self.size as f64 + 1.0)
            ),
            false => format!(
                "no rank count would: every rank reads the mesh, and rank 0 holds u_n at \
                 every dof and a few of the memory's vectors more at each checkpoint (≈ {} \
                 here{}), and \
                 only the matrices, PETSc's part and the rest of the memory spread; use a \
                 coarser mesh or ranks with more memory (docs/cluster.md)",
                human(self.setup_peak(0.0)),
                whole,
            ),
        };
        Err(Error::input(format!(
            "a run on {} would need ≈ {} a rank (≈ {} of its own and ≈ {} of PETSc's) but {} \
             (a run may plan {:.0} % of it): {remedy}",
            self.ranks(),
            human(self.per_rank()),
            human(self.own),
            human(self.spread),
            memory_phrase(avail),
            100.0 * MARGIN
        )))
    }

    /// "one rank", "4 ranks".
    fn ranks(&self) -> String {
        match self.size {
            1 => "one rank".to_string(),
            n => format!("{n} ranks"),
        }
    }
}

/// `check`'s `ranks` line.
#[cfg(feature = "petsc")]
impl std::fmt::Display for Plan {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        use crate::resources::human;
        let l = &self.largest;
        let others = "the other ranks' columns of K_A, K_B and K_R";
        let others = match self.holding {
            Holding::Columns => format!(", less {others}, which it does not assemble"),
            Holding::WholeFirst => format!(", less {others}, which it drops once assembled"),
            Holding::Whole => ", with the matrices whole (prescribed dofs)".to_string(),
        };
        let cells = match (self.holding, self.vertices) {
            (Holding::Columns, true) => {
                ", and the cells, which it does not hold (rank 0 their vertices)"
            }
            (Holding::Columns, false) => ", and the cells, which it does not hold",
            _ => "",
        };
        let dropped = match (self.size, self.rows_bytes > 0.0) {
            (1, _) => String::new(),
            (_, false) => format!("{others}{cells}"),
            (_, true) => format!("{others}, its own of K_A (its rows go to PETSc){cells}"),
        };
        write!(
            f,
            "{}: the largest holds {} of K_A's {} rows ({} entries; a product with K_A \
             fetches {} values of other ranks' rows); memory ≈ {} a rank: ≈ {} of its own \
             (this setup's peak, measured{dropped}, and what the steps hold) and ≈ {} of \
             PETSc's (its share of the matrices and the multigrid)",
            self.ranks(),
            l.rows,
            self.rows,
            l.entries,
            l.ghosts,
            human(self.per_rank()),
            human(self.own),
            human(self.spread)
        )?;
        if let Some(step) = self.step_s {
            // Two significant digits: 11, 5.1, 0.015.
            let digits = (1.0 - step.log10().floor()).clamp(0.0, 9.0) as usize;
            let how = match self.newton {
                false => "K_A's solve",
                true => "the active set's Newton systems, on average over a run",
            };
            write!(
                f,
                "; a step ≈ {step:.digits$} s on this machine ({how}: a product with K_A timed \
                 here, scaled to the rank's entries, times the products a step's Krylov \
                 iterations cost on the measured plates; docs/cluster.md)"
            )?;
        }
        Ok(())
    }
}

/// The fraction of the dofs at which the largest rank, rank 0, holds the memory sum
/// (`run::hold_history_of_first`): its rows and the values its rows' products fetch (its
/// reach: its rows of K_R's columns, which are K_A's, and its piece's points), where the
/// frames are in pieces (`.vtu`) and the matrices spread; else every dof.
#[cfg(feature = "petsc")]
fn memory_reach(
    disc: &crate::fem::Discretization,
    scene: &crate::scene::Scene,
    holding: Holding,
    largest: &crate::petsc::RankShare,
) -> f64 {
    let pieces = scene.output.options.format == crate::output::Format::Vtu;
    match pieces && holding != Holding::Whole {
        true => ((largest.rows + largest.ghosts) as f64 / disc.n_free.max(1) as f64).min(1.0),
        false => 1.0,
    }
}

/// Whether rank 0 of several keeps every cell's vertices past its setup (`fem::Hold`), for
/// the stresses of every cell in a frame that is not in pieces (`format = "vtkhdf"`) or
/// for history.csv's resultant of a body force, made again from every cell at every step;
/// elsewhere it lets go of them (`run::first_lets_go_of_cells`).
pub fn first_keeps_vertices(scene: &crate::scene::Scene) -> bool {
    let pieces = scene.output.options.format == crate::output::Format::Vtu;
    !pieces || !scene.physics.body_forces.is_empty()
}

/// The bytes of the cells that `disc` holds (`check`, one process) and a rank of several
/// holding the matrices as `holding` says does not: where a rank assembles its own columns
/// alone it holds no cell, rank 0 (the largest) each cell's vertices where it keeps them
/// ([`first_keeps_vertices`]).
#[cfg(feature = "petsc")]
fn cell_bytes(
    disc: &crate::fem::Discretization,
    holding: Holding,
    scene: &crate::scene::Scene,
) -> f64 {
    let vertices = if first_keeps_vertices(scene) {
        4 * (disc.dim + 1)
    } else {
        0
    };
    match holding {
        Holding::Columns => {
            let cell = std::mem::size_of::<crate::fem::Cell>() - vertices;
            (disc.cells.len() * cell) as f64
        }
        _ => 0.0,
    }
}

/// The bytes of K_A, K_B and K_R as the discretization holds them: an index (8 bytes) and
/// a value (8) an entry, each.
#[cfg(feature = "petsc")]
fn matrix_bytes(disc: &crate::fem::Discretization) -> f64 {
    let entries = |m: &crate::fem::Sparse| m.as_ref().val().len() as f64;
    let (k_b, k_r) = (disc.k_b.iter(), disc.k_r.iter());
    16.0 * (entries(&disc.k_a) + k_b.chain(k_r).map(entries).sum::<f64>())
}

/// The bytes a rank keeps of its own columns of K_A, K_B and K_R, an entry of K_A's
/// pattern (no prescribed dofs, so one pattern): 16 of each where it keeps their columns,
/// and where its rows of K_A go to PETSc (`hands_over`), none of K_A, and 20 of K_B and
/// K_R^(0) paired (`Discretization::pair_own_rows`; 16 of K_R^(0) alone without K_B).
#[cfg(feature = "petsc")]
fn kept_per_entry(disc: &crate::fem::Discretization, hands_over: bool) -> f64 {
    let (k_b, k_r) = (disc.k_b.iter().count(), disc.k_r.len());
    let columns = 16.0 * (1 + k_b + k_r) as f64;
    match hands_over {
        false => columns,
        true => columns - 16.0 - 12.0 * (k_b.min(k_r)) as f64,
    }
}

/// The bytes of K_A, K_B and K_R whole, K_A's pattern holding `entries` (all the ranks'
/// shares): the same as [`matrix_bytes`] of the whole, which a rank that keeps its columns
/// does not hold; K_B and K_R share K_A's pattern where a rank keeps columns (no prescribed
/// dofs, which a whole discretization counts itself).
#[cfg(feature = "petsc")]
fn whole_matrix_bytes(disc: &crate::fem::Discretization, entries: usize) -> f64 {
    match disc.own {
        None => matrix_bytes(disc),
        Some(_) => 16.0 * entries as f64 * (1 + disc.k_b.iter().count() + disc.k_r.len()) as f64,
    }
}

/// A Krylov iteration of CG + GAMG on K_A costs this many products with K_A (its
/// V-cycle's smoothing and coarse levels besides the product): the fine plate's linear
/// PETSc run on one rank took 4.68 s a step, 301.6 times a product (0.0155 s, timed as
/// [`product_seconds`] does, in the same session), in 31.0 iterations a step as
/// `step_products` counts them (docs/cluster.md, "Planning").
#[cfg(feature = "petsc")]
const ITERATION_PRODUCTS: f64 = 9.7;

/// A step through the active set costs this many linear steps, on average over a run: the
/// fine plate's 20 steps (the onset of contact and sliding included) took 2.49 times the
/// linear PETSc run's in one call (docs/performance.md, "The thin slab: ρ at a tenth of
/// K's diagonal").
#[cfg(feature = "petsc")]
const NEWTON_STEPS: f64 = 2.5;

/// The products with K_A that a step costs on `rows` unknowns: K_A's solve took 23 CG
/// iterations a step on the plate of 54 990 unknowns and 31 on the one of 367 470
/// (docs/performance.md), a growth as rows^0.157 that this extrapolates.
#[cfg(feature = "petsc")]
fn step_products(rows: usize, newton: bool) -> f64 {
    let iterations = 23.0 * (rows.max(1) as f64 / 54_990.0).powf(0.157);
    let linear = iterations * ITERATION_PRODUCTS;
    match newton {
        false => linear,
        true => linear * NEWTON_STEPS,
    }
}

/// The seconds of one product y = K_A x on one thread, the least of five (after one that
/// warms the caches): what a rank's Krylov iteration is made of, on this machine.
#[cfg(feature = "petsc")]
fn product_seconds(disc: &crate::fem::Discretization) -> f64 {
    let k = disc.k_a.as_ref();
    let (ptr, idx, val) = (k.symbolic().col_ptr(), k.symbolic().row_idx(), k.val());
    let x: Vec<f64> = (0..disc.n_free).map(|i| 1.0 + (i % 7) as f64).collect();
    let mut y = vec![0.0; disc.n_free];
    let mut best = f64::INFINITY;
    for round in 0..6 {
        let start = std::time::Instant::now();
        // K_A is symmetric: its column j is its row j.
        for (j, yj) in y.iter_mut().enumerate() {
            let range = ptr[j]..ptr[j + 1];
            *yj = idx[range.clone()]
                .iter()
                .zip(&val[range])
                .map(|(&i, v)| v * x[i])
                .sum();
        }
        std::hint::black_box(&y);
        if round > 0 {
            best = best.min(start.elapsed().as_secs_f64());
        }
    }
    best
}

/// Rank 0's error where only another rank's setup failed, with that rank's exit status.
fn elsewhere_failed(code: i32) -> Error {
    let what = format!(
        "another rank's setup failed (exit status {code}; its message is above): the run \
         stopped before it changed anything on disk"
    );
    match code {
        2 => Error::input(what),
        c if c > 128 => Error::Interrupted(c - 128),
        _ => Error::solve(what),
    }
}

#[cfg(feature = "petsc")]
fn world() -> Result<Ranks> {
    crate::petsc::initialize()?;
    let (rank, size) = crate::petsc::world()?;
    Ok(Ranks { rank, size })
}

// Without PETSc there is no MPI, and a run is one rank (`Ranks::of_process` refuses more).
#[cfg(not(feature = "petsc"))]
fn world() -> Result<Ranks> {
    Ok(Ranks::ONE)
}

/// The collective calls, through PETSc's MPI; none without it, where a run is one rank.
#[cfg(feature = "petsc")]
use crate::petsc as mpi;

#[cfg(not(feature = "petsc"))]
mod mpi {
    pub fn from_rank0(value: i32) -> crate::Result<i32> {
        Ok(value)
    }

    pub fn max_over_ranks(value: i32) -> crate::Result<i32> {
        Ok(value)
    }

    pub fn max_real_over_ranks(value: f64) -> crate::Result<f64> {
        Ok(value)
    }

    pub fn from_rank0_bytes(_: &mut [u8]) -> crate::Result<()> {
        Ok(())
    }

    pub fn sum_at_first(values: &[f64]) -> crate::Result<Vec<f64>> {
        Ok(values.to_vec())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_rank_agrees_with_itself_and_stops_as_asked() {
        let one = Ranks::ONE;
        assert!(one.agree(Ok(3)).is_ok());
        assert_eq!(
            one.agree::<()>(Err(Error::input("x")))
                .unwrap_err()
                .exit_code(),
            2
        );
        let said = |signal, stop, clock| AfterStep {
            signal,
            stop,
            clock,
        };
        assert_eq!(
            one.stop(None, false, false).unwrap(),
            said(None, false, false)
        );
        assert_eq!(
            one.stop(None, true, false).unwrap(),
            said(None, true, false)
        );
        assert_eq!(
            one.stop(None, false, true).unwrap(),
            said(None, false, true)
        );
        assert_eq!(one.stop(None, true, true).unwrap(), said(None, true, false));
        let signalled = one.stop(Some(15), false, true).unwrap();
        assert_eq!(signalled, said(Some(15), true, false));
        assert_eq!(one.first_says(7).unwrap(), 7);
    }
}
