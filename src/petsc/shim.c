/* The C side of viscontact's PETSc binding (src/petsc/mod.rs): a handful of functions with
 * plain C types, so that PETSc's macros (PetscCall, PETSC_COMM_SELF, which is a pointer in
 * Open MPI) and its types stay on this side. Every function returns a PetscErrorCode (0:
 * success); vc_error_message turns one into PETSc's text. K_A's own KSP spans the ranks an MPI
 * launcher started (PETSC_COMM_WORLD: each rank holds a contiguous block of its rows, and
 * gets its rows of the solution back: the caller sends them where they are read), and so
 * do the active set's Newton systems, whose matrix each rank assembles for its own rows. */
#include <petscksp.h>

#if defined(VC_REQUIRE_32BIT_INDICES) && defined(PETSC_USE_64BIT_INDICES)
  #error "viscontact's PETSc binding declares PetscInt as 32 bits: use a PETSc without --with-64-bit-indices"
#endif

int vc_initialize(void)
{
  /* The run takes SIGINT and SIGTERM in a thread of its own (src/run/interrupt.rs): PETSc
   * installs no handlers of its own. Set before PetscInitialize, which keeps the option and
   * reads PETSC_OPTIONS on top of it. */
  PetscCall(PetscOptionsSetValue(NULL, "-no_signal_handler", NULL));
  PetscCall(PetscInitializeNoArguments());
  return 0;
}

int vc_finalize(void) { return PetscFinalize(); }

const char *vc_error_message(int code)
{
  const char *text = NULL;
  PetscErrorMessage((PetscErrorCode)code, &text, NULL);
  return text ? text : "unknown PETSc error";
}

const char *vc_reason_name(int reason) { return KSPConvergedReasons[reason]; }

/* This process's rank and the number of ranks in PETSC_COMM_WORLD. */
int vc_world(int *rank, int *size)
{
  PetscCallMPI(MPI_Comm_rank(PETSC_COMM_WORLD, rank));
  PetscCallMPI(MPI_Comm_size(PETSC_COMM_WORLD, size));
  return 0;
}

/* *value ← the largest of every rank's *value (collective). */
int vc_max_over_ranks(int *value)
{
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, value, 1, MPI_INT, MPI_MAX, PETSC_COMM_WORLD));
  return 0;
}

/* *value ← the largest of every rank's *value (collective). */
int vc_max_real_over_ranks(double *value)
{
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, value, 1, MPI_DOUBLE, MPI_MAX, PETSC_COMM_WORLD));
  return 0;
}

/* bytes[0..n) ← rank 0's (collective; every rank gives the same n). */
int vc_from_rank0_bytes(char *bytes, int n)
{
  PetscCallMPI(MPI_Bcast(bytes, n, MPI_CHAR, 0, PETSC_COMM_WORLD));
  return 0;
}

/* *value ← rank 0's *value (collective). */
int vc_from_rank0(int *value)
{
  PetscCallMPI(MPI_Bcast(value, 1, MPI_INT, 0, PETSC_COMM_WORLD));
  return 0;
}

/* Ends every rank with exit status `code` (a rank that failed alone). */
void vc_abort(int code) { MPI_Abort(PETSC_COMM_WORLD, code); }

/* The nodal terms of the constrained operator (vc_constrained_solve): `np` directions removed,
 * each on up to three dofs (-1: none) with its coefficients, applied one after the other
 * (orthonormal within a node: the product is the orthogonal projection Π); `ns` local
 * stiffness blocks, each 3 × 3 on up to three dofs. Valid during one solve. */
typedef struct {
  PetscInt           np, ns;
  const PetscInt    *pdofs, *sdofs;
  const PetscScalar *pdirs, *smats;
} VcTerms;

typedef struct VcKsp VcKsp;

/* A Krylov solve's request and outcome (vc_ksp_solve, vc_constrained_solve): the question
 * `requested(flag)` (NULL: none), asked at every iteration, whether to give the solve up;
 * then its iterations, converged reason (< 0: diverged), final residual norm and whether
 * it was given up. */
typedef struct {
  int (*requested)(void *);
  void     *flag;
  PetscInt  its;
  int       reason;
  PetscReal rnorm;
  int       given_up;
} VcSolve;

/* A KSP's convergence test (PETSc's, after the options), wrapped by converged_or_given_up. */
typedef struct {
  PetscErrorCode (*inner)(KSP, PetscInt, PetscReal, KSPConvergedReason *, void *);
  void *inner_ctx;
  PetscErrorCode (*inner_destroy)(void *);
  VcKsp *s;
} Watch;

struct VcKsp {
  Mat A;
  KSP ksp;
  Vec b, x;
  /* The rows this rank owns, [lo, lo + m) (whole nodes); each rank's count and first row
   * (displ); count and displ NULL on one process. */
  PetscInt     lo, m;
  PetscMPIInt *count, *displ;
  /* The convergence tests of K_A's KSP and of the constrained one; the solve in progress
   * (NULL between solves), whose request they ask. */
  Watch    kw, cw;
  VcSolve *solve;
  /* The constrained system, created with the KSP where `newton` (else NULL): its assembled
   * matrix N, the matrix Q its preconditioner was built from, its KSP, the terms of the
   * solve in progress. */
  Mat       N, Q;
  KSP       kc;
  VcTerms   terms;
  /* Each of this rank's columns of N's frame (−1: none; −1 between calls: newton_matrix),
   * by its place: its own rows', then the off-diagonal block's columns (`place_of`). */
  PetscInt *frame_of;
  /* On several ranks, the CSR of this rank's rows of K (offsets from 0; global columns
   * and values in the caller's arrays, vc_ksp_create), and how many entries of each row
   * lie left of the rank's own columns (`below`, by which a CSR entry is found in N's and
   * Q's blocks: Values); one process reads K's, N's and Q's own arrays. */
  PetscInt          *kai, *below;
  const PetscInt    *kaj;
  const PetscScalar *kav;
  /* On several ranks, for vc_mult: the values of x at the columns of this rank's rows that
   * other ranks hold (`ghost`, in the order of N's off-diagonal columns, garray) and how
   * they come from those ranks' rows (`ghosts`). */
  Vec        ghost;
  VecScatter ghosts;
  /* GAMG's levels (0: coarsest) and K's Galerkin operators on levels 0 … nlev − 2, kept for
   * galerkin_update; NULL where the constrained PC is not GAMG (the options chose another). */
  PetscInt nlev;
  Mat     *coarse_k;
  /* The PETSc option -viscontact_galerkin_check, read once at setup (check_galerkin). */
  PetscBool galerkin_check;
  int      of_start; /* the convergence test's: rtol of the initial residual, else of b; −1: none yet */
};

static PetscErrorCode constrained_setup(VcKsp *s);
static PetscErrorCode check_blocks(VcKsp *s);

/* K_A on the ranks: on one, a SEQAIJ of the whole CSR (what the Newton systems update in
 * place); on several, an MPIAIJ of which each rank gives its own rows [lo, lo + m) as a
 * CSR of those rows alone (m + 1 row pointers from 0), rank r the rows
 * blocks[r] … blocks[r + 1] − 1 (whole nodes: the Newton matrix's frames and slip
 * stiffness act on a node's own rows), with each rank's share recorded. */
static PetscErrorCode distributed_matrix(VcKsp *s, PetscInt n, const PetscInt *rowptr,
                                         const PetscInt *cols, const PetscScalar *vals, PetscInt bs,
                                         const PetscInt *blocks)
{
  PetscMPIInt size, rank;

  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(PETSC_COMM_WORLD, &size));
  PetscCallMPI(MPI_Comm_rank(PETSC_COMM_WORLD, &rank));
  if (size == 1) {
    PetscCall(MatCreate(PETSC_COMM_SELF, &s->A));
    PetscCall(MatSetSizes(s->A, n, n, n, n));
    PetscCall(MatSetType(s->A, MATSEQAIJ));
    if (bs > 1) PetscCall(MatSetBlockSize(s->A, bs));
    PetscCall(MatSeqAIJSetPreallocationCSR(s->A, rowptr, cols, vals));
    s->lo = 0;
    s->m = n;
    PetscFunctionReturn(0);
  }
  PetscBool chosen;
  /* GAMG's Galerkin products add other ranks' contributions in the order their messages
   * arrive with PETSc's default algorithm: on 3 ranks and more (two have one message each
   * way), two runs differed in the last bits (docs/cluster.md). The all-at-once product
   * gave the same bits in every run tried on 3, 4 and 5 ranks, so it is the default there
   * where PETSC_OPTIONS does not choose one (the scene's options may still). It costs: on
   * the fine plate its products took 28 s of a 42 s setup on 2 ranks, where the default's
   * setup took 21 s. */
  PetscCall(PetscOptionsHasName(NULL, NULL, "-matptap_via", &chosen));
  if (size > 2 && !chosen) PetscCall(PetscOptionsSetValue(NULL, "-matptap_via", "allatonce"));
  PetscCall(PetscMalloc2(size, &s->count, size, &s->displ));
  for (PetscMPIInt r = 0; r < size; r++) {
    s->count[r] = (PetscMPIInt)(blocks[r + 1] - blocks[r]);
    s->displ[r] = (PetscMPIInt)blocks[r];
  }
  s->lo = s->displ[rank];
  s->m = s->count[rank];
  PetscCall(MatCreate(PETSC_COMM_WORLD, &s->A));
  PetscCall(MatSetSizes(s->A, s->m, s->m, n, n));
  PetscCall(MatSetType(s->A, MATMPIAIJ));
  if (bs > 1) PetscCall(MatSetBlockSize(s->A, bs));
  PetscCall(MatMPIAIJSetPreallocationCSR(s->A, rowptr, cols, vals));
  PetscFunctionReturn(0);
}

/* On several ranks, this rank's rows of K (columns in order) that the Newton systems are
 * made from (newton_matrix) and vc_mult multiplies by: the caller's arrays, read in place
 * (their row pointers, from 0, copied), with each row's count of columns left of the
 * rank's own. */
static PetscErrorCode local_rows(VcKsp *s, const PetscInt *rowptr, const PetscInt *cols,
                                 const PetscScalar *vals)
{
  PetscFunctionBeginUser;
  PetscCall(PetscMalloc2(s->m + 1, &s->kai, s->m, &s->below));
  for (PetscInt i = 0; i <= s->m; i++) s->kai[i] = rowptr[i];
  s->kaj = cols;
  s->kav = vals;
  for (PetscInt r = 0; r < s->m; r++) {
    PetscInt x = s->kai[r];
    while (x < s->kai[r + 1] && s->kaj[x] < s->lo) x++;
    s->below[r] = x - s->kai[r];
  }
  PetscFunctionReturn(0);
}

/* On several ranks, how vc_mult gets x at the columns of this rank's rows that other ranks
 * hold: N's off-diagonal block's columns (garray, increasing; N holds K's pattern:
 * check_blocks), scattered from a vector of the ranks' rows into `ghost`, a value each
 * (no rank holds x whole). */
static PetscErrorCode ghost_scatter(VcKsp *s)
{
  Mat             off;
  const PetscInt *garray;
  PetscInt        nghost;
  IS              is;

  PetscFunctionBeginUser;
  PetscCall(MatMPIAIJGetSeqAIJ(s->N, NULL, &off, &garray));
  PetscCall(MatGetSize(off, NULL, &nghost));
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, nghost, &s->ghost));
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, nghost, garray, PETSC_USE_POINTER, &is));
  PetscCall(VecScatterCreate(s->b, is, s->ghost, NULL, &s->ghosts));
  PetscCall(ISDestroy(&is));
  PetscFunctionReturn(0);
}

/* A KSP's convergence test: PETSc's, unless the solve is to be given up (the run's stop,
 * the solve's `requested`), which every rank learns at the same iteration (a reduction
 * over the ranks): the KSP then ends with KSP_DIVERGED_NULL and `given_up`, so that the
 * ranks leave the collective calls together. Mpirun kills the ranks a second after it
 * passes a Ctrl-C on as SIGTERM (docs/cluster.md): a step cannot be waited for. */
static PetscErrorCode converged_or_given_up(KSP ksp, PetscInt it, PetscReal rnorm,
                                            KSPConvergedReason *reason, void *ctx)
{
  Watch   *w = (Watch *)ctx;
  VcKsp   *s = w->s;
  VcSolve *v = s->solve;
  int      stop = v && v->requested ? v->requested(v->flag) : 0;
  MPI_Comm comm;

  PetscFunctionBeginUser;
  PetscCall(w->inner(ksp, it, rnorm, reason, w->inner_ctx));
  PetscCall(PetscObjectGetComm((PetscObject)ksp, &comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &stop, 1, MPI_INT, MPI_MAX, comm));
  if (stop && *reason == KSP_CONVERGED_ITERATING) {
    *reason = KSP_DIVERGED_NULL;
    v->given_up = 1;
  }
  PetscFunctionReturn(0);
}

/* ksp's convergence test, as it stands, wrapped by converged_or_given_up in w (the test
 * w wrapped before, if any, destroyed). */
static PetscErrorCode watch(VcKsp *s, KSP ksp, Watch *w)
{
  PetscFunctionBeginUser;
  if (w->inner_destroy) PetscCall(w->inner_destroy(w->inner_ctx));
  PetscCall(KSPGetAndClearConvergenceTest(ksp, &w->inner, &w->inner_ctx, &w->inner_destroy));
  w->s = s;
  PetscCall(KSPSetConvergenceTest(ksp, converged_or_given_up, w, NULL));
  PetscFunctionReturn(0);
}

/* The matrix in CSR (a symmetric matrix's CSC is its CSR), the ranks' rows (`blocks`: size
 * + 1 row numbers, distributed_matrix), its near-null space as `nvec` orthonormal vectors,
 * the rank's rows of each (the whole on one rank) stored one after the other, CG + GAMG
 * with relative tolerance `rtol`, then `options` (PETSc's command-line syntax) and
 * KSPSetFromOptions; set up for K's own solves, or where `newton`, for the constrained
 * systems alone (their KSP and multigrid: constrained_setup), K's never being solved (on
 * several ranks K's matrix and KSP then go).
 * On one rank the matrix is whole; on several each rank gives (and keeps) its own rows, the
 * others' rows empty, and for the Newton systems the shim reads `cols` and `vals` of them
 * until vc_ksp_destroy (its copy of K's rows: the caller keeps them). */
int vc_ksp_create(PetscInt n, const PetscInt *rowptr, const PetscInt *cols, const PetscScalar *vals,
                  PetscInt bs, const PetscInt *blocks, PetscInt nvec, const PetscScalar *near,
                  PetscReal rtol, const char *options, int newton, void **out)
{
  VcKsp       *s;
  MatNullSpace space;
  Vec         *vecs;
  PC           pc;
  MPI_Comm     comm;

  PetscCall(PetscCalloc1(1, &s));
  s->of_start = -1;
  PetscCall(distributed_matrix(s, n, rowptr, cols, vals, bs, blocks));
  PetscCall(PetscObjectGetComm((PetscObject)s->A, &comm));
  PetscCall(MatSetOption(s->A, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatSetOption(s->A, MAT_SPD, PETSC_TRUE));

  PetscCall(PetscMalloc1(nvec, &vecs));
  for (PetscInt k = 0; k < nvec; k++) {
    PetscScalar *a;
    PetscCall(MatCreateVecs(s->A, &vecs[k], NULL));
    PetscCall(VecGetArray(vecs[k], &a));
    PetscCall(PetscArraycpy(a, near + k * s->m, s->m));
    PetscCall(VecRestoreArray(vecs[k], &a));
  }
  PetscCall(MatNullSpaceCreate(comm, PETSC_FALSE, nvec, vecs, &space));
  PetscCall(MatSetNearNullSpace(s->A, space));
  PetscCall(MatNullSpaceDestroy(&space));
  for (PetscInt k = 0; k < nvec; k++) PetscCall(VecDestroy(&vecs[k]));
  PetscCall(PetscFree(vecs));

  PetscCall(KSPCreate(comm, &s->ksp));
  PetscCall(KSPSetOperators(s->ksp, s->A, s->A));
  PetscCall(KSPSetType(s->ksp, KSPCG));
  PetscCall(KSPGetPC(s->ksp, &pc));
  PetscCall(PCSetType(pc, PCGAMG));
  PetscCall(KSPSetTolerances(s->ksp, rtol, 0.0, PETSC_DEFAULT, PETSC_DEFAULT));
  PetscCall(KSPSetInitialGuessNonzero(s->ksp, PETSC_TRUE));
  PetscCall(PetscOptionsInsertString(NULL, options));
  PetscCall(KSPSetFromOptions(s->ksp));
  if (newton) {
    PetscCall(constrained_setup(s));
    if (s->count) PetscCall(local_rows(s, rowptr, cols, vals));
    if (s->count) PetscCall(check_blocks(s));
  } else {
    PetscCall(KSPSetUp(s->ksp));
    PetscCall(watch(s, s->ksp, &s->kw));
  }
  PetscCall(MatCreateVecs(s->A ? s->A : s->N, &s->x, &s->b));
  if (newton && s->count) PetscCall(ghost_scatter(s));
  *out = s;
  return 0;
}

/* x ← the solution of ksp's system (K_A's or the constrained one) with right side b, from
 * the initial guess in x, asking and filling v (VcSolve). b and x are this rank's rows;
 * where a rank's request gave the solve up, x holds an iterate. */
static PetscErrorCode solved(VcKsp *s, KSP ksp, const PetscScalar *b, PetscScalar *x, VcSolve *v)
{
  KSPConvergedReason r;
  PetscErrorCode     err;

  PetscFunctionBeginUser;
  v->given_up = 0;
  PetscCall(VecPlaceArray(s->b, b));
  PetscCall(VecPlaceArray(s->x, x));
  s->solve = v; /* for the convergence test, during this call only */
  err = KSPSolve(ksp, s->b, s->x);
  s->solve = NULL;
  PetscCall(err);
  PetscCall(VecResetArray(s->x));
  PetscCall(VecResetArray(s->b));
  PetscCall(KSPGetIterationNumber(ksp, &v->its));
  PetscCall(KSPGetConvergedReason(ksp, &r));
  PetscCall(KSPGetResidualNorm(ksp, &v->rnorm));
  v->reason = (int)r;
  PetscFunctionReturn(0);
}

/* x ← K⁻¹ b by K_A's KSP, as `solved` says. */
int vc_ksp_solve(void *ctx, const PetscScalar *b, PetscScalar *x, VcSolve *v)
{
  VcKsp *s = (VcKsp *)ctx;

  PetscCheck(s->ksp, PETSC_COMM_SELF, PETSC_ERR_ORDER, "K's KSP went with K's matrix (the Newton systems' KSP on several ranks)");
  PetscCall(solved(s, s->ksp, b, x, v));
  return 0;
}

/* The KSP's and the PC's type names (after the options). */
int vc_ksp_types(void *ctx, const char **ksp_type, const char **pc_type)
{
  VcKsp *s = (VcKsp *)ctx;
  PC     pc;

  KSP    ksp = s->ksp ? s->ksp : s->kc; /* the same type and options */

  PetscCall(KSPGetType(ksp, ksp_type));
  PetscCall(KSPGetPC(ksp, &pc));
  PetscCall(PCGetType(pc, pc_type));
  return 0;
}

/* recv ← each rank's send (nsend values), rank r's at displs[r] (counts[r] values): on
 * every rank where `every`, else on rank 0 alone (recv, counts and displs read there only). */
int vc_gather(const PetscScalar *send, int nsend, PetscScalar *recv, const int *counts, const int *displs, int every)
{
  if (every) PetscCallMPI(MPI_Allgatherv(send, nsend, MPIU_SCALAR, recv, counts, displs, MPIU_SCALAR, PETSC_COMM_WORLD));
  else PetscCallMPI(MPI_Gatherv(send, nsend, MPIU_SCALAR, recv, counts, displs, MPIU_SCALAR, 0, PETSC_COMM_WORLD));
  return 0;
}

/* Every rank's recv[r] ← rank r's send[rank]: one count to and from each rank. */
int vc_alltoall_counts(const int *send, int *recv)
{
  PetscCallMPI(MPI_Alltoall(send, 1, MPI_INT, recv, 1, MPI_INT, PETSC_COMM_WORLD));
  return 0;
}

/* Each rank sends scounts[r] values from send + sdispls[r] to rank r and receives
 * rcounts[r] values from it at recv + rdispls[r]: doubles, or where `ints`, ints. */
int vc_alltoallv(const void *send, const int *scounts, const int *sdispls, void *recv,
                 const int *rcounts, const int *rdispls, int ints)
{
  MPI_Datatype t = ints ? MPI_INT : MPIU_SCALAR;

  PetscCallMPI(MPI_Alltoallv(send, scounts, sdispls, t, recv, rcounts, rdispls, t, PETSC_COMM_WORLD));
  return 0;
}

/* The dofs of node term e that exist (d ≥ 0), packed: their count, indices and positions. */
static PetscInt present(const PetscInt *d, PetscInt idx[3], int pos[3])
{
  PetscInt k = 0;
  for (int c = 0; c < 3; c++)
    if (d[c] >= 0) {
      idx[k] = d[c];
      pos[k++] = c;
    }
  return k;
}

/* A node's removed directions as the reflection R = I − 2 Σ v vᵀ on its k dofs (packed,
 * row-major k × k; orthonormal directions, so R = Π − (I − Π) and R² = I). */
typedef struct {
  PetscInt    k, dof[3], place[3]; /* the dofs as PETSc's rows, and as s->frame_of's places */
  PetscScalar r[9];
} Frame;

/* The position of entry (row, col) in the CSR arrays, −1 if the pattern lacks it. */
static PetscInt entry(const PetscInt *ai, const PetscInt *aj, PetscInt row, PetscInt col)
{
  PetscInt lo = ai[row], hi = ai[row + 1];
  while (lo < hi) {
    PetscInt mid = (lo + hi) / 2;
    if (aj[mid] < col) lo = mid + 1;
    else hi = mid;
  }
  return lo < ai[row + 1] && aj[lo] == col ? lo : -1;
}

/* The place of PETSc's row g among this rank's columns of N, as s->frame_of holds them:
 * g − lo for its own rows, m + k for the off-diagonal block's column k (garray, ng
 * increasing), −1 where its rows read none. */
static PetscInt place_of(const VcKsp *s, const PetscInt *garray, PetscInt ng, PetscInt g)
{
  PetscInt lo = 0, hi = ng;

  if (g >= s->lo && g < s->lo + s->m) return g - s->lo;
  while (lo < hi) {
    PetscInt mid = (lo + hi) / 2;
    if (garray[mid] < g) lo = mid + 1;
    else hi = mid;
  }
  return lo < ng && garray[lo] == g ? s->m + lo : -1;
}

/* N's off-diagonal columns on several ranks (garray, *ng of them); none on one process. */
static PetscErrorCode ghost_columns(const VcKsp *s, const PetscInt **garray, PetscInt *ng)
{
  Mat off;

  PetscFunctionBeginUser;
  *garray = NULL;
  *ng = 0;
  if (!s->count) PetscFunctionReturn(0);
  PetscCall(MatMPIAIJGetSeqAIJ(s->N, NULL, &off, garray));
  PetscCall(MatGetSize(off, NULL, ng));
  PetscFunctionReturn(0);
}

/* The frames of the terms' directions at the nodes this rank's rows read, one per node,
 * and the frame (−1: none) of each of its columns in s->frame_of, which the caller resets:
 * a node's dofs are one rank's rows, and P1 assembly couples every pair of dofs of
 * neighbouring nodes, so a node's dofs are all among a rank's columns or none is. */
static PetscErrorCode frames(VcKsp *s, Frame **out, PetscInt *count)
{
  const VcTerms  *t = &s->terms;
  const PetscInt *garray;
  Frame          *fr;
  PetscInt        nf = 0, ng;

  PetscFunctionBeginUser;
  PetscCall(ghost_columns(s, &garray, &ng));
  PetscCall(PetscMalloc1(t->np, &fr));
  for (PetscInt e = 0; e < t->np; e++) {
    PetscInt           idx[3];
    int                pos[3];
    const PetscScalar *v = t->pdirs + 3 * e;
    PetscInt           k = present(t->pdofs + 3 * e, idx, pos), first;
    Frame             *f;
    if (k == 0 || (first = place_of(s, garray, ng, idx[0])) < 0) continue;
    if (s->frame_of[first] < 0) {
      f = &fr[nf];
      *f = (Frame){k, {idx[0], idx[1 % k], idx[2 % k]}, {0}, {0}};
      for (PetscInt a = 0; a < k; a++) {
        f->place[a] = place_of(s, garray, ng, idx[a]);
        f->r[k * a + a] = 1.0;
        s->frame_of[f->place[a]] = nf;
      }
      nf++;
    } else f = &fr[s->frame_of[first]];
    for (PetscInt a = 0; a < k; a++)
      for (PetscInt b = 0; b < k; b++) f->r[k * a + b] -= 2.0 * v[pos[a]] * v[pos[b]];
  }
  *out = fr;
  *count = nf;
  PetscFunctionReturn(0);
}

/* A rank's rows of K in CSR, [lo, lo + m): offsets ai from 0, global columns aj (in
 * order), values k, and on several ranks each row's count of columns left of the rank's
 * own (below; NULL on one process). N and Q share the pattern (Values). On one process,
 * N's pattern and K's own array; on several, the caller's rows (local_rows). */
typedef struct {
  PetscInt           lo, m;
  const PetscInt    *ai, *aj, *below;
  const PetscScalar *k;
} Local;

/* N's or Q's values, written or read in place where Local's CSR has them: on one process
 * the matrix's own array, in that order; on several, the arrays of its two blocks
 * (PETSc's MPIAIJ): the diagonal block (the rank's own columns) and the off-diagonal one,
 * whose row holds the columns left of the own ones, then those right of them, in order.
 * So a CSR entry's place follows from its row's count of left columns: no copy of the
 * values in CSR order (N's and Q's were 8 bytes an entry each: 0.13 GB a rank on two ranks
 * of the fine plate). */
typedef struct {
  Mat             blocks[2]; /* NULL, NULL on one process */
  PetscScalar    *a[2];
  const PetscInt *ai[2], *aj[2];
} Values;

/* The place of CSR entry x, in local row r, among the values v. */
static PetscScalar *at(const Values *v, const Local *l, PetscInt r, PetscInt x)
{
  PetscInt off = x - l->ai[r], left, own;

  if (!v->blocks[0]) return v->a[0] + x;
  left = l->below[r];
  own = v->ai[0][r + 1] - v->ai[0][r];
  if (off < left) return v->a[1] + v->ai[1][r] + off;
  if (off < left + own) return v->a[0] + v->ai[0][r] + off - left;
  return v->a[1] + v->ai[1][r] + off - own;
}

/* The lengths of row r's three runs of CSR entries, one after the other in CSR order: on
 * several ranks its left columns (off-diagonal block), its own (diagonal block) and its
 * right ones (off-diagonal block, after the left), and 1; on one process the row, then
 * nothing, and 0. */
static int run_lengths(const Values *v, const Local *l, PetscInt r, PetscInt len[3])
{
  PetscInt width = l->ai[r + 1] - l->ai[r];

  if (!v->blocks[0]) {
    len[0] = width;
    len[1] = len[2] = 0;
    return 0;
  }
  len[0] = l->below[r];
  len[1] = v->ai[0][r + 1] - v->ai[0][r];
  len[2] = width - len[0] - len[1];
  return 1;
}

/* Row r's CSR entries among v's values as the three runs of `run_lengths`. */
static void runs(const Values *v, const Local *l, PetscInt r, PetscScalar *run[3], PetscInt len[3])
{
  if (!run_lengths(v, l, r, len)) {
    run[0] = run[1] = run[2] = v->a[0] + l->ai[r];
    return;
  }
  run[0] = v->a[1] + v->ai[1][r];
  run[1] = v->a[0] + v->ai[0][r];
  run[2] = run[0] + len[0];
}

/* The places of row r's columns among the rank's columns of N (`place_of`), in the runs
 * of `run_lengths`: shift[p] + col[p][k] for the k-th entry of run p. On several ranks
 * the left and right runs are the off-diagonal block's columns (m + its column), the
 * middle one the diagonal block's; on one process the row's columns. */
static void column_runs(const Values *v, const Local *l, PetscInt r, const PetscInt *col[3],
                        PetscInt shift[3], PetscInt len[3])
{
  if (!run_lengths(v, l, r, len)) {
    col[0] = col[1] = col[2] = l->aj + l->ai[r];
    shift[0] = shift[1] = shift[2] = 0;
    return;
  }
  col[0] = v->aj[1] + v->ai[1][r];
  col[1] = v->aj[0] + v->ai[0][r];
  col[2] = col[0] + len[0];
  shift[0] = shift[2] = l->m;
  shift[1] = 0;
}

/* The values of m (N or Q) in place (`write`: to be written). */
static PetscErrorCode values_open(Mat m, PetscBool write, Values *v)
{
  PetscBool seq;

  PetscFunctionBeginUser;
  *v = (Values){{NULL, NULL}, {NULL, NULL}, {NULL, NULL}, {NULL, NULL}};
  PetscCall(PetscObjectTypeCompare((PetscObject)m, MATSEQAIJ, &seq));
  if (seq) {
    if (write) PetscCall(MatSeqAIJGetArray(m, &v->a[0]));
    else PetscCall(MatSeqAIJGetArrayRead(m, (const PetscScalar **)&v->a[0]));
    PetscFunctionReturn(0);
  }
  PetscCall(MatMPIAIJGetSeqAIJ(m, &v->blocks[0], &v->blocks[1], NULL));
  for (int b = 0; b < 2; b++) {
    PetscInt  rows;
    PetscBool done;
    PetscCall(MatGetRowIJ(v->blocks[b], 0, PETSC_FALSE, PETSC_FALSE, &rows, &v->ai[b], &v->aj[b], &done));
    PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "a block of the Newton matrix has no CSR arrays");
    if (write) PetscCall(MatSeqAIJGetArray(v->blocks[b], &v->a[b]));
    else PetscCall(MatSeqAIJGetArrayRead(v->blocks[b], (const PetscScalar **)&v->a[b]));
  }
  PetscFunctionReturn(0);
}

/* Ends what values_open began on m. A matrix written is assembled again on several ranks
 * (collective; its values stay), as MatSetValues would have it, which tells its KSP. */
static PetscErrorCode values_close(Mat m, PetscBool write, Values *v)
{
  PetscFunctionBeginUser;
  if (!v->blocks[0]) {
    if (write) PetscCall(MatSeqAIJRestoreArray(m, &v->a[0]));
    else PetscCall(MatSeqAIJRestoreArrayRead(m, (const PetscScalar **)&v->a[0]));
    PetscFunctionReturn(0);
  }
  for (int b = 0; b < 2; b++) {
    PetscInt  rows;
    PetscBool done;
    if (write) PetscCall(MatSeqAIJRestoreArray(v->blocks[b], &v->a[b]));
    else PetscCall(MatSeqAIJRestoreArrayRead(v->blocks[b], (const PetscScalar **)&v->a[b]));
    PetscCall(MatRestoreRowIJ(v->blocks[b], 0, PETSC_FALSE, PETSC_FALSE, &rows, &v->ai[b], &v->aj[b], &done));
  }
  if (write) PetscCall(MatAssemblyBegin(m, MAT_FINAL_ASSEMBLY));
  if (write) PetscCall(MatAssemblyEnd(m, MAT_FINAL_ASSEMBLY));
  PetscFunctionReturn(0);
}

/* y = this rank's rows of K x, x this rank's rows: by K's matrix, or where it went (the
 * Newton systems' KSP on several ranks: constrained_setup) by this rank's rows
 * (local_rows), the values of other ranks' rows from them (ghost_scatter), each row's sum
 * in the order of its columns. Collective on several ranks. */
int vc_mult(void *ctx, const PetscScalar *x, PetscScalar *y)
{
  VcKsp *s = (VcKsp *)ctx;

  if (!s->A) {
    const PetscScalar *g;
    Values             n;

    PetscCall(VecPlaceArray(s->b, x));
    PetscCall(VecScatterBegin(s->ghosts, s->b, s->ghost, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(s->ghosts, s->b, s->ghost, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecResetArray(s->b));
    PetscCall(VecGetArrayRead(s->ghost, &g));
    /* A CSR entry's ghost is its column in N's off-diagonal block, as `at` finds it. */
    PetscCall(values_open(s->N, PETSC_FALSE, &n));
    for (PetscInt r = 0; r < s->m; r++) {
      PetscInt        left = s->below[r], own = n.ai[0][r + 1] - n.ai[0][r];
      const PetscInt *off = n.aj[1] + n.ai[1][r];
      PetscScalar     sum = 0;
      for (PetscInt k = s->kai[r], e = 0; k < s->kai[r + 1]; k++, e++) {
        PetscScalar v = e < left ? g[off[e]] : e < left + own ? x[s->kaj[k] - s->lo] : g[off[e - own]];
        sum += s->kav[k] * v;
      }
      y[r] = sum;
    }
    PetscCall(values_close(s->N, PETSC_FALSE, &n));
    PetscCall(VecRestoreArrayRead(s->ghost, &g));
    return 0;
  }
  PetscCall(VecPlaceArray(s->b, x));
  PetscCall(VecPlaceArray(s->x, y));
  PetscCall(MatMult(s->A, s->b, s->x));
  PetscCall(VecResetArray(s->x));
  PetscCall(VecResetArray(s->b));
  return 0;
}

/* (A M B)_ij, M the local rows' values (n) with row i among them, A = R over i's frame
 * `left` where given (else I), B = R over j's frame `right` where given (else I); a dof
 * without a frame is its own (R = 1). A node's dofs are all on one rank, so the rows of
 * i's frame are local too. */
static PetscScalar reflected(const Frame *left, const Frame *right, const Local *l,
                             const Values *n, PetscInt i, PetscInt j)
{
  Frame        unit_i = {1, {i}, {0}, {1.0}}, unit_j = {1, {j}, {0}, {1.0}};
  const Frame *fi = left ? left : &unit_i;
  const Frame *fj = right ? right : &unit_j;
  PetscInt     a = 0, b = 0;
  PetscScalar  sum = 0;

  while (fi->dof[a] != i) a++;
  while (fj->dof[b] != j) b++;
  for (PetscInt p = 0; p < fi->k; p++)
    for (PetscInt q = 0; q < fj->k; q++) {
      PetscInt row = fi->dof[p] - l->lo, e = entry(l->ai, l->aj, row, fj->dof[q]);
      if (e >= 0) sum += fi->r[fi->k * a + p] * *at(n, l, row, e) * fj->r[fj->k * q + b];
    }
  return sum;
}

/* This rank's rows of K. */
static PetscErrorCode local_open(VcKsp *s, Local *l)
{
  PetscBool done;

  PetscFunctionBeginUser;
  if (s->count) {
    *l = (Local){s->lo, s->m, s->kai, s->kaj, s->below, s->kav};
    PetscFunctionReturn(0);
  }
  *l = (Local){0};
  PetscCall(MatGetRowIJ(s->N, 0, PETSC_FALSE, PETSC_FALSE, &l->m, &l->ai, &l->aj, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "the Newton matrix has no CSR arrays");
  PetscCall(MatSeqAIJGetArrayRead(s->A, &l->k));
  PetscFunctionReturn(0);
}

/* Ends what local_open began. */
static PetscErrorCode local_close(VcKsp *s, Local *l)
{
  PetscBool done;

  PetscFunctionBeginUser;
  if (s->count) PetscFunctionReturn(0);
  PetscCall(MatSeqAIJRestoreArrayRead(s->A, &l->k));
  PetscCall(MatRestoreRowIJ(s->N, 0, PETSC_FALSE, PETSC_FALSE, &l->m, &l->ai, &l->aj, &done));
  PetscFunctionReturn(0);
}

/* On several ranks, that N's two blocks hold this rank's rows of K's pattern as Values
 * reads them: each row's own columns in the diagonal block, the others in the
 * off-diagonal one, left ones first (checked once; a PETSc that stored them otherwise
 * would have the Newton systems made wrong). */
static PetscErrorCode check_blocks(VcKsp *s)
{
  Local           l;
  Values          n;
  const PetscInt *garray;
  PetscInt        bad = 0;

  PetscFunctionBeginUser;
  PetscCall(local_open(s, &l));
  PetscCall(values_open(s->N, PETSC_FALSE, &n));
  PetscCall(MatMPIAIJGetSeqAIJ(s->N, NULL, NULL, &garray));
  for (PetscInt r = 0; r < l.m && !bad; r++) {
    PetscInt left = l.below[r], own = n.ai[0][r + 1] - n.ai[0][r];
    PetscInt other = n.ai[1][r + 1] - n.ai[1][r];
    bad = left > other || own + other != l.ai[r + 1] - l.ai[r];
    for (PetscInt x = l.ai[r]; x < l.ai[r + 1] && !bad; x++) {
      PetscInt off = x - l.ai[r], col;
      if (off < left) col = garray[n.aj[1][n.ai[1][r] + off]];
      else if (off < left + own) col = l.lo + n.aj[0][n.ai[0][r] + off - left];
      else col = garray[n.aj[1][n.ai[1][r] + off - own]];
      bad = col != l.aj[x];
    }
  }
  PetscCall(values_close(s->N, PETSC_FALSE, &n));
  PetscCheck(!bad, PETSC_COMM_SELF, PETSC_ERR_PLIB, "the Newton matrix's blocks do not hold K's rows in order");
  PetscFunctionReturn(0);
}

/* N ← K, row by row in place. */
static PetscErrorCode reset_to_k(const Local *l, const Values *n)
{
  PetscFunctionBeginUser;
  if (!n->blocks[0]) PetscCall(PetscArraycpy(n->a[0], l->k, l->ai[l->m]));
  else
    for (PetscInt r = 0; r < l->m; r++) {
      PetscScalar *run[3];
      PetscInt     len[3], x = l->ai[r];
      runs(n, l, r, run, len);
      for (int p = 0; p < 3; p++)
        for (PetscInt i = 0; i < len[p]; i++) run[p][i] = l->k[x++];
    }
  PetscFunctionReturn(0);
}

/* Q ← N, the matrix the constrained preconditioner is now built from. */
static PetscErrorCode keep_q(VcKsp *s)
{
  PetscFunctionBeginUser;
  PetscCall(MatCopy(s->N, s->Q, SAME_NONZERO_PATTERN));
  PetscFunctionReturn(0);
}

/* The scale α of the removed directions' block in the Newton matrix (newton_matrix). The
 * block is decoupled, so α does not move the solution; GAMG's aggregates come from K, so it
 * need not be K's scale either, and the smaller it is, the nearer N's coarse operators
 * P^T N P come to the constrained operator's, P^T Π(K + S)Π P, while staying definite.
 * Measured (CG iterations; docs/performance.md): plate 0.03, 10 steps, α = 1, 0.3, 0.1,
 * 0.01: 543, 496, 472, 505; the fine plate's first 7 steps, α = 1, 0.1, 0.03: 980, 944,
 * 927; its 20 steps 2 113 and 2 023, 475.9 and 433.2 s. */
#define DECOUPLED 0.1

/* s->N ← Π(K + S)Π + α (I − Π)(K + S)(I − Π), with Π = (I + R)/2 node by node:
 * ¼(1 + α)(M + RMR) + ¼(1 − α)(RM + MR) for M = K + S, α = DECOUPLED. The second term is
 * a multiple of K's own restriction to the removed directions: it decouples them from the
 * rest (so that N x = Π b gives (I − Π) x = 0 and Π x the constrained solution, as
 * Π(K + S)Π + (I − Π) would) while keeping K's graph: with the identity in their place a
 * sticking node was an aggregate of its own, too small for the rigid-body modes, when
 * GAMG aggregated N. N has K's pattern, for R and S act within a node and P1 assembly
 * stores every pair of dofs of neighbouring nodes; only the rows and columns of nodes with
 * removed directions change, computed here in place (a product of sparse matrices took a
 * fifth of the step on the plate 0.03). Each rank makes its own rows: a framed row in full,
 * and in the others the entries in framed columns. */
static PetscErrorCode newton_matrix(VcKsp *s)
{
  const VcTerms *t = &s->terms;
  Local          l;
  Values         n;
  PetscScalar   *upd = NULL, **dst = NULL;
  PetscInt       nf, nu = 0, cap = 0;
  Frame         *fr = NULL;

  PetscFunctionBeginUser;
  PetscCall(local_open(s, &l));
  PetscCall(values_open(s->N, PETSC_TRUE, &n));
  PetscCall(reset_to_k(&l, &n));
  for (PetscInt e = 0; e < t->ns; e++) {
    PetscInt idx[3];
    int      pos[3];
    PetscInt k = present(t->sdofs + 3 * e, idx, pos);
    if (k == 0 || idx[0] < l.lo || idx[0] >= l.lo + l.m) continue; /* another rank's node */
    for (PetscInt r = 0; r < k; r++) {
      for (PetscInt c = 0; c < k; c++) {
        PetscInt x = entry(l.ai, l.aj, idx[r] - l.lo, idx[c]);
        PetscCheck(x >= 0, PETSC_COMM_SELF, PETSC_ERR_SUP, "K lacks a pair of a node's dofs");
        *at(&n, &l, idx[r] - l.lo, x) += t->smats[9 * e + 3 * pos[r] + pos[c]];
      }
    }
  }
  PetscCall(frames(s, &fr, &nf));
  /* The new values, from N = K + S as it stands, written once all are known. */
  for (PetscInt r = 0; r < l.m; r++) {
    PetscInt        i = l.lo + r, x = l.ai[r], shift[3], len[3];
    const PetscInt *col[3];
    const Frame    *fi = s->frame_of[r] >= 0 ? &fr[s->frame_of[r]] : NULL;
    column_runs(&n, &l, r, col, shift, len);
    for (int p = 0; p < 3; p++)
      for (PetscInt k = 0; k < len[p]; k++, x++) {
        PetscInt     j = l.aj[x], c = s->frame_of[shift[p] + col[p][k]];
        const Frame *fj = c >= 0 ? &fr[c] : NULL;
        if (!fi && !fj) continue;
        PetscScalar rmr = reflected(fi, fj, &l, &n, i, j);
        PetscScalar rm = reflected(fi, NULL, &l, &n, i, j);
        PetscScalar mr = reflected(NULL, fj, &l, &n, i, j);
        if (nu == cap) {
          cap = PetscMax(2 * cap, 1024);
          PetscCall(PetscRealloc(cap * sizeof(*upd), &upd));
          PetscCall(PetscRealloc(cap * sizeof(*dst), &dst));
        }
        dst[nu] = at(&n, &l, r, x);
        upd[nu] = 0.25 * (1 + DECOUPLED) * (*dst[nu] + rmr) + 0.25 * (1 - DECOUPLED) * (rm + mr);
        nu++;
      }
  }
  for (PetscInt u = 0; u < nu; u++) *dst[u] = upd[u];
  for (PetscInt f = 0; f < nf; f++)
    for (PetscInt a = 0; a < fr[f].k; a++) s->frame_of[fr[f].place[a]] = -1;
  PetscCall(PetscFree(upd));
  PetscCall(PetscFree(dst));
  PetscCall(PetscFree(fr));
  PetscCall(values_close(s->N, PETSC_TRUE, &n));
  PetscCall(local_close(s, &l));
  PetscFunctionReturn(0);
}

/* The smoother of the multigrid's level l (0: the coarsest, its solve) and its matrix. */
static PetscErrorCode level(PC pc, PetscInt l, KSP *smoother, Mat *a)
{
  PetscFunctionBeginUser;
  PetscCall(PCMGGetSmoother(pc, l, smoother));
  PetscCall(KSPGetOperators(*smoother, a, NULL));
  PetscFunctionReturn(0);
}

/* m is symmetric positive definite, with the near-null space `near`. */
static PetscErrorCode spd(Mat m, MatNullSpace near)
{
  PetscFunctionBeginUser;
  PetscCall(MatSetOption(m, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatSetOption(m, MAT_SPD, PETSC_TRUE));
  PetscCall(MatSetNearNullSpace(m, near));
  PetscFunctionReturn(0);
}

/* The constrained KSP: the type of ksp and its PC (CG and GAMG by default, or what the
 * options chose). Its operator is the Newton matrix N, its preconditioner is built from Q,
 * N's copy at the last rebuild (same pattern, block size and near-null space as K). GAMG's
 * aggregates and interpolation are made once, here, from K itself, and kept, with K's
 * coarse operators; a rebuild updates the coarse operators by galerkin_update, and the
 * smoothers re-estimate their eigenvalues for the matrices changed (the aggregation's
 * estimate would be K's). So a step's hierarchies are a function of K and of the step's
 * own systems, nothing before: a resumed run rebuilds what the uninterrupted one did.
 * Aggregating each step's first system anew instead cost 16 % more on the plate 0.03, and
 * GAMG's own rebuild on kept aggregates (Galerkin products of the whole of Q) more than
 * the update (docs/performance.md). Another PC, chosen by the options, is set up anew from
 * Q at each rebuild. */
static PetscErrorCode constrained_setup(VcKsp *s)
{
  KSPType         type;
  PC              pc;
  MatNullSpace    near;
  const PetscInt *garray;
  PetscInt        ng;
  PetscBool       gamg, chosen;
  MPI_Comm        comm;

  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)s->A, &comm));
  PetscCall(MatGetNearNullSpace(s->A, &near));
  PetscCall(MatDuplicate(s->A, MAT_COPY_VALUES, &s->Q));
  PetscCall(spd(s->Q, near)); /* Q's reference keeps `near` when K's matrix goes, below */
  PetscCall(KSPCreate(comm, &s->kc));
  /* Q is the operator too until the multigrid is made: N, whose values every solve writes
   * (newton_matrix), is made last, so that it is not held through the setup's peak. */
  PetscCall(KSPSetOperators(s->kc, s->Q, s->Q));
  PetscCall(KSPGetType(s->ksp, &type));
  PetscCall(KSPSetType(s->kc, type));
  PetscCall(KSPGetPC(s->kc, &pc));
  PetscCall(PCSetType(pc, PCGAMG));
  PetscCall(PCGAMGSetUseSAEstEig(pc, PETSC_FALSE));
  /* Coarsening stops at 1 000 equations, not GAMG's 50: the coarsest level, solved
   * exactly, then holds more of the constrained operator, which K's aggregates approximate
   * least well. With the W-cycle it took the CG iterations a system on the plates 0.03 and
   * 0.015 from 5.42 and 8.29 to 5.32 and 6.18, and the steps less time (docs/performance.md,
   * "Updating the multigrid where the slip stiffness moves"). The options may choose
   * another (-pc_gamg_coarse_eq_limit). */
  PetscCall(PCGAMGSetCoarseEqLim(pc, 1000));
  /* GAMG's smoothers would use the operator N, whose residuals its coarse levels (of Q) do
   * not match: CG then met an indefinite preconditioner. */
  PetscCall(PCSetUseAmat(pc, PETSC_FALSE));
  PetscCall(KSPSetInitialGuessNonzero(s->kc, PETSC_TRUE));
  PetscCall(KSPSetFromOptions(s->kc));
  /* On several ranks K's matrix, and the KSP of K that is never solved here, go before
   * GAMG's setup, a rank's peak: the Newton systems are made of the rank's rows of K as
   * the caller gave them (local_rows), and vc_mult multiplies by them. */
  if (s->count) {
    PetscCall(KSPDestroy(&s->ksp));
    PetscCall(MatDestroy(&s->A));
  }
  PetscCall(PCSetUp(pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCGAMG, &gamg));
  /* A W-cycle: the coarse operators, K's aggregates with N's values, approximate the
   * constrained operator less well on finer meshes, and visiting them twice a level halved
   * the fine plate's CG iterations (docs/performance.md, "A W-cycle for the Newton
   * systems"). Set once GAMG made its levels (its setup resets their cycles), unless the
   * options choose one (-pc_mg_cycle_type v puts the V-cycle back). */
  PetscCall(PetscOptionsHasName(NULL, NULL, "-pc_mg_cycle_type", &chosen));
  if (gamg && !chosen) PetscCall(PCMGSetCycleType(pc, PC_MG_CYCLE_W));
  PetscCall(PetscOptionsHasName(NULL, NULL, "-viscontact_galerkin_check", &s->galerkin_check));
  if (gamg) PetscCall(PCMGGetLevels(pc, &s->nlev));
  if (gamg && s->nlev > 1) {
    /* GAMG's Galerkin products keep what a product of the same pattern would reuse; the
     * hierarchy is updated by galerkin_update alone, which makes products of its own, so
     * that goes: 0.30 GB a rank on two ranks of the fine plate, nothing on one process. */
    for (PetscInt l = 0; l < s->nlev; l++) {
      KSP smoother;
      Mat a, p;
      PetscCall(level(pc, l, &smoother, &a));
      PetscCall(MatProductClear(a));
      if (l == 0) continue;
      PetscCall(PCMGGetInterpolation(pc, l, &p));
      PetscCall(MatProductClear(p));
    }
    PetscCall(PetscMalloc1(s->nlev - 1, &s->coarse_k));
    for (PetscInt l = 0; l + 1 < s->nlev; l++) {
      KSP smoother;
      Mat a;
      PetscCall(level(pc, l, &smoother, &a));
      PetscCall(MatSetOption(a, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE));
      PetscCall(MatDuplicate(a, MAT_COPY_VALUES, &s->coarse_k[l]));
    }
    /* The hierarchy is updated here, by galerkin_update, never by GAMG again. */
    PetscCall(KSPSetReusePreconditioner(s->kc, PETSC_TRUE));
  }
  /* The preconditioner's matrix stays Q, so the PC is not set up again for N. */
  PetscCall(MatDuplicate(s->Q, MAT_DO_NOT_COPY_VALUES, &s->N));
  PetscCall(spd(s->N, near));
  /* N's values are written in place (newton_matrix), never a new entry. */
  PetscCall(MatSetOption(s->N, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE));
  PetscCall(KSPSetOperators(s->kc, s->N, s->Q));
  /* Each of the rank's columns of N has its place in frame_of: its rows and its ghosts,
   * not the whole (4 bytes a dof on every rank). */
  PetscCall(ghost_columns(s, &garray, &ng));
  PetscCall(PetscMalloc1(s->m + ng, &s->frame_of));
  for (PetscInt c = 0; c < s->m + ng; c++) s->frame_of[c] = -1;
  PetscFunctionReturn(0);
}

/* *out ← a square parallel matrix of global size `size` whose m rows on this rank are the
 * CSR given (row offsets from 0, global columns in order), values copied. */
static PetscErrorCode from_csr(MPI_Comm comm, PetscInt m, PetscInt size, const PetscInt *rowptr,
                               const PetscInt *cols, const PetscScalar *vals, Mat *out)
{
  PetscFunctionBeginUser;
  PetscCall(MatCreate(comm, out));
  PetscCall(MatSetSizes(*out, m, m, size, size));
  PetscCall(MatSetType(*out, MATAIJ));
  PetscCall(MatSeqAIJSetPreallocationCSR(*out, rowptr, cols, vals));
  PetscCall(MatMPIAIJSetPreallocationCSR(*out, rowptr, cols, vals));
  PetscFunctionReturn(0);
}

/* Row r's entries where N (values n) and M (Q's values q, or K where q is NULL) differ:
 * their count, and where cols is given, their columns and N − M there. N and Q share
 * their layout, so their runs match. */
static PetscInt row_difference(const Local *l, const Values *n, const Values *q, PetscInt r,
                               PetscInt *cols, PetscScalar *vals)
{
  PetscScalar *nrun[3], *qrun[3];
  PetscInt     len[3], x = l->ai[r], k = 0;

  runs(n, l, r, nrun, len);
  if (q) runs(q, l, r, qrun, len);
  for (int p = 0; p < 3; p++)
    for (PetscInt i = 0; i < len[p]; i++, x++) {
      PetscScalar nv = nrun[p][i], mv = q ? qrun[p][i] : l->k[x];
      if (nv == mv) continue;
      if (cols) {
        cols[k] = l->aj[x];
        vals[k] = nv - mv;
      }
      k++;
    }
  return k;
}

/* N − M (M: K where `from_k`, else Q) as a matrix of its own, with N's layout: the
 * entries where the two differ (the rows and columns of nodes whose removed directions or
 * slip stiffness differ), on K's pattern; NULL where none does on any rank. */
static PetscErrorCode difference(VcKsp *s, PetscBool from_k, Mat *d)
{
  Local        l;
  Values       n, q, *m = from_k ? NULL : &q;
  PetscInt     size, nnz = 0, total, *rowptr, *cols;
  PetscScalar *vals;
  MPI_Comm     comm;

  PetscFunctionBeginUser;
  *d = NULL;
  PetscCall(PetscObjectGetComm((PetscObject)s->N, &comm));
  PetscCall(MatGetSize(s->N, &size, NULL));
  PetscCall(local_open(s, &l));
  PetscCall(values_open(s->N, PETSC_FALSE, &n));
  if (!from_k) PetscCall(values_open(s->Q, PETSC_FALSE, &q));
  for (PetscInt r = 0; r < l.m; r++) nnz += row_difference(&l, &n, m, r, NULL, NULL);
  PetscCallMPI(MPI_Allreduce(&nnz, &total, 1, MPIU_INT, MPI_SUM, comm));
  if (total > 0) {
    PetscCall(PetscMalloc3(l.m + 1, &rowptr, nnz, &cols, nnz, &vals));
    rowptr[0] = 0;
    for (PetscInt r = 0; r < l.m; r++)
      rowptr[r + 1] = rowptr[r] + row_difference(&l, &n, m, r, cols + rowptr[r], vals + rowptr[r]);
    PetscCall(from_csr(comm, l.m, size, rowptr, cols, vals, d));
    PetscCall(PetscFree3(rowptr, cols, vals));
  }
  if (!from_k) PetscCall(values_close(s->Q, PETSC_FALSE, &q));
  PetscCall(values_close(s->N, PETSC_FALSE, &n));
  PetscCall(local_close(s, &l));
  PetscFunctionReturn(0);
}

/* Pᵀ D P for a symmetric D with few nonzero rows R: P_Rᵀ D_RR P_R, so that the product
 * costs what R holds, not what P does. NULL where D is. */
static PetscErrorCode restricted_ptap(Mat d, Mat p, Mat *out)
{
  PetscInt c0, c1;
  IS       isr, isc;
  Mat      dr, pr;
  MPI_Comm comm;

  PetscFunctionBeginUser;
  *out = NULL;
  if (!d) PetscFunctionReturn(0);
  PetscCall(PetscObjectGetComm((PetscObject)d, &comm));
  PetscCall(MatFindNonzeroRows(d, &isr));
  if (!isr) { /* every row is nonzero */
    PetscInt r0, r1;
    PetscCall(MatGetOwnershipRange(d, &r0, &r1));
    PetscCall(ISCreateStride(comm, r1 - r0, r0, 1, &isr));
  }
  PetscCall(MatGetOwnershipRangeColumn(p, &c0, &c1));
  PetscCall(ISCreateStride(comm, c1 - c0, c0, 1, &isc));
  PetscCall(MatCreateSubMatrix(d, isr, isr, MAT_INITIAL_MATRIX, &dr));
  PetscCall(MatCreateSubMatrix(p, isr, isc, MAT_INITIAL_MATRIX, &pr));
  PetscCall(MatPtAP(dr, pr, MAT_INITIAL_MATRIX, PETSC_DEFAULT, out));
  PetscCall(MatDestroy(&dr));
  PetscCall(MatDestroy(&pr));
  PetscCall(ISDestroy(&isr));
  PetscCall(ISDestroy(&isc));
  PetscFunctionReturn(0);
}

/* This rank's rows of D over the fine indices `need` (its nonzero rows and every column
 * they touch, sorted): row k of *local is D's row need[k] where that row is this rank's,
 * empty where it is another's. */
static PetscErrorCode own_rows(Mat d, IS *need, Mat *local)
{
  PetscInt           r0, r1, n = 0, nnz = 0, *idx, *rowptr, *cols;
  PetscScalar       *vals;
  const PetscInt    *c;
  const PetscScalar *v;

  PetscFunctionBeginUser;
  PetscCall(MatGetOwnershipRange(d, &r0, &r1));
  for (PetscInt r = r0; r < r1; r++) {
    PetscInt nc;
    PetscCall(MatGetRow(d, r, &nc, NULL, NULL));
    nnz += nc;
    PetscCall(MatRestoreRow(d, r, &nc, NULL, NULL));
  }
  PetscCall(PetscMalloc1(nnz + r1 - r0, &idx));
  for (PetscInt r = r0; r < r1; r++) {
    PetscInt nc;
    PetscCall(MatGetRow(d, r, &nc, &c, NULL));
    if (nc) idx[n++] = r;
    for (PetscInt j = 0; j < nc; j++) idx[n++] = c[j];
    PetscCall(MatRestoreRow(d, r, &nc, &c, NULL));
  }
  PetscCall(PetscSortRemoveDupsInt(&n, idx));
  PetscCall(PetscMalloc3(n + 1, &rowptr, nnz, &cols, nnz, &vals));
  rowptr[0] = 0;
  for (PetscInt k = 0; k < n; k++) {
    PetscInt nc = 0, at = rowptr[k];
    if (idx[k] >= r0 && idx[k] < r1) PetscCall(MatGetRow(d, idx[k], &nc, &c, &v));
    for (PetscInt j = 0; j < nc; j++, at++) {
      PetscCall(PetscFindInt(c[j], n, idx, &cols[at]));
      vals[at] = v[j];
    }
    if (nc) PetscCall(MatRestoreRow(d, idx[k], &nc, &c, &v));
    rowptr[k + 1] = at;
  }
  PetscCall(MatCreate(PETSC_COMM_SELF, local));
  PetscCall(MatSetSizes(*local, n, n, n, n));
  PetscCall(MatSetType(*local, MATSEQAIJ));
  PetscCall(MatSeqAIJSetPreallocationCSR(*local, rowptr, cols, vals));
  PetscCall(PetscFree3(rowptr, cols, vals));
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, n, idx, PETSC_OWN_POINTER, need));
  PetscFunctionReturn(0);
}

/* The coarse entries of Pᵀ D P that this rank's rows of D make: P's rows `need` fetched
 * whole (collective) and a sequential product over them; NULL where the rank has no row. */
static PetscErrorCode partial_ptap(Mat d, Mat p, Mat *part)
{
  PetscInt n, nc;
  IS       need, all;
  Mat      local, *rows;

  PetscFunctionBeginUser;
  *part = NULL;
  PetscCall(MatGetSize(p, NULL, &nc));
  PetscCall(own_rows(d, &need, &local));
  PetscCall(ISCreateStride(PETSC_COMM_SELF, nc, 0, 1, &all));
  PetscCall(MatCreateSubMatrices(p, 1, &need, &all, MAT_INITIAL_MATRIX, &rows));
  PetscCall(ISGetLocalSize(need, &n));
  if (n > 0) {
    PetscCall(MatProductCreate(local, rows[0], NULL, part));
    /* A prefix of its own: the -matptap_via that GAMG's products read is not for it. */
    PetscCall(MatSetOptionsPrefix(*part, "vc_update_"));
    PetscCall(MatProductSetType(*part, MATPRODUCT_PtAP));
    PetscCall(MatProductSetAlgorithm(*part, MATPRODUCTALGORITHMDEFAULT));
    PetscCall(MatProductSetFill(*part, PETSC_DEFAULT));
    PetscCall(MatProductSetFromOptions(*part));
    PetscCall(MatProductSymbolic(*part));
    PetscCall(MatProductNumeric(*part));
    PetscCall(MatProductClear(*part));
  }
  PetscCall(MatDestroySubMatrices(1, &rows));
  PetscCall(MatDestroy(&local));
  PetscCall(ISDestroy(&all));
  PetscCall(ISDestroy(&need));
  PetscFunctionReturn(0);
}

/* Each rank's rows of part (NULL: none), sent to the rank that owns them in P's column
 * layout (collective). Received, rank by rank: *ints (row, count, columns, for each row;
 * *length of them) and *vals (the values). */
static PetscErrorCode send_to_owners(Mat part, Mat p, PetscInt **ints, PetscInt *length,
                                     PetscScalar **vals)
{
  const PetscInt    *ranges, *ia = NULL, *ja = NULL;
  const PetscScalar *va = NULL;
  PetscInt           rows = 0, *sendi;
  PetscScalar       *sends;
  PetscMPIInt        size, *si, *sv, *ei, *ev, *ni, *nv, *di, *dv;
  PetscBool          done;
  MPI_Comm           comm;

  PetscFunctionBeginUser;
  PetscCall(PetscObjectGetComm((PetscObject)p, &comm));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCall(MatGetOwnershipRangesColumn(p, &ranges));
  PetscCall(PetscCalloc4(size, &si, size, &sv, size + 1, &ei, size + 1, &ev));
  PetscCall(PetscMalloc4(size, &ni, size, &nv, size + 1, &di, size + 1, &dv));
  if (part) {
    PetscCall(MatGetRowIJ(part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &ia, &ja, &done));
    PetscCall(MatSeqAIJGetArrayRead(part, &va));
  }
  for (PetscInt a = 0, q = 0; a < rows; a++) {
    while (a >= ranges[q + 1]) q++;
    if (ia[a + 1] == ia[a]) continue;
    si[q] += (PetscMPIInt)(2 + ia[a + 1] - ia[a]);
    sv[q] += (PetscMPIInt)(ia[a + 1] - ia[a]);
  }
  for (PetscMPIInt q = 0; q < size; q++) {
    ei[q + 1] = ei[q] + si[q];
    ev[q + 1] = ev[q] + sv[q];
  }
  PetscCall(PetscMalloc2(ei[size], &sendi, ev[size], &sends));
  for (PetscInt a = 0, xi = 0, xv = 0; a < rows; a++) {
    PetscInt len = ia[a + 1] - ia[a];
    if (!len) continue;
    sendi[xi++] = a;
    sendi[xi++] = len;
    PetscCall(PetscArraycpy(sendi + xi, ja + ia[a], len));
    PetscCall(PetscArraycpy(sends + xv, va + ia[a], len));
    xi += len;
    xv += len;
  }
  if (part) {
    PetscCall(MatSeqAIJRestoreArrayRead(part, &va));
    PetscCall(MatRestoreRowIJ(part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &ia, &ja, &done));
  }
  PetscCallMPI(MPI_Alltoall(si, 1, MPI_INT, ni, 1, MPI_INT, comm));
  PetscCallMPI(MPI_Alltoall(sv, 1, MPI_INT, nv, 1, MPI_INT, comm));
  di[0] = dv[0] = 0;
  for (PetscMPIInt q = 0; q < size; q++) {
    di[q + 1] = di[q] + ni[q];
    dv[q + 1] = dv[q] + nv[q];
  }
  PetscCall(PetscMalloc2(di[size], ints, dv[size], vals));
  PetscCallMPI(MPI_Alltoallv(sendi, si, ei, MPIU_INT, *ints, ni, di, MPIU_INT, comm));
  PetscCallMPI(MPI_Alltoallv(sends, sv, ev, MPIU_SCALAR, *vals, nv, dv, MPIU_SCALAR, comm));
  *length = di[size];
  PetscCall(PetscFree2(sendi, sends));
  PetscCall(PetscFree4(si, sv, ei, ev));
  PetscCall(PetscFree4(ni, nv, di, dv));
  PetscFunctionReturn(0);
}

/* sum ← this rank's coarse rows (P's column layout), the received parts added rank by
 * rank as the buffers hold them (ints: row, count, columns; vals: the values), so that
 * every run adds them in the same order. */
static PetscErrorCode add_in_rank_order(Mat p, const PetscInt *ints, PetscInt length,
                                        const PetscScalar *vals, Mat *sum)
{
  const PetscInt *ranges;
  PetscInt        c0, nc, rows, *bound;
  PetscMPIInt     rank;

  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(PetscObjectComm((PetscObject)p), &rank));
  PetscCall(MatGetOwnershipRangesColumn(p, &ranges));
  PetscCall(MatGetSize(p, NULL, &nc));
  c0   = ranges[rank];
  rows = ranges[rank + 1] - c0;
  PetscCall(PetscCalloc1(rows, &bound));
  for (PetscInt x = 0; x < length; x += 2 + ints[x + 1]) bound[ints[x] - c0] += ints[x + 1];
  PetscCall(MatCreateSeqAIJ(PETSC_COMM_SELF, rows, nc, 0, bound, sum));
  for (PetscInt x = 0, y = 0; x < length; y += ints[x + 1], x += 2 + ints[x + 1]) {
    PetscInt row = ints[x] - c0;
    PetscCall(MatSetValues(*sum, 1, &row, ints[x + 1], ints + x + 2, vals + y, ADD_VALUES));
  }
  PetscCall(MatAssemblyBegin(*sum, MAT_FINAL_ASSEMBLY));
  PetscCall(MatAssemblyEnd(*sum, MAT_FINAL_ASSEMBLY));
  PetscCall(PetscFree(bound));
  PetscFunctionReturn(0);
}

/* *out ← the parallel matrix whose rows on this rank are those of the sequential `rows`
 * (square, its columns global). */
static PetscErrorCode as_parallel(Mat rows, MPI_Comm comm, Mat *out)
{
  const PetscInt    *ia, *ja;
  const PetscScalar *va;
  PetscInt           m, nc;
  PetscBool          done;

  PetscFunctionBeginUser;
  PetscCall(MatGetSize(rows, NULL, &nc));
  PetscCall(MatGetRowIJ(rows, 0, PETSC_FALSE, PETSC_FALSE, &m, &ia, &ja, &done));
  PetscCall(MatSeqAIJGetArrayRead(rows, &va));
  PetscCall(from_csr(comm, m, nc, ia, ja, va, out));
  PetscCall(MatSeqAIJRestoreArrayRead(rows, &va));
  PetscCall(MatRestoreRowIJ(rows, 0, PETSC_FALSE, PETSC_FALSE, &m, &ia, &ja, &done));
  PetscFunctionReturn(0);
}

/* Pᵀ D P on three ranks or more, the same bits in every run: each rank multiplies its own
 * rows of D by the rows of P they touch (partial_ptap), and the rank that owns a coarse row
 * adds what every rank made of it in rank order. PETSc's parallel products add other ranks'
 * contributions in the order their messages arrive (the scalable one), or cost many times
 * the work on these thin products (the all-at-once one, docs/performance.md). NULL where D
 * is. */
static PetscErrorCode ordered_ptap(Mat d, Mat p, Mat *out)
{
  PetscInt    *ints, length = 0;
  PetscScalar *vals;
  Mat          part, sum;

  PetscFunctionBeginUser;
  *out = NULL;
  if (!d) PetscFunctionReturn(0);
  PetscCall(partial_ptap(d, p, &part));
  PetscCall(send_to_owners(part, p, &ints, &length, &vals));
  PetscCall(MatDestroy(&part));
  PetscCall(add_in_rank_order(p, ints, length, vals, &sum));
  PetscCall(as_parallel(sum, PetscObjectComm((PetscObject)p), out));
  PetscCall(MatDestroy(&sum));
  PetscCall(PetscFree2(ints, vals));
  PetscFunctionReturn(0);
}

/* Q ← N and its coarse operators on K's interpolations P_l, A_{l−1} = P_lᵀ A_l P_l with
 * A_fine = Q, computed as a reference's plus the difference carried down: K's own at a
 * step's first system (`from_k`), so that a step's hierarchies depend on K and the step
 * alone, and the last system's within a step. Q differs from K only near the contact
 * boundary, and from the last system only where the sets changed, so each product costs
 * a fraction of GAMG's, which multiplies the whole of Q. The difference's pattern lies
 * within K's, so each level's lies within its operator's, and the sum is written in place
 * (MatAXPY on a subset pattern). */
static PetscErrorCode galerkin_update(VcKsp *s, PetscBool from_k)
{
  PC          pc;
  Mat         d;
  PetscMPIInt size;

  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)s->N), &size));
  PetscCall(KSPGetPC(s->kc, &pc));
  PetscCall(difference(s, from_k, &d));
  PetscCall(keep_q(s));
  for (PetscInt l = s->nlev - 1; l > 0; l--) {
    KSP smoother;
    Mat p, a, dc;
    PetscCall(PCMGGetInterpolation(pc, l, &p));
    PetscCall(size > 2 ? ordered_ptap(d, p, &dc) : restricted_ptap(d, p, &dc));
    PetscCall(MatDestroy(&d));
    PetscCall(level(pc, l - 1, &smoother, &a));
    if (from_k) PetscCall(MatCopy(s->coarse_k[l - 1], a, SAME_NONZERO_PATTERN));
    if (dc) PetscCall(MatAXPY(a, 1.0, dc, SUBSET_NONZERO_PATTERN));
    d = dc;
  }
  PetscCall(MatDestroy(&d));
  /* A matrix changed in place is news to a KSP only through KSPSetOperators: without it,
   * Chebyshev kept K's eigenvalue estimates, and CG met an indefinite preconditioner. */
  for (PetscInt l = 0; l < s->nlev; l++) {
    KSP smoother;
    Mat a;
    PetscCall(level(pc, l, &smoother, &a));
    PetscCall(KSPSetOperators(smoother, a, a));
  }
  PetscFunctionReturn(0);
}

int vc_galerkin_defect(void *ctx, PetscReal *defect);

/* With the PETSc option -viscontact_galerkin_check, rank 0 prints after each update how far
 * the hierarchy is from the Galerkin products computed anew (vc_galerkin_defect): the
 * check of the update on several ranks, whose runs no library test can host (tests/petsc). */
static PetscErrorCode check_galerkin(VcKsp *s)
{
  PetscReal defect;

  PetscFunctionBeginUser;
  if (!s->galerkin_check) PetscFunctionReturn(0);
  PetscCall(vc_galerkin_defect(s, &defect));
  PetscCall(PetscPrintf(PETSC_COMM_WORLD, "Galerkin defect %.3e\n", (double)defect));
  PetscFunctionReturn(0);
}

/* x ← the solution of the constrained system Π(K + S)Π x + (I − Π) x = Π b (b this rank's
 * rows of Π b) with the terms given (every rank gives all of them), from the initial guess
 * in x, to relative tolerance
 * rtol (of b's norm, or where `of_start`, of the initial residual's: an inexact Newton
 * system), as `solved` says. `rebuild`: 0, the preconditioner of the last system serves;
 * 1, it is rebuilt from this system's matrix, on K's aggregates and interpolation (what a
 * step starts with, so that a resumed run builds what the uninterrupted one did); 2, the
 * same, by an update of the last one (galerkin_update). */
int vc_constrained_solve(void *ctx, PetscInt np, const PetscInt *pdofs, const PetscScalar *pdirs,
                         PetscInt ns, const PetscInt *sdofs, const PetscScalar *smats, int rebuild,
                         PetscReal rtol, int of_start, const PetscScalar *b, PetscScalar *x,
                         VcSolve *v)
{
  VcKsp *s = (VcKsp *)ctx;

  PetscCheck(s->kc, PETSC_COMM_SELF, PETSC_ERR_ORDER, "the KSP is not the Newton systems'");
  s->terms = (VcTerms){np, ns, pdofs, sdofs, pdirs, smats};
  PetscCall(newton_matrix(s));
  s->terms = (VcTerms){0};
  if (rebuild && s->coarse_k) {
    PetscCall(galerkin_update(s, rebuild == 1));
    PetscCall(check_galerkin(s));
  } else if (rebuild) PetscCall(keep_q(s));
  PetscCall(KSPSetTolerances(s->kc, rtol, 0.0, PETSC_DEFAULT, PETSC_DEFAULT));
  if (of_start != s->of_start) {
    void *test;
    PetscCall(KSPConvergedDefaultCreate(&test));
    PetscCall(KSPSetConvergenceTest(s->kc, KSPConvergedDefault, test, KSPConvergedDefaultDestroy));
    if (of_start) PetscCall(KSPConvergedDefaultSetUIRNorm(s->kc));
    PetscCall(watch(s, s->kc, &s->cw));
    s->of_start = of_start;
  }
  PetscCall(solved(s, s->kc, b, x, v));
  return 0;
}

/* How far the constrained multigrid is from the Galerkin products of its fine matrix: the
 * largest ‖A_{l−1} − P_lᵀ A_l P_l‖ / ‖A_{l−1}‖ (Frobenius) over the levels, the products
 * computed anew from A_fine = Q (tests/petsc); 0 before the constrained system exists and
 * where the PC is not GAMG. */
int vc_galerkin_defect(void *ctx, PetscReal *defect)
{
  VcKsp *s = (VcKsp *)ctx;
  PC     pc;

  *defect = 0;
  if (!s->coarse_k) return 0;
  PetscCall(KSPGetPC(s->kc, &pc));
  for (PetscInt l = s->nlev - 1; l > 0; l--) {
    KSP       fine, coarse;
    Mat       a, p, ac, c;
    PetscReal dnorm, cnorm;
    PetscCall(level(pc, l, &fine, &a));
    PetscCall(level(pc, l - 1, &coarse, &ac));
    PetscCall(PCMGGetInterpolation(pc, l, &p));
    PetscCall(MatPtAP(a, p, MAT_INITIAL_MATRIX, PETSC_DEFAULT, &c));
    PetscCall(MatNorm(ac, NORM_FROBENIUS, &cnorm));
    PetscCall(MatAXPY(c, -1.0, ac, DIFFERENT_NONZERO_PATTERN));
    PetscCall(MatNorm(c, NORM_FROBENIUS, &dnorm));
    PetscCall(MatDestroy(&c));
    *defect = PetscMax(*defect, dnorm / cnorm);
  }
  return 0;
}

int vc_ksp_destroy(void *ctx)
{
  VcKsp *s = (VcKsp *)ctx;

  if (!s) return 0;
  for (int k = 0; k < 2; k++) {
    Watch *w = k ? &s->cw : &s->kw;
    if (w->inner_destroy) PetscCall(w->inner_destroy(w->inner_ctx));
  }
  for (PetscInt l = 0; s->coarse_k && l + 1 < s->nlev; l++) PetscCall(MatDestroy(&s->coarse_k[l]));
  PetscCall(PetscFree(s->coarse_k));
  PetscCall(KSPDestroy(&s->kc));
  PetscCall(MatDestroy(&s->N));
  PetscCall(MatDestroy(&s->Q));
  PetscCall(PetscFree(s->frame_of));
  PetscCall(PetscFree2(s->kai, s->below));
  PetscCall(VecScatterDestroy(&s->ghosts));
  PetscCall(VecDestroy(&s->ghost));
  PetscCall(VecDestroy(&s->b));
  PetscCall(VecDestroy(&s->x));
  PetscCall(KSPDestroy(&s->ksp));
  PetscCall(MatDestroy(&s->A));
  PetscCall(PetscFree2(s->count, s->displ));
  PetscCall(PetscFree(s));
  return 0;
}
