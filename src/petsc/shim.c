/* The C side of viscontact's PETSc binding (src/petsc/mod.rs): a handful of functions with
 * plain C types, so that PETSc's macros (PetscCall, PETSC_COMM_SELF, which is a pointer in
 * Open MPI) and its types stay on this side. Every function returns a PetscErrorCode (0:
 * success); vc_error_message turns one into PETSc's text. One process, PETSC_COMM_SELF. */
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

typedef struct {
  Mat A;
  KSP ksp;
  Vec b, x;
} VcKsp;

/* The matrix in CSR (a symmetric matrix's CSC is its CSR), its near-null space as `nvec`
 * orthonormal vectors of length n stored one after the other, CG + GAMG with relative
 * tolerance `rtol`, then `options` (PETSc's command-line syntax) and KSPSetFromOptions. */
int vc_ksp_create(PetscInt n, const PetscInt *rowptr, const PetscInt *cols, const PetscScalar *vals,
                  PetscInt bs, PetscInt nvec, const PetscScalar *near, PetscReal rtol,
                  const char *options, void **out)
{
  VcKsp       *s;
  MatNullSpace space;
  Vec         *vecs;
  PC           pc;

  PetscCall(PetscCalloc1(1, &s));
  PetscCall(MatCreate(PETSC_COMM_SELF, &s->A));
  PetscCall(MatSetSizes(s->A, n, n, n, n));
  PetscCall(MatSetType(s->A, MATSEQAIJ));
  if (bs > 1) PetscCall(MatSetBlockSize(s->A, bs));
  PetscCall(MatSeqAIJSetPreallocationCSR(s->A, rowptr, cols, vals));
  PetscCall(MatSetOption(s->A, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatSetOption(s->A, MAT_SPD, PETSC_TRUE));

  PetscCall(PetscMalloc1(nvec, &vecs));
  for (PetscInt k = 0; k < nvec; k++) {
    PetscScalar *a;
    PetscCall(MatCreateVecs(s->A, &vecs[k], NULL));
    PetscCall(VecGetArray(vecs[k], &a));
    PetscCall(PetscArraycpy(a, near + k * n, n));
    PetscCall(VecRestoreArray(vecs[k], &a));
  }
  PetscCall(MatNullSpaceCreate(PETSC_COMM_SELF, PETSC_FALSE, nvec, vecs, &space));
  PetscCall(MatSetNearNullSpace(s->A, space));
  PetscCall(MatNullSpaceDestroy(&space));
  for (PetscInt k = 0; k < nvec; k++) PetscCall(VecDestroy(&vecs[k]));
  PetscCall(PetscFree(vecs));

  PetscCall(KSPCreate(PETSC_COMM_SELF, &s->ksp));
  PetscCall(KSPSetOperators(s->ksp, s->A, s->A));
  PetscCall(KSPSetType(s->ksp, KSPCG));
  PetscCall(KSPGetPC(s->ksp, &pc));
  PetscCall(PCSetType(pc, PCGAMG));
  PetscCall(KSPSetTolerances(s->ksp, rtol, 0.0, PETSC_DEFAULT, PETSC_DEFAULT));
  PetscCall(KSPSetInitialGuessNonzero(s->ksp, PETSC_TRUE));
  PetscCall(PetscOptionsInsertString(NULL, options));
  PetscCall(KSPSetFromOptions(s->ksp));
  PetscCall(KSPSetUp(s->ksp));
  PetscCall(MatCreateVecs(s->A, &s->x, &s->b));
  *out = s;
  return 0;
}

/* x ← K⁻¹ b by the KSP, from the initial guess in x; its iterations, converged reason (< 0:
 * diverged) and final residual norm. */
int vc_ksp_solve(void *ctx, const PetscScalar *b, PetscScalar *x, PetscInt *its, int *reason,
                 PetscReal *rnorm)
{
  VcKsp             *s = (VcKsp *)ctx;
  KSPConvergedReason r;

  PetscCall(VecPlaceArray(s->b, b));
  PetscCall(VecPlaceArray(s->x, x));
  PetscCall(KSPSolve(s->ksp, s->b, s->x));
  PetscCall(VecResetArray(s->x));
  PetscCall(VecResetArray(s->b));
  PetscCall(KSPGetIterationNumber(s->ksp, its));
  PetscCall(KSPGetConvergedReason(s->ksp, &r));
  PetscCall(KSPGetResidualNorm(s->ksp, rnorm));
  *reason = (int)r;
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

int vc_ksp_destroy(void *ctx)
{
  VcKsp *s = (VcKsp *)ctx;

  if (!s) return 0;
  PetscCall(VecDestroy(&s->b));
  PetscCall(VecDestroy(&s->x));
  PetscCall(KSPDestroy(&s->ksp));
  PetscCall(MatDestroy(&s->A));
  PetscCall(PetscFree(s));
  return 0;
}
