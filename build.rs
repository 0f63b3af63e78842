//! Compiles the PETSc shim (src/petsc/shim.c) when the `petsc` feature is on; does nothing
//! otherwise. The include and library flags come from pkg-config: PETSc's file (`PETSc` on
//! Debian) and MPI's (`mpi`: PETSc's headers include mpi.h, which Debian keeps in Open
//! MPI's own directory).

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "petsc")]
    petsc::build();
}

#[cfg(feature = "petsc")]
mod petsc {
    use std::process::Command;

    /// The packages' flags, split into include paths, library paths and libraries.
    fn pkg_config(packages: &[&str]) -> (Vec<String>, Vec<String>, Vec<String>) {
        let out = Command::new("pkg-config")
            .arg("--cflags")
            .arg("--libs")
            .args(packages)
            .output()
            .unwrap_or_else(|e| panic!("pkg-config could not be run ({e}): {}", HELP));
        if !out.status.success() {
            panic!(
                "pkg-config {}: {}\n{}",
                packages.join(" "),
                String::from_utf8_lossy(&out.stderr).trim(),
                HELP
            );
        }
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        let (mut inc, mut dirs, mut libs) = (Vec::new(), Vec::new(), Vec::new());
        for flag in text.split_whitespace() {
            if let Some(p) = flag.strip_prefix("-I") {
                inc.push(p.to_string());
            } else if let Some(p) = flag.strip_prefix("-L") {
                dirs.push(p.to_string());
            } else if let Some(l) = flag.strip_prefix("-l") {
                libs.push(l.to_string());
            }
        }
        (inc, dirs, libs)
    }

    const HELP: &str = "the `petsc` feature needs PETSc's development files: on Debian 12, \
        `apt-get install --no-install-recommends petsc-dev`";

    pub fn build() {
        println!("cargo:rerun-if-changed=src/petsc/shim.c");
        println!("cargo:rerun-if-env-changed=PKG_CONFIG_PATH");
        let (inc, dirs, libs) = pkg_config(&["PETSc", "mpi"]);
        let mut cc = cc::Build::new();
        cc.file("src/petsc/shim.c").warnings(true);
        for i in &inc {
            cc.include(i);
        }
        // PetscInt must be 32 bits: src/petsc/mod.rs declares it as i32.
        cc.define("VC_REQUIRE_32BIT_INDICES", None);
        cc.compile("viscontact_petsc_shim");
        for d in &dirs {
            println!("cargo:rustc-link-search=native={d}");
            // The shared libraries are found at run time too without LD_LIBRARY_PATH.
            println!("cargo:rustc-link-arg=-Wl,-rpath,{d}");
        }
        for l in &libs {
            println!("cargo:rustc-link-lib={l}");
        }
    }
}
