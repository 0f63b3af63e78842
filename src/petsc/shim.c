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
  /* The constrained system, created on first use: its shell operator and preconditioner
   * (shell PC around the PC of ksp), a work vector, the terms of the solve in progress. */
  Mat     C;
  KSP     kc;
  Vec     t;
  VcTerms terms;
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

/* a ← Π a: each removed direction v on its dofs, a ← a − (v·a) v. */
static void project(const VcTerms *t, PetscScalar *a)
{
  for (PetscInt e = 0; e < t->np; e++) {
    const PetscInt    *d = t->pdofs + 3 * e;
    const PetscScalar *v = t->pdirs + 3 * e;
    PetscScalar        p = 0;
    for (int c = 0; c < 3; c++)
      if (d[c] >= 0) p += v[c] * a[d[c]];
    for (int c = 0; c < 3; c++)
      if (d[c] >= 0) a[d[c]] -= p * v[c];
  }
}

/* y ← y + S x over the stiffness blocks. */
static void add_stiffness(const VcTerms *t, const PetscScalar *x, PetscScalar *y)
{
  for (PetscInt e = 0; e < t->ns; e++) {
    const PetscInt    *d = t->sdofs + 3 * e;
    const PetscScalar *m = t->smats + 9 * e;
    for (int r = 0; r < 3; r++) {
      if (d[r] < 0) continue;
      for (int c = 0; c < 3; c++)
        if (d[c] >= 0) y[d[r]] += m[3 * r + c] * x[d[c]];
    }
  }
}

/* y = Π(K + S)Π x + (I − Π) x: the operator of the constrained system, SPD on the whole
 * space where K + S is SPD on range Π. */
static PetscErrorCode constrained_mult(Mat C, Vec x, Vec y)
{
  VcKsp             *s;
  const PetscScalar *xa;
  PetscScalar       *ta, *ya;
  PetscInt           n;

  PetscFunctionBeginUser;
  PetscCall(MatShellGetContext(C, &s));
  PetscCall(VecCopy(x, s->t));
  PetscCall(VecGetArray(s->t, &ta));
  project(&s->terms, ta);
  PetscCall(VecRestoreArray(s->t, &ta));
  PetscCall(MatMult(s->A, s->t, y));
  PetscCall(VecGetLocalSize(x, &n));
  PetscCall(VecGetArrayRead(x, &xa));
  PetscCall(VecGetArray(s->t, &ta));
  PetscCall(VecGetArray(y, &ya));
  add_stiffness(&s->terms, ta, ya);
  project(&s->terms, ya);
  for (PetscInt i = 0; i < n; i++) ta[i] = xa[i] - ta[i]; /* (I − Π) x */
  for (PetscInt i = 0; i < n; i++) ya[i] += ta[i];
  PetscCall(VecRestoreArray(y, &ya));
  PetscCall(VecRestoreArray(s->t, &ta));
  PetscCall(VecRestoreArrayRead(x, &xa));
  PetscFunctionReturn(0);
}

/* y = Π M⁻¹ Π x + (I − Π) x, M⁻¹ the PC of K (GAMG by default): symmetric positive definite
 * where M⁻¹ is, and set up once for K. */
static PetscErrorCode constrained_pc(PC pc, Vec x, Vec y)
{
  VcKsp             *s;
  PC                 inner;
  const PetscScalar *xa;
  PetscScalar       *ta, *ya;
  PetscInt           n;

  PetscFunctionBeginUser;
  PetscCall(PCShellGetContext(pc, &s));
  PetscCall(KSPGetPC(s->ksp, &inner));
  PetscCall(VecCopy(x, s->t));
  PetscCall(VecGetArray(s->t, &ta));
  project(&s->terms, ta);
  PetscCall(VecRestoreArray(s->t, &ta));
  PetscCall(PCApply(inner, s->t, y));
  PetscCall(VecGetLocalSize(x, &n));
  PetscCall(VecGetArrayRead(x, &xa));
  PetscCall(VecGetArray(s->t, &ta));
  PetscCall(VecGetArray(y, &ya));
  project(&s->terms, ya);
  for (PetscInt i = 0; i < n; i++) ya[i] += xa[i] - ta[i];
  PetscCall(VecRestoreArray(y, &ya));
  PetscCall(VecRestoreArray(s->t, &ta));
  PetscCall(VecRestoreArrayRead(x, &xa));
  PetscFunctionReturn(0);
}

/* The constrained KSP: the type of ksp (CG by default, or what the options chose), its
 * monitors and norms, with the shell operator and preconditioner above. */
static PetscErrorCode constrained_setup(VcKsp *s)
{
  PetscInt n;
  KSPType  type;
  PC       pc;

  PetscFunctionBeginUser;
  PetscCall(MatGetSize(s->A, &n, NULL));
  PetscCall(MatCreateShell(PETSC_COMM_SELF, n, n, n, n, s, &s->C));
  PetscCall(MatShellSetOperation(s->C, MATOP_MULT, (void (*)(void))constrained_mult));
  PetscCall(MatSetOption(s->C, MAT_SYMMETRIC, PETSC_TRUE));
  PetscCall(MatCreateVecs(s->A, &s->t, NULL));
  PetscCall(KSPCreate(PETSC_COMM_SELF, &s->kc));
  PetscCall(KSPSetOperators(s->kc, s->C, s->C));
  PetscCall(KSPGetType(s->ksp, &type));
  PetscCall(KSPSetType(s->kc, type));
  PetscCall(KSPSetInitialGuessNonzero(s->kc, PETSC_TRUE));
  PetscCall(KSPSetFromOptions(s->kc));
  /* After the options, which would otherwise make the PC GAMG's type. */
  PetscCall(KSPGetPC(s->kc, &pc));
  PetscCall(PCSetType(pc, PCSHELL));
  PetscCall(PCShellSetContext(pc, s));
  PetscCall(PCShellSetApply(pc, constrained_pc));
  PetscCall(PCShellSetName(pc, "projected PC of K"));
  PetscFunctionReturn(0);
}

/* x ← the solution of the constrained system Π(K + S)Π x + (I − Π) x = Π b with the terms
 * given, from the initial guess in x, to relative tolerance rtol: iterations, reason and
 * final residual norm as vc_ksp_solve. */
int vc_constrained_solve(void *ctx, PetscInt np, const PetscInt *pdofs, const PetscScalar *pdirs,
                         PetscInt ns, const PetscInt *sdofs, const PetscScalar *smats,
                         PetscReal rtol, const PetscScalar *b, PetscScalar *x, PetscInt *its,
                         int *reason, PetscReal *rnorm)
{
  VcKsp             *s = (VcKsp *)ctx;
  KSPConvergedReason r;

  if (!s->kc) PetscCall(constrained_setup(s));
  s->terms = (VcTerms){np, ns, pdofs, sdofs, pdirs, smats};
  PetscCall(KSPSetTolerances(s->kc, rtol, 0.0, PETSC_DEFAULT, PETSC_DEFAULT));
  PetscCall(VecPlaceArray(s->b, b));
  PetscCall(VecPlaceArray(s->x, x));
  PetscCall(KSPSolve(s->kc, s->b, s->x));
  PetscCall(VecResetArray(s->x));
  PetscCall(VecResetArray(s->b));
  s->terms = (VcTerms){0};
  PetscCall(KSPGetIterationNumber(s->kc, its));
  PetscCall(KSPGetConvergedReason(s->kc, &r));
  PetscCall(KSPGetResidualNorm(s->kc, rnorm));
  *reason = (int)r;
  return 0;
}

int vc_ksp_destroy(void *ctx)
{
  VcKsp *s = (VcKsp *)ctx;

  if (!s) return 0;
  PetscCall(KSPDestroy(&s->kc));
  PetscCall(MatDestroy(&s->C));
  PetscCall(VecDestroy(&s->t));
  PetscCall(VecDestroy(&s->b));
  PetscCall(VecDestroy(&s->x));
  PetscCall(KSPDestroy(&s->ksp));
  PetscCall(MatDestroy(&s->A));
  PetscCall(PetscFree(s));
  return 0;
}
