//! The `viscontact` command line (DESIGN.md "Command line").

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;
use viscontact::run::{run, setup, RunOptions};
use viscontact::{effects::Effects, mesh::Mesh, Result};

#[derive(Parser)]
#[command(
    name = "viscontact",
    version,
    about = "Quasi-static contact of viscoelastic bodies with long memory (Problem 3.1 of Xu et al. 2021)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene: writes solution.pvd + solution_NNNNNN.vtu and summary.json.
    Run {
        scene: PathBuf,
        /// Output directory (default: out/<scene name>/).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Override a scene key by its dotted path, e.g. --set time.steps=64 (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Do not show a progress bar even on a terminal.
        #[arg(long)]
        quiet: bool,
    },
    /// Validate a scene and print its effects, sizes and solver path; runs nothing.
    Check {
        scene: PathBuf,
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Nodes, elements, physical groups with sizes, and element quality of a gmsh mesh.
    MeshInfo {
        mesh: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run {
            scene,
            out,
            set,
            quiet,
        } => run(
            &scene,
            &RunOptions {
                out,
                overrides: set,
                progress: !quiet,
            },
        )
        .map(|s| {
            println!(
                "{}: {} steps, {} dofs, {:.2} s; ‖u_N‖_H1 = {:.6e}; wrote {}",
                s.name, s.steps, s.dofs, s.timing.total_s, s.final_.u_h1, s.output.directory
            );
        }),
        Command::Check { scene, set } => check(&scene, &set),
        Command::MeshInfo { mesh, json } => mesh_info(&mesh, json),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

fn check(path: &std::path::Path, set: &[String]) -> Result<()> {
    let (scene, mesh, disc) = setup(path, set)?;
    let effects = Effects::new(&scene, &disc);
    println!("scene      {} ({})", scene.name, scene.path.display());
    println!(
        "mesh       {}: {} nodes, {} triangles, {} free dofs",
        mesh.path.display(),
        mesh.nodes.len(),
        mesh.triangles.len(),
        disc.n_free
    );
    println!(
        "time       T = {}, N = {}, k = {}",
        scene.end,
        scene.steps,
        scene.k()
    );
    println!("effects    {}", effects.names().join(", "));
    let solver = if effects.linear() {
        "linear (one solve with the stored Cholesky factor of K_A per step)".to_string()
    } else {
        format!(
            "{} contact solver on {} Γ3,1 rows + {} Γ3,2 rows",
            match scene.contact_solver {
                viscontact::scene::ContactSolver::Fast => "fast (condensed dual active set)",
                viscontact::scene::ContactSolver::Clarabel => "clarabel",
            },
            disc.contact.len(),
            disc.friction.len()
        )
    };
    println!("solver     {solver}");
    let limit = viscontact::stability::step_limit(&disc, scene.relaxation.as_ref());
    let memory_note = if limit.includes_memory {
        ""
    } else {
        "; memory term of a non-Prony kernel not included"
    };
    match (scene.history, limit.k_max) {
        (viscontact::scene::History::Implicit, _) => {
            println!("stability  implicit history: unconditionally stable")
        }
        (_, Some(k)) => println!(
            "stability  left endpoint scheme stable for k ≤ {k:.6e} (k/limit = {:.3}{memory_note})",
            scene.k() / k
        ),
        (_, None) => println!("stability  no explicit elastic or memory term: no step limit"),
    }
    let history_bytes = match &scene.relaxation {
        Some(viscontact::scene::Kernel::Prony(t)) => t.len() * disc.n_free * 8,
        Some(_) => (scene.steps + 1) * disc.n_free * 8,
        None => 0,
    };
    println!(
        "memory     history state ≈ {:.1} MB",
        history_bytes as f64 / 1e6
    );
    if disc.contact_kink_deg > 1.0 {
        println!(
            "warning    the contact boundary bends by up to {:.1}° at a node; nodal normals average the facets there",
            disc.contact_kink_deg
        );
    }
    Ok(())
}

fn mesh_info(path: &std::path::Path, json: bool) -> Result<()> {
    let mesh = Mesh::read(path)?;
    let q = mesh.quality();
    let groups: Vec<serde_json::Value> = mesh
        .groups
        .iter()
        .map(|g| {
            let length: f64 = g.facets.iter().map(|f| mesh.facet_length(*f)).sum();
            serde_json::json!({
                "name": Mesh::display_name(g),
                "tag": g.tag,
                "dim": g.dim,
                "elements": if g.dim == 1 { g.facets.len() } else { g.cells.len() },
                "nodes": mesh.group_nodes(g).len(),
                "length": if g.dim == 1 { Some(length) } else { None },
            })
        })
        .collect();
    if json {
        let v = serde_json::json!({
            "file": path.display().to_string(),
            "nodes": mesh.nodes.len(),
            "triangles": mesh.triangles.len(),
            "reoriented": mesh.flipped,
            "groups": groups,
            "quality": {
                "min_angle_deg": q.min_angle_deg,
                "max_aspect_ratio": q.max_aspect_ratio,
                "min_area": q.min_area,
                "max_area": q.max_area,
            }
        });
        println!("{}", serde_json::to_string_pretty(&v).expect("json"));
        return Ok(());
    }
    println!("{}", path.display());
    println!(
        "  {} nodes, {} triangles ({} reoriented to counter-clockwise)",
        mesh.nodes.len(),
        mesh.triangles.len(),
        mesh.flipped
    );
    println!("  physical groups:");
    for g in &groups {
        println!(
            "    {:<10} tag {:<4} dim {}  {:>7} {}  {:>7} nodes{}",
            g["name"].as_str().unwrap_or(""),
            g["tag"],
            g["dim"],
            g["elements"],
            if g["dim"] == 1 { "edges" } else { "cells" },
            g["nodes"],
            g["length"]
                .as_f64()
                .map(|l| format!("  length {l:.6}"))
                .unwrap_or_default()
        );
    }
    println!(
        "  quality: min angle {:.2}°, max aspect ratio {:.3}, area {:.3e} .. {:.3e}",
        q.min_angle_deg, q.max_aspect_ratio, q.min_area, q.max_area
    );
    Ok(())
}
