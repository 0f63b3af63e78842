/* The C side of viscontact's PETSc binding (src/petsc/mod.rs): a handful of functions with
 * plain C types, so that PETSc's macros (PetscCall, PETSC_COMM_SELF, which is a pointer in
 * Open MPI) and its types stay on this side. Every function returns a PetscErrorCode (0:
 * success); vc_error_message turns one into PETSc's text. K_A's own KSP spans the ranks an MPI
 * launcher started (PETSC_COMM_WORLD: each rank holds a contiguous block of its rows, and
 * every rank gets the whole solution back); the active set's Newton systems are one
 * process's (PETSC_COMM_SELF, refused on several). */
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

typedef struct {
  Mat A;
  KSP ksp;
  Vec b, x;
  /* The rows this rank owns, [lo, lo + count[rank]); each rank's count and first row
   * (displ) for gathering the solution; count and displ NULL on one process. */
  PetscInt     lo;
  PetscMPIInt *count, *displ;
  /* K_A's convergence test (PETSc's, after the options), wrapped by converged_or_given_up;
   * the request to give the solve up during vc_ksp_solve (NULL: none), and whether it did. */
  PetscErrorCode (*inner)(KSP, PetscInt, PetscReal, KSPConvergedReason *, void *);
  void *inner_ctx;
  PetscErrorCode (*inner_destroy)(void *);
  int (*requested)(void *);
  void     *flag;
  PetscBool given_up;
  /* The constrained system, created with the KSP where `newton` (else NULL): its assembled
   * matrix N, the matrix Q its preconditioner was built from, its KSP, the terms of the
   * solve in progress. */
  Mat       N, Q;
  KSP       kc;
  VcTerms   terms;
  PetscInt *frame_of; /* n entries, −1 between calls (newton_matrix) */
  /* GAMG's levels (0: coarsest) and K's Galerkin operators on levels 0 … nlev − 2, kept for
   * galerkin_update; NULL where the constrained PC is not GAMG (the options chose another). */
  PetscInt nlev;
  Mat     *coarse_k;
  int      of_start; /* the convergence test's: rtol of the initial residual, else of b */
} VcKsp;

static PetscErrorCode constrained_setup(VcKsp *s);

/* The rows of `rank` among `size` ranks: whole blocks of bs rows, as even as they come. */
static void owned(PetscInt n, PetscInt bs, PetscMPIInt rank, PetscMPIInt size, PetscInt *lo,
                  PetscInt *hi)
{
  PetscInt64 blocks = n / bs;
  *lo = (PetscInt)(bs * (blocks * rank / size));
  *hi = rank + 1 == size ? n : (PetscInt)(bs * (blocks * (rank + 1) / size));
}

/* K_A on the ranks: on one, a SEQAIJ of the whole CSR (what the Newton systems update in
 * place); on several, an MPIAIJ of which each rank gives its own rows [lo, hi) of the same
 * global CSR, with each rank's share recorded for gathering the solution. */
static PetscErrorCode distributed_matrix(VcKsp *s, PetscInt n, const PetscInt *rowptr,
                                         const PetscInt *cols, const PetscScalar *vals, PetscInt bs,
                                         PetscInt *hi)
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
    *hi = n;
    PetscFunctionReturn(0);
  }
  PetscInt *local;
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
    PetscInt lo, h;
    owned(n, bs, r, size, &lo, &h);
    s->count[r] = (PetscMPIInt)(h - lo);
    s->displ[r] = (PetscMPIInt)lo;
  }
  owned(n, bs, rank, size, &s->lo, hi);
  PetscCall(PetscMalloc1(*hi - s->lo + 1, &local));
  for (PetscInt i = s->lo; i <= *hi; i++) local[i - s->lo] = rowptr[i] - rowptr[s->lo];
  PetscCall(MatCreate(PETSC_COMM_WORLD, &s->A));
  PetscCall(MatSetSizes(s->A, *hi - s->lo, *hi - s->lo, n, n));
  PetscCall(MatSetType(s->A, MATMPIAIJ));
  if (bs > 1) PetscCall(MatSetBlockSize(s->A, bs));
  PetscCall(MatMPIAIJSetPreallocationCSR(s->A, local, cols + rowptr[s->lo], vals + rowptr[s->lo]));
  PetscCall(PetscFree(local));
  PetscFunctionReturn(0);
}

/* K_A's convergence test: PETSc's, unless the solve is to be given up (the run's stop,
 * vc_ksp_solve's `requested`), which every rank learns at the same iteration (a reduction
 * over the ranks): the KSP then ends with KSP_DIVERGED_NULL and `given_up`, so that the
 * ranks leave the collective calls together. Mpirun kills the ranks a second after it
 * passes a Ctrl-C on as SIGTERM (docs/cluster.md): a step cannot be waited for. */
static PetscErrorCode converged_or_given_up(KSP ksp, PetscInt it, PetscReal rnorm,
                                            KSPConvergedReason *reason, void *ctx)
{
  VcKsp   *s = (VcKsp *)ctx;
  int      stop = s->requested ? s->requested(s->flag) : 0;
  MPI_Comm comm;

  PetscFunctionBeginUser;
  PetscCall(s->inner(ksp, it, rnorm, reason, s->inner_ctx));
  PetscCall(PetscObjectGetComm((PetscObject)ksp, &comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &stop, 1, MPI_INT, MPI_MAX, comm));
  if (stop && *reason == KSP_CONVERGED_ITERATING) {
    *reason = KSP_DIVERGED_NULL;
    s->given_up = PETSC_TRUE;
  }
  PetscFunctionReturn(0);
}

/* The matrix in CSR (a symmetric matrix's CSC is its CSR), its near-null space as `nvec`
 * orthonormal vectors of length n stored one after the other, CG + GAMG with relative
 * tolerance `rtol`, then `options` (PETSc's command-line syntax) and KSPSetFromOptions;
 * set up for K's own solves, or where `newton`, for the constrained systems alone (their
 * KSP and multigrid: constrained_setup), K's never being solved. Every rank gives the
 * whole matrix; on several ranks each keeps its rows, and `newton` is refused. */
int vc_ksp_create(PetscInt n, const PetscInt *rowptr, const PetscInt *cols, const PetscScalar *vals,
                  PetscInt bs, PetscInt nvec, const PetscScalar *near, PetscReal rtol,
                  const char *options, int newton, void **out)
{
  VcKsp       *s;
  MatNullSpace space;
  Vec         *vecs;
  PC           pc;
  PetscInt     hi;
  MPI_Comm     comm;

  PetscCall(PetscCalloc1(1, &s));
  PetscCall(distributed_matrix(s, n, rowptr, cols, vals, bs, &hi));
  PetscCheck(!newton || !s->count, PETSC_COMM_WORLD, PETSC_ERR_SUP,
             "the active set's Newton systems run on one process");
  PetscCall(PetscObjectGetComm((PetscObject)s->A, &comm));
  PetscCall(MatSetOption(s->A, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatSetOption(s->A, MAT_SPD, PETSC_TRUE));

  PetscCall(PetscMalloc1(nvec, &vecs));
  for (PetscInt k = 0; k < nvec; k++) {
    PetscScalar *a;
    PetscCall(MatCreateVecs(s->A, &vecs[k], NULL));
    PetscCall(VecGetArray(vecs[k], &a));
    PetscCall(PetscArraycpy(a, near + k * n + s->lo, hi - s->lo));
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
  if (newton) PetscCall(constrained_setup(s));
  else {
    PetscCall(KSPSetUp(s->ksp));
    PetscCall(KSPGetAndClearConvergenceTest(s->ksp, &s->inner, &s->inner_ctx, &s->inner_destroy));
    PetscCall(KSPSetConvergenceTest(s->ksp, converged_or_given_up, s, NULL));
  }
  PetscCall(MatCreateVecs(s->A, &s->x, &s->b));
  *out = s;
  return 0;
}

/* Every rank's x ← the whole of x, from each rank's owned rows (nothing on one process). */
static PetscErrorCode gathered(VcKsp *s, PetscScalar *x)
{
  MPI_Comm comm;

  PetscFunctionBeginUser;
  if (!s->count) PetscFunctionReturn(0);
  PetscCall(PetscObjectGetComm((PetscObject)s->A, &comm));
  PetscCallMPI(MPI_Allgatherv(MPI_IN_PLACE, 0, MPIU_SCALAR, x, s->count, s->displ, MPIU_SCALAR, comm));
  PetscFunctionReturn(0);
}

/* x ← K⁻¹ b by the KSP, from the initial guess in x; its iterations, converged reason (< 0:
 * diverged) and final residual norm. b and x are whole on every rank (each gives the same
 * b), and x is whole on every rank after it. `requested(flag)` (NULL: none), asked at every
 * iteration, gives the solve up where it returns nonzero on any rank: then `given_up` and x
 * holds an iterate. */
int vc_ksp_solve(void *ctx, const PetscScalar *b, PetscScalar *x, int (*requested)(void *),
                 void *flag, PetscInt *its, int *reason, PetscReal *rnorm, int *given_up)
{
  VcKsp             *s = (VcKsp *)ctx;
  KSPConvergedReason r;

  s->requested = requested;
  s->flag = flag;
  s->given_up = PETSC_FALSE;
  PetscCall(VecPlaceArray(s->b, b + s->lo));
  PetscCall(VecPlaceArray(s->x, x + s->lo));
  PetscCall(KSPSolve(s->ksp, s->b, s->x));
  PetscCall(VecResetArray(s->x));
  PetscCall(VecResetArray(s->b));
  PetscCall(gathered(s, x));
  PetscCall(KSPGetIterationNumber(s->ksp, its));
  PetscCall(KSPGetConvergedReason(s->ksp, &r));
  PetscCall(KSPGetResidualNorm(s->ksp, rnorm));
  *reason = (int)r;
  *given_up = s->given_up;
  s->requested = NULL;
  return 0;
}

/* The KSP's and the PC's type names (after the options). */
int vc_ksp_types(void *ctx, const char **ksp_type, const char **pc_type)
{
  VcKsp *s = (VcKsp *)ctx;
  PC     pc;

  PetscCall(KSPGetType(s->ksp, ksp_type));
  PetscCall(KSPGetPC(s->ksp, &pc));
  PetscCall(PCGetType(pc, pc_type));
  return 0;
}

/* y = K x. */
int vc_mult(void *ctx, const PetscScalar *x, PetscScalar *y)
{
  VcKsp *s = (VcKsp *)ctx;

  PetscCall(VecPlaceArray(s->b, x));
  PetscCall(VecPlaceArray(s->x, y));
  PetscCall(MatMult(s->A, s->b, s->x));
  PetscCall(VecResetArray(s->x));
  PetscCall(VecResetArray(s->b));
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
  PetscInt    k, dof[3];
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

/* The frames of the terms' directions, one per node, and each dof's frame (−1: none) in
 * s->frame_of, which the caller resets. */
static PetscErrorCode frames(VcKsp *s, Frame **out, PetscInt *count)
{
  const VcTerms *t = &s->terms;
  Frame         *fr;
  PetscInt       nf = 0;

  PetscFunctionBeginUser;
  PetscCall(PetscMalloc1(t->np, &fr));
  for (PetscInt e = 0; e < t->np; e++) {
    PetscInt           idx[3];
    int                pos[3];
    const PetscScalar *v = t->pdirs + 3 * e;
    PetscInt           k = present(t->pdofs + 3 * e, idx, pos);
    Frame             *f;
    if (k == 0) continue;
    if (s->frame_of[idx[0]] < 0) {
      f = &fr[nf];
      *f = (Frame){k, {idx[0], idx[1 % k], idx[2 % k]}, {0}};
      for (PetscInt a = 0; a < k; a++) {
        f->r[k * a + a] = 1.0;
        s->frame_of[idx[a]] = nf;
      }
      nf++;
    } else f = &fr[s->frame_of[idx[0]]];
    for (PetscInt a = 0; a < k; a++)
      for (PetscInt b = 0; b < k; b++) f->r[k * a + b] -= 2.0 * v[pos[a]] * v[pos[b]];
  }
  *out = fr;
  *count = nf;
  PetscFunctionReturn(0);
}

/* (A M B)_ij, M in CSR, A = R over the frame of i where `left` (else I), B = R over the
 * frame of j where `right` (else I); a dof without a frame is its own (R = 1). */
static PetscScalar reflected(const Frame *fr, const PetscInt *frame_of, const PetscInt *ai,
                             const PetscInt *aj, const PetscScalar *m, PetscInt i, PetscInt j,
                             int left, int right)
{
  Frame        unit_i = {1, {i}, {1.0}}, unit_j = {1, {j}, {1.0}};
  const Frame *fi = left && frame_of[i] >= 0 ? &fr[frame_of[i]] : &unit_i;
  const Frame *fj = right && frame_of[j] >= 0 ? &fr[frame_of[j]] : &unit_j;
  PetscInt     a = 0, b = 0;
  PetscScalar  sum = 0;

  while (fi->dof[a] != i) a++;
  while (fj->dof[b] != j) b++;
  for (PetscInt p = 0; p < fi->k; p++)
    for (PetscInt q = 0; q < fj->k; q++) {
      PetscInt e = entry(ai, aj, fi->dof[p], fj->dof[q]);
      if (e >= 0) sum += fi->r[fi->k * a + p] * m[e] * fj->r[fj->k * q + b];
    }
  return sum;
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
 * fifth of the step on the plate 0.03). */
static PetscErrorCode newton_matrix(VcKsp *s)
{
  const VcTerms     *t = &s->terms;
  const PetscInt    *ai, *aj;
  const PetscScalar *ka;
  PetscScalar       *na, *upd;
  PetscInt          *at, n, nf, nu = 0, cap = 0;
  PetscBool          done;
  Frame             *fr = NULL;

  PetscFunctionBeginUser;
  PetscCall(MatGetRowIJ(s->N, 0, PETSC_FALSE, PETSC_FALSE, &n, &ai, &aj, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "the Newton matrix has no CSR arrays");
  PetscCall(MatSeqAIJGetArrayRead(s->A, &ka));
  PetscCall(MatSeqAIJGetArray(s->N, &na));
  PetscCall(PetscArraycpy(na, ka, ai[n]));
  PetscCall(MatSeqAIJRestoreArrayRead(s->A, &ka));
  for (PetscInt e = 0; e < t->ns; e++) {
    PetscInt idx[3];
    int      pos[3];
    PetscInt k = present(t->sdofs + 3 * e, idx, pos);
    for (PetscInt r = 0; r < k; r++)
      for (PetscInt c = 0; c < k; c++) {
        PetscInt x = entry(ai, aj, idx[r], idx[c]);
        PetscCheck(x >= 0, PETSC_COMM_SELF, PETSC_ERR_SUP, "K lacks a pair of a node's dofs");
        na[x] += t->smats[9 * e + 3 * pos[r] + pos[c]];
      }
  }
  PetscCall(frames(s, &fr, &nf));
  for (PetscInt f = 0; f < nf; f++)
    for (PetscInt a = 0; a < fr[f].k; a++) cap += 2 * (ai[fr[f].dof[a] + 1] - ai[fr[f].dof[a]]);
  PetscCall(PetscMalloc2(cap, &upd, cap, &at));
  /* The new values, from N = K + S as it stands, written once all are known: a framed row
   * in full, and the mirrored entry of a column without a frame (N stays symmetric). */
  for (PetscInt f = 0; f < nf; f++)
    for (PetscInt a = 0; a < fr[f].k; a++) {
      PetscInt i = fr[f].dof[a];
      for (PetscInt x = ai[i]; x < ai[i + 1]; x++) {
        PetscInt    j = aj[x];
        PetscScalar rmr = reflected(fr, s->frame_of, ai, aj, na, i, j, 1, 1);
        PetscScalar rm = reflected(fr, s->frame_of, ai, aj, na, i, j, 1, 0);
        PetscScalar mr = reflected(fr, s->frame_of, ai, aj, na, i, j, 0, 1);
        PetscScalar v = 0.25 * (1 + DECOUPLED) * (na[x] + rmr) + 0.25 * (1 - DECOUPLED) * (rm + mr);
        upd[nu] = v;
        at[nu++] = x;
        if (s->frame_of[j] < 0) {
          upd[nu] = v;
          at[nu++] = entry(ai, aj, j, i);
        }
      }
    }
  for (PetscInt u = 0; u < nu; u++) na[at[u]] = upd[u];
  for (PetscInt f = 0; f < nf; f++)
    for (PetscInt a = 0; a < fr[f].k; a++) s->frame_of[fr[f].dof[a]] = -1;
  PetscCall(PetscFree2(upd, at));
  PetscCall(PetscFree(fr));
  PetscCall(MatSeqAIJRestoreArray(s->N, &na));
  PetscCall(MatRestoreRowIJ(s->N, 0, PETSC_FALSE, PETSC_FALSE, &n, &ai, &aj, &done));
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
  KSPType      type;
  PC           pc;
  MatNullSpace near;
  PetscInt     n;
  PetscBool    gamg;

  PetscFunctionBeginUser;
  PetscCall(MatGetNearNullSpace(s->A, &near));
  PetscCall(MatDuplicate(s->A, MAT_DO_NOT_COPY_VALUES, &s->N));
  PetscCall(MatDuplicate(s->A, MAT_DO_NOT_COPY_VALUES, &s->Q));
  for (int k = 0; k < 2; k++) {
    Mat m = k ? s->Q : s->N;
    PetscCall(MatSetOption(m, MAT_SYMMETRIC, PETSC_TRUE));
    PetscCall(MatSetOption(m, MAT_SPD, PETSC_TRUE));
    PetscCall(MatSetNearNullSpace(m, near));
  }
  PetscCall(MatGetSize(s->A, &n, NULL));
  PetscCall(PetscMalloc1(n, &s->frame_of));
  for (PetscInt i = 0; i < n; i++) s->frame_of[i] = -1;
  PetscCall(KSPCreate(PETSC_COMM_SELF, &s->kc));
  PetscCall(KSPSetOperators(s->kc, s->N, s->Q));
  PetscCall(KSPGetType(s->ksp, &type));
  PetscCall(KSPSetType(s->kc, type));
  PetscCall(KSPGetPC(s->kc, &pc));
  PetscCall(PCSetType(pc, PCGAMG));
  PetscCall(PCGAMGSetUseSAEstEig(pc, PETSC_FALSE));
  /* GAMG's smoothers would use the operator N, whose residuals its coarse levels (of Q) do
   * not match: CG then met an indefinite preconditioner. */
  PetscCall(PCSetUseAmat(pc, PETSC_FALSE));
  PetscCall(KSPSetInitialGuessNonzero(s->kc, PETSC_TRUE));
  PetscCall(KSPSetFromOptions(s->kc));
  PetscCall(MatCopy(s->A, s->Q, SAME_NONZERO_PATTERN));
  PetscCall(PCSetUp(pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, PCGAMG, &gamg));
  if (gamg) PetscCall(PCMGGetLevels(pc, &s->nlev));
  if (gamg && s->nlev > 1) {
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
  PetscFunctionReturn(0);
}

/* N − M (M: K or Q) as a matrix of its own: the entries where the two differ (the rows and
 * columns of nodes whose removed directions or slip stiffness differ), on K's pattern; NULL
 * where none does. */
static PetscErrorCode difference(VcKsp *s, Mat m, Mat *d)
{
  const PetscInt    *ai, *aj;
  const PetscScalar *ma, *na;
  PetscInt           n, nnz = 0, *rowptr, *cols;
  PetscScalar       *vals;
  PetscBool          done;

  PetscFunctionBeginUser;
  *d = NULL;
  PetscCall(MatGetRowIJ(s->N, 0, PETSC_FALSE, PETSC_FALSE, &n, &ai, &aj, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "the Newton matrix has no CSR arrays");
  PetscCall(MatSeqAIJGetArrayRead(m, &ma));
  PetscCall(MatSeqAIJGetArrayRead(s->N, &na));
  for (PetscInt x = 0; x < ai[n]; x++) nnz += na[x] != ma[x];
  if (nnz > 0) {
    PetscCall(PetscMalloc1(n + 1, &rowptr));
    PetscCall(PetscMalloc1(nnz, &cols));
    PetscCall(PetscMalloc1(nnz, &vals));
    rowptr[0] = 0;
    for (PetscInt i = 0, k = 0; i < n; i++) {
      for (PetscInt x = ai[i]; x < ai[i + 1]; x++)
        if (na[x] != ma[x]) {
          cols[k] = aj[x];
          vals[k++] = na[x] - ma[x];
        }
      rowptr[i + 1] = k;
    }
    PetscCall(MatCreate(PETSC_COMM_SELF, d));
    PetscCall(MatSetSizes(*d, n, n, n, n));
    PetscCall(MatSetType(*d, MATSEQAIJ));
    PetscCall(MatSeqAIJSetPreallocationCSR(*d, rowptr, cols, vals));
    PetscCall(PetscFree(rowptr));
    PetscCall(PetscFree(cols));
    PetscCall(PetscFree(vals));
  }
  PetscCall(MatSeqAIJRestoreArrayRead(s->N, &na));
  PetscCall(MatSeqAIJRestoreArrayRead(m, &ma));
  PetscCall(MatRestoreRowIJ(s->N, 0, PETSC_FALSE, PETSC_FALSE, &n, &ai, &aj, &done));
  PetscFunctionReturn(0);
}

/* Pᵀ D P for a symmetric D with few nonzero rows R: P_Rᵀ D_RR P_R, so that the product
 * costs what R holds, not what P does. NULL where D is. */
static PetscErrorCode restricted_ptap(Mat d, Mat p, Mat *out)
{
  const PetscInt *ai, *aj;
  PetscInt        n, nc, nr = 0, *rows;
  PetscBool       done;
  IS              isr, isc;
  Mat             dr, pr;

  PetscFunctionBeginUser;
  *out = NULL;
  if (!d) PetscFunctionReturn(0);
  PetscCall(MatGetRowIJ(d, 0, PETSC_FALSE, PETSC_FALSE, &n, &ai, &aj, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "a difference matrix has no CSR arrays");
  PetscCall(PetscMalloc1(n, &rows));
  for (PetscInt i = 0; i < n; i++)
    if (ai[i + 1] > ai[i]) rows[nr++] = i;
  PetscCall(MatRestoreRowIJ(d, 0, PETSC_FALSE, PETSC_FALSE, &n, &ai, &aj, &done));
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, nr, rows, PETSC_OWN_POINTER, &isr));
  PetscCall(MatGetSize(p, NULL, &nc));
  PetscCall(ISCreateStride(PETSC_COMM_SELF, nc, 0, 1, &isc));
  PetscCall(MatCreateSubMatrix(d, isr, isr, MAT_INITIAL_MATRIX, &dr));
  PetscCall(MatCreateSubMatrix(p, isr, isc, MAT_INITIAL_MATRIX, &pr));
  PetscCall(MatPtAP(dr, pr, MAT_INITIAL_MATRIX, PETSC_DEFAULT, out));
  PetscCall(MatDestroy(&dr));
  PetscCall(MatDestroy(&pr));
  PetscCall(ISDestroy(&isr));
  PetscCall(ISDestroy(&isc));
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
  PC  pc;
  Mat d;

  PetscFunctionBeginUser;
  PetscCall(KSPGetPC(s->kc, &pc));
  PetscCall(difference(s, from_k ? s->A : s->Q, &d));
  PetscCall(MatCopy(s->N, s->Q, SAME_NONZERO_PATTERN));
  for (PetscInt l = s->nlev - 1; l > 0; l--) {
    KSP smoother;
    Mat p, a, dc;
    PetscCall(PCMGGetInterpolation(pc, l, &p));
    PetscCall(restricted_ptap(d, p, &dc));
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

/* x ← the solution of the constrained system Π(K + S)Π x + (I − Π) x = Π b with the terms
 * given, from the initial guess in x, to relative tolerance rtol (of b's norm, or where
 * `of_start`, of the initial residual's: an inexact Newton system): iterations, reason and
 * final residual norm as vc_ksp_solve. `rebuild`: 0, the preconditioner of the last system
 * serves; 1, it is rebuilt from this system's matrix, on K's aggregates and interpolation
 * (what a step starts with, so that a resumed run builds what the uninterrupted one did);
 * 2, the same, by an update of the last one (galerkin_update). */
int vc_constrained_solve(void *ctx, PetscInt np, const PetscInt *pdofs, const PetscScalar *pdirs,
                         PetscInt ns, const PetscInt *sdofs, const PetscScalar *smats, int rebuild,
                         PetscReal rtol, int of_start, const PetscScalar *b, PetscScalar *x, PetscInt *its,
                         int *reason, PetscReal *rnorm)
{
  VcKsp             *s = (VcKsp *)ctx;
  KSPConvergedReason r;

  PetscCheck(s->kc, PETSC_COMM_SELF, PETSC_ERR_ORDER, "the KSP is not the Newton systems'");
  s->terms = (VcTerms){np, ns, pdofs, sdofs, pdirs, smats};
  PetscCall(newton_matrix(s));
  s->terms = (VcTerms){0};
  if (rebuild && s->coarse_k) PetscCall(galerkin_update(s, rebuild == 1));
  else if (rebuild) PetscCall(MatCopy(s->N, s->Q, SAME_NONZERO_PATTERN));
  PetscCall(KSPSetTolerances(s->kc, rtol, 0.0, PETSC_DEFAULT, PETSC_DEFAULT));
  if (of_start != s->of_start) {
    void *test;
    PetscCall(KSPConvergedDefaultCreate(&test));
    PetscCall(KSPSetConvergenceTest(s->kc, KSPConvergedDefault, test, KSPConvergedDefaultDestroy));
    if (of_start) PetscCall(KSPConvergedDefaultSetUIRNorm(s->kc));
    s->of_start = of_start;
  }
  PetscCall(VecPlaceArray(s->b, b));
  PetscCall(VecPlaceArray(s->x, x));
  PetscCall(KSPSolve(s->kc, s->b, s->x));
  PetscCall(VecResetArray(s->x));
  PetscCall(VecResetArray(s->b));
  PetscCall(KSPGetIterationNumber(s->kc, its));
  PetscCall(KSPGetConvergedReason(s->kc, &r));
  PetscCall(KSPGetResidualNorm(s->kc, rnorm));
  *reason = (int)r;
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
  if (s->inner_destroy) PetscCall(s->inner_destroy(s->inner_ctx));
  for (PetscInt l = 0; s->coarse_k && l + 1 < s->nlev; l++) PetscCall(MatDestroy(&s->coarse_k[l]));
  PetscCall(PetscFree(s->coarse_k));
  PetscCall(KSPDestroy(&s->kc));
  PetscCall(MatDestroy(&s->N));
  PetscCall(MatDestroy(&s->Q));
  PetscCall(PetscFree(s->frame_of));
  PetscCall(VecDestroy(&s->b));
  PetscCall(VecDestroy(&s->x));
  PetscCall(KSPDestroy(&s->ksp));
  PetscCall(MatDestroy(&s->A));
  PetscCall(PetscFree2(s->count, s->displ));
  PetscCall(PetscFree(s));
  return 0;
}
