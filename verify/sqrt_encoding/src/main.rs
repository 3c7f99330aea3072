//! ns per call of the landmark observation and its Jacobian (range needs a
//! square root) with the generated crate's `math::sqrt`, and of libm's
//! `sqrt` alone against `math::sqrt` alone, on 300,000 random arguments,
//! timed in turns by thread CPU time (median and range of 15 rounds).
//! With `dirty`, the upper halves of a vector register are left dirty before
//! each round, as AVX code that does not end in `vzeroupper` leaves them:
//! there a legacy-SSE instruction (libm's) waits on them, a VEX one does not.
use kinegen_generated::{math, unicycle_ekf as uc};
use std::hint::black_box;

fn cpu_ns() -> f64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a valid clock id and a live timespec
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 * 1e9 + t.tv_nsec as f64
}

fn dirty_upper() {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    // SAFETY: writes only the named register, which is declared clobbered
    unsafe {
        std::arch::asm!("vpcmpeqd ymm9, ymm9, ymm9", out("ymm9") _)
    };
}

type Case<'a> = (&'a str, &'a dyn Fn(f64, f64, f64) -> f64);

fn main() {
    let dirty = std::env::args().any(|a| a == "dirty");
    // a fixed linear congruential sequence: the same arguments in every build
    let mut s = 0x2545f4914f6cdd1du64;
    let mut next = move || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 * 20.0 - 10.0
    };
    let args: Vec<(f64, f64, f64)> = (0..300_000).map(|_| (next(), next(), next())).collect();
    let landmark = |x: f64, y: f64, t: f64| {
        let (pose, lm) = ([x, y, t], [y, t]);
        uc::obs_landmark(&pose, &[0.0; 2], &[1.0], &lm)[0]
            + uc::obs_landmark_jac_x(&pose, &[0.0; 2], &[1.0], &lm)[0][0]
    };
    let cases: [Case; 3] = [
        ("landmark h + H_x (math::sqrt)", &landmark),
        ("math::sqrt alone", &|x: f64, y: f64, _| math::sqrt(x * x + y)),
        ("libm::sqrt alone", &|x: f64, y: f64, _| libm::sqrt(x * x + y)),
    ];
    let mut times = vec![Vec::new(); cases.len()];
    let mut sink = 0.0;
    for _ in 0..15 {
        for (case, t) in cases.iter().zip(&mut times) {
            let f = black_box(case.1);
            if dirty {
                dirty_upper();
            }
            let start = cpu_ns();
            for &(x, y, z) in &args {
                sink += f(black_box(x), y, z);
            }
            t.push((cpu_ns() - start) / args.len() as f64);
        }
    }
    black_box(sink);
    let avx = cfg!(target_feature = "avx");
    println!("build: {}; upper halves {}", if avx { "AVX (native)" } else { "generic x86-64" },
        if dirty { "dirty" } else { "clean" });
    for ((name, _), t) in cases.iter().zip(&mut times) {
        t.sort_by(f64::total_cmp);
        println!("  {name:32} {:6.1} ns per call (range {:.1}-{:.1})", t[7], t[0], t[14]);
    }
}
