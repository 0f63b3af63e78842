//! The cell field `material_region` of a scene with `[[material.region]]` entries: each
//! cell's entry (0 outside every region), static like `region`, in the `.vtu` series and in
//! `solution.vtkhdf`, continued by a resume; a scene without regions writes no such field.

use crate::common;
use common::{finished, repo, resume_quiet, run_options, SceneText};
use std::path::Path;
use viscontact::output::read::{read_frame, read_series, Vtu};

/// The bimaterial bar (tests/data/bimaterial_bar.msh) with a region on "stiff".
fn bar(format: &str, regions: bool) -> SceneText {
    let scene = SceneText::on(repo().join("tests/data/bimaterial_bar.msh"))
        .set("time.end", 1.0)
        .set("time.steps", 8)
        .set("output.format", format)
        .set("material.viscosity.theta", 0.1)
        .set("material.elasticity.young", 0.5)
        .traction(Some("right"), &["0.01", "0"]);
    if !regions {
        return scene;
    }
    // The stiff part relaxes with a compressed kernel of its own, the soft one with
    // [material]'s Prony series: two memory groups in the checkpoint.
    let scene = scene.table("material.relaxation", "prony = [[0.7, 3.0]]");
    let entry: toml::Table = toml::from_str(
        "on = \"stiff\"\nelasticity = { young = 2.0 }\n\
         relaxation = { expr = \"0.5*exp(-s) + 0.2*exp(-s/5)\" }",
    )
    .unwrap();
    scene.push("material.region", entry)
}

/// The last frame of the series in `dir`.
fn last_frame(dir: &Path) -> Vtu {
    let (_, frames) = read_series(dir).unwrap();
    read_frame(&frames.last().unwrap().1).unwrap()
}

#[test]
fn material_region_is_written_in_both_formats_and_continued_by_resume() {
    let mesh = viscontact::mesh::Mesh::read(&repo().join("tests/data/bimaterial_bar.msh")).unwrap();
    let stiff = &mesh.cell_group("stiff").unwrap().cells;
    let mut want = vec![0.0; mesh.n_cells()];
    stiff.iter().for_each(|&c| want[c] = 1.0);
    let tags = viscontact::run::region(&mesh);
    let tmp = tempfile::tempdir().unwrap();
    for format in ["vtu", "vtkhdf"] {
        let scene = bar(format, true).write(tmp.path(), &format!("{format}.toml"));
        let (full, part) = (
            tmp.path().join(format),
            tmp.path().join(format!("{format}-part")),
        );
        finished(viscontact::run::run(&scene, &run_options(&full, &[], None)).unwrap());
        let frame = last_frame(&full);
        let field = frame
            .cell_field("material_region")
            .expect("material_region");
        assert_eq!(field.values, want, "{format}");
        let region = frame.cell_field("region").expect("region");
        assert!(region
            .values
            .iter()
            .zip(&tags)
            .all(|(&a, &b)| a == b as f64));
        // Stopped after step 2 and resumed: the series is verified (the static fields too)
        // and continued to the same last frame.
        viscontact::run::run(&scene, &run_options(&part, &[], Some(2))).unwrap();
        finished(resume_quiet(&part.join("checkpoint.h5")));
        let resumed = last_frame(&part);
        for (a, b) in (frame.cell_data.iter().zip(&resumed.cell_data))
            .chain(frame.point_data.iter().zip(&resumed.point_data))
        {
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                (&a.name, bits(&a.values)),
                (&b.name, bits(&b.values)),
                "{format}"
            );
        }
        assert_eq!(frame.cell_data.len(), resumed.cell_data.len());
        // Without regions: no material_region.
        let plain = bar(format, false).write(tmp.path(), &format!("{format}-plain.toml"));
        let out = tmp.path().join(format!("{format}-plain"));
        finished(viscontact::run::run(&plain, &run_options(&out, &[], None)).unwrap());
        let frame = last_frame(&out);
        assert!(frame.cell_field("material_region").is_none(), "{format}");
        assert!(frame.cell_field("region").is_some(), "{format}");
    }
}
