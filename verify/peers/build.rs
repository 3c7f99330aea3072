//! Compiles the C and C++ peers at -O3, as their users would: CasADi's
//! generated C (casadi/, written by `python3 verify/casadi/reference.py
//! --emit-c verify/peers/casadi`), wrenfold's generated C++ (wrenfold/,
//! written by `verify/peers/wrenfold_kernels.py`) and SymForce's (symforce/,
//! `verify/peers/symforce_kernels.py`), each behind the benchmark's calling
//! convention (the `adapters` files).
//!
//! wrenfold's C++ needs its span headers, which `pip install wrenfold`
//! puts under Python's include directory: found by asking python3 (or given
//! as $WRENFOLD_INCLUDE). SymForce's needs Eigen's headers (Debian's
//! libeigen3-dev, or $EIGEN_INCLUDE). Without them that C++ peer is left out
//! and the benchmark says so (cfg `wrenfold_cpp` / `symforce_cpp` unset);
//! nothing else depends on them at build time.
use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    println!("cargo:rustc-check-cfg=cfg(wrenfold_cpp, symforce_cpp)");
    for f in [
        "args.h",
        "casadi/casadi_kernels.c",
        "casadi/adapters.c",
        "wrenfold/kernels.h",
        "wrenfold/adapters.cpp",
        "symforce/kernels.h",
        "symforce/adapters.cpp",
    ] {
        println!("cargo:rerun-if-changed={f}");
    }
    println!("cargo:rerun-if-env-changed=WRENFOLD_INCLUDE");
    println!("cargo:rerun-if-env-changed=CARGO_ENCODED_RUSTFLAGS");
    println!("cargo:rerun-if-env-changed=EIGEN_INCLUDE");
    // the bench prints how the C and C++ peers were built
    let march = target_cpu().map(|c| format!("-march={c}"));
    println!(
        "cargo:rustc-env=PEERS_C_MARCH={}",
        march.as_deref().unwrap_or("the compiler's default -march")
    );
    let march = march.as_deref();
    c_build(march)
        .file("casadi/adapters.c")
        .opt_level(3)
        .warnings(false)
        .compile("casadi_adapters");
    match wrenfold_include() {
        Some(include) => cpp_peer("wrenfold", &include, march),
        None => println!("cargo:warning=wrenfold's C++ headers not found (pip install wrenfold, or set WRENFOLD_INCLUDE): the benchmark leaves out wrenfold C++"),
    }
    let eigen = std::env::var_os("EIGEN_INCLUDE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("/usr/include/eigen3"));
    if eigen.join("Eigen").join("Core").is_file() {
        cpp_peer("symforce", &eigen, march);
    } else {
        println!("cargo:warning=Eigen's headers not found (apt-get install libeigen3-dev, or set EIGEN_INCLUDE): the benchmark leaves out SymForce C++");
    }
}

/// A C or C++ build for the same CPU as the Rust code beside it (`march`,
/// from [`target_cpu`]): with `-C target-cpu=native` in RUSTFLAGS (the
/// bench's native build), the peers get `-march=native` as their users'
/// native builds would. cc 1.11 reads the
/// target CPU from RUSTFLAGS but does not pass it on to the C compiler, so
/// without this the native table compared native Rust with generic C.
fn c_build(march: Option<&str>) -> cc::Build {
    let mut build = cc::Build::new();
    if let Some(flag) = march {
        build.flag(flag);
    }
    build
}

/// The `-C target-cpu` RUSTFLAGS give (the last one, as rustc takes it),
/// whether written `-C target-cpu=x` or `-Ctarget-cpu=x`.
fn target_cpu() -> Option<String> {
    let flags = std::env::var("CARGO_ENCODED_RUSTFLAGS").unwrap_or_default();
    let mut after_c = false;
    let mut cpu = None;
    for flag in flags.split('\x1f') {
        let option = if after_c {
            Some(flag)
        } else {
            flag.strip_prefix("-C")
        };
        if let Some(name) = option.and_then(|o| o.strip_prefix("target-cpu=")) {
            cpu = Some(name.to_string());
        }
        after_c = flag == "-C";
    }
    cpu
}

/// Compile `<peer>/adapters.cpp` and set cfg `<peer>_cpp`; without a C++
/// compiler the peer is left out (a warning), not the build.
fn cpp_peer(peer: &str, include: &Path, march: Option<&str>) {
    let built = c_build(march)
        .cpp(true)
        .std("c++17")
        .file(format!("{peer}/adapters.cpp"))
        .include(include)
        .opt_level(3)
        .warnings(false)
        .try_compile(&format!("{peer}_adapters"));
    match built {
        Ok(()) => println!("cargo:rustc-cfg={peer}_cpp"),
        Err(e) => println!("cargo:warning={peer}'s C++ adapters did not compile ({e}): the benchmark leaves them out"),
    }
}

/// The directory holding `wrenfold/span.h`.
fn wrenfold_include() -> Option<PathBuf> {
    let has_span = |d: &PathBuf| d.join("wrenfold").join("span.h").is_file();
    if let Some(d) = std::env::var_os("WRENFOLD_INCLUDE").map(PathBuf::from) {
        return has_span(&d).then_some(d);
    }
    let out = Command::new("python3")
        .args([
            "-c",
            "import sysconfig; print(sysconfig.get_paths()['include'])",
        ])
        .output()
        .ok()?;
    let d = PathBuf::from(String::from_utf8(out.stdout).ok()?.trim());
    has_span(&d).then_some(d)
}
