//! A rank's own columns (`Discretization::keep_columns`): a rank of a run over several MPI
//! ranks keeps of K_A, K_B and K_R the columns of the unknowns whose rows it holds, and
//! computes its entries of the right side's products from them (`fem::mul_add_rows`). On
//! the 3D block with elasticity and memory, for a random half of the nodes: those entries
//! agree with the whole matrices' products to round-off, and the other columns are gone,
//! the matrices' columns those alone, each the whole's bits (the diagonal at Γ3's other
//! unknowns too: the ranks that hold their rows send it). A rank that assembles those
//! columns alone (`Discretization::numbered`, then `assembled`) holds the same matrices, bit for bit, and
//! the same loads in its own rows, whether it holds the cells, their vertices or nothing;
//! from the vertices alone (rank 0) it computes the stresses and norms of the cells held,
//! and visits every load's terms (a body force's made again), bit for bit; its rows of K_B
//! and K_R paired (`Discretization::pair_own_rows`) give the same products, and so do
//! those it makes after PETSc's setup instead (`Discretization::own_pair_made`).
//! Where a rank's rows of K_A go to PETSc, K_A keeps its diagonal at its own of the unknowns
//! of Γ3's rows alone (`Discretization::keep_diagonal_of_k_a`), and a follower's rows of K_B and K_R
//! numbered over the dofs its history holds give the same products of the vectors held
//! there (`Discretization::number_rows_over`). A scene with prescribed dofs keeps its
//! matrices whole.

use crate::common;
use common::*;
use std::collections::BTreeSet;
use viscontact::fem::{
    diagonal, mul_add, mul_add_rows, CellMaterials, Discretization, Hold, PairWhen, Sparse,
    StressCells,
};

/// The discretization of `scene` on `mesh` with of its matrices the columns of `own` alone,
/// in its two stages, as a rank of several makes it (`Ranks::discretize`).
fn with_columns(
    (mesh, scene): (&viscontact::mesh::Mesh, &viscontact::scene::Scene),
    how: (Hold, PairWhen),
    own: &[usize],
) -> Discretization {
    let materials = CellMaterials::new(mesh, scene).unwrap();
    let disc = Discretization::numbered(mesh, scene, how.0).unwrap();
    (disc.assembled(mesh, scene, how, (materials, Some(own.to_vec())))).unwrap()
}

/// The unknowns of a random half of `disc`'s nodes, increasing.
fn random_half(disc: &Discretization, rng: &mut SplitMix) -> Vec<usize> {
    let d = disc.dim;
    (0..disc.free.dofs() / d)
        .filter(|_| rng.below(2) == 0)
        .flat_map(|v| disc.free.of_node(d, v))
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect()
}

#[test]
fn a_ranks_own_columns_give_its_rows_of_the_products() {
    let dir = tempfile::tempdir().unwrap();
    let path = SceneText::block().write(dir.path(), "block.toml");
    let (_, _, whole) = load(&path, &[]);
    let (_, _, mut mine) = load(&path, &[]);
    let mut rng = SplitMix(52);
    let own = random_half(&mine, &mut rng);
    assert!(own.len() > whole.n_free / 4 && own.len() < 3 * whole.n_free / 4);
    mine.keep_columns(own.clone());
    assert_eq!(mine.own.as_deref(), Some(own.as_slice()));
    let x: Vec<f64> = (0..whole.n_dofs).map(|_| rng.unit() - 0.5).collect();
    let pairs: Vec<(&Sparse, &Sparse)> = [(&whole.k_a, &mine.k_a)]
        .into_iter()
        .chain(whole.k_b.iter().zip(&mine.k_b))
        .chain(whole.k_r.iter().zip(&mine.k_r))
        .collect();
    assert_eq!(pairs.len(), 3, "K_A, K_B and one K_R");
    for (k, (full, kept)) in pairs.into_iter().enumerate() {
        let (mut y, mut rows) = (vec![0.0; x.len()], vec![0.0; x.len()]);
        mul_add(full, &x, -1.0, &mut y);
        mul_add_rows(kept, &own, &x, -1.0, &mut rows);
        let at = |v: &[f64]| own.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let diff = rel_diff(&at(&rows), &at(&y));
        assert!(diff < 1e-14, "matrix {k}: own rows differ by {diff:e}");
        // Its own columns alone, column c the whole's column own[c], the same bits: no
        // column start of the others (8 bytes a dof of the whole on every rank).
        assert_eq!((kept.nrows(), kept.ncols()), (full.nrows(), own.len()));
        let (kept, full) = (kept.as_ref(), full.as_ref());
        let column = |m: faer::sparse::SparseColMatRef<'_, usize, f64>, j: usize| {
            let p = m.symbolic().col_ptr()[j]..m.symbolic().col_ptr()[j + 1];
            let bits = m.val()[p.clone()].iter().map(|v| v.to_bits());
            m.symbolic().row_idx()[p]
                .iter()
                .copied()
                .zip(bits)
                .collect::<Vec<_>>()
        };
        for (c, &j) in own.iter().enumerate() {
            assert_eq!(column(kept, c), column(full, j), "matrix {k}, dof {j}");
        }
        let d_full = diagonal(&whole.k_a);
        let d_kept = mine.diagonal_of(&mine.k_a, None);
        for j in 0..whole.n_free {
            let expected = if own.binary_search(&j).is_ok() {
                d_full[j]
            } else {
                0.0
            };
            assert_eq!(d_kept[j].to_bits(), expected.to_bits(), "dof {j}");
        }
        assert!(kept.val().len() < full.val().len() * 3 / 4, "matrix {k}");
    }
}

/// On the 3D block and the paper's 2D scene (K_A, K_B and K_R each, and a body force), for
/// a random half of the nodes: the columns a rank assembles alone are those it keeps of the
/// whole, bit for bit, and so are its loads in its own rows (the only ones it makes),
/// whether it holds the cells, their vertices (rank 0, which then visits every term of the
/// loads in the whole's order, a body force's made again) or none (a follower); rank 0 that
/// assembled the whole first and then keeps its own loads still visits every term.
#[test]
fn a_rank_that_assembles_its_own_columns_alone_holds_what_it_would_keep_of_the_whole() {
    let dir = tempfile::tempdir().unwrap();
    for (name, scene) in [
        ("block.toml", SceneText::block().body(&["0", "0", "-0.5*x"])),
        ("paper.toml", SceneText::paper().body(&["0.1*y", "-1"])),
    ] {
        let path = scene.write(dir.path(), name);
        let (scene, mesh, mut kept) = load(&path, &[]);
        let own = random_half(&kept, &mut SplitMix(7));
        kept.keep_columns(own.clone());
        for hold in [Hold::Cells, Hold::Vertices, Hold::Nothing] {
            let case = format!("{name}, holding {hold:?}");
            let numbered = Discretization::numbered(&mesh, &scene, hold).unwrap();
            assert!(
                numbered.n_free == kept.n_free && numbered.k_a.nrows() == 0,
                "{case}: the unknowns come before the matrices"
            );
            let mine = with_columns((&mesh, &scene), (hold, PairWhen::Setup), &own);
            let (held, read) = match hold {
                Hold::Cells => (kept.cells.len(), kept.cells.len()),
                Hold::Vertices => (0, kept.cells.len()),
                Hold::Nothing => (0, 0),
            };
            assert_eq!((mine.cells.len(), mine.n_cells()), (held, read), "{case}");
            assert_eq!(mine.own, kept.own, "{case}");
            let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            let loads = |d: &Discretization| {
                let mut f = vec![0.0; d.n_dofs];
                let free = (&d.free, &d.frames);
                d.loads.add(0.5, free, &scene, (&mut f, None)).unwrap();
                f
            };
            // A rank of several makes the loads of its own rows alone: those rows are the
            // whole's.
            let f = loads(&kept);
            assert!(f.iter().any(|&v| v != 0.0), "{case}");
            let at = |f: &[f64]| match hold {
                Hold::Cells => f.to_vec(),
                _ => own.iter().map(|&i| f[i]).collect(),
            };
            assert_eq!(bits(&at(&loads(&mine))), bits(&at(&f)), "{case}");
            // A follower's b_n, held at its own rows alone (and others: `time_loop`).
            let mut f_own = vec![0.0; own.len()];
            let free = (&mine.free, &mine.frames);
            (mine.loads.add(0.5, free, &scene, (&mut f_own, Some(&own)))).unwrap();
            let own_f: Vec<f64> = own.iter().map(|&i| f[i]).collect();
            assert_eq!(bits(&f_own), bits(&own_f), "{case}");
            assert_eq!(mine.loads.is_part(), hold != Hold::Cells, "{case}");
            // Rank 0 (and one process) sees every term, in the whole's order, the body
            // force's made again from its cells; a follower its own alone.
            let every = hold != Hold::Nothing;
            assert_eq!(mine.loads.sees_every_value(), every, "{case}");
            if every {
                assert_eq!(
                    every_term(&mine, &scene),
                    every_term(&kept, &scene),
                    "{case}"
                );
            }
            let matrices = |d: &Discretization| {
                let mut all = vec![d.k_a.clone()];
                all.extend(d.k_b.iter().cloned());
                all.extend(d.k_r.iter().cloned());
                all
            };
            let (a, b) = (matrices(&mine), matrices(&kept));
            assert_eq!(a.len(), b.len(), "{case}");
            for (k, (a, b)) in a.iter().zip(&b).enumerate() {
                let (a, b) = (a.as_ref(), b.as_ref());
                assert_eq!(a.symbolic().col_ptr(), b.symbolic().col_ptr(), "{case} {k}");
                assert_eq!(a.symbolic().row_idx(), b.symbolic().row_idx(), "{case} {k}");
                assert_eq!(bits(a.val()), bits(b.val()), "{case} {k}");
            }
        }
        // Where the whole was assembled first (`solver.linear = "auto"`), rank 0 then keeps
        // its own rows' points and the tractions', and still sees every term.
        let before = every_term(&kept, &scene);
        kept.keep_own_loads(true);
        assert!(
            kept.loads.is_part() && kept.loads.sees_every_value(),
            "{name}"
        );
        assert_eq!(every_term(&kept, &scene), before, "{name}");
    }
}

/// Every term of `disc`'s loads at t = 0.5 (`Discretization::visit_every_load`): load,
/// dof and the value's bits, in their order.
fn every_term(disc: &Discretization, scene: &viscontact::scene::Scene) -> Vec<(usize, usize, u64)> {
    let mut terms = Vec::new();
    let put = |l, dof, v: f64| terms.push((l, dof, v.to_bits()));
    disc.visit_every_load(0.5, scene, put).unwrap();
    terms
}

/// Rank 0 of several holds each cell's vertices alone (`Hold::Vertices`) and makes a cell
/// from them when it reads it: on the 3D block and the paper's 2D scene, the stresses of
/// every cell and of some, the largest von Mises stress and the norms are the bits of the
/// cells held.
#[test]
fn rank_0_computes_from_the_cells_vertices_what_it_would_from_the_cells() {
    let dir = tempfile::tempdir().unwrap();
    for (name, scene) in [
        ("block.toml", SceneText::block()),
        ("paper.toml", SceneText::paper()),
    ] {
        let path = scene.write(dir.path(), name);
        let (scene, mesh, mut held) = load(&path, &[]);
        let own = random_half(&held, &mut SplitMix(3));
        held.keep_columns(own.clone());
        let mine = with_columns((&mesh, &scene), (Hold::Vertices, PairWhen::Setup), &own);
        assert!(mine.cells.is_empty() && mine.n_cells() == held.cells.len());
        let mut rng = SplitMix(5);
        let mut random = |len: usize| (0..len).map(|_| rng.unit() - 0.5).collect::<Vec<_>>();
        let (w, u) = (random(held.n_dofs), random(held.n_dofs));
        let m = random(held.n_dofs * held.k_r.len());
        let m = (!m.is_empty()).then_some(m.as_slice());
        let model = scene.mesh.model;
        let bits = |m: &[f64]| m.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let some: Vec<usize> = (0..held.cells.len()).step_by(3).rev().collect();
        for cells in [StressCells::All, StressCells::Only(&some)] {
            let (s, vm) = held.stress([&w, &u], (m, [None; 2]), model, cells);
            let (s2, vm2) = mine.stress([&w, &u], (m, [None; 2]), model, cells);
            assert!(vm.iter().any(|&v| v > 0.0), "{name}");
            assert_eq!(
                (bits(&s2), bits(&vm2)),
                (bits(&s), bits(&vm)),
                "{name} {cells:?}"
            );
        }
        let largest = held.max_von_mises([&w, &u], (m, [None; 2]), model, StressCells::All);
        let vm = |cells| mine.max_von_mises([&w, &u], (m, [None; 2]), model, cells);
        assert_eq!(vm(StressCells::All).to_bits(), largest.to_bits());
        // Over pieces that split the cells, the largest of theirs (how the ranks of a run
        // compute it: each its own piece's, then the largest of those).
        let (a, b): (Vec<usize>, Vec<usize>) = (0..held.cells.len()).partition(|c| c % 3 == 1);
        let pieces = vm(StressCells::Only(&a)).max(vm(StressCells::Only(&b)));
        assert_eq!(pieces.to_bits(), largest.to_bits());
        let (l2, semi) = held.norms(&w);
        let (l2_mine, semi_mine) = mine.norms(&w);
        assert!(l2 > 0.0 && semi > 0.0, "{name}");
        assert_eq!(
            [l2_mine, semi_mine].map(f64::to_bits),
            [l2, semi].map(f64::to_bits)
        );
        // summary.json's norms over the same pieces (how the ranks of a run compute them:
        // each its piece's part of the squares, summed), to the last digits.
        let part = |cells| mine.norm_parts((&w, None), cells);
        let ([l2_a, h1_a], [l2_b, h1_b]) =
            (part(StressCells::Only(&a)), part(StressCells::Only(&b)));
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-14 * y;
        assert!(
            close((l2_a + l2_b).sqrt(), l2),
            "{name}: {l2_a} + {l2_b} against {l2}²"
        );
        assert!(
            close((h1_a + h1_b).sqrt(), semi),
            "{name}: {h1_a} + {h1_b} against {semi}²"
        );
        // A piece's cells named by their vertices' places among its points (`Of`, a rank's
        // piece of the frames): its part's bits and its stresses'.
        let vertices = |c: &usize| held.cells[*c].vertices().to_vec();
        let mut points: Vec<usize> = a.iter().flat_map(vertices).collect();
        points.sort_unstable();
        points.dedup();
        let places: Vec<usize> = (a.iter().flat_map(vertices))
            .map(|v| points.binary_search(&v).unwrap())
            .collect();
        let materials: Vec<u32> = a.iter().map(|&c| held.materials.of_cell[c]).collect();
        let of = StressCells::Of(&places, &materials, &points);
        assert_eq!(part(of).map(f64::to_bits), [l2_a, h1_a].map(f64::to_bits));
        let stress = |cells| mine.stress([&w, &u], (m, [None; 2]), model, cells);
        let ((s_of, vm_of), (s_a, vm_a)) = (stress(of), stress(StressCells::Only(&a)));
        assert_eq!(
            (bits(&s_of), bits(&vm_of)),
            (bits(&s_a), bits(&vm_a)),
            "{name}"
        );
    }
}

/// A rank's rows of K_B and K_R paired (`Discretization::pair_own_rows`): the product
/// gives the rank's entries the bits of the two matrices' own products one after the
/// other, with and without the memory term, and the two matrices keep no entry beside the
/// pair.
#[test]
fn k_b_and_k_r_paired_give_the_bits_of_their_own_products() {
    let dir = tempfile::tempdir().unwrap();
    let path = SceneText::block().write(dir.path(), "block.toml");
    let (_, _, mut disc) = load(&path, &[]);
    let mut rng = SplitMix(11);
    let own = random_half(&disc, &mut rng);
    disc.keep_columns(own.clone());
    let (k_b, k_r) = (disc.k_b.clone().unwrap(), disc.k_r[0].clone());
    disc.pair_own_rows();
    let pair = disc.own_pair.as_ref().expect("K_B and K_R paired");
    let (x, z): (Vec<f64>, Vec<f64>) = (0..disc.n_dofs)
        .map(|_| (rng.unit() - 0.5, rng.unit() - 0.5))
        .unzip();
    let y0: Vec<f64> = (0..disc.n_dofs).map(|_| rng.unit()).collect();
    let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let (mut both, mut alone) = (y0.clone(), y0.clone());
    mul_add_rows(&k_b, &own, &x, -1.0, &mut both);
    alone.clone_from(&both);
    mul_add_rows(&k_r, &own, &z, -1.0, &mut both);
    let (mut paired, mut paired_alone) = (y0.clone(), y0.clone());
    pair.mul_add(&own, &x, Some(&z), -1.0, &mut paired);
    pair.mul_add(&own, &x, None, -1.0, &mut paired_alone);
    assert_eq!(bits(&paired), bits(&both));
    assert_eq!(bits(&paired_alone), bits(&alone));
    assert_ne!(bits(&paired), bits(&y0));
    for (kept, whole) in [(disc.k_b.as_ref().unwrap(), &k_b), (&disc.k_r[0], &k_r)] {
        assert_eq!(kept.as_ref().val().len(), 0);
        assert_eq!((kept.nrows(), kept.ncols()), (whole.nrows(), whole.ncols()));
    }
}

/// A rank that makes its rows of K_B and K_R^(0) after PETSc's setup
/// (`PairWhen::AfterKrylov`, `Discretization::own_pair_made`), in pieces, from its cells
/// with one of its own nodes: on the 3D block and the paper's 2D scene, for a random half of
/// the nodes, holding the cells' vertices (rank 0) or none (a follower), meanwhile K_B and
/// K_R^(0) with no entry and the same reach as the rank that paired them in its setup, and
/// then the products of that rank's pair, bit for bit, in the whole numbering and numbered
/// over the reach; in the implicit variant, whose step matrix reads all three, it pairs
/// in its setup.
#[test]
fn rows_paired_after_the_krylov_setup_are_those_paired_in_the_setup() {
    let dir = tempfile::tempdir().unwrap();
    let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for (name, scene) in [
        ("block.toml", SceneText::block()),
        ("paper.toml", SceneText::paper()),
    ] {
        let path = scene.write(dir.path(), name);
        let (scene, mesh, whole) = load(&path, &[]);
        let own = random_half(&whole, &mut SplitMix(17));
        for hold in [Hold::Vertices, Hold::Nothing] {
            let case = format!("{name}, holding {hold:?}");
            let make = |when| {
                let mut mine = with_columns((&mesh, &scene), (hold, when), &own);
                mine.pair_own_rows();
                // As a follower before PETSc's setup (`run::follow`): the rows it makes
                // after that read the places it kept alone.
                if hold == Hold::Nothing {
                    mine.keep_places(&mesh.nodes, &[]);
                }
                mine
            };
            let (mut now, mut later) = (make(PairWhen::Setup), make(PairWhen::AfterKrylov));
            assert!(now.own_pair.is_some() && later.own_pair.is_none(), "{case}");
            assert!(now.own_pair_made(None).is_none(), "{case}");
            for m in later.k_b.iter().chain(&later.k_r) {
                assert_eq!(m.as_ref().val().len(), 0, "{case}");
            }
            let local = now.local_reach([]).unwrap();
            assert_eq!(later.local_reach([]).as_ref(), Some(&local), "{case}");
            assert!(local.len() < now.n_dofs, "{case}");
            let mut rng = SplitMix(29);
            let mut random = |len: usize| (0..len).map(|_| rng.unit() - 0.5).collect::<Vec<_>>();
            let (u, m, y0) = (random(now.n_dofs), random(now.n_dofs), random(now.n_dofs));
            let product = |pair: &viscontact::fem::RowsPair, u: &[f64], m: &[f64]| {
                let mut y = y0.clone();
                pair.mul_add(&own, u, Some(m), -1.0, &mut y);
                bits(&y)
            };
            let paired = now.own_pair.as_ref().unwrap();
            let made = later.own_pair_made(None).expect("the rows made");
            assert_eq!(product(&made, &u, &m), product(paired, &u, &m), "{case}");
            assert_ne!(product(paired, &u, &m), bits(&y0), "{case}");
            now.number_rows_over(&local);
            later.number_rows_over(&local);
            let held = |v: &[f64]| local.iter().map(|&i| v[i]).collect::<Vec<_>>();
            let (u, m) = (held(&u), held(&m));
            let made = later.own_pair_made(Some(&local)).unwrap();
            let paired = now.own_pair.as_ref().unwrap();
            assert_eq!(product(&made, &u, &m), product(paired, &u, &m), "{case}");
        }
        let implicit = SceneText::file(&path).set("scheme.history", "implicit");
        let path = implicit.write(dir.path(), &format!("implicit_{name}"));
        let (scene, mesh, _) = load(&path, &[]);
        let how = (Hold::Nothing, PairWhen::AfterKrylov);
        let mut mine = with_columns((&mesh, &scene), how, &own);
        mine.pair_own_rows();
        assert!(
            mine.own_pair.is_some() && mine.own_pair_made(None).is_none(),
            "{name}"
        );
    }
}

/// A follower whose history holds u_n and m_n at its reach alone (`history::Holds::Local`):
/// its rows of K_B and K_R, paired or not, numbered over `Discretization::local_reach`
/// (`Discretization::number_rows_over`), give from the vectors held there the bits of its
/// rows of the products from the whole vectors, and a piece's stresses and displacements
/// read from them (`fem::place`) have the bits of the whole vectors'. The reach holds the
/// rank's own unknowns and the dofs asked for (the piece's), and not every dof.
#[test]
fn rows_numbered_over_the_reach_give_the_bits_of_the_whole_vectors() {
    let dir = tempfile::tempdir().unwrap();
    let path = SceneText::block().write(dir.path(), "block.toml");
    let bits = |v: &[f64]| v.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for paired in [false, true] {
        let (scene, _, mut disc) = load(&path, &[]);
        let d = disc.dim;
        let nodes = disc.free.dofs() / d;
        // The unknowns of a quarter of the nodes; the piece: the cells with one of them.
        let own: Vec<usize> = (0..d * nodes / 4)
            .filter_map(|g| disc.free.get(g))
            .collect();
        let piece: Vec<usize> = (0..disc.cells.len())
            .filter(|&c| {
                disc.cells[c].vertices()[..=d]
                    .iter()
                    .any(|&v| v < nodes / 4)
            })
            .collect();
        let also: BTreeSet<usize> = (piece.iter())
            .flat_map(|&c| disc.cells[c].vertices()[..=d].to_vec())
            .flat_map(|v| (d * v..d * v + d).filter_map(|g| disc.free.get(g)))
            .collect();
        disc.keep_columns(own.clone());
        if paired {
            disc.pair_own_rows();
            assert!(disc.own_pair.is_some());
        }
        let mut rng = SplitMix(23);
        let mut random = |len: usize| (0..len).map(|_| rng.unit() - 0.5).collect::<Vec<_>>();
        let (w, u, m, y0) = (
            random(disc.n_dofs),
            random(disc.n_dofs),
            random(disc.n_dofs),
            random(disc.n_dofs),
        );
        let product = |disc: &Discretization, u: &[f64], m: &[f64]| {
            let mut y = y0.clone();
            match &disc.own_pair {
                Some(pair) => pair.mul_add(&own, u, Some(m), -1.0, &mut y),
                None => {
                    mul_add_rows(disc.k_b.as_ref().unwrap(), &own, u, -1.0, &mut y);
                    mul_add_rows(&disc.k_r[0], &own, m, -1.0, &mut y);
                }
            }
            y
        };
        let whole = product(&disc, &u, &m);
        assert_ne!(bits(&whole), bits(&y0));
        let model = scene.mesh.model;
        let cells = StressCells::Only(&piece);
        let (s, vm) = disc.stress([&w, &u], (Some(&m), [None; 2]), model, cells);
        let local = disc.local_reach(also.iter().copied()).unwrap();
        assert!(also
            .iter()
            .chain(&own)
            .all(|i| local.binary_search(i).is_ok()));
        assert!(
            local.len() < disc.n_dofs,
            "{} of {}",
            local.len(),
            disc.n_dofs
        );
        disc.number_rows_over(&local);
        let held = |v: &[f64]| local.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let (u_held, m_held) = (held(&u), held(&m));
        let numbered = product(&disc, &u_held, &m_held);
        assert_eq!(bits(&numbered), bits(&whole), "paired: {paired}");
        let place = Some(local.as_slice());
        let (s2, vm2) = disc.stress([&w, &u_held], (Some(&m_held), [None, place]), model, cells);
        assert!(vm.iter().any(|&v| v > 0.0));
        assert_eq!((bits(&s2), bits(&vm2)), (bits(&s), bits(&vm)));
        // A follower's w_n held at its history's dofs too (and more: `time_loop`).
        let w_held = held(&w);
        let m_u = (Some(m_held.as_slice()), [place, place]);
        let (s3, vm3) = disc.stress([&w_held, &u_held], m_u, model, cells);
        assert_eq!((bits(&s3), bits(&vm3)), (bits(&s), bits(&vm)));
        // Its part of summary.json's norms of u_n held at its history's dofs.
        let norms = disc.norm_parts((&u, None), cells);
        assert!(norms.iter().all(|&v| v > 0.0));
        let norms_held = disc.norm_parts((&u_held, place), cells);
        assert_eq!(norms_held.map(f64::to_bits), norms.map(f64::to_bits));
        let at: Vec<usize> = (0..nodes)
            .step_by(5)
            .filter(|&v| {
                (d * v..d * v + d)
                    .filter_map(|g| disc.free.get(g))
                    .all(|i| also.contains(&i))
            })
            .collect();
        assert!(!at.is_empty());
        let nodal = disc.nodal_at((&u_held, place), &at);
        assert_eq!(bits(&nodal), bits(&disc.nodal_at((&u, None), &at)));
    }
}

#[test]
fn k_a_handed_over_keeps_its_diagonal_at_its_own_rows_of_gamma3_alone() {
    let dir = tempfile::tempdir().unwrap();
    let path = SceneText::block().write(dir.path(), "block.toml");
    let (_, _, mut disc) = load(&path, &[]);
    let whole = diagonal(&disc.k_a);
    assert!(whole.iter().all(|&d| d > 0.0));
    let read: BTreeSet<usize> = (disc.contact.iter().chain(&disc.friction))
        .flat_map(|row| row.entries().map(|(d, _)| d))
        .collect();
    assert!(!disc.contact.is_empty() && !disc.friction.is_empty());
    assert!(
        read.len() < disc.n_free / 2,
        "{} of {}",
        read.len(),
        disc.n_free
    );
    let own: Vec<usize> = (0..disc.n_free).step_by(2).collect();
    disc.keep_columns(own.clone());
    disc.keep_diagonal_of_k_a();
    let own_read = read.iter().filter(|&&d| d % 2 == 0).count();
    assert!(own_read > 0 && own_read < read.len());
    assert_eq!(disc.k_a.as_ref().val().len(), own_read);
    // Its own columns alone: no column start of the whole (8 bytes a dof on every rank).
    assert_eq!(
        (disc.k_a.nrows(), disc.k_a.ncols()),
        (disc.n_free, own.len())
    );
    let kept = disc.diagonal_of(&disc.k_a, None);
    assert_eq!(kept.len(), disc.n_free);
    for (d, (kept, whole)) in kept.iter().zip(&whole).enumerate() {
        let expected = if read.contains(&d) && d % 2 == 0 {
            *whole
        } else {
            0.0
        };
        assert_eq!(kept.to_bits(), expected.to_bits(), "dof {d}");
    }
}

#[test]
fn a_scene_with_prescribed_dofs_keeps_its_matrices_whole() {
    let dir = tempfile::tempdir().unwrap();
    let path = SceneText::unclamped_square()
        .dirichlet("Γ1", &["x", "y"], Some(&["0.01*t", "0"]))
        .write(dir.path(), "prescribed.toml");
    let (scene, mesh, mut disc) = load(&path, &[]);
    assert!(disc.k_a_all.is_some());
    let before = disc.k_a.as_ref().val().to_vec();
    disc.keep_columns(vec![0, 1]);
    assert!(disc.own.is_none());
    assert_eq!(disc.k_a.as_ref().val(), &before[..]);
    let mine = with_columns((&mesh, &scene), (Hold::Nothing, PairWhen::Setup), &[0, 1]);
    assert!(mine.own.is_none());
    assert_eq!(mine.k_a.as_ref().val(), &before[..]);
}
