//! PETSc as a linear backend (cargo feature `petsc`): the step matrix K_A solved by a Krylov
//! method with algebraic multigrid instead of the stored Cholesky factor.
//!
//! The binding is our own and small (docs/decisions.md): `shim.c`, compiled by build.rs
//! with the flags of PETSc's pkg-config file, keeps PETSc's macros and types on the C side
//! and offers a few functions with plain C types; this module declares them and wraps them
//! safely. PETSc is initialized once per process, on first use ([`initialize`]) or, under an
//! MPI launcher with several processes, before the run reads anything (docs/cluster.md),
//! and finalized by [`finalize`] at the end of `main`. The KSPs span the ranks, K_A's and
//! the active set's Newton systems' (each rank holds a block of whole nodes' rows, as
//! [`Layout`] partitions them, and gets back the solution where it reads it: `Spread`).
//!
//! # The solve
//!
//! K_A w = b by preconditioned CG with PETSc's smoothed-aggregation multigrid (GAMG), the
//! default `-ksp_type cg -pc_type gamg`, stopped when the preconditioned residual has
//! fallen by `rtol` (default 1e-12, [`DEFAULT_RTOL`]) relative to the preconditioned right
//! side. The initial guess is the previous step's w. GAMG is given the near-null space of
//! linear elasticity, the rigid-body modes restricted to the free dofs: d translations
//! e_c and the rotations, (−y, x) in 2D and (0, −z, y), (z, 0, −x), (−y, x, 0) in 3D, about
//! the centroid of the nodes, orthonormalized (PETSc's `MatNullSpaceCreate` asks for
//! orthonormal vectors). Each rank makes its own rows of them alone, the Gram–Schmidt's
//! inner products each rank's part summed over the ranks in rank order
//! ([`rigid_body_modes`]): the same bits run after run on a rank count, one process's on
//! one. The modes are built here rather than by `MatNullSpaceCreateRigidBody`, which needs
//! every node's d dofs in one block: a node on a Γ1 that clamps some of its components
//! breaks the blocks. Where the free dofs are node blocks (each node's d dofs free and
//! consecutive, or all clamped), the matrix gets block size d, which GAMG uses to
//! aggregate nodes.
//!
//! The scene's `[solver.petsc] options` are inserted into PETSc's options database before
//! `KSPSetFromOptions`, after the `PETSC_OPTIONS` environment variable that PETSc reads at
//! initialization: the scene's options win where both set a key. A KSP that does not
//! converge (`KSPGetConvergedReason` < 0) fails the step with its reason.
//!
//! The active-set solver's Newton systems (`solve_constrained`) have a KSP of their own, of
//! the same type and options, on an assembled matrix with K's pattern (`shim.c` builds it
//! in place and says why it is the one it is); its GAMG makes its aggregates and
//! interpolation once, from K, and updates the coarse operators where the matrix changed
//! (`Hierarchy`). A KSP made for them (`KrylovSettings::newton`) sets up only their
//! multigrid: K's own KSP keeps its type and options but is never set up or solved, and on
//! several ranks it goes, with K's matrix, before GAMG's setup (a rank's memory peaks
//! there): a product with K ([`Krylov::mult_at`]) then takes the rank's rows of K, which
//! the Krylov keeps (the rank's only copy of them: `ranks::Own`), and its rows of x, the
//! values of the others' rows that its rows read coming from them in the shim.

mod exchange;
mod layout;

pub use exchange::scatter_from_first;
use exchange::Exchange;
pub use layout::{part_unknowns, Csr, Layout, RankShare};

use crate::fem::constraints::rigid_mode;
use crate::fem::{Discretization, Sparse};
use crate::{Error, Result};
use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::sync::Mutex;

/// The relative tolerance of the Krylov method by default: u_N agrees with the Cholesky
/// run's to 1e-8 relative and better (tests/petsc.rs).
pub const DEFAULT_RTOL: f64 = 1e-12;

/// What to try where a KSP stopped without converging.
pub const REMEDY: &str = "check the options in [solver.petsc] options and PETSC_OPTIONS (a \
     -ksp_max_it or -ksp_rtol, a preconditioner that does not suit an SPD matrix), or set \
     [solver] linear = \"cholesky\" (with contact, and a contact solver of the factor: \
     dense, sparse, matrix_free or clarabel)";

/// PetscInt of Debian's PETSc: 32 bits (build.rs refuses 64-bit indices).
pub type PetscInt = i32;

extern "C" {
    fn vc_initialize() -> c_int;
    fn vc_finalize() -> c_int;
    fn vc_error_message(code: c_int) -> *const c_char;
    fn vc_reason_name(reason: c_int) -> *const c_char;
    fn vc_world(rank: *mut c_int, size: *mut c_int) -> c_int;
    fn vc_max_over_ranks(value: *mut c_int) -> c_int;
    fn vc_from_rank0(value: *mut c_int) -> c_int;
    fn vc_max_real_over_ranks(value: *mut f64) -> c_int;
    fn vc_from_rank0_bytes(bytes: *mut c_char, n: c_int) -> c_int;
    fn vc_abort(code: c_int);
    #[allow(clippy::too_many_arguments)]
    fn vc_ksp_create(
        n: PetscInt,
        rowptr: *const PetscInt,
        cols: *const PetscInt,
        vals: *const f64,
        bs: PetscInt,
        blocks: *const PetscInt,
        nvec: PetscInt,
        near: *const f64,
        rtol: f64,
        options: *const c_char,
        newton: c_int,
        out: *mut *mut c_void,
    ) -> c_int;
    fn vc_ksp_solve(ctx: *mut c_void, b: *const f64, x: *mut f64, v: *mut VcSolve) -> c_int;
    fn vc_mult(ctx: *mut c_void, x: *const f64, y: *mut f64) -> c_int;
    fn vc_gather(
        send: *const f64,
        nsend: c_int,
        recv: *mut f64,
        counts: *const c_int,
        displs: *const c_int,
        every: c_int,
    ) -> c_int;
    #[allow(clippy::too_many_arguments)]
    fn vc_constrained_solve(
        ctx: *mut c_void,
        np: PetscInt,
        pdofs: *const PetscInt,
        pdirs: *const f64,
        ns: PetscInt,
        sdofs: *const PetscInt,
        smats: *const f64,
        rebuild: c_int,
        rtol: f64,
        of_start: c_int,
        b: *const f64,
        x: *mut f64,
        v: *mut VcSolve,
    ) -> c_int;
    fn vc_ksp_types(ctx: *mut c_void, ksp: *mut *const c_char, pc: *mut *const c_char) -> c_int;
    fn vc_galerkin_defect(ctx: *mut c_void, defect: *mut f64) -> c_int;
    fn vc_ksp_destroy(ctx: *mut c_void) -> c_int;
}

/// Whether PETSc is initialized in this process: None before the first use, then the
/// outcome of `PetscInitialize` (which cannot be tried twice), Some(Ok(false)) once finalized.
static STATE: Mutex<Option<std::result::Result<bool, i32>>> = Mutex::new(None);

/// PETSc's message for an error code of the shim's functions.
fn message(code: c_int) -> String {
    // SAFETY: vc_error_message returns a static NUL-terminated string for any code.
    unsafe { CStr::from_ptr(vc_error_message(code)) }
        .to_string_lossy()
        .into_owned()
}

/// A shim call's code as the run's error (exit 1): PETSc refused or failed at `what`.
fn check(code: c_int, what: &str) -> Result<()> {
    match code {
        0 => Ok(()),
        c => Err(Error::solve(format!(
            "PETSc failed at {what}: {} (error code {c})",
            message(c)
        ))),
    }
}

/// PETSc's error code for memory it could not get (`PETSC_ERR_MEM`).
const PETSC_ERR_MEM: c_int = 55;

/// The setup's code as the run's error: where options were given (the scene's or
/// `PETSC_OPTIONS`), a refusal is taken as theirs (exit 2, naming both); otherwise, or when
/// memory ran out, the setup failed (exit 1).
fn check_setup(code: c_int, options: &str) -> Result<()> {
    let env = std::env::var("PETSC_OPTIONS").unwrap_or_default();
    if code == 0 || code == PETSC_ERR_MEM || (options.trim().is_empty() && env.trim().is_empty()) {
        return check(code, "setting up the KSP of K_A");
    }
    Err(Error::input(format!(
        "PETSc refused the KSP of K_A with the options [solver.petsc] options = {options:?} \
         and PETSC_OPTIONS = {env:?}: {} (error code {code}); correct the option PETSc's \
         messages above name",
        message(code)
    )))
}

/// Initializes PETSc (and MPI through it) on the first call in the process; later calls
/// do nothing. PETSc reads the `PETSC_OPTIONS` environment variable here.
pub fn initialize() -> Result<()> {
    let mut state = STATE.lock().unwrap_or_else(|e| e.into_inner());
    let code = match *state {
        Some(Ok(true)) => return Ok(()),
        Some(Ok(false)) => {
            return Err(Error::solve(
                "PETSc was finalized in this process and cannot be initialized again",
            ))
        }
        Some(Err(code)) => code,
        // SAFETY: called once per process, under the lock.
        None => unsafe { vc_initialize() },
    };
    *state = Some(if code == 0 { Ok(true) } else { Err(code) });
    check(code, "PetscInitialize")
}

/// This process's rank and the number of ranks (MPI's world; PETSc initialized).
pub fn world() -> Result<(usize, usize)> {
    let (mut rank, mut size) = (0, 0);
    // SAFETY: PETSc (and MPI) is initialized (`initialize`); the shim writes two ints.
    check(unsafe { vc_world(&mut rank, &mut size) }, "MPI_Comm_size")?;
    Ok((rank as usize, size as usize))
}

/// The largest of every rank's `value` (collective: every rank calls it).
pub fn max_over_ranks(mut value: i32) -> Result<i32> {
    // SAFETY: PETSc (and MPI) is initialized; the shim reads and writes one int.
    check(unsafe { vc_max_over_ranks(&mut value) }, "MPI_Allreduce")?;
    Ok(value)
}

/// Rank 0's `value` (collective: every rank calls it).
pub fn from_rank0(mut value: i32) -> Result<i32> {
    // SAFETY: PETSc (and MPI) is initialized; the shim reads and writes one int.
    check(unsafe { vc_from_rank0(&mut value) }, "MPI_Bcast")?;
    Ok(value)
}

/// The largest of every rank's `value` (collective: every rank calls it).
pub fn max_real_over_ranks(mut value: f64) -> Result<f64> {
    // SAFETY: PETSc (and MPI) is initialized; the shim reads and writes one double.
    check(
        unsafe { vc_max_real_over_ranks(&mut value) },
        "MPI_Allreduce",
    )?;
    Ok(value)
}

/// Every rank's `values` summed on rank 0, rank by rank in their order, so that a run
/// on as many ranks sums them alike (collective: every rank calls it with as many); the
/// rank's own `values` elsewhere.
pub fn sum_at_first(values: &[f64]) -> Result<Vec<f64>> {
    let (rank, size) = world()?;
    let n = values.len();
    let counts = vec![n as c_int; size];
    let displs: Vec<c_int> = (0..size).map(|r| (r * n) as c_int).collect();
    let mut all = vec![0.0; if rank == 0 { n * size } else { 0 }];
    gather(values, &mut all, (&counts, &displs), false)?;
    if rank != 0 {
        return Ok(values.to_vec());
    }
    let mut sums = vec![0.0; n];
    for part in all.chunks_exact(n.max(1)) {
        sums.iter_mut().zip(part).for_each(|(s, v)| *s += v);
    }
    Ok(sums)
}

/// Rank 0's `bytes` (collective: every rank calls it with as many), in pieces of at most
/// 2^30 bytes (MPI counts in an `int`).
pub fn from_rank0_bytes(bytes: &mut [u8]) -> Result<()> {
    for piece in bytes.chunks_mut(1 << 30) {
        let n = piece.len() as c_int;
        // SAFETY: PETSc (and MPI) is initialized; the shim reads and writes the n bytes.
        check(
            unsafe { vc_from_rank0_bytes(piece.as_mut_ptr().cast(), n) },
            "MPI_Bcast",
        )?;
    }
    Ok(())
}

/// `recv` ← each rank's `send`, rank r's at displs[r] (counts[r] values, `cut`), on every
/// rank where `every`, else on rank 0 alone (collective: every rank calls it; `recv`
/// holds the sum of the counts where it receives).
fn gather(send: &[f64], recv: &mut [f64], cut: (&[c_int], &[c_int]), every: bool) -> Result<()> {
    let (counts, displs) = cut;
    // SAFETY: send holds this rank's count; recv, where it receives, the sum of counts,
    // which the displacements cut in rank order; MPI writes recv within the call.
    let code = unsafe {
        vc_gather(
            send.as_ptr(),
            send.len() as c_int,
            recv.as_mut_ptr(),
            counts.as_ptr(),
            displs.as_ptr(),
            c_int::from(every),
        )
    };
    check(
        code,
        if every {
            "MPI_Allgatherv"
        } else {
            "MPI_Gatherv"
        },
    )
}

/// Ends every rank with exit status `code` (`MPI_Abort`).
pub fn abort(code: i32) {
    // SAFETY: PETSc (and MPI) is initialized by whoever has several ranks to end.
    unsafe { vc_abort(code) }
}

/// Finalizes PETSc (and MPI) if it was initialized; every [`Krylov`] must be dropped
/// before. Called once, at the end of `main`.
pub fn finalize() {
    let mut state = STATE.lock().unwrap_or_else(|e| e.into_inner());
    if *state == Some(Ok(true)) {
        // SAFETY: PETSc is initialized and no object of ours is alive (the caller's promise).
        let code = unsafe { vc_finalize() };
        if code != 0 {
            crate::errln!("warning: PetscFinalize: {}", message(code));
        }
        *state = Some(Ok(false));
    }
}

/// The options a [`Krylov`] solve runs with.
#[derive(Clone, Debug)]
pub struct KrylovSettings {
    /// `[solver.petsc] options`: PETSc's command-line syntax, e.g. "-ksp_monitor".
    pub options: String,
    /// The relative tolerance before the options ([`DEFAULT_RTOL`]; `-ksp_rtol` changes it).
    pub rtol: f64,
    /// What the KSP is for: K_A's linear steps (false), or the active set's Newton systems
    /// (true, the only KSP `solve_constrained` takes), whose multigrid is then set up at once
    /// in place of K_A's, which would never serve (one GAMG setup less: half of the 25.6 s
    /// that `-log_view` gave the two on the fine plate; its peak 2.58 → 2.39 GB).
    pub newton: bool,
}

/// K_A in a PETSc matrix and its KSP, set up once per run.
pub struct Krylov {
    ctx: *mut c_void,
    n: usize,
    /// The KSP's and the PC's type after the options (`cg`, `gamg` by default).
    pub ksp_type: String,
    pub pc_type: String,
    /// The options the scene passed.
    pub options: String,
    /// Whether K_A's solve in progress is to be given up (`Krylov::give_up_when`).
    give_up: Option<GiveUp>,
    /// Where the caller's places stand among PETSc's rows (its unknowns', or those it holds
    /// alone: `Layout::placed`), and this rank's rows among them; where the calls
    /// need one, a vector of this rank's rows (a right side's, a product's): on several
    /// ranks, or for a right side or a product that is not a whole vector of the caller's
    /// (`solve_constrained`, `mult_at`); on several ranks, a solve's x, and a product's,
    /// in this rank's rows too.
    layout: Layout,
    mine: std::ops::Range<usize>,
    own: Vec<f64>,
    own_x: Vec<f64>,
    /// On several ranks, how this rank's rows of a solution reach the ranks that read them.
    spread: Option<Spread>,
    /// How `values_at` collects the values at the dofs it was last asked for (the active
    /// set asks for the same at every product): made once, not at every product.
    at: Option<AtDofs>,
    /// On several ranks, for the Newton systems: this rank's rows of the step matrix, which
    /// the shim reads as its copy of K until the KSP is destroyed (it keeps none).
    _rows: Option<Csr<'static>>,
}

/// The question `Krylov::solve` asks at every iteration: give the solve up now?
type GiveUp = Box<dyn Fn() -> bool>;

impl Krylov {
    /// The KSP of `matrix` (the free-dof step matrix of `disc`: whole on one rank, this
    /// rank's columns on several), its near-null space from `disc`'s nodes. On one of
    /// several ranks, `own` is the layout of `disc` over the ranks where it was made
    /// already, and the rank's rows of K_A where they were taken out of `disc`
    /// (`Ranks::keep_own_columns`: `matrix` then holds no more than K_A's diagonal).
    pub fn new(
        matrix: &Sparse,
        own: Option<(Layout, Option<Csr<'static>>)>,
        disc: &Discretization,
        settings: &KrylovSettings,
        reads: Reads<'_>,
    ) -> Result<Self> {
        initialize()?;
        // The length of the caller's vectors.
        let n = match reads.held {
            true => reads.dofs.len(),
            false => matrix.nrows(),
        };
        let (rank, size) = world()?;
        let (layout, rows) = match own {
            Some(own) => own,
            None => (Layout::new(disc, disc.cell_source(), size)?, None),
        };
        let csr = match rows {
            Some(rows) => rows,
            None => layout.rows_of(matrix, rank)?,
        };
        let blocks = layout::petsc_ints(&layout.blocks)?;
        let mine = layout.blocks[rank]..layout.blocks[rank + 1];
        let modes = rigid_body_modes(disc, &layout, mine.clone(), sum_over_ranks)?;
        let (nvec, near) = (modes.len(), modes.concat());
        let options = CString::new(settings.options.as_str())
            .map_err(|_| Error::input("[solver.petsc] options: a NUL character"))?;
        let mut ctx = std::ptr::null_mut();
        // SAFETY: the arrays hold m + 1, nnz, nnz, size + 1 and nvec times m values as the
        // shim reads them (m this rank's count of rows, n on one rank; nnz its entries);
        // PETSc copies them, and on several ranks for the Newton systems the shim
        // reads cols and vals until the KSP is destroyed: the Krylov keeps them (`_rows`),
        // their buffers never moved.
        let code = unsafe {
            vc_ksp_create(
                matrix.nrows() as PetscInt,
                csr.rowptr.as_ptr(),
                csr.cols.as_ptr(),
                csr.vals.as_ptr(),
                block_size(disc) as PetscInt,
                blocks.as_ptr(),
                nvec as PetscInt,
                near.as_ptr(),
                settings.rtol,
                options.as_ptr(),
                settings.newton.into(),
                &mut ctx,
            )
        };
        check_setup(code, &settings.options)?;
        let (mut ksp, mut pc) = (std::ptr::null(), std::ptr::null());
        // SAFETY: ctx is a live KSP; the names are PETSc's static strings.
        check(
            unsafe { vc_ksp_types(ctx, &mut ksp, &mut pc) },
            "KSPGetType",
        )?;
        let name = |p: *const c_char| unsafe { CStr::from_ptr(p) }.to_string_lossy().into();
        let spread = match layout.permutes() {
            true => Some(Spread::new(&layout, rank, reads)?),
            false => None,
        };
        let layout = match reads.held {
            true => layout.placed(reads.dofs),
            false => layout,
        };
        Ok(Krylov {
            ctx,
            n,
            ksp_type: name(ksp),
            pc_type: name(pc),
            options: settings.options.clone(),
            give_up: None,
            mine,
            own: Vec::new(),
            own_x: Vec::new(),
            spread,
            at: None,
            layout,
            _rows: (size > 1 && settings.newton).then(|| csr.into_owned()),
        })
    }

    /// From now on K_A's solve in progress is given up where `now` says so on any rank, on
    /// every rank at the same Krylov iteration ([`Solve::given_up`]).
    pub fn give_up_when(&mut self, now: impl Fn() -> bool + 'static) {
        self.give_up = Some(Box::new(now));
    }

    /// w ← K_A⁻¹ b from the initial guess in w: the Krylov iterations, the final residual
    /// norm and, where the KSP did not converge, its reason; where the solve was given up
    /// (`give_up_when`), w holds an iterate.
    pub fn solve(&mut self, b: &[f64], w: &mut [f64]) -> Result<Solve> {
        assert!(b.len() == self.n && w.len() == self.n);
        // SAFETY: b and x hold this rank's count of rows; PETSc reads the one and writes
        // the other within the call.
        self.solved("KSPSolve", (b, &[], &[]), w, |ctx, b, w, v| unsafe {
            vc_ksp_solve(ctx, b, w, v)
        })
    }

    /// This rank's rows of the right side b but at `dofs`, where it is `values` (`dofs` −1:
    /// none), in PETSc's order: b itself where it is (one rank, nothing at `dofs`), else
    /// `own` filled.
    fn own_rows<'a>(&'a mut self, (b, dofs, values): RightSide<'a>) -> &'a [f64] {
        let mine = self.mine.clone();
        match &self.spread {
            None if dofs.is_empty() => return b,
            None => {
                self.own.clear();
                self.own.extend_from_slice(b);
            }
            Some(spread) => {
                spread.own_of(b, &mut self.own);
            }
        }
        for (&d, &value) in dofs.iter().zip(values).filter(|(&d, _)| d >= 0) {
            if let Some(r) = Some(self.layout.row(d as usize)).filter(|r| mine.contains(r)) {
                self.own[r - mine.start] = value;
            }
        }
        &self.own
    }

    /// A shim solve, `call(ctx, b, x, v)` on this rank's rows of the right side (b at
    /// `dofs` replaced by `values`: `own_rows`) and of w, both in the order of PETSc's rows
    /// (on several ranks, x's values go back to w, and the values of others' rows that this
    /// rank reads come to it: `Spread`), which asks at every iteration whether
    /// to give the solve up (where `give_up_when` said how: the shim's `requested` and, in
    /// v, a pointer to the question that lives through the call) and fills v: what it did,
    /// or PETSc's error at `what`.
    fn solved(
        &mut self,
        what: &str,
        b: RightSide<'_>,
        w: &mut [f64],
        call: impl FnOnce(*mut c_void, *const f64, *mut f64, *mut VcSolve) -> c_int,
    ) -> Result<Solve> {
        let b = self.own_rows(b).as_ptr();
        let mut v = VcSolve {
            requested: None,
            flag: std::ptr::null_mut(),
            its: 0,
            reason: 0,
            rnorm: 0.0,
            given_up: 0,
        };
        if let Some(now) = &self.give_up {
            v.requested = Some(requested);
            v.flag = now as *const GiveUp as *mut c_void;
        }
        let x = match &self.spread {
            None => w.as_mut_ptr(),
            Some(spread) => {
                spread.own_of(w, &mut self.own_x);
                self.own_x.as_mut_ptr()
            }
        };
        check(call(self.ctx, b, x, &mut v), what)?;
        if let Some(spread) = &self.spread {
            spread.put(&self.own_x, w);
            spread.halo.run(w)?;
        }
        Ok(Solve {
            given_up: v.given_up != 0,
            ..Solve::of(v.its, v.reason, v.rnorm)
        })
    }
}

/// What a rank of several reads of a solution and of a right side besides its own rows: the
/// unknowns `dofs` at every solve. Where `held` (a rank whose history holds some dofs
/// alone, `time_loop`: a follower, and rank 0 whose frames are in pieces), its vectors (a solve's b and w, a product's x) hold the unknowns
/// `dofs` alone, in their order (increasing: its history's, its own rows and Γ3's), and
/// not every unknown; elsewhere they are whole, `dofs` are Γ3's unknowns (which the active
/// set's decisions read on every rank), and every unknown comes to the rank once a step is
/// solved (its history holds every dof: rank 0 whose frames are not in pieces, and a
/// follower where K_A is not the step matrix).
#[derive(Clone, Copy, Debug)]
pub struct Reads<'a> {
    pub dofs: &'a [usize],
    pub held: bool,
}

/// How a rank's rows of a solution reach the ranks that read them: its rows' unknowns in
/// PETSc's order; at every solve, the unknowns it reads (`Reads::dofs`) by an `Exchange` (a
/// product with K takes the other ranks' values its rows read itself: `vc_mult`); once a
/// step is solved, every rank's rows gathered whole in PETSc's order on rank 0 where its
/// history holds every dof (`Whole`), or on every rank where the followers' histories hold
/// every dof too (not `Reads::held`), where each rank's count and first row among them say.
struct Spread {
    unknowns: Vec<u32>,
    /// The unknowns of this rank's rows (`unknowns` before they were placed), for what a
    /// caller holds by the unknowns' numbering (`Krylov::gather_at_first`).
    numbered: Vec<u32>,
    halo: Exchange,
    first: bool,
    /// On rank 0 where its vectors hold some unknowns alone (`Reads::held`), the layout of
    /// every unknown, which puts what its checkpoints gather in the unknowns' order
    /// (`Krylov::gather_at_first`; the Krylov's own is placed: `Layout::placed`).
    every: Option<Layout>,
    whole: Whole,
    counts: Vec<c_int>,
    displs: Vec<c_int>,
}

/// Who gathers every rank's rows once a step is solved (`Krylov::complete`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Whole {
    /// Nobody: every rank holds its history at its reach (`Holds::Local`), rank 0 too,
    /// whose checkpoints gather what they save (`Krylov::gather_at_first`).
    Nobody,
    /// Rank 0 alone: a follower holds its history at its reach (`Holds::Local`).
    First,
    /// Every rank: a follower's history holds every dof of u_n.
    Every,
}

impl Spread {
    /// Made by every rank at once: the exchange is collective.
    fn new(layout: &Layout, rank: usize, reads: Reads) -> Result<Spread> {
        let n = layout.n_unknowns();
        let mut unknowns = layout.unknowns_of(rank);
        // What this rank reads at every solve of the others' rows: the unknowns it reads
        // whose rows are not its own, increasing (no flag of every unknown).
        let mine = layout.blocks[rank]..layout.blocks[rank + 1];
        let mut halo: Vec<u32> = (reads.dofs.iter())
            .filter(|&&i| i < n && !mine.contains(&layout.row(i)))
            .map(|&i| i as u32)
            .collect();
        halo.sort_unstable();
        halo.dedup();
        let mut halo = Exchange::new(layout, halo)?;
        let numbered = unknowns.clone();
        if reads.held {
            // The caller's vectors hold `reads.dofs` alone: each unknown at its place there.
            let place = |i: u32| crate::fem::place(Some(reads.dofs), i as usize) as u32;
            unknowns.iter_mut().for_each(|i| *i = place(*i));
            halo.place(place);
        }
        // The most any rank receives: 2, a follower whose history holds every dof; 1, rank
        // 0 that does; 0, none (each rank holds its reach alone).
        let receives = match (rank, reads.held) {
            (_, true) => 0,
            (0, false) => 1,
            (_, false) => 2,
        };
        let whole = match max_over_ranks(receives)? {
            0 => Whole::Nobody,
            1 => Whole::First,
            _ => Whole::Every,
        };
        debug_assert!(
            whole != Whole::Every || !reads.held,
            "a rank that holds its reach alone receives no whole solution"
        );
        let counts: Vec<c_int> = (layout.blocks.windows(2))
            .map(|b| (b[1] - b[0]) as c_int)
            .collect();
        Ok(Spread {
            unknowns,
            numbered,
            halo,
            first: rank == 0,
            every: (rank == 0 && reads.held).then(|| layout.clone()),
            whole,
            displs: exchange::displacements(&counts),
            counts,
        })
    }

    /// out ← v at this rank's rows' unknowns, in PETSc's order.
    fn own_of(&self, v: &[f64], out: &mut Vec<f64>) {
        out.clear();
        out.extend(self.unknowns.iter().map(|&i| v[i as usize]));
    }

    /// v at this rank's rows' unknowns ← `own`, in PETSc's order (what `own_of` took).
    fn put(&self, own: &[f64], v: &mut [f64]) {
        (self.unknowns.iter())
            .zip(own)
            .for_each(|(&i, &x)| v[i as usize] = x);
    }

    /// Whether this rank receives every rank's rows of a solved step (`Krylov::complete`).
    fn receives(&self) -> bool {
        match self.whole {
            Whole::Nobody => false,
            Whole::First => self.first,
            Whole::Every => true,
        }
    }
}

/// How the values of a product at some dofs reach every rank (`Krylov::values_at`): the
/// positions k of the dofs that exist (≥ 0) ordered by the rank that holds their rows, those
/// rows in that order, and each rank's count and first place among them.
struct AtDofs {
    dofs: Vec<i32>,
    order: Vec<usize>,
    rows: Vec<usize>,
    counts: Vec<c_int>,
    displs: Vec<c_int>,
}

impl AtDofs {
    fn new(layout: &Layout, dofs: &[i32]) -> AtDofs {
        let row = |k: usize| layout.row(dofs[k] as usize);
        let mut order: Vec<usize> = (0..dofs.len()).filter(|&k| dofs[k] >= 0).collect();
        order.sort_by_key(|&k| layout.rank_of_row(row(k)));
        let rows: Vec<usize> = order.iter().map(|&k| row(k)).collect();
        let mut counts = vec![0; layout.blocks.len() - 1];
        rows.iter()
            .for_each(|&r| counts[layout.rank_of_row(r)] += 1);
        let displs = exchange::displacements(&counts);
        AtDofs {
            dofs: dofs.to_vec(),
            order,
            rows,
            counts,
            displs,
        }
    }
}

/// A right side as a shim solve takes it: b, but at `dofs` (−1: none), where it is
/// `values` (the constrained system's Π(b − f_slip), b itself but at Γ3's nodes).
type RightSide<'a> = (&'a [f64], &'a [i32], &'a [f64]);

/// A shim solve's request and outcome (shim.c's `VcSolve`).
#[repr(C)]
struct VcSolve {
    requested: Option<unsafe extern "C" fn(*mut c_void) -> c_int>,
    flag: *mut c_void,
    its: PetscInt,
    reason: c_int,
    rnorm: f64,
    given_up: c_int,
}

/// Whether the solve is to be given up: the shim's question, at every Krylov iteration.
///
/// # Safety
/// `flag` points to a live [`GiveUp`].
unsafe extern "C" fn requested(flag: *mut c_void) -> c_int {
    // SAFETY: the caller's promise (`Krylov::solved` passes the Krylov's own).
    let now = unsafe { &*(flag as *const GiveUp) };
    c_int::from(now())
}

/// The nodal terms of a constrained system (`Krylov::solve_constrained`), flat as the shim
/// reads them: directions removed, three dofs (−1: none) and three coefficients each,
/// orthonormal within a node, so that applying them one after the other is the orthogonal
/// projection Π onto the unconstrained directions; and 3 × 3 stiffness blocks S (row-major)
/// on three dofs each.
#[derive(Clone, Copy, Debug)]
pub struct NodalTerms<'a> {
    pub removed_dofs: &'a [PetscInt],
    pub removed: &'a [f64],
    pub stiffness_dofs: &'a [PetscInt],
    pub stiffness: &'a [f64],
}

/// What a constrained system's multigrid is built from (`Krylov::solve_constrained`); the
/// shim's `rebuild` codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hierarchy {
    /// The last system's, as it stands.
    Last = 0,
    /// This system's, from K's coarse operators: a step's first system, so that a step
    /// depends only on what a checkpoint holds.
    FromK = 1,
    /// This system's, by an update of the last one's where the matrices differ.
    Updated = 2,
}

/// Where a constrained solve stops (`Krylov::solve_constrained`): at a residual of
/// relative tolerance to the right side, PETSc's default, or to the initial residual
/// (`KSPConvergedDefaultSetUIRNorm`), for the inexact systems of a Newton iteration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    OfRhs(f64),
    OfStart(f64),
}

impl Krylov {
    /// y ← (K x) at `dofs`, `y[k]` at `dofs[k]` (0 where it is −1), on every rank, x exact
    /// in this rank's rows: each rank computes its own rows of K x from its rows of x and
    /// the others' values its rows read (which the shim takes from the ranks that hold
    /// them), and the values at `dofs` come from the ranks that hold them (`values_at`),
    /// where the whole product crossed to every rank.
    pub fn mult_at(&mut self, x: &[f64], dofs: &[i32], y: &mut [f64]) -> Result<()> {
        assert!(x.len() == self.n && dofs.len() == y.len());
        self.own.resize(self.mine.len(), 0.0);
        let x = match &self.spread {
            Some(spread) => {
                spread.own_of(x, &mut self.own_x);
                &self.own_x
            }
            None => x,
        };
        // SAFETY: x and own hold this rank's count of rows; PETSc reads x and writes own
        // within the call.
        let out = unsafe { vc_mult(self.ctx, x.as_ptr(), self.own.as_mut_ptr()) };
        check(out, "MatMult")?;
        self.values_at(dofs, y)
    }

    /// y[k] ← `own`'s value at dofs[k] (0 where it is −1), from the rank that holds the
    /// row: on several ranks each sends its values, in the order of `dofs`, to all.
    fn values_at(&mut self, dofs: &[i32], y: &mut [f64]) -> Result<()> {
        if self.at.as_ref().is_none_or(|at| at.dofs != dofs) {
            self.at = Some(AtDofs::new(&self.layout, dofs));
        }
        let at = self.at.as_ref().expect("made above");
        let mine: Vec<f64> = (at.rows.iter())
            .filter(|r| self.mine.contains(r))
            .map(|r| self.own[r - self.mine.start])
            .collect();
        let mut all = vec![0.0; at.order.len()];
        match self.layout.permutes() {
            true => gather(&mine, &mut all, (&at.counts, &at.displs), true)?,
            false => all = mine,
        }
        y.fill(0.0);
        at.order
            .iter()
            .zip(all)
            .for_each(|(&k, value)| y[k] = value);
        Ok(())
    }

    /// w ← the solution of Π(K + S)Π w + (I − Π) w = Π b, from the initial guess in w, by
    /// the KSP's method (CG by default) on the assembled matrix Π(K + S)Π + (I − Π)(K +
    /// S)(I − Π), which has the same solution, preconditioned by GAMG built from one such
    /// matrix, as `hierarchy` says, on the aggregates and interpolation GAMG made of K.
    /// Stopped at `tolerance`. The right side Π b is given as b but at Γ3's nodes' `dofs`
    /// (−1: none), where it is `values`: Π acts there alone.
    pub fn solve_constrained(
        &mut self,
        terms: NodalTerms<'_>,
        (b, dofs, values): (&[f64], &[i32], &[f64]),
        w: &mut [f64],
        tolerance: Tolerance,
        hierarchy: Hierarchy,
    ) -> Result<Solve> {
        let (rtol, of_start) = match tolerance {
            Tolerance::OfRhs(rtol) => (rtol, false),
            Tolerance::OfStart(eta) => (eta, true),
        };
        assert!(b.len() == self.n && w.len() == self.n && dofs.len() == values.len());
        let (np, ns) = (terms.removed_dofs.len() / 3, terms.stiffness_dofs.len() / 3);
        assert!(terms.removed.len() == 3 * np && terms.stiffness.len() == 9 * ns);
        // The terms' dofs as PETSc's rows (−1, none, stays).
        let rows = |dofs: &[PetscInt]| -> Vec<PetscInt> {
            let row = |&d: &PetscInt| match d {
                d if d < 0 => d,
                d => self.layout.row(d as usize) as PetscInt,
            };
            dofs.iter().map(row).collect()
        };
        let (removed_rows, stiffness_rows) = (rows(terms.removed_dofs), rows(terms.stiffness_dofs));
        // SAFETY: the arrays hold what the counts say, b and x this rank's count of rows;
        // PETSc reads them and writes x within the call, and keeps no pointer after it.
        let what = "KSPSolve of the constrained system";
        self.solved(what, (b, dofs, values), w, |ctx, b, w, v| unsafe {
            vc_constrained_solve(
                ctx,
                np as PetscInt,
                removed_rows.as_ptr(),
                terms.removed.as_ptr(),
                ns as PetscInt,
                stiffness_rows.as_ptr(),
                terms.stiffness.as_ptr(),
                hierarchy as c_int,
                rtol,
                c_int::from(of_start),
                b,
                w,
                v,
            )
        })
    }

    /// The largest of every rank's `x` (collective where the rows are spread over ranks);
    /// `x` on one rank.
    pub fn largest(&self, x: f64) -> Result<f64> {
        match self.layout.permutes() {
            true => max_real_over_ranks(x),
            false => Ok(x),
        }
    }

    /// v at the unknowns this rank reads (`Reads`) ← their values from the ranks that hold
    /// their rows, v exact in this rank's own rows (a right side each rank made its own
    /// entries of); nothing on one rank.
    pub fn share(&self, v: &mut [f64]) -> Result<()> {
        match &self.spread {
            Some(spread) => spread.halo.run(v),
            None => Ok(()),
        }
    }

    /// A solved step's w at every unknown on rank 0 where its history holds every dof, and
    /// on every rank where the followers' histories do (not `Reads::held`), from the ranks
    /// that hold their rows (collective, once a step): each rank's rows gathered into w in
    /// PETSc's order, then put in the unknowns' order in place
    /// (`Layout::to_unknowns_order`); nothing on one rank, nor where every rank holds its
    /// reach alone (`Whole::Nobody`).
    pub fn complete(&mut self, w: &mut [f64]) -> Result<()> {
        let Some(spread) = self.spread.as_ref().filter(|s| s.whole != Whole::Nobody) else {
            return Ok(());
        };
        spread.own_of(w, &mut self.own_x);
        let cut = (spread.counts.as_slice(), spread.displs.as_slice());
        let every = spread.whole == Whole::Every;
        match spread.receives() {
            true => {
                gather(&self.own_x, w, cut, every)?;
                self.layout.to_unknowns_order(w);
            }
            false => gather(&self.own_x, &mut [], cut, every)?,
        }
        Ok(())
    }

    /// The `n` unknowns' values on rank 0 (and on one rank), each rank giving `value` of the
    /// unknowns of its own rows (collective: every rank calls it): Some there, in the
    /// unknowns' order, None elsewhere. What a checkpoint saves of the values that each
    /// rank holds in its part alone (`history::History::gathered`).
    pub fn gather_at_first(
        &self,
        n: usize,
        value: &dyn Fn(usize) -> f64,
    ) -> Result<Option<Vec<f64>>> {
        let Some(spread) = &self.spread else {
            return Ok(Some((0..n).map(value).collect()));
        };
        let mine: Vec<f64> = spread.numbered.iter().map(|&i| value(i as usize)).collect();
        let cut = (spread.counts.as_slice(), spread.displs.as_slice());
        if !spread.first {
            gather(&mine, &mut [], cut, false)?;
            return Ok(None);
        }
        let layout = spread.every.as_ref().unwrap_or(&self.layout);
        let mut all = vec![0.0; layout.n_unknowns()];
        gather(&mine, &mut all, cut, false)?;
        layout.to_unknowns_order(&mut all);
        Ok(Some(all))
    }

    /// `kept` ← what of w this rank restores a step given up from (`restore`): on a rank of
    /// several that holds w exact where it reads it alone, its own rows, in PETSc's order
    /// (the others it reads come back from the ranks that hold them); elsewhere every
    /// value (one rank, rank 0, a follower whose history holds every dof).
    pub fn keep(&self, w: &[f64], kept: &mut Vec<f64>) {
        match &self.spread {
            Some(spread) if !spread.receives() => spread.own_of(w, kept),
            _ => {
                kept.clear();
                kept.extend_from_slice(w);
            }
        }
    }

    /// w ← what `keep` kept in `kept`, and on several ranks the values this rank reads of
    /// the others' rows from the ranks that hold them (collective): w as it was, wherever
    /// it is exact.
    pub fn restore(&self, kept: &[f64], w: &mut [f64]) -> Result<()> {
        match &self.spread {
            Some(spread) if !spread.receives() => spread.put(kept, w),
            _ => w.copy_from_slice(kept),
        }
        self.share(w)
    }

    /// The largest |x_i| over the ranks' own rows (`f64::max`: NaN skipped), x exact in
    /// this rank's (collective on several ranks).
    pub fn largest_abs(&self, x: &[f64]) -> Result<f64> {
        let abs = |i: usize| x[i].abs();
        match &self.spread {
            Some(spread) => {
                let mine = (spread.unknowns.iter()).fold(0.0, |m, &i| abs(i as usize).max(m));
                max_real_over_ranks(mine)
            }
            None => Ok((0..x.len()).fold(0.0, |m, i| abs(i).max(m))),
        }
    }

    /// How far the Newton systems' multigrid is from the Galerkin products of its fine
    /// matrix: the largest relative difference (Frobenius) between a coarse operator and
    /// the product of the level above, computed anew. The coarse operators are updated in
    /// place, not recomputed (`Hierarchy`); this is their check (tests/petsc). 0 before the
    /// first Newton system and where the options chose another preconditioner than GAMG.
    pub fn galerkin_defect(&mut self) -> Result<f64> {
        let mut defect = 0.0;
        // SAFETY: ctx is a live KSP; the shim writes one value.
        check(
            unsafe { vc_galerkin_defect(self.ctx, &mut defect) },
            "the Galerkin check",
        )?;
        Ok(defect)
    }
}

impl Solve {
    fn of(its: PetscInt, reason: c_int, rnorm: f64) -> Self {
        // SAFETY: KSPConvergedReasons names every reason PETSc returns, statically.
        let name = || unsafe { CStr::from_ptr(vc_reason_name(reason)) };
        Solve {
            iterations: its as usize,
            residual: rnorm,
            failed: (reason < 0).then(|| name().to_str().unwrap_or("DIVERGED")),
            given_up: false,
        }
    }
}

/// What one KSP solve did.
#[derive(Clone, Copy, Debug)]
pub struct Solve {
    pub iterations: usize,
    /// The final residual norm (preconditioned, unless the options changed the norm).
    pub residual: f64,
    /// The `KSPConvergedReason` by name (`DIVERGED_ITS`, …) where it is negative.
    pub failed: Option<&'static str>,
    /// The solve was given up on request (`Krylov::give_up_when`; `failed` then names
    /// `DIVERGED_NULL`).
    pub given_up: bool,
}

impl Drop for Krylov {
    fn drop(&mut self) {
        // SAFETY: ctx came from vc_ksp_create and is destroyed once, before PetscFinalize.
        let code = unsafe { vc_ksp_destroy(self.ctx) };
        if code != 0 {
            crate::errln!("warning: destroying the KSP: {}", message(code));
        }
    }
}

/// d where every node's unknowns are d consecutive ones starting at a multiple of d, or
/// none (a node clamped on Γ1); 1 otherwise.
fn block_size(disc: &Discretization) -> usize {
    let (d, unknown) = (disc.dim, |g: usize| disc.free.unknown(g));
    let blocked = (0..disc.free.dofs() / d).all(|p| match unknown(d * p) {
        None => (1..d).all(|c| unknown(d * p + c).is_none()),
        Some(first) => first % d == 0 && (1..d).all(|c| unknown(d * p + c) == Some(first + c)),
    });
    if blocked {
        d
    } else {
        1
    }
}

/// GAMG's near-null space: the rigid-body modes on the free dofs at the rows `mine` (a
/// rank's, in the order of `layout`'s rows), about the nodes' centroid, orthonormalized over
/// every rank's rows (modified Gram–Schmidt, twice; each inner product the rank's part of it
/// summed over the ranks by `sum`, every rank's call at once: `sum_over_ranks` in a run):
/// d(d + 1)/2 vectors of `mine.len()` values (fewer where a mode vanishes on the free dofs).
/// A rank makes and holds its own rows of them alone; on one process they are the whole.
pub fn rigid_body_modes(
    disc: &Discretization,
    layout: &Layout,
    mine: std::ops::Range<usize>,
    mut sum: impl FnMut(f64) -> Result<f64>,
) -> Result<Vec<Vec<f64>>> {
    let d = disc.dim;
    let centre = disc.nodes.centre();
    // The global dof of each of the rank's rows: the modes read the places of its own
    // unknowns' nodes alone (a follower keeps no others: `fem::Places`).
    let dofs: Vec<usize> = match mine.is_empty() {
        true => Vec::new(),
        false => (layout.unknowns_of(layout.rank_of_row(mine.start)).iter())
            .map(|&u| disc.free.global(u as usize))
            .collect(),
    };
    let modes = d * (d + 1) / 2;
    let mut v: Vec<Vec<f64>> = (0..modes)
        .map(|k| {
            let value = |g: usize| {
                let (i, x) = (g / d, disc.nodes[g / d]);
                let y = [0, 1, 2].map(|c| x[c] - centre[c]);
                // Mode k at the node (relative to the centre), in the node's dofs.
                disc.frames.to_dofs(i, rigid_mode(k, d, y))[g % d]
            };
            dofs.iter().map(|&g| value(g)).collect()
        })
        .collect();
    let mut dot = |a: &[f64], b: &[f64]| sum(dot(a, b));
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for m in v.iter_mut() {
        let norm0 = dot(m, m)?.sqrt();
        for _ in 0..2 {
            for q in &basis {
                let p = dot(m, q)?;
                m.iter_mut().zip(q).for_each(|(a, b)| *a -= p * b);
            }
        }
        let norm = dot(m, m)?.sqrt();
        if norm > 1e-10 * norm0 {
            basis.push(m.iter().map(|a| a / norm).collect());
        }
    }
    Ok(basis)
}

/// The sum of every rank's `x`, added in rank order, so that a rank count gives the same
/// bits run after run (collective: every rank calls it); `x` on one rank.
fn sum_over_ranks(x: f64) -> Result<f64> {
    let size = world()?.1;
    if size == 1 {
        return Ok(x);
    }
    let counts = vec![1; size];
    let mut all = vec![0.0; size];
    gather(
        &[x],
        &mut all,
        (&counts, &exchange::displacements(&counts)),
        true,
    )?;
    Ok(all.into_iter().fold(0.0, |sum, x| sum + x))
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
