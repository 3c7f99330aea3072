//! Compiles CasADi's generated C (casadi/, written by
//! `python3 verify/casadi/reference.py --emit-c verify/peers/casadi`) with the
//! `cc` crate at -O3, as a C user of CasADi would.
fn main() {
    println!("cargo:rerun-if-changed=casadi/casadi_kernels.c");
    cc::Build::new()
        .file("casadi/casadi_kernels.c")
        .opt_level(3)
        .warnings(false)
        .compile("casadi_kernels");
}
