//! One run over several MPI ranks (`viscontact::ranks`) under Open MPI's real `mpirun`, as
//! root where CI runs as root and with more ranks than cores: a PETSc run, linear or with
//! contact and friction through the active set, 2D and 3D, Prony and compressed kernels,
//! on 1, 2 and 3 ranks agrees with the one-process run (bit for bit on one rank, to 1e-8
//! relative in u_N and the von Mises stress on more; history.csv's largest stress the same
//! bits with or without frames); stopped on 3 ranks and resumed on 2,
//! it agrees with the uninterrupted run on 2 to the same tolerance, and resumed on the rank
//! count it stopped on, bit for bit; SIGTERM to every rank stops it after a step with a
//! checkpoint, and SIGKILL of one rank ends the others at once, the run then resuming from
//! its last checkpoint; a run whose steps do not spread is refused (exit 2) before anything
//! is written; the followers run without the mesh file, which rank 0 alone reads.

use crate::common::{self, SceneText};
use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};
use viscontact::output::read::{read_frame, read_series, read_vtu};

/// `mpirun -n RANKS viscontact ARGS` from the repository root (`launching`).
fn mpirun(ranks: usize, args: &[&str]) -> Command {
    let mut mpirun = Command::new("mpirun");
    launching(&mut mpirun)
        .args(["--oversubscribe", "-n", &ranks.to_string(), common::BIN])
        .args(args);
    mpirun
}

/// A command that starts mpirun, from the repository root, with what Open MPI asks of root.
/// This process's own MPI (initialized with PETSc by the library tests beside these) left
/// its launcher's variables in the environment; mpirun must not inherit them.
fn launching(command: &mut Command) -> &mut Command {
    for (var, _) in std::env::vars_os() {
        let name = var.to_string_lossy();
        if ["OMPI_", "PMIX_", "ORTE_", "OPAL_"]
            .iter()
            .any(|p| name.starts_with(p))
        {
            command.env_remove(&var);
        }
    }
    command
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env_remove("PETSC_OPTIONS")
        .current_dir(common::repo())
}

/// Its exit status and its output, stderr then stdout.
fn outcome(out: Output) -> (i32, String) {
    let text =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    (out.status.code().unwrap_or(-1), text)
}

/// `run SCENE --out OUT` on `ranks` ranks (0: one process without mpirun), then `more`.
fn run(ranks: usize, scene: &Path, out: &Path, more: &[&str]) -> (i32, String) {
    let mut args = vec!["run", scene.to_str().unwrap(), "--quiet"];
    args.extend(["--out", out.to_str().unwrap()]);
    args.extend(more);
    outcome(match ranks {
        0 => common::viscontact(&args),
        n => mpirun(n, &args).output().unwrap(),
    })
}

/// `resume DIR/checkpoint.h5` on `ranks` ranks.
fn resume(ranks: usize, dir: &Path) -> (i32, String) {
    let cp = dir.join("checkpoint.h5");
    outcome(
        mpirun(ranks, &["resume", cp.to_str().unwrap(), "--quiet"])
            .output()
            .unwrap(),
    )
}

/// The displacement of a run's last frame, node by node.
fn u_last(dir: &Path) -> Vec<f64> {
    let (_, frames) = read_series(&dir.join("solution.pvd")).unwrap();
    let (_, last) = frames.last().unwrap();
    let vtu = read_frame(last).unwrap();
    vtu.point_field("displacement").unwrap().values.clone()
}

/// The von Mises stress of the last frame in `dir`, cell by cell in the order of the cells'
/// sorted vertices (a frame in pieces lists its cells piece by piece).
fn von_mises_last(dir: &Path) -> Vec<f64> {
    let (_, frames) = read_series(&dir.join("solution.pvd")).unwrap();
    let vtu = read_frame(&frames.last().unwrap().1).unwrap();
    let values = &vtu.cell_field("von_mises").unwrap().values;
    let mut cells: Vec<(Vec<usize>, f64)> = (vtu.cells.iter().zip(values))
        .map(|(c, &v)| {
            let mut c = c.clone();
            c.sort_unstable();
            (c, v)
        })
        .collect();
    cells.sort_by(|a, b| a.0.cmp(&b.0));
    assert!(cells.iter().any(|&(_, v)| v > 0.0), "{}", dir.display());
    cells.into_iter().map(|(_, v)| v).collect()
}

/// The 3D block (examples/block.toml, a Prony kernel), the paper's scene with a power-law
/// kernel compressed to a certified Prony sum, without contact and friction, through
/// PETSc: 12 steps each.
fn linear_scenes(dir: &Path) -> Vec<std::path::PathBuf> {
    let block = SceneText::block().remove("contact").remove("friction");
    let paper = (SceneText::paper().remove("contact").remove("friction"))
        .table("material.relaxation", "expr = \"0.2*(s+0.01)^(-0.5)\"");
    [("block.toml", block), ("paper.toml", paper)]
        .into_iter()
        .map(|(name, s)| {
            s.set("solver.linear", "petsc")
                .set("time.steps", 12)
                .write(dir, name)
        })
        .collect()
}

/// The block with contact and friction (a Prony kernel) and the paper's scene with its
/// power-law kernel compressed (2D, contact and friction), through the active set on
/// PETSc: 8 steps each.
fn contact_scenes(dir: &Path) -> Vec<std::path::PathBuf> {
    let paper = SceneText::paper().table("material.relaxation", "expr = \"0.2*(s+0.01)^(-0.5)\"");
    [("block.toml", SceneText::block()), ("paper.toml", paper)]
        .into_iter()
        .map(|(name, s)| {
            (s.set("solver.linear", "petsc"))
                .set("solver.contact", "active_set")
                .set("time.steps", 8)
                .write(dir, name)
        })
        .collect()
}

/// The block linear (`linear_scenes`) and with contact and friction (`contact_scenes`),
/// each in a directory of its own under `dir`, for the tests that run both.
fn both_blocks(dir: &Path) -> [std::path::PathBuf; 2] {
    let (linear, contact) = (dir.join("linear"), dir.join("contact"));
    std::fs::create_dir_all(&linear).unwrap();
    std::fs::create_dir_all(&contact).unwrap();
    [
        linear_scenes(&linear).swap_remove(0),
        contact_scenes(&contact).swap_remove(0),
    ]
}

/// Each scene run on 1, 2 and 3 ranks agrees with the one-process run: bit for bit on one
/// rank, to 1e-8 relative in u_N and the last frame's von Mises stress on more, with the
/// same files in its directory.
fn agree_on_1_2_and_3_ranks(scenes: &[std::path::PathBuf]) {
    for scene in scenes {
        let dir = scene.parent().unwrap();
        let what = scene.file_name().unwrap().to_string_lossy().into_owned();
        let one = dir.join(format!("{what}.one"));
        // mpirun binds a rank to a core (one thread); the results do not depend on it.
        let (code, text) = run(0, scene, &one, &["--threads", "1"]);
        assert_eq!(code, 0, "{text}");
        let reference = u_last(&one);
        assert!(common::max_abs(&reference) > 0.0);
        for ranks in 1..=3 {
            let out = dir.join(format!("{what}.{ranks}"));
            let (code, text) = run(ranks, scene, &out, &["--threads", "1"]);
            assert_eq!(code, 0, "{what} on {ranks} ranks: {text}");
            // Rank 0 alone reports (and writes: the directory is checked whole below).
            assert_eq!(text.matches("; wrote").count(), 1, "{text}");
            assert_eq!(common::summary(&out)["ranks"], ranks, "{what}");
            if ranks == 1 {
                common::assert_same_series(&one, &out, "mpirun -n 1 against one process");
                continue;
            }
            let d = common::rel_diff(&u_last(&out), &reference);
            println!("{what}, {ranks} ranks: max|Δu_N| / max|u_N| = {d:e}");
            assert!(d <= 1e-8, "{what} on {ranks} ranks: u_N differs by {d:e}");
            // The stresses, which a rank of several computes from its cells, not packed.
            let d = common::rel_diff(&von_mises_last(&out), &von_mises_last(&one));
            assert!(
                d <= 1e-8,
                "{what} on {ranks} ranks: von Mises differs by {d:e}"
            );
            assert_pieces(&out, &one, ranks, &what);
            assert_same_final(&out, &one, &format!("{what} on {ranks} ranks"));
        }
    }
}

/// summary.json's `final` of the run in `out` (its norms the ranks' pieces' sums over
/// several) agrees with `reference`'s to 1e-8 relative, at the same time, and the two count
/// the same cells.
fn assert_same_final(out: &Path, reference: &Path, what: &str) {
    let (s, r) = (common::summary(out), common::summary(reference));
    assert_eq!(s["final"]["time"], r["final"]["time"], "{what}");
    assert_eq!(s["elements"], r["elements"], "{what}");
    for key in ["u_l2", "u_h1", "u_max"] {
        let (a, b) = (
            s["final"][key].as_f64().unwrap(),
            r["final"][key].as_f64().unwrap(),
        );
        assert!(
            b > 0.0 && (a - b).abs() <= 1e-8 * b,
            "{what}: final.{key} {a} against {b}"
        );
    }
}

/// The directory `out` of a run over `ranks` ranks holds the files of `one`'s, the one
/// process's, with each frame a `.pvtu` of `ranks` pieces in place of its `.vtu`; VTK's
/// parallel reader reads the last with every piece's points (more than the mesh's) and the
/// one-process frame's cells.
fn assert_pieces(out: &Path, one: &Path, ranks: usize, what: &str) {
    let names = |dir: &Path| {
        let mut n: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| !n.starts_with("solution_") || n.contains('.'))
            .map(|n| n.replace(".pvtu", ".vtu"))
            .collect();
        n.sort();
        n
    };
    assert_eq!(names(out), names(one), "{what}: the directories' files");
    let (_, frames) = read_series(&out.join("solution.pvd")).unwrap();
    let pvtu = frames.last().unwrap().1.path().to_path_buf();
    let text = std::fs::read_to_string(&pvtu).unwrap();
    assert_eq!(text.matches("<Piece ").count(), ranks, "{}", pvtu.display());
    if !common::python_available() {
        return;
    }
    let script = r#"
import sys, vtk
counts = []
for name, reader in ((sys.argv[1], vtk.vtkXMLPUnstructuredGridReader()), (sys.argv[2], vtk.vtkXMLUnstructuredGridReader())):
    reader.SetFileName(name)
    reader.Update()
    g = reader.GetOutput()
    counts += [g.GetNumberOfPoints(), g.GetNumberOfCells()]
print(*counts)
"#;
    let last_vtu = one.join(pvtu.file_name().unwrap()).with_extension("vtu");
    let counts: Vec<usize> = common::python_out(script, &[&pvtu, &last_vtu])
        .split_whitespace()
        .map(|w| w.parse().unwrap())
        .collect();
    let pieces_points: usize = (text.split("Source=\"").skip(1))
        .map(|s| &s[..s.find('"').unwrap()])
        .map(|s| {
            read_vtu(&pvtu.parent().unwrap().join(s))
                .unwrap()
                .points
                .len()
        })
        .sum();
    assert_eq!(counts[0], pieces_points, "{what}: VTK's points");
    assert!(
        counts[0] > counts[2],
        "{what}: the borders' points are in two pieces"
    );
    assert_eq!(counts[1], counts[3], "{what}: VTK's cells");
}

#[test]
fn a_linear_run_on_1_2_and_3_ranks_agrees_with_one_process() {
    let tmp = tempfile::tempdir().unwrap();
    agree_on_1_2_and_3_ranks(&linear_scenes(tmp.path()));
}

/// A half model whose plane of symmetry holds each node's normal component (a node there
/// has two unknowns, so K_A has no node blocks): the ranks split its rows where a node's
/// unknowns begin, and the run agrees with one process as the whole models do.
#[test]
fn a_half_model_with_two_unknowns_on_its_plane_on_1_2_and_3_ranks_agrees_with_one_process() {
    example_on_1_2_and_3_ranks("half_block.toml");
}

/// The example `name` through the active set on PETSc, 8 steps, on 1, 2 and 3 ranks
/// against one process (`agree_on_1_2_and_3_ranks`).
fn example_on_1_2_and_3_ranks(name: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let scene = (SceneText::example(name).set("solver.linear", "petsc"))
        .set("solver.contact", "active_set")
        .set("time.steps", 8)
        .write(tmp.path(), name);
    agree_on_1_2_and_3_ranks(&[scene]);
}

/// A punch's prescribed displacement (examples/punch.toml: no clamped group, contact and
/// friction), whose velocities reach every row's right side, so that every rank keeps the
/// matrices whole: on 1, 2 and 3 ranks the run agrees with one process, rank 0 making the
/// stresses of history.csv and of its piece from the cells' vertices it holds.
#[test]
fn a_prescribed_displacement_with_contact_on_1_2_and_3_ranks_agrees_with_one_process() {
    example_on_1_2_and_3_ranks("punch.toml");
}

/// The active set's Newton systems spread as K_A's solves do: each rank makes the Newton
/// matrix's rows of its own nodes, and every rank takes the same decisions from the whole
/// w it gets back.
#[test]
fn a_run_with_contact_and_friction_on_1_2_and_3_ranks_agrees_with_one_process() {
    let tmp = tempfile::tempdir().unwrap();
    agree_on_1_2_and_3_ranks(&contact_scenes(tmp.path()));
}

/// Regions (examples/bimaterial.toml: a soft layer under its core, `[[material.region]]`),
/// whose materials and physical groups a follower gets with its part of the mesh's cells
/// from rank 0 (`Ranks::cells_of_first`): on 1, 2 and 3 ranks the run agrees with one
/// process, and the last frame's pieces hold between them as many cells of each physical
/// group (`region`) and of each material region (`material_region`) as the one process's
/// frame.
#[test]
fn regions_on_1_2_and_3_ranks_agree_and_the_pieces_hold_each_regions_cells() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = (SceneText::example("bimaterial.toml").set("solver.linear", "petsc"))
        .set("solver.contact", "active_set")
        .set("time.steps", 4)
        .write(tmp.path(), "bimaterial.toml");
    agree_on_1_2_and_3_ranks(std::slice::from_ref(&scene));
    // The cells of each (region, material_region) pair in the frames `files`.
    let counts = |files: &[std::path::PathBuf]| {
        let mut counts = std::collections::BTreeMap::new();
        for file in files {
            let vtu = read_vtu(file).unwrap();
            let field = |name: &str| {
                let a = vtu.cell_data.iter().find(|a| a.name == name);
                a.unwrap_or_else(|| panic!("{}: no {name}", file.display()))
                    .values
                    .clone()
            };
            for pair in field("region").into_iter().zip(field("material_region")) {
                *counts.entry(format!("{pair:?}")).or_insert(0) += 1;
            }
        }
        counts
    };
    let last = |dir: &Path| {
        read_series(&dir.join("solution.pvd"))
            .unwrap()
            .1
            .last()
            .unwrap()
            .1
            .path()
            .to_path_buf()
    };
    let one = counts(&[last(&tmp.path().join("bimaterial.toml.one"))]);
    assert!(one.len() >= 2, "the layer and the core: {one:?}");
    let pvtu = last(&tmp.path().join("bimaterial.toml.3"));
    let text = std::fs::read_to_string(&pvtu).unwrap();
    let pieces: Vec<_> = (text.split("Source=\"").skip(1))
        .map(|s| pvtu.parent().unwrap().join(&s[..s.find('"').unwrap()]))
        .collect();
    assert_eq!(pieces.len(), 3);
    assert_eq!(counts(&pieces), one, "the pieces' cells of each region");
}

/// What only the whole mesh shows, which rank 0 alone checks (a follower holds its part of
/// the mesh's cells alone): regions that share cells, and two halves of a body that were
/// not fragmented (their nodes coincide), each refused on 3 ranks (exit 2) with rank 0's
/// message alone, the others quiet, and nothing written.
#[test]
fn what_only_the_whole_mesh_shows_is_refused_on_3_ranks_with_rank_0s_message() {
    let tmp = tempfile::tempdir().unwrap();
    let data = common::repo().join("tests/data/mesh_checks");
    let mesh = data.join("regions.msh");
    let shared = SceneText::parse(&format!(
        "name = \"shared\"\n[mesh]\nfile = {:?}\nmodel = \"plane_stress\"\n\
         [mesh.groups]\nfixed = [\"Γ1\"]\n[time]\nend = 1.0\nsteps = 2\n\
         [material.viscosity]\ntheta = 0.1\nzeta = 0.1\n\
         [[material.region]]\non = \"Ω\"\n[material.region.viscosity]\ntheta = 0.2\nzeta = 0.1\n\
         [[material.region]]\non = \"inner\"\n[material.region.viscosity]\ntheta = 0.3\nzeta = 0.1\n\
         [[load.body]]\nvalue = [\"0.01*t\", \"-0.02*t\"]\n",
        mesh.display().to_string()
    ));
    let unfragmented = SceneText::file(&data.join("unfragmented.toml"));
    for (scene, what) in [
        (shared, "share 14 elements"),
        (unfragmented, "coincide with another node"),
    ] {
        let path = scene
            .set("solver.linear", "petsc")
            .write(tmp.path(), "scene.toml");
        let out = tmp.path().join("o");
        let (code, text) = run(3, &path, &out, &[]);
        assert_eq!(code, 2, "{text}");
        assert_eq!(text.matches("error:").count(), 1, "{text}");
        assert!(text.contains(what), "{text}");
        assert!(!out.exists(), "a refused run wrote {}", out.display());
    }
}

/// history.csv's largest von Mises stress, which over several ranks is the largest of the
/// ranks' pieces' at every step (`run::frame::OwnFrames::solved`): on 3 ranks of the block
/// with contact it has the same bits whether a frame at the step hands it over, no frame is
/// due or the frames have no stress, and agrees with one process's at every step.
#[test]
fn the_largest_stress_in_history_csv_on_3_ranks_is_the_same_with_or_without_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = contact_scenes(tmp.path()).swap_remove(0);
    let column = |out: &Path| common::History::read(out).column("max_von_mises");
    let one = tmp.path().join("one");
    let (code, text) = run(0, &scene, &one, &["--threads", "1"]);
    assert_eq!(code, 0, "{text}");
    let reference = column(&one);
    assert!(reference.iter().all(|&v| v > 0.0), "{reference:?}");
    let frames = [
        ("every step", "output.every=1"),
        ("the last step", "output.every=100"),
        ("no stress", "output.fields=[\"displacement\"]"),
    ];
    let mut first: Option<Vec<u64>> = None;
    for (what, set) in frames {
        let out = tmp.path().join(what.replace(' ', "_"));
        let (code, text) = run(3, &scene, &out, &["--set", set]);
        assert_eq!(code, 0, "frames at {what}: {text}");
        let largest = column(&out);
        let d = common::rel_diff(&largest, &reference);
        assert!(
            d <= 1e-8,
            "frames at {what}: differs from one process's by {d:e}"
        );
        let bits: Vec<u64> = largest.iter().map(|v| v.to_bits()).collect();
        assert_eq!(
            first.get_or_insert_with(|| bits.clone()),
            &bits,
            "frames at {what}"
        );
    }
}

/// A body force, of which every rank keeps the quadrature points of its own rows alone
/// (rank 0 makes the others again where it reads them): on 1, 2 and 3 ranks the run agrees
/// with one process, in 3D and in 2D, and history.csv's resultants are one process's bits;
/// where the force is
/// not finite at a step in part of the body, every rank stops at that step, rank 0 alone
/// saying where (exit 1, summary.json "failed").
#[test]
fn a_body_force_on_1_2_and_3_ranks_agrees_and_a_load_not_finite_stops_every_rank() {
    let tmp = tempfile::tempdir().unwrap();
    let block = |z: &str| {
        (SceneText::block().body(&["0.001*t", "0", z]))
            .set("solver.linear", "petsc")
            .set("solver.contact", "active_set")
            .set("time.steps", 8)
    };
    let plane = (common::paper("paper/rect_032.msh", false))
        .body(&["0.01*sin(x)*t", "-0.02*(1+y)*min(t, 0.5)"])
        .set("solver.linear", "petsc")
        .set("solver.contact", "active_set")
        .set("time.steps", 8);
    let scenes = [
        block("-0.02*(1+x)*min(t, 0.5)").write(tmp.path(), "body.toml"),
        plane.write(tmp.path(), "plane.toml"),
    ];
    agree_on_1_2_and_3_ranks(&scenes);
    // Rank 0 keeps the body force's points of its own rows alone and makes the others again
    // for history.csv, and keeps every traction's: each load's resultant is one process's,
    // bit for bit (a part would differ).
    let loads = |out: &str| {
        let history = common::History::read(&tmp.path().join(out));
        let names = history.header.iter();
        let names = names.filter(|c| c.starts_with("body_") || c.starts_with("load_"));
        names
            .map(|c| (c.clone(), history.column(c)))
            .collect::<Vec<_>>()
    };
    for name in ["body.toml", "plane.toml"] {
        let one = loads(&format!("{name}.one"));
        assert!(one.iter().any(|(c, _)| c == "body_y"), "{one:?}");
        assert!(
            one.iter().filter(|(_, v)| common::max_abs(v) > 0.0).count() >= 4,
            "{name}: {one:?}"
        );
        for ranks in [2, 3] {
            assert_eq!(
                loads(&format!("{name}.{ranks}")),
                one,
                "{name}, {ranks} ranks"
            );
        }
    }
    // ln of a negative number beyond x = 1.5 from t = 0.375 (step 3) on.
    let bad = block("if(x <= 1.5, -0.01, ln(0.31 - t))").write(tmp.path(), "bad.toml");
    for ranks in [2, 3] {
        let out = tmp.path().join(format!("bad.{ranks}"));
        let (code, text) = run(ranks, &bad, &out, &[]);
        assert_eq!(code, 1, "{text}");
        assert_eq!(text.matches("error:").count(), 1, "{text}");
        assert!(
            text.contains("'load.body[0].value[2]' evaluates to NaN"),
            "{text}"
        );
        assert!(text.contains("at t = 0.375"), "{text}");
        assert_eq!(common::summary(&out)["status"], "failed", "{text}");
    }
}

/// The Newton systems' multigrid, updated in place by the difference carried down its
/// levels (on 3 ranks and more each rank multiplies its rows of the difference, and the
/// owner of a coarse row adds the parts in rank order), is the Galerkin hierarchy of its
/// system: after every update, each coarse operator equals the product of the level above
/// computed anew by PETSc to 1e-12 relative (the shim's `-viscontact_galerkin_check`).
#[test]
fn the_updated_multigrid_on_2_3_and_4_ranks_is_the_galerkin_hierarchy() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = contact_scenes(tmp.path()).swap_remove(0);
    for ranks in 2..=4 {
        let out = tmp.path().join(format!("out{ranks}"));
        let check = ["--set", "solver.petsc.options=-viscontact_galerkin_check"];
        let (code, text) = run(
            ranks,
            &scene,
            &out,
            &[&check[..], &["--set", "time.steps=3"]].concat(),
        );
        assert_eq!(code, 0, "{ranks} ranks: {text}");
        let defects: Vec<f64> = (text.lines())
            .filter_map(|l| l.strip_prefix("Galerkin defect "))
            .map(|d| d.trim().parse().unwrap())
            .collect();
        println!(
            "{ranks} ranks: {} updates, largest defect {:e}",
            defects.len(),
            defects.iter().cloned().fold(0.0, f64::max)
        );
        assert!(defects.len() >= 3, "{ranks} ranks: {text}");
        assert!(
            defects.iter().all(|&d| d <= 1e-12),
            "{ranks} ranks: {defects:?}"
        );
    }
}

/// With the implicit history the step matrix is K_A + k K_B + k² r(0) K_R, not K_A: a rank
/// then keeps its columns of K_A, and PETSc takes the step matrix's rows, made from the
/// rank's columns (`Ranks::keep_own_columns` hands K_A's rows over only where K_A is it).
#[test]
fn the_implicit_history_with_contact_on_1_2_and_3_ranks_agrees_with_one_process() {
    let tmp = tempfile::tempdir().unwrap();
    let block = (SceneText::block().set("scheme.history", "implicit"))
        .set("solver.linear", "petsc")
        .set("solver.contact", "active_set")
        .set("time.steps", 8)
        .write(tmp.path(), "block.toml");
    agree_on_1_2_and_3_ranks(&[block]);
}

/// The direct sum (an expression kernel with `memory = "exact"`), whose past displacements
/// each rank keeps of the dofs it reads alone (`Holds`), rank 0 those its steps and
/// history.csv read, and a checkpoint (here one every 2 steps) gathers from the ranks'
/// own rows (`TimeLoop::gather_memory`), with contact and friction: on 1, 2 and 3 ranks it
/// agrees with one process, its reactions too, and stopped on 3 ranks it resumes from the
/// checkpoint's whole past on 3, bit for bit, and on 2.
#[test]
fn the_direct_sum_on_1_2_and_3_ranks_agrees_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let kernel = "expr = \"exp(-10*s)\"\nmemory = \"exact\"";
    let block = (SceneText::block().table("material.relaxation", kernel))
        .set("solver.linear", "petsc")
        .set("solver.contact", "active_set")
        .set("time.steps", 8)
        .set("checkpoint.every", 2)
        .write(tmp.path(), "block.toml");
    agree_on_1_2_and_3_ranks(std::slice::from_ref(&block));
    let reactions = |out: &str| {
        let h = common::History::read(&tmp.path().join(out));
        let names = h.header.iter().filter(|n| n.starts_with("reaction_"));
        names.flat_map(|n| h.column(n)).collect::<Vec<f64>>()
    };
    let one = reactions("block.toml.one");
    assert!(common::max_abs(&one) > 0.0);
    for ranks in [2, 3] {
        let d = common::rel_diff(&reactions(&format!("block.toml.{ranks}")), &one);
        println!("{ranks} ranks: history.csv's reactions, max|Δ| / max|r| = {d:e}");
        assert!(d <= 1e-8, "{ranks} ranks: the reactions differ by {d:e}");
    }
    stopped_on_3_resumed_on_2_and_on_3(&block);
}

/// The block, linear and with contact and friction.
#[test]
fn stopped_on_3_ranks_a_run_resumes_on_2_and_on_3() {
    let tmp = tempfile::tempdir().unwrap();
    for scene in &both_blocks(tmp.path()) {
        stopped_on_3_resumed_on_2_and_on_3(scene);
    }
}

/// `scene` stopped on 3 ranks after step 5 and resumed on 3 equals the run never stopped on
/// 3, bit for bit; resumed on 2, the run on 2 to 1e-8 relative in u_N.
fn stopped_on_3_resumed_on_2_and_on_3(scene: &Path) {
    let dir = scene.parent().unwrap();
    let whole = |ranks: usize| {
        let out = dir.join(format!("whole{ranks}"));
        let (code, text) = run(ranks, scene, &out, &[]);
        assert_eq!(code, 0, "{text}");
        out
    };
    let (whole2, whole3) = (whole(2), whole(3));
    let one_stopped = dir.join("stopped_one");
    let (code, text) = run(0, scene, &one_stopped, &["--stop-after", "5"]);
    assert_eq!(code, 0, "{text}");
    for (again, reference) in [(3, &whole3), (2, &whole2)] {
        let out = dir.join(format!("stopped_resumed_on_{again}"));
        let (code, text) = run(3, scene, &out, &["--stop-after", "5"]);
        assert_eq!(code, 0, "{text}");
        assert_eq!(common::summary(&out)["status"], "interrupted");
        // Of u_6, which the loop holds once it stops after step 5.
        assert_same_final(&out, &one_stopped, "stopped on 3 ranks");
        let (code, text) = resume(again, &out);
        assert_eq!(code, 0, "resumed on {again}: {text}");
        assert_eq!(common::summary(&out)["status"], "completed");
        if again == 3 {
            common::assert_same_series(reference, &out, "stopped and resumed on 3 ranks");
        } else {
            let d = common::rel_diff(&u_last(&out), &u_last(reference));
            println!("stopped on 3, resumed on 2: max|Δu_N| / max|u_N| = {d:e}");
            assert!(d <= 1e-8, "u_N differs by {d:e} from the run on 2");
            assert_same_final(&out, reference, "stopped on 3 ranks, resumed on 2");
        }
    }
}

/// The ranks mpirun started (its children), once there are `ranks` of them.
fn ranks_of(mpirun: u32, ranks: usize) -> Vec<String> {
    let start = Instant::now();
    loop {
        let out = Command::new("pgrep")
            .args(["-P", &mpirun.to_string()])
            .output()
            .unwrap();
        let pids: Vec<String> = String::from_utf8_lossy(&out.stdout)
            .split_whitespace()
            .map(String::from)
            .collect();
        if pids.len() == ranks {
            return pids;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "{pids:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The signalled runs' steps and checkpoints (`signalled`).
const SIGNALLED: [&str; 4] = ["--set", "time.steps=400", "--set", "checkpoint.every=10"];

/// Resumes the run of `scene` that `signalled` left in DIR/o on 2 ranks: it equals the same
/// run never stopped, bit for bit.
fn resumes_as_never_stopped(scene: &Path, what: &str) {
    let dir = scene.parent().unwrap();
    let out = dir.join("o");
    let (code, text) = resume(2, &out);
    assert_eq!(code, 0, "{what}: {text}");
    let whole = dir.join("whole");
    let (code, text) = run(2, scene, &whole, &SIGNALLED);
    assert_eq!(code, 0, "{text}");
    common::assert_same_series(&whole, &out, what);
}

/// A run of `scene` on 2 ranks, 400 steps with a checkpoint every 10, that `signal` reaches
/// on `which` of its ranks (none: on mpirun) once frame 20 is written, in the scene's
/// directory: mpirun's exit status, its output, and how long it took to end.
fn signalled(signal: &str, which: &[usize], scene: &Path) -> (i32, String, Duration) {
    let out = scene.parent().unwrap().join("o");
    let child = mpirun(2, &["run", scene.to_str().unwrap(), "--quiet", "--out"])
        .arg(&out)
        .args(SIGNALLED)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pids = ranks_of(child.id(), 2);
    let frame = out.join("solution_000020.pvtu");
    let start = Instant::now();
    while !frame.exists() {
        assert!(start.elapsed() < Duration::from_secs(120), "no frame 20");
        std::thread::sleep(Duration::from_millis(2));
    }
    // None of the ranks: mpirun itself, as Ctrl-C in its terminal reaches it (the ranks are
    // process groups of their own).
    let mpirun_pid = child.id().to_string();
    let targets: Vec<&String> = match which {
        [] => vec![&mpirun_pid],
        _ => which.iter().map(|&r| &pids[r]).collect(),
    };
    for pid in targets {
        let kill = Command::new("kill")
            .args(["-s", signal, pid])
            .status()
            .unwrap();
        assert!(kill.success());
    }
    let sent = Instant::now();
    let (code, text) = outcome(child.wait_with_output().unwrap());
    (code, text, sent.elapsed())
}

/// The block, linear and with contact and friction.
#[test]
fn sigterm_to_every_rank_stops_after_a_step_with_a_checkpoint_and_the_run_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    for scene in &both_blocks(tmp.path()) {
        let (code, text, _) = signalled("TERM", &[0, 1], scene);
        let out = scene.parent().unwrap().join("o");
        assert_eq!(code, 143, "{text}");
        let s = common::summary(&out);
        assert_eq!(s["status"], "interrupted", "{s}");
        assert!(text.contains("interrupted by SIGTERM after step"), "{text}");
        resumes_as_never_stopped(scene, "SIGTERM on 2 ranks, resumed on 2");
    }
}

/// Ctrl-C to mpirun: Open MPI passes SIGTERM to the ranks and kills them a second later;
/// they give up the step in progress at once and stop before it, rank 0 with its
/// checkpoint and summary.json, and the run resumes bit for bit.
#[test]
fn sigint_to_mpirun_stops_the_ranks_before_it_kills_them() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = &linear_scenes(tmp.path())[0];
    let (_, text, _) = signalled("INT", &[], scene);
    let out = tmp.path().join("o");
    let s = common::summary(&out);
    assert_eq!(s["status"], "interrupted", "{s}\n{text}");
    resumes_as_never_stopped(scene, "Ctrl-C to mpirun, resumed on 2");
}

#[test]
fn sigterm_to_one_rank_stops_them_all_after_the_same_step() {
    let tmp = tempfile::tempdir().unwrap();
    let (code, text, _) = signalled("TERM", &[1], &linear_scenes(tmp.path())[0]);
    assert_eq!(code, 143, "{text}");
    let s = common::summary(&tmp.path().join("o"));
    assert_eq!(s["status"], "interrupted", "{s}");
    assert!(s["message"].as_str().unwrap().contains("SIGTERM"), "{s}");
}

/// The block, linear and with contact and friction: mpirun ends the other rank within
/// seconds, and the run resumes from its last checkpoint to the run never stopped, bit for
/// bit.
#[test]
fn sigkill_of_one_rank_ends_the_others_and_the_run_resumes_from_its_checkpoint() {
    let tmp = tempfile::tempdir().unwrap();
    for scene in &both_blocks(tmp.path()) {
        let (code, text, took) = signalled("KILL", &[1], scene);
        assert_ne!(code, 0, "{text}");
        assert!(
            took < Duration::from_secs(20),
            "the others ran on for {took:?}"
        );
        let out = scene.parent().unwrap().join("o");
        assert!(
            out.join("checkpoint.h5").exists(),
            "no checkpoint to resume"
        );
        resumes_as_never_stopped(scene, "SIGKILL of one rank, resumed on 2");
    }
}

/// Each rank writes its own piece of a frame. One that cannot (its piece's file is taken by
/// a directory) fails the run on every rank (exit 1), naming its file, before the frame's
/// `.pvtu` lists the pieces; the series and the checkpoint before it stay, and the run then
/// resumes to the same bits as the run never stopped.
#[test]
fn a_rank_that_cannot_write_its_piece_fails_the_run_and_it_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let [linear, _] = both_blocks(tmp.path());
    let dir = linear.parent().unwrap();
    let (whole, out) = (dir.join("whole"), dir.join("o"));
    let (code, text) = run(2, &linear, &whole, &[]);
    assert_eq!(code, 0, "{text}");
    let (code, text) = run(2, &linear, &out, &["--stop-after", "5"]);
    assert_eq!(code, 0, "{text}");
    let taken = out.join("solution_000008/solution_000008_1.vtu");
    std::fs::create_dir_all(taken.join("in_the_way")).unwrap();
    let (code, text) = resume(2, &out);
    assert_eq!(code, 1, "{text}");
    assert!(text.contains("error: rank 1:"), "{text}");
    assert!(text.contains("solution_000008_1.vtu"), "{text}");
    assert!(
        text.contains("another rank could not write its piece"),
        "{text}"
    );
    assert_eq!(common::summary(&out)["status"], "failed");
    let pvd = std::fs::read_to_string(out.join("solution.pvd")).unwrap();
    assert!(pvd.contains("solution_000007.pvtu"), "{pvd}");
    assert!(!pvd.contains("solution_000008.pvtu"), "{pvd}");
    assert!(!out.join("solution_000008.pvtu").exists());
    std::fs::remove_dir_all(&taken).unwrap();
    let (code, text) = resume(2, &out);
    assert_eq!(code, 0, "{text}");
    common::assert_same_series(&whole, &out, "failed at a piece, resumed on 2 ranks");
}

/// `check` and `run --emit slurm` under mpirun print once, on rank 0.
#[test]
fn check_on_two_ranks_prints_once() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = &linear_scenes(tmp.path())[1];
    let (code, text) = outcome(
        mpirun(2, &["check", scene.to_str().unwrap()])
            .output()
            .unwrap(),
    );
    assert_eq!(code, 0, "{text}");
    assert_eq!(text.matches("scene      ").count(), 1, "{text}");
    // The run's own directory in the temporary one: mpirun starts in the repository, whose
    // out/paper may hold the README's run, which an emitted job refuses.
    let (job, out) = (tmp.path().join("job"), tmp.path().join("o"));
    let emit = [
        &["run", scene.to_str().unwrap(), "--emit", "slurm"][..],
        &[job.to_str().unwrap(), "--out", out.to_str().unwrap()],
    ];
    let (code, text) = outcome(mpirun(2, &emit.concat()).output().unwrap());
    assert_eq!(code, 0, "{text}");
    assert_eq!(text.matches("submit with sbatch").count(), 1, "{text}");
    assert!(job.join("job.sh").exists());
}

/// Rank 0 alone reads the mesh file and hands the mesh to the others: followers started
/// where the scene's mesh file is not (Open MPI's second app context, in a directory with
/// the scene alone) run the scene with rank 0, and the run is the same bytes as one whose
/// ranks all start beside the mesh.
#[test]
fn the_followers_never_read_the_mesh_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (with_mesh, without) = (tmp.path().join("with_mesh"), tmp.path().join("without"));
    std::fs::create_dir_all(&with_mesh).unwrap();
    std::fs::create_dir_all(&without).unwrap();
    std::fs::copy(
        common::repo().join("meshes/3d/block_004.msh"),
        with_mesh.join("mesh.msh"),
    )
    .unwrap();
    let scene = SceneText::block()
        .set("mesh.file", "mesh.msh")
        .set("solver.linear", "petsc")
        .set("solver.contact", "active_set")
        .set("time.steps", 4);
    scene.clone().write(&with_mesh, "scene.toml");
    scene.write(&without, "scene.toml");
    let (all, apart) = (tmp.path().join("all"), tmp.path().join("apart"));
    // Rank 0 beside the mesh, two followers in `followers_in`.
    let ranks = |out: &Path, followers_in: &Path| {
        let out = out.to_str().unwrap();
        let context = |dir: &Path, n: &'static str| -> Vec<String> {
            let dir = dir.to_str().unwrap();
            let args = ["-wdir", dir, "-n", n, common::BIN, "run", "scene.toml"];
            let args = [&args[..], &["--quiet", "--out", out]].concat();
            args.into_iter().map(String::from).collect()
        };
        let apart = [":".to_string()];
        let args = [
            context(&with_mesh, "1"),
            apart.into(),
            context(followers_in, "2"),
        ]
        .concat();
        let mut mpirun = Command::new("mpirun");
        launching(&mut mpirun).arg("--oversubscribe").args(args);
        outcome(mpirun.output().unwrap())
    };
    let (code, text) = ranks(&all, &with_mesh);
    assert_eq!(code, 0, "{text}");
    let (code, text) = ranks(&apart, &without);
    assert_eq!(code, 0, "followers without the mesh file: {text}");
    common::assert_same_series(&all, &apart, "followers without the mesh file");
    let csv = |dir: &Path| std::fs::read(dir.join("history.csv")).unwrap();
    assert_eq!(csv(&all), csv(&apart), "history.csv");
}

/// A run whose steps take the stored factor or a contact solver does not spread: every
/// rank refuses it (exit 2), rank 0 alone says why, and nothing is written.
#[test]
fn a_run_that_does_not_spread_is_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let linear = tmp.path().join("cholesky.toml");
    SceneText::paper()
        .remove("contact")
        .remove("friction")
        .write(tmp.path(), "cholesky.toml");
    for (scene, what) in [
        (
            common::repo().join("examples/paper.toml"),
            "contact solver dense",
        ),
        (linear, "stored Cholesky factor"),
    ] {
        let out = tmp.path().join("o");
        let (code, text) = run(2, &scene, &out, &[]);
        assert_eq!(code, 2, "{text}");
        assert_eq!(text.matches("error:").count(), 1, "{text}");
        assert!(text.contains("started on 2 MPI ranks"), "{text}");
        assert!(text.contains(what), "{text}");
        assert!(!out.exists(), "a refused rank wrote {}", out.display());
    }
}

/// `run --emit slurm` with two tasks: the job starts the run's ranks with srun (here a
/// stand-in that runs Open MPI's mpirun with Slurm's task count) and the run completes on
/// two ranks; a scene whose steps do not spread is refused.
#[test]
fn a_slurm_job_of_two_tasks_runs_the_scene_on_two_ranks() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = &linear_scenes(tmp.path())[0];
    let (job, out) = (tmp.path().join("job"), tmp.path().join("o"));
    let emit = |scene: &Path| {
        common::cli(&[
            "run",
            scene.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--emit",
            "slurm",
            job.to_str().unwrap(),
            "--ntasks-per-node",
            "2",
        ])
    };
    let (code, text) = emit(&common::repo().join("examples/paper.toml"));
    assert_eq!(code, 2, "{text}");
    assert!(
        text.contains("only a run whose steps are PETSc solves"),
        "{text}"
    );
    let (code, text) = emit(scene);
    assert_eq!(code, 0, "{text}");
    let script = std::fs::read_to_string(job.join("job.sh")).unwrap();
    assert!(script.contains("#SBATCH --ntasks-per-node=2\n"), "{script}");
    assert!(
        script.contains("srun --kill-on-bad-exit=1 \"$VISCONTACT\" run"),
        "{script}"
    );
    // --mem: what `check --ranks 2` says a rank holds, for each of the node's two tasks.
    let (code, text) = common::cli(&["check", scene.to_str().unwrap(), "--ranks", "2"]);
    assert_eq!(code, 0, "{text}");
    let rank = megabytes_after(&text, "memory ≈ ");
    let mem = script.split("#SBATCH --mem=").nth(1).unwrap();
    let mib: f64 = mem.split('M').next().unwrap().parse().unwrap();
    let asked = mib * 1024.0 * 1024.0;
    assert!(
        (asked - 2.0 * rank).abs() < 4e6,
        "--mem {asked:e} against 2 × {rank:e}"
    );
    // --time: check's estimate of the 12 steps, ten minutes at least.
    assert!(
        script.contains("# --time: 1.5 × check's estimate"),
        "{script}"
    );
    assert!(script.contains("#SBATCH --time=0-00:10:00\n"), "{script}");
    let bin = tmp.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let srun = "#!/bin/sh\nshift\nexec mpirun --oversubscribe -n \"$SLURM_NTASKS\" \"$@\"\n";
    common::write(&bin, "srun", srun);
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::Permissions::from_mode(0o755);
    std::fs::set_permissions(bin.join("srun"), mode).unwrap();
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap());
    let got = launching(&mut Command::new("bash"))
        .arg(job.join("job.sh"))
        .env("PATH", path)
        .env("SLURM_NTASKS", "2")
        .output()
        .unwrap();
    let (code, text) = outcome(got);
    assert_eq!(code, 0, "{text}");
    let s = common::summary(&out);
    assert_eq!(
        (&s["status"], &s["ranks"]),
        (&"completed".into(), &2.into()),
        "{s}"
    );
}

/// A PETSc step given up, linear or the active set's (the request every rank's Krylov
/// solves ask at each iteration: the first signal on several ranks, the second on one),
/// leaves the run where a stop after the step before leaves it, w as it was: the checkpoint
/// of the state before the step resumes to the run never stopped, bit for bit. One process
/// here, through the library, with the request made before the run: the first step it can
/// stop before is given up, whatever the timing.
#[test]
fn a_petsc_step_given_up_resumes_as_the_run_never_stopped() {
    use viscontact::run::{resume, run, Outcome, ResumeOptions};
    let tmp = tempfile::tempdir().unwrap();
    let _one = super::PETSC.lock().unwrap_or_else(|e| e.into_inner());
    for scene in &both_blocks(tmp.path()) {
        let dir = scene.parent().unwrap();
        let (full, part) = (dir.join("full"), dir.join("part"));
        common::finished(run(scene, &common::run_options(&full, &[], None)).unwrap());
        let o = common::run_options(&part, &[], None);
        let armed = o.interrupt.abandon().arm();
        assert!(o.interrupt.abandon().request(), "granted while armed");
        drop(armed);
        match run(scene, &o).unwrap() {
            Outcome::Stopped { step, signal, .. } => assert_eq!((step, signal), (0, None)),
            other => panic!("step 1 was not given up: {other:?}"),
        }
        assert_eq!(common::summary(&part)["last_step"], 0);
        assert!(!part.join("solution_000001.vtu").exists());
        let o = ResumeOptions {
            progress: false,
            ..Default::default()
        };
        common::finished(resume(&part.join("checkpoint.h5"), &o).unwrap());
        common::assert_same_series(&full, &part, "a PETSc step given up, resumed");
    }
}

/// SIGTERM to both ranks at random moments of setup and of the first steps (the moments
/// drawn up to 1.2 times what a run of 4 steps takes, mpirun's start included), with an
/// earlier run in the directory: every
/// mpirun ends within 10 s of the signal, and either the directory is byte for byte as it
/// was (setup stopped) or it holds this run, interrupted with a checkpoint that resumes.
/// `VISCONTACT_SEED` sets the seed (printed).
#[test]
fn sigterm_to_every_rank_during_setup_leaves_the_earlier_run_or_a_resumable_one() {
    let seed: u64 = common::env_or("VISCONTACT_SEED", 52);
    println!("seed {seed}");
    let mut rng = common::SplitMix(seed);
    let tmp = tempfile::tempdir().unwrap();
    let scene = (SceneText::paper().remove("contact").remove("friction"))
        .mesh(common::repo().join("meshes/paper/rect_128.msh"))
        .set("solver.linear", "petsc")
        .set("time.steps", 200)
        .write(tmp.path(), "big.toml");
    let out = tmp.path().join("o");
    // The earlier run, and how long mpirun takes to start the ranks, set up and solve 4 steps.
    let start = Instant::now();
    let (code, text) = run(2, &scene, &out, &["--stop-after", "3"]);
    assert_eq!(code, 0, "{text}");
    let span = start.elapsed().as_secs_f64();
    let args = ["run", scene.to_str().unwrap(), "--quiet", "--out"];
    let (mut in_setup, mut after) = (0, 0);
    for _ in 0..4 {
        let before = common::dir_contents(&out);
        let delay = Duration::from_secs_f64(1.2 * span * rng.unit());
        let mut child = mpirun(2, &args)
            .arg(&out)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let pids = ranks_of(child.id(), 2);
        std::thread::sleep(delay);
        for pid in &pids {
            let _ = Command::new("kill").args(["-s", "TERM", pid]).status();
        }
        let code = common::exit_within(&mut child, Duration::from_secs(10), "mpirun");
        println!("SIGTERM after {delay:?} (of {span:.2} s): exit {code}");
        if common::dir_contents(&out) == before {
            in_setup += 1;
            assert_ne!(code, 0, "{delay:?}: setup stopped, yet exit 0");
            continue;
        }
        after += 1;
        let s = common::summary(&out);
        assert_eq!(s["status"], "interrupted", "{delay:?}: {s}");
        let (code, text) = resume(2, &out);
        assert_eq!(code, 0, "{delay:?}: {text}");
        let (code, text) = run(2, &scene, &out, &["--stop-after", "3"]);
        assert_eq!(code, 0, "{text}");
    }
    println!("{in_setup} signals stopped setup, {after} a run");
}

/// `viscontact ARGS` (on `ranks` ranks; 0: one process without mpirun) with
/// `VISCONTACT_MEMORY=memory`: its exit status and output.
fn with_memory(ranks: usize, memory: f64, args: &[&str]) -> (i32, String) {
    let mut command = match ranks {
        0 => {
            let mut plain = Command::new(common::BIN);
            launching(&mut plain).args(args);
            plain
        }
        n => mpirun(n, args),
    };
    let out = command
        .env("VISCONTACT_MEMORY", memory.to_string())
        .output()
        .unwrap();
    outcome(out)
}

/// The megabytes `check` prints after `before` in `text` ("≈ 45.2 MB").
fn megabytes_after(text: &str, before: &str) -> f64 {
    let at = text
        .find(before)
        .unwrap_or_else(|| panic!("no {before:?} in {text}"));
    let figure = text[at + before.len()..].split_whitespace().next().unwrap();
    assert!(text[at + before.len()..].contains(" MB"), "{text}");
    1e6 * figure.parse::<f64>().unwrap()
}

/// `check --ranks N` plans a run through PETSc over N ranks: the largest rank's share of
/// K_A's rows (whole nodes) and its memory, its own part (the setup's peak less the
/// columns of the matrices it does not assemble) and its share of PETSc's. Where a rank
/// would not fit `VISCONTACT_MEMORY` (a rank's memory), `check` refuses (exit 2) naming how
/// many ranks would, `check` with that many passes and the run on that many completes;
/// below what every rank holds whatever their count (the mesh, the history), `check` and
/// `run` (one process, or under mpirun) refuse naming none, before anything is written.
#[test]
fn check_plans_the_ranks_and_refuses_ranks_that_would_not_fit_naming_how_many_would() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = &contact_scenes(tmp.path())[0];
    let path = scene.to_str().unwrap();
    let (code, text) = common::cli(&["check", path, "--ranks", "2"]);
    assert_eq!(code, 0, "{text}");
    assert!(
        text.contains("ranks      2 ranks: the largest holds 1944 of K_A's 3888 rows"),
        "{text}"
    );
    // A step's time on this machine, estimated from a product timed by `check`.
    let step = text
        .split("a step ≈ ")
        .nth(1)
        .and_then(|t| t.split(' ').next());
    let step: f64 = step.and_then(|s| s.parse().ok()).expect(&text);
    assert!(step > 0.0 && step < 10.0, "{text}");
    assert!(text.contains("the active set's Newton systems"), "{text}");
    // A budget between what 2 ranks and 3 ranks need a rank (PETSc's share falls by a
    // third, a margin of a sixth of it on either side; the rank's own part falls too).
    let own = megabytes_after(&text, "a rank: ≈ ");
    let petsc = megabytes_after(&text, "what the steps hold) and ≈ ");
    let memory = (own + 0.84 * petsc) / 0.8;
    let (code, text) = with_memory(0, memory, &["check", path, "--ranks", "2"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("≈ 3 ranks would fit (mpirun -n 3"), "{text}");
    let (code, text) = with_memory(0, memory, &["check", path, "--ranks", "3"]);
    assert_eq!(code, 0, "{text}");
    let out = tmp.path().join("o3");
    let run3 = ["run", path, "--quiet", "--out", out.to_str().unwrap()];
    let (code, text) = with_memory(3, memory, &run3);
    assert_eq!(code, 0, "{text}");
    assert_eq!(common::summary(&out)["status"], "completed");
    // Less than a rank's own part (below what every rank holds): no count fits.
    let memory = 0.9 * own;
    for ranks in ["1", "2"] {
        let (code, text) = with_memory(0, memory, &["check", path, "--ranks", ranks]);
        assert_eq!(code, 2, "{text}");
        assert!(text.contains("no rank count would"), "{text}");
    }
    let out = tmp.path().join("refused");
    let run = ["run", path, "--quiet", "--out", out.to_str().unwrap()];
    for ranks in [0, 2] {
        let (code, text) = with_memory(ranks, memory, &run);
        assert_eq!(code, 2, "{text}");
        assert_eq!(text.matches("no rank count would").count(), 1, "{text}");
        assert!(!out.exists(), "a refused run wrote {}", out.display());
    }
}
