//! The Newton systems (QᵀDQ + diag κ) x = −Qᵀ(D z₀ − d): the direct and the Woodbury
//! form, the reuse of a step's factor, the dense Cholesky solves.

use super::delassus::{column, lower_product, Delassus};
use super::groups::{Coord, Group};
use super::{blocks, DualSettings, NewtonCounts, NewtonForm, Team};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt;
use faer::{Mat, MatMut, Par};
use std::cell::OnceCell;
use std::ops::Range;

/// The buffers of `newton_step`, and its counts.
pub(super) struct Scratch {
    /// The columns of U (the Woodbury form's coordinates).
    pub(super) u: Vec<Coord>,
    /// A Newton point, and the gradient there.
    pub(super) point: Vec<f64>,
    pub(super) grad: Vec<f64>,
    /// m-vectors of the Woodbury form: its right side s and B-products.
    pub(super) sv: Vec<f64>,
    pub(super) bv: Vec<f64>,
    /// The Newton matrix, and the step's last factorization of one. Both buffers are kept
    /// across iterations, so the iterations allocate no matrix (at nq = 1350 each is
    /// 14.6 MB; fresh ones cost the 3D block's run 4% of its samples in zeroing pages).
    pub(super) h: Mat<f64>,
    pub(super) factor: NewtonFactor,
    /// Building a Newton matrix, cut in blocks of columns over the threads where that pays.
    pub(super) gram_team: Team,
    pub(super) counts: NewtonCounts,
}

impl Scratch {
    /// The buffers for m multipliers.
    pub(super) fn new(m: usize, settings: &DualSettings) -> Scratch {
        Scratch {
            u: Vec::with_capacity(m),
            point: vec![0.0; m],
            grad: vec![0.0; m],
            sv: vec![0.0; m],
            bv: vec![0.0; m],
            h: Mat::new(),
            factor: NewtonFactor {
                l: Mat::new(),
                single: Mat::new(),
                form: None,
                precision: Precision::Double,
                coords: Vec::with_capacity(m),
                par_min: settings.par_min,
                single_min: settings.single_min,
                pcg_max: settings.pcg_max,
                split_rows: settings.split_rows,
                team: Team::default(),
            },
            gram_team: Team::default(),
            counts: NewtonCounts::default(),
        }
    }
}

/// Which matrix a cached factor belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Form {
    /// H = QᵀDQ + diag κ.
    Direct,
    /// H_U = UᵀBU + diag(0 on N, 1/κ on R).
    Woodbury,
}

/// Which of `NewtonFactor`'s buffers holds the factor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Precision {
    /// `l`: the exact factor, whose solve is the direct solution.
    Double,
    /// `single`: a preconditioner (`DualSettings::single_min`).
    Single,
}

/// A Cholesky factor of a Newton matrix, its form and the coordinates it was built from.
pub(super) struct NewtonFactor {
    /// L in the lower triangle (the upper one holds what the matrix had there), in double
    /// or in single precision.
    pub(super) l: Mat<f64>,
    pub(super) single: Mat<f32>,
    /// The form of the matrix factored; None while neither buffer holds a valid factor.
    pub(super) form: Option<Form>,
    pub(super) precision: Precision,
    pub(super) coords: Vec<Coord>,
    /// `DualSettings::par_min`, `single_min` and `pcg_max`.
    pub(super) par_min: usize,
    pub(super) single_min: usize,
    pub(super) pcg_max: usize,
    /// `DualSettings::split_rows`, and the threads of the conjugate gradients' products.
    pub(super) split_rows: usize,
    pub(super) team: Team,
}

/// A Newton matrix that is not positive definite to working precision
/// (`StepStatus::NewtonIndefinite`).
pub(in crate::solver) struct Indefinite;

/// What the Newton steps are solved with.
pub(super) struct Operators<'a> {
    pub(super) d: &'a Delassus,
    /// d = P K_A⁻¹ b.
    pub(super) dvec: &'a [f64],
    /// B = D⁻¹ and z_u = B d (computed at the step's first Woodbury system), when the
    /// Woodbury form is available.
    pub(super) woodbury: Option<(&'a Mat<f64>, &'a OnceCell<Vec<f64>>)>,
    pub(super) settings: &'a DualSettings,
    /// The Newton residual a Woodbury solve must reach (absolute): `newton_accuracy` times
    /// the dual's tolerance, so that its inexactness cannot reach the stopping test.
    pub(super) accuracy: f64,
}

/// The gradient D z₀ − d at a Newton step's base point, if known (the base point is the
/// iterate); else a buffer for it and the iterate `near`, from whose coordinates an
/// iterative solve starts (`solver::matrix_free`; a direct solve has no use for it).
pub(in crate::solver) enum Gradient<'a> {
    Known(&'a [f64]),
    Unknown {
        buffer: &'a mut [f64],
        near: &'a [f64],
    },
}

/// out += Q x, where (QᵀDQ + diag κ) x = −Qᵀ(D z₀ − d) and Q, κ are given by `coords`: the
/// Newton step from z₀ on those coordinates.
///
/// Direct form. The matrix H = QᵀDQ + diag κ is SPD; a dense Cholesky factorization costs
/// nq³/3 and dominates an iteration on large contact boundaries (nq ≈ 1350 of m = 1850
/// rows on the 3D block at h = 1/24).
///
/// Woodbury form. Let N be the directions the step keeps fixed (a contact row at zero, the
/// radial direction v̂ of a disc on its rim: the complement of Q, column by column within
/// each group) and R the columns of Q with κ > 0 (the rims' tangents). The step is the
/// point z⁺ = z₀ + Q x with Nᵀ z⁺ = Nᵀ z₀ and Qᵀ(D z⁺ − d) + K x = 0; with ν = K_R x_R,
/// D z⁺ − d + R ν lies in the span of N, so with B = D⁻¹, z_u = B d and U = [N R]:
///
///   z⁺ = z_u − B U c,   (UᵀBU + diag(0 on N, 1/κ on R)) c = Uᵀ(z_u − z₀),   x = Qᵀ(z⁺ − z₀).
///
/// Its matrix has |U| = (m − nq) + |R| rows — in 3D the rims' tangents, which make nq
/// large, leave U small (820 against 1350 on average on the block) — and the step costs
/// |U|³/3 + one pass over |U| columns of B. Rounding: z⁺ is a difference of terms that
/// grow with the conditioning of D, so the Newton residual Qᵀ(D z⁺ − d) + K x is checked
/// (one product with D, which the direct form spends on D z₀ − d) and refined by the same
/// formula (x' = Qᵀ(s − B U c'), s = B Q r, for the residual r). The form is chosen per
/// system by its flop estimate, the Woodbury form only where it is well below the direct
/// one's (`WOODBURY_SHARE`).
///
/// Either form's factor is reused within a step: consecutive iterations mostly keep the
/// same coordinate structure (which rows are free, which discs on their rim) and change
/// only the rims' tangents and shifts slightly, so the step's last factor, when its
/// structure matches, preconditions conjugate gradients on the new matrix (O(nq²) per
/// iteration) to the accuracy of a direct solve; only a new structure, or CG not converging
/// in `pcg_max` iterations, costs a new factorization. For an unchanged matrix the first
/// preconditioned solve is already the direct solution.
pub(super) fn newton_step(
    ops: &Operators,
    groups: &[Group],
    coords: &[Coord],
    z0: &[f64],
    grad: Gradient,
    out: &mut [f64],
    s: &mut Scratch,
) -> Result<(), Indefinite> {
    let nq = coords.len();
    if nq == 0 {
        return Ok(());
    }
    if let Some((b, z_u)) = ops.woodbury {
        complement(groups, coords, &mut s.u);
        if ops.settings.newton_form == NewtonForm::Woodbury
            || woodbury_cost(nq, s.u.len()) < WOODBURY_SHARE * direct_cost(nq)
        {
            let z_u = z_u.get_or_init(|| unconstrained(b, ops.dvec));
            if let Some(x) = woodbury_step(ops, b, z_u, coords, z0, s)? {
                s.counts.woodbury += 1;
                add_columns(coords, &x, out);
                return Ok(());
            }
            s.counts.fallbacks += 1;
        }
    }
    s.counts.direct += 1;
    let grad = match grad {
        Gradient::Known(g) => g,
        Gradient::Unknown { buffer, .. } => {
            ops.d.gradient(z0, ops.dvec, buffer);
            &*buffer
        }
    };
    gram(&ops.d.mat, coords, &mut s.h, &s.gram_team, ops.d.split_rows);
    let rhs = Mat::<f64>::from_fn(nq, 1, |a, _| -coords[a].dot(grad));
    let x = solve_cached(Form::Direct, &rhs, coords, &s.h, &mut s.factor)?;
    add_columns(coords, &x, out);
    Ok(())
}

/// The Woodbury form of `newton_step`: x, or None if it is not accurate to
/// `ops.accuracy` after `refinements` refinements (`DualSettings`).
fn woodbury_step(
    ops: &Operators,
    b: &Mat<f64>,
    z_u: &[f64],
    coords: &[Coord],
    z0: &[f64],
    s: &mut Scratch,
) -> Result<Option<Mat<f64>>, Indefinite> {
    gram(b, &s.u, &mut s.h, &s.gram_team, ops.d.split_rows);
    let mut x = Mat::<f64>::zeros(coords.len(), 1);
    // In y = z − z₀: y⁺ = s − B U c, (UᵀBU + diag) c = Uᵀ s, x = Qᵀ y⁺, with s = z_u − z₀;
    // a refinement solves for the residual r the same way with s = −B Q r.
    for ((t, zu), z) in s.sv.iter_mut().zip(z_u).zip(z0) {
        *t = zu - z;
    }
    let refinements = ops.settings.refinements;
    for refinement in 0..=refinements {
        s.bv.copy_from_slice(&s.sv);
        if !s.u.is_empty() {
            let rhs = Mat::<f64>::from_fn(s.u.len(), 1, |a, _| s.u[a].dot(&s.sv));
            let c = solve_cached(Form::Woodbury, &rhs, &s.u, &s.h, &mut s.factor)?;
            axpy_columns(b, scaled_entries(&s.u, |a| -c[(a, 0)]), &mut s.bv);
        }
        let Scratch {
            point,
            grad,
            sv,
            bv,
            counts,
            ..
        } = &mut *s;
        for (a, q) in coords.iter().enumerate() {
            x[(a, 0)] += q.dot(bv);
        }
        // The Newton residual r = Qᵀ(D (z₀ + Q x) − d) + K x.
        point.copy_from_slice(z0);
        add_columns(coords, &x, point);
        ops.d.gradient(point, ops.dvec, grad);
        let r = Mat::<f64>::from_fn(coords.len(), 1, |a, _| {
            coords[a].dot(grad) + coords[a].shift * x[(a, 0)]
        });
        if r.norm_max() <= ops.accuracy {
            return Ok(Some(x));
        }
        if refinement == refinements {
            break;
        }
        counts.refinements += 1;
        sv.fill(0.0);
        axpy_columns(b, scaled_entries(coords, |a| -r[(a, 0)]), sv);
    }
    Ok(None)
}

/// z_u = B d, the unconstrained minimizer of q (B symmetric: column j of B is its row j).
fn unconstrained(b: &Mat<f64>, d: &[f64]) -> Vec<f64> {
    let mut z_u = vec![0.0; d.len()];
    axpy_columns(b, d.iter().copied().enumerate(), &mut z_u);
    z_u
}

/// The entries (i, f(a) v) of the columns a of Q (or U) scaled by f(a).
fn scaled_entries<'a>(
    coords: &'a [Coord],
    f: impl Fn(usize) -> f64 + 'a,
) -> impl Iterator<Item = (usize, f64)> + 'a {
    coords.iter().enumerate().flat_map(move |(a, q)| {
        let fa = f(a);
        q.entries().map(move |(i, v)| (i, fa * v))
    })
}

/// out += Σ y_j M e_j over the pairs (j, y_j): columns of M scaled and summed.
fn axpy_columns(mat: &Mat<f64>, pairs: impl Iterator<Item = (usize, f64)>, out: &mut [f64]) {
    for (j, y) in pairs {
        if y != 0.0 {
            for (o, mij) in out.iter_mut().zip(column(mat, j)) {
                *o += y * mij;
            }
        }
    }
}

/// out += Q x.
fn add_columns(coords: &[Coord], x: &Mat<f64>, out: &mut [f64]) {
    for (a, q) in coords.iter().enumerate() {
        for (i, v) in q.entries() {
            out[i] += v * x[(a, 0)];
        }
    }
}

/// The columns of U for the columns Q of a Newton step (`newton_step`), group by group:
/// the directions of each group that Q leaves out (shift 0), then its columns with κ > 0
/// (shift 1/κ). `coords` lists each group's columns together, in group order.
fn complement(groups: &[Group], coords: &[Coord], u: &mut Vec<Coord>) {
    u.clear();
    let mut k = 0;
    for grp in groups {
        let first = k;
        while k < coords.len() && grp.rows().contains(&coords[k].start) {
            k += 1;
        }
        let own = &coords[first..k];
        match own {
            [] => u.extend(grp.free().map(|c| Coord { shift: 0.0, ..c })),
            // A disc on its rim: the radial direction, normal to the tangent t̂.
            [t] if t.len == 2 => u.push(Coord {
                dir: [t.dir[1], -t.dir[0]],
                shift: 0.0,
                ..*t
            }),
            _ => debug_assert_eq!(own.len(), grp.len, "a group is all free"),
        }
        u.extend(own.iter().filter(|q| q.shift > 0.0).map(|q| Coord {
            shift: 1.0 / q.shift,
            ..*q
        }));
    }
    debug_assert_eq!(k, coords.len());
}

/// The Woodbury form is taken where its flops are at most this share of the direct form's
/// (up to |U| ≈ 0.73 nq): it also reads D once (its residual) and |U| columns of B,
/// memory-bound passes that the flop counts leave out, so near |U| = nq it is the slower
/// form (timed system by system in docs/performance.md, "The Woodbury form only where it
/// is well below the direct one").
const WOODBURY_SHARE: f64 = 0.4;

/// Flops of a Newton system in the direct form: the factorization (building H and the
/// product D z₀ are about the same in both forms).
fn direct_cost(nq: usize) -> f64 {
    (nq as f64).powi(3) / 3.0
}

/// Flops of the Woodbury form: the factorization and the pass over |U| columns of B.
fn woodbury_cost(nq: usize, nu: usize) -> f64 {
    let (nq, nu) = (nq as f64, nu as f64);
    nu.powi(3) / 3.0 + 2.0 * nu * (nq + nu)
}

/// h = CᵀMC + diag(shift) for the columns C given by `coords`, column by column from M's
/// contiguous columns (M symmetric). Every entry is written: h's buffer is reused as it is.
/// From `split_rows` columns on, the columns are cut in blocks over the team's threads
/// (each column's arithmetic is the same in any block).
pub(super) fn gram(
    mat: &Mat<f64>,
    coords: &[Coord],
    h: &mut Mat<f64>,
    team: &Team,
    split_rows: usize,
) {
    let n = coords.len();
    h.resize_with(n, n, |_, _| 0.0);
    // The columns `cols` of h, in `part`.
    let fill = |(cols, mut part): (Range<usize>, MatMut<f64>)| {
        for (k, b) in cols.enumerate() {
            let qb = &coords[b];
            // (M q_b)_i = Σ_j y_j M_ij, gathered at the rows of the other columns only.
            let mut cols = qb.entries().map(|(j, y)| (column(mat, j), y));
            let (c0, y0) = cols.next().expect("a column has an entry");
            let second = cols.next();
            let mq = |i: usize| match second {
                None => 0.0 + y0 * c0[i],
                Some((c1, y1)) => 0.0 + y0 * c0[i] + y1 * c1[i],
            };
            let hb = part
                .as_mut()
                .col_mut(k)
                .try_as_col_major_mut()
                .unwrap()
                .as_slice_mut();
            for (hab, qa) in hb.iter_mut().zip(coords) {
                *hab = qa.entries().map(|(i, x)| x * mq(i)).sum();
            }
            hb[b] += qb.shift;
        }
    };
    let (mut parts, mut rest) = (Vec::new(), h.as_mut());
    for cols in blocks(n, team.pieces(n >= split_rows)) {
        let (part, next) = rest.split_at_col_mut(cols.len());
        parts.push((cols, part));
        rest = next;
    }
    team.each(parts, fill);
}

/// Solves H x = rhs by the step's last factor `f` (conjugate gradients preconditioned with
/// it, when it was built for the same form and structure) or a new factorization, which
/// then replaces it in its buffer: in single precision from `single_min` rows on, its
/// system then solved by the same conjugate gradients (`DualSettings::single_min`).
pub(super) fn solve_cached(
    form: Form,
    rhs: &Mat<f64>,
    coords: &[Coord],
    h: &Mat<f64>,
    f: &mut NewtonFactor,
) -> Result<Mat<f64>, Indefinite> {
    let same_structure = f.form == Some(form)
        && f.coords.len() == coords.len()
        && f.coords
            .iter()
            .zip(coords)
            .all(|(a, b)| a.start == b.start && a.len == b.len);
    if same_structure {
        if let Some(x) = pcg(h, rhs, f) {
            return Ok(x);
        }
    }
    f.form = None;
    let n = h.nrows();
    let par = dense_par(n, f.par_min);
    f.coords.clear();
    f.coords.extend_from_slice(coords);
    if n >= f.single_min {
        if let Some(x) = single_solve(form, rhs, h, f, par) {
            return Ok(x);
        }
    }
    f.l.resize_with(n, n, |_, _| 0.0);
    f.l.copy_from_triangular_lower(h);
    cholesky(f.l.as_mut(), par)?;
    f.form = Some(form);
    f.precision = Precision::Double;
    Ok(llt_solve(f, rhs))
}

/// `solve_cached`'s new factorization in single precision: H's lower triangle rounded to
/// f32 and factored into `f.single`, the system solved by `pcg` with it. None (and the f32
/// buffer freed) where H is not definite in f32 or CG does not converge: the caller
/// factors in f64. The two buffers never both hold a large factor, so that the memory stays
/// that of one f64 factor (`resources::dense_dual_bytes`): a large f64 buffer (left by such
/// a fallback) is freed first.
fn single_solve(
    form: Form,
    rhs: &Mat<f64>,
    h: &Mat<f64>,
    f: &mut NewtonFactor,
    par: Par,
) -> Option<Mat<f64>> {
    let n = h.nrows();
    if f.l.nrows() >= f.single_min {
        f.l = Mat::new();
    }
    f.single.resize_with(n, n, |_, _| 0.0);
    for j in 0..n {
        for i in j..n {
            f.single[(i, j)] = h[(i, j)] as f32;
        }
    }
    if cholesky(f.single.as_mut(), par).is_ok() {
        f.form = Some(form);
        f.precision = Precision::Single;
        if let Some(x) = pcg(h, rhs, f) {
            return Some(x);
        }
        f.form = None;
    }
    f.single = Mat::new();
    None
}

/// The Cholesky factor of the matrix in the lower triangle of `l`, in place.
pub(super) fn cholesky<T: faer::traits::ComplexField>(
    l: MatMut<T>,
    par: Par,
) -> Result<(), Indefinite> {
    let mut mem = MemBuffer::new(llt::factor::cholesky_in_place_scratch::<T>(
        l.nrows(),
        par,
        Default::default(),
    ));
    llt::factor::cholesky_in_place(
        l,
        Default::default(),
        par,
        MemStack::new(&mut mem),
        Default::default(),
    )
    .map(|_| ())
    .map_err(|_| Indefinite)
}

/// The parallelism of the factorization of an n × n Newton matrix: one thread below
/// `par_min`, all the process's threads above (`DualSettings::par_min`). faer's parallel
/// factorization gives the same bits for every thread count (`threads`).
fn dense_par(n: usize, par_min: usize) -> Par {
    if n < par_min {
        Par::Seq
    } else {
        crate::threads::par()
    }
}

/// x = (L Lᵀ)⁻¹ rhs for the factor L of `f` (in single precision: rhs rounded to f32,
/// the solve in f32), on one thread: faer's parallel solve of a single right side splits
/// its sums by the thread count (`threads`).
fn llt_solve(f: &NewtonFactor, rhs: &Mat<f64>) -> Mat<f64> {
    match f.precision {
        Precision::Double => {
            let mut x = rhs.clone();
            lower_solve(&f.l, x.as_mut());
            x
        }
        Precision::Single => {
            let mut x = Mat::<f32>::from_fn(rhs.nrows(), 1, |i, _| rhs[(i, 0)] as f32);
            lower_solve(&f.single, x.as_mut());
            Mat::from_fn(rhs.nrows(), 1, |i, _| f64::from(x[(i, 0)]))
        }
    }
}

/// x ← (L Lᵀ)⁻¹ x for L in the lower triangle of `l`, on one thread.
fn lower_solve<T: faer::traits::ComplexField>(l: &Mat<T>, x: MatMut<T>) {
    llt::solve::solve_in_place_with_conj(
        l.as_ref(),
        faer::Conj::No,
        x,
        Par::Seq,
        MemStack::new(&mut MemBuffer::new(StackReq::EMPTY)),
    );
}

/// H x. From `single_min` rows on (the matrices factored in single precision, whose
/// conjugate gradients take a product or more per system) from H's lower triangle
/// (`delassus::lower_product`, on the factor's team: the same bits on any number of
/// threads), which reads half of H: on the plate 0.03 (2 730 rows on average) faer's
/// product of the whole H on one thread took most of those gradients' time. Below, faer's
/// product on one thread, for the same reason as `llt_solve` (`h * &x` would use faer's
/// global parallelism); the golden scenes' systems are all smaller, and keep their bits.
fn mat_vec(h: &Mat<f64>, x: &Mat<f64>, f: &NewtonFactor) -> Mat<f64> {
    let n = h.nrows();
    let mut y = Mat::zeros(n, 1);
    if n >= f.single_min {
        let out = y.col_mut(0).try_as_col_major_mut().unwrap().as_slice_mut();
        lower_product(h, &f.team, f.split_rows, column(x, 0), &vec![0.0; n], out);
    } else {
        faer::linalg::matmul::matmul(y.as_mut(), faer::Accum::Replace, h, x, 1.0, Par::Seq);
    }
    y
}

/// Solves H x = rhs by conjugate gradients preconditioned with the factor `f` of a nearby
/// matrix, or with its single-precision factor, to a relative residual of 1e-14; None if
/// that takes more than `f.pcg_max` iterations.
fn pcg(h: &Mat<f64>, rhs: &Mat<f64>, f: &NewtonFactor) -> Option<Mat<f64>> {
    let target = 1e-14 * rhs.norm_l2();
    let mut x = llt_solve(f, rhs);
    let mut r = rhs - mat_vec(h, &x, f);
    if r.norm_l2() <= target {
        return Some(x);
    }
    let mut z = llt_solve(f, &r);
    let mut p = z.clone();
    let mut rz = (r.transpose() * &z)[(0, 0)];
    for _ in 0..f.pcg_max {
        let hp = mat_vec(h, &p, f);
        let php = (p.transpose() * &hp)[(0, 0)];
        if php.is_nan() || php <= 0.0 {
            return None;
        }
        let alpha = rz / php;
        x += alpha * &p;
        r -= alpha * &hp;
        if r.norm_l2() <= target {
            return Some(x);
        }
        z = llt_solve(f, &r);
        let rz_new = (r.transpose() * &z)[(0, 0)];
        p = &z + (rz_new / rz) * &p;
        rz = rz_new;
    }
    None
}
