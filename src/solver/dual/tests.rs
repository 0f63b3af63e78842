//! The dense kernels of the dual against their definitions.

use super::delassus::Delassus;
use super::groups::Coord;
use super::newton::gram;
use super::{DualSettings, Team};
use faer::Mat;

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
