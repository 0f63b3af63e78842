//! The dense kernels of the dual against their definitions.

use super::delassus::Delassus;
use super::groups::Coord;
use super::newton::{cholesky, gram, solve_cached, Form, NewtonFactor, Precision, Scratch};
use super::{condense_selected, condense_solved, inverse, selection, DualSettings, Team};
use crate::fem::{NodalRow, Sparse};
use crate::solver::{Factor, Rows};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Par};

/// A symmetric m×m matrix with entries of both signs.
fn symmetric(m: usize) -> Mat<f64> {
    let entry = |i: usize, j: usize| (((i * 7 + j * 13) % 17) as f64 - 8.0) / 3.0;
    Mat::from_fn(m, m, |i, j| {
        entry(i.max(j), i.min(j)) + f64::from(u8::from(i == j))
    })
}

/// D z − d from the lower triangle equals the full product to rounding, below and above
/// the size where it splits over the threads and where it cuts D in more parts, and is the
/// same bit for bit on one thread or several.
#[test]
fn gradient_from_the_lower_triangle() {
    for m in [1, 5, 37, 700, 1100] {
        // z with zeros among its entries.
        let mat = symmetric(m);
        let z: Vec<f64> = (0..m)
            .map(|i| if i % 5 == 3 { 0.0 } else { (i as f64).sin() })
            .collect();
        let d: Vec<f64> = (0..m).map(|i| (i as f64 * 0.3).cos()).collect();
        let expected: Vec<f64> = (0..m)
            .map(|i| (0..m).map(|j| mat[(i, j)] * z[j]).sum::<f64>() - d[i])
            .collect();
        let scale = m as f64 * 3.0;
        let mut got = [vec![0.0; m], vec![0.0; m], vec![0.0; m], vec![0.0; m]];
        for (team, g) in [Team::default(), Team::of(1), Team::of(3), Team::of(5)]
            .into_iter()
            .zip(&mut got)
        {
            let op = Delassus {
                mat: mat.clone(),
                team,
                split_rows: DualSettings::default().split_rows,
            };
            op.gradient(&z, &d, g);
        }
        for (a, b) in got[0].iter().zip(&expected) {
            assert!((a - b).abs() <= 1e-14 * scale, "m = {m}: {a} against {b}");
        }
        for other in &got[1..] {
            assert!(
                got[0]
                    .iter()
                    .zip(other)
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "m = {m}: the thread counts differ"
            );
        }
    }
}

/// The Newton matrix CᵀMC + diag(shift) equals its dense product, for single rows and
/// two-row (disc) coordinates, and is the same bit for bit on one to eight threads (as
/// many blocks of columns).
#[test]
fn gram_is_the_dense_product() {
    for (m, n) in [(9, 4), (1400, 700)] {
        let mat = symmetric(m);
        // Coordinates: a single row, or a unit direction in a pair of rows.
        let coords: Vec<Coord> = (0..n)
            .map(|a| {
                let angle = a as f64;
                if a % 3 == 0 {
                    Coord {
                        start: 2 * a,
                        len: 1,
                        dir: [1.0, 0.0],
                        shift: 0.5,
                    }
                } else {
                    Coord {
                        start: 2 * a,
                        len: 2,
                        dir: [angle.cos(), angle.sin()],
                        shift: 0.0,
                    }
                }
            })
            .collect();
        // The dense oracle: C (m×n) column by column, then CᵀMC.
        let c = Mat::from_fn(m, n, |i, a| {
            coords[a]
                .entries()
                .find(|&(r, _)| r == i)
                .map_or(0.0, |(_, x)| x)
        });
        let dense = c.transpose() * &mat * &c;
        let got: Vec<_> = (1..=8)
            .map(|threads| {
                let mut h = Mat::new();
                let split_rows = DualSettings::default().split_rows;
                gram(&mat, &coords, &mut h, &Team::of(threads), split_rows);
                h
            })
            .collect();
        for a in 0..n {
            for b in 0..n {
                let mut expected = dense[(a, b)];
                if a == b {
                    expected += coords[a].shift;
                }
                let h = got[0][(a, b)];
                assert!(
                    (h - expected).abs() <= 1e-12,
                    "n = {n}: ({a}, {b}) {h} against {expected}"
                );
                for (threads, other) in got.iter().enumerate().skip(1) {
                    assert_eq!(
                        h.to_bits(),
                        other[(a, b)].to_bits(),
                        "n = {n}: one thread and {} differ",
                        threads + 1
                    );
                }
            }
        }
    }
}

/// H x = rhs solved as a new Newton system in the direct form, each row a coordinate of
/// its own, with `DualSettings::single_min` = `single_min`; and the factor it left.
fn newton_solve(
    h: &Mat<f64>,
    rhs: &Mat<f64>,
    single_min: usize,
    threads: usize,
) -> (Mat<f64>, NewtonFactor) {
    let n = h.nrows();
    let coords: Vec<Coord> = (0..n)
        .map(|a| Coord {
            start: a,
            len: 1,
            dir: [1.0, 0.0],
            shift: 0.0,
        })
        .collect();
    let settings = DualSettings {
        single_min,
        ..Default::default()
    };
    let mut f = Scratch::new(n, &settings).factor;
    f.team = Team::of(threads);
    let x = solve_cached(Form::Direct, rhs, &coords, h, &mut f)
        .ok()
        .unwrap();
    (x, f)
}

/// A Newton matrix of `single_min` rows or more is factored in single precision and its
/// system solved by the conjugate gradients that factor preconditions: the answer is the
/// double factor's direct solution to 1e-12 (the CG stop at 1e-14 relative residual, and
/// this matrix's condition number is about 4 000); the single factor, and the answer (the
/// CG's products with H are cut over the threads), have the same bits on one to four
/// threads.
#[test]
fn single_precision_newton_factors_solve_as_the_double_ones() {
    let n = 1100;
    let h = Mat::from_fn(n, n, |i, j| match i.abs_diff(j) {
        0 => 2.001,
        1 => -1.0,
        _ => 0.0,
    });
    let rhs = Mat::from_fn(n, 1, |i, _| ((i * 37) % 23) as f64 / 11.0 - 1.0);
    let (exact, f) = newton_solve(&h, &rhs, usize::MAX, 2);
    assert_eq!(f.precision, Precision::Double);
    let (single, f) = newton_solve(&h, &rhs, n, 2);
    assert_eq!(f.precision, Precision::Single);
    let error = (&single - &exact).norm_l2() / exact.norm_l2();
    assert!(error < 1e-12 && error > 0.0, "{error:e}");
    for threads in [1, 4] {
        assert!(
            newton_solve(&h, &rhs, n, threads).0 == single,
            "{threads} threads"
        );
    }
    let factors: Vec<Vec<u32>> = [1, 2, 4]
        .into_iter()
        .map(|threads| {
            let mut l = Mat::<f32>::from_fn(n, n, |i, j| h[(i, j)] as f32);
            cholesky(l.as_mut(), Par::rayon(threads)).ok().unwrap();
            (0..n)
                .flat_map(|j| (j..n).map(move |i| (i, j)))
                .map(|(i, j)| l[(i, j)].to_bits())
                .collect()
        })
        .collect();
    assert!(
        factors.iter().all(|f| *f == factors[0]),
        "the thread counts differ"
    );
}

/// A Newton matrix that is definite in f64 but not in f32 (its off-diagonal 1 − 1e-9
/// rounds to 1 in f32) is factored in double precision after the single factorization
/// fails, with the double factor's answer bit for bit; its single buffer is freed.
#[test]
fn a_matrix_not_definite_in_single_precision_is_factored_in_double() {
    let n = 4;
    let h = Mat::from_fn(n, n, |i, j| match (i == j, i / 2 == j / 2) {
        (true, _) => 1.0,
        (false, true) => 1.0 - 1e-9,
        _ => 0.0,
    });
    let rhs = Mat::from_fn(n, 1, |i, _| 1.0 + i as f64);
    let solve = |single_min| {
        let (x, f) = newton_solve(&h, &rhs, single_min, 2);
        assert_eq!(f.precision, Precision::Double);
        assert_eq!(f.single.nrows(), 0);
        x
    };
    let (tried, direct) = (solve(1), solve(usize::MAX));
    assert!((0..n).all(|i| tried[(i, 0)].to_bits() == direct[(i, 0)].to_bits()));
}

/// `held_on_rim` holds a 3D disc multiplier on its rim with κ = max(μ, 0)/c and nothing
/// else; the prediction with it keeps such a group on the rim where v = z − g/(ηδ) falls
/// inside the disc, and predicts every other group as without it.
#[test]
fn held_rims_keep_a_disc_on_its_rim_for_the_first_prediction() {
    use super::groups::{Group, Set};
    use super::iteration::prediction;
    let disc = |start, len, c| Group {
        start,
        len,
        set: Set::Ball(c),
        scale: 2.0,
        shift: 0.0,
    };
    let rim = DualSettings::default().rim;
    let d3 = disc(0, 2, 0.5);
    // On the rim (0.3, 0.4), the gradient pointing inward (μ = −g·ẑ = −1) or outward (μ = 2).
    let z = [0.3, 0.4];
    let (z0, kappa) = d3.held_on_rim(&z, &[0.6, 0.8], rim).unwrap();
    assert_eq!((z0, kappa), ([0.3, 0.4], 0.0));
    let (_, kappa) = d3.held_on_rim(&z, &[-1.2, -1.6], rim).unwrap();
    assert!((kappa - 4.0).abs() < 1e-15, "κ = μ/c = 2/0.5, got {kappa}");
    // Inside the disc, a 2D friction row (its rim two points), a contact row, c = 0: none.
    assert!(d3.held_on_rim(&[0.3, 0.3], &[0.6, 0.8], rim).is_none());
    assert!(disc(0, 1, 0.5).held_on_rim(&[0.5], &[1.0], rim).is_none());
    let contact = Group {
        set: Set::HalfLine,
        ..disc(0, 1, 0.0)
    };
    assert!(contact.held_on_rim(&[0.5], &[1.0], rim).is_none());
    assert!(disc(0, 2, 0.0)
        .held_on_rim(&[0.0, 0.0], &[1.0, 0.0], rim)
        .is_none());

    // The prediction: the disc at rows 0..2 on its rim with v inside (η = 64), a free
    // contact row at row 2, a disc inside its rim at rows 3..5.
    let groups = [
        d3,
        Group {
            set: Set::HalfLine,
            ..disc(2, 1, 0.0)
        },
        disc(3, 2, 0.5),
    ];
    let (z, g) = ([0.3, 0.4, 1.0, 0.1, 0.1], [0.6, 0.8, 0.5, 0.1, 0.0]);
    let (mut trial, mut coords) = (vec![0.0; 5], Vec::new());
    let columns = |coords: &Vec<Coord>| -> Vec<(usize, usize)> {
        coords.iter().map(|c| (c.start, c.len)).collect()
    };
    prediction(&groups, &z, &g, 64.0, None, &mut trial, &mut coords);
    assert_eq!(columns(&coords), [(0, 1), (1, 1), (2, 1), (3, 1), (4, 1)]);
    prediction(&groups, &z, &g, 64.0, Some(rim), &mut trial, &mut coords);
    assert_eq!(columns(&coords), [(0, 2), (2, 1), (3, 1), (4, 1)]);
    assert_eq!(&trial[..2], &[0.3, 0.4]);
    assert_eq!((coords[0].dir, coords[0].shift), ([-0.8, 0.6], 0.0));
}

/// A chain of `nodes` 3D nodes, each tied to the next two by springs of varied stiffness
/// (diagonally dominant: SPD), and rows along the axes on the first half of the nodes: a
/// contact row −e_z (a coefficient −1) on the even ones, the friction tangents e_y, e_x on
/// the others. So E selects, as on a flat boundary along the axes.
fn axis_rows(nodes: usize) -> (Sparse, Rows) {
    let n = 3 * nodes;
    let mut t = Vec::new();
    for i in 0..n {
        t.push(Triplet::new(i, i, 5.0 + (i % 7) as f64 / 7.0));
        for j in [i + 1, i + 3, i + 5].into_iter().filter(|&j| j < n) {
            let v = -0.4 - ((i * 5 + j) % 11) as f64 / 20.0;
            t.push(Triplet::new(i, j, v));
            t.push(Triplet::new(j, i, v));
        }
    }
    let k = SparseColMat::try_new_from_triplets(n, n, &t).unwrap();
    let row = |node: usize, dir: [f64; 3], bound: f64| NodalRow {
        node,
        dofs: [3 * node, 3 * node + 1, 3 * node + 2],
        dir,
        dim: 3,
        bound,
        area: 1.0,
    };
    let top = 0..nodes / 2;
    let contact: Vec<_> = top
        .clone()
        .filter(|i| i % 2 == 0)
        .map(|i| row(i, [0.0, 0.0, -1.0], f64::INFINITY))
        .collect();
    let friction: Vec<_> = top
        .filter(|i| i % 2 == 1)
        .flat_map(|i| [row(i, [0.0, 1.0, 0.0], 0.5), row(i, [1.0, 0.0, 0.0], 0.5)])
        .collect();
    (k, Rows::new(&contact, &friction, 2))
}

/// Where E selects, D by two triangles (`condense_selected`) equals D by the solve and
/// the full product (`condense_solved`) to rounding, with the same bits on one to three
/// threads, and B by the Schur complement (`inverse`) is D's inverse.
#[test]
fn selected_rows_condense_as_solved_ones() {
    let (k, rows) = axis_rows(600);
    let factor = Factor::new(&k, &rows.dofs()).unwrap();
    let first = factor.dim() - factor.last();
    let p = rows.in_factor(&factor, first);
    let sel = selection(factor.last(), &p).expect("the rows select");
    let d = condense_selected(&factor, &sel, Par::Seq);
    let d_solved = condense_solved(&factor, &p, Par::Seq);
    assert!((&d - &d_solved).norm_max() <= 1e-14 * d_solved.norm_max());
    for threads in [2, 3] {
        let d_par = condense_selected(&factor, &sel, Par::rayon(threads));
        assert!(d_par == d, "{threads} threads differ");
    }
    let b = inverse(&factor, Some(&sel), &d).unwrap();
    let m = rows.len();
    assert!((&b * &d - Mat::<f64>::identity(m, m)).norm_max() <= 1e-12);
    // A row of two entries (the first friction row, turned in its node's x-y plane): E
    // does not select.
    let (_, mut turned) = axis_rows(600);
    turned.rows[turned.n_contact].dir = [0.8, 0.6, 0.0];
    assert!(selection(factor.last(), &turned.in_factor(&factor, first)).is_none());
}
