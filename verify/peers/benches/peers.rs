//! `cargo bench -p kinegen-peers`: kinegen's generated kernels against CasADi's
//! generated C for the same math (issue #13's table), in one run, on the same
//! 300,000 random inputs: median ns per call over 7 repetitions, and the ratio
//! kinegen / CasADi (below 1: kinegen faster). Before timing, the outputs are
//! checked to agree within 1e-9 (relative to the output's scale) wherever
//! |omega dt| > 0.05: CasADi's exact step is the plain closed form, which loses
//! digits to cancellation near omega = 0 (kinegen switches to a series there).
//!
//! Both sides are compiled for the generic target (C at -O3 by the `cc` crate,
//! Rust at the bench profile). For host-tuned code on both sides run with
//! RUSTFLAGS="-C target-cpu=native" CFLAGS="-march=native".
use kinegen_generated::{diff_drive as dd, omni_caster as oc, unicycle_ekf as uc};
use kinegen_peers::*;
use rand::{Rng, SeedableRng};
use std::hint::black_box;
use std::time::Instant;

const N: usize = 300_000;
const REPS: usize = 7;

fn median_ns(inputs: usize, mut run: impl FnMut() -> f64) -> f64 {
    let mut t: Vec<f64> = (0..REPS)
        .map(|_| {
            let s = Instant::now();
            black_box(run());
            s.elapsed().as_secs_f64() * 1e9 / inputs as f64
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[REPS / 2]
}

fn row(label: &str, ours: f64, casadi: f64) {
    println!(
        "{label:<44} {ours:>9.1} {casadi:>9.1} {:>8.2}",
        ours / casadi
    );
}

/// Largest |a - b| / max(scale of the output, 1e-300) over the entries.
fn disagreement(a: &[f64], b: &[f64]) -> f64 {
    let scale = a
        .iter()
        .chain(b)
        .fold(0.0f64, |m, v| m.max(v.abs()))
        .max(1e-300);
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs() / scale))
}

fn uniform<const K: usize>(rng: &mut rand::rngs::SmallRng, lo: f64, hi: f64) -> [f64; K] {
    std::array::from_fn(|_| rng.gen_range(lo..hi))
}

fn main() {
    let mut rng = rand::rngs::SmallRng::seed_from_u64(13);
    println!(
        "{:<44} {:>9} {:>9} {:>8}",
        "kernel (ns per call)", "kinegen", "CasADi", "ratio"
    );

    // diff_drive: step_exact + jac_x + jac_p
    type DdIn = ([f64; 3], [f64; 2], [f64; 2], [f64; 5], f64);
    let inputs: Vec<DdIn> = (0..N)
        .map(|_| {
            let mut p = dd::PARAM_NOMINAL;
            p.iter_mut().for_each(|v| *v *= rng.gen_range(0.9..1.1));
            (
                uniform(&mut rng, -2.0, 2.0),
                uniform(&mut rng, -2000.0, 2000.0),
                uniform(&mut rng, -0.01, 0.01),
                p,
                rng.gen_range(0.005..0.05),
            )
        })
        .collect();
    let mut ca = diff_drive_step();
    let mut worst = 0.0f64;
    for (x, u, w, p, dt) in inputs.iter().take(20_000) {
        let ours_twist = dd::twist(u, p);
        if (ours_twist[2] * dt).abs() <= 0.05 {
            continue;
        }
        ca.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
        let a = dd::step_exact(x, u, w, p, *dt);
        let jx: Vec<f64> = dd::step_exact_jac_x(x, u, w, p, *dt).concat();
        let jp: Vec<f64> = dd::step_exact_jac_p(x, u, w, p, *dt).concat();
        worst = worst
            .max(disagreement(&a, &ca.dense(0)))
            .max(disagreement(&jx, &ca.dense(1)))
            .max(disagreement(&jp, &ca.dense(2)));
    }
    assert!(
        worst < 1e-9,
        "diff_drive step: kinegen and CasADi disagree by {worst:.1e}"
    );
    let ours = median_ns(N, || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                dd::step_exact(x, u, w, p, dt)[0]
                    + dd::step_exact_jac_x(x, u, w, p, dt)[0][2]
                    + dd::step_exact_jac_p(x, u, w, p, dt)[1][0]
            })
            .sum()
    });
    let theirs = median_ns(N, || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, dt));
                ca.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
                ca.out[0][0] + ca.out[1][0] + ca.out[2][0]
            })
            .sum()
    });
    row("diff_drive step_exact + jac_x + jac_p", ours, theirs);
    // the same three outputs from the fused kernel, which shares their work
    let fused = median_ns(N, || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                let (a, b, c) = dd::step_exact_with_jac_p(x, u, w, p, dt);
                a[0] + b[0][2] + c[1][0]
            })
            .sum()
    });
    row("diff_drive step_exact_with_jac_p (fused)", fused, theirs);

    // unicycle_ekf: landmark range-bearing + jacobian wrt pose
    type UcIn = ([f64; 3], [f64; 2], [f64; 1], [f64; 2]);
    let inputs: Vec<UcIn> = (0..N)
        .map(|_| {
            (
                uniform(&mut rng, -5.0, 5.0),
                uniform(&mut rng, -1.0, 1.0),
                uc::PARAM_NOMINAL,
                uniform(&mut rng, -10.0, 10.0),
            )
        })
        .collect();
    let mut ca = unicycle_landmark();
    let mut worst = 0.0f64;
    for (x, u, p, l) in inputs.iter().take(20_000) {
        ca.call(&[x.as_ptr(), u.as_ptr(), p.as_ptr(), l.as_ptr()]);
        worst = worst.max(disagreement(&uc::obs_landmark(x, u, p, l), &ca.dense(0)));
        worst = worst.max(disagreement(
            &uc::obs_landmark_jac_x(x, u, p, l).concat(),
            &ca.dense(1),
        ));
    }
    assert!(
        worst < 1e-9,
        "landmark: kinegen and CasADi disagree by {worst:.1e}"
    );
    let ours = median_ns(N, || {
        inputs
            .iter()
            .map(|(x, u, p, l)| {
                let (x, u, p, l) = black_box((x, u, p, l));
                uc::obs_landmark(x, u, p, l)[0] + uc::obs_landmark_jac_x(x, u, p, l)[1][2]
            })
            .sum()
    });
    let theirs = median_ns(N, || {
        inputs
            .iter()
            .map(|(x, u, p, l)| {
                let (x, u, p, l) = black_box((x, u, p, l));
                ca.call(&[x.as_ptr(), u.as_ptr(), p.as_ptr(), l.as_ptr()]);
                ca.out[0][0] + ca.out[1][0]
            })
            .sum()
    });
    row("unicycle_ekf obs_landmark + jac_x", ours, theirs);

    // omni_caster (seed 000): least-squares twist, and step_exact + jac_p
    type OcIn = ([f64; 3], [f64; 9], [f64; 3], [f64; 12], f64);
    let inputs: Vec<OcIn> = (0..N)
        .map(|_| {
            let mut u = uniform::<9>(&mut rng, -3.0, 3.0);
            u[..3]
                .iter_mut()
                .for_each(|a| *a = rng.gen_range(-3.1..3.1)); // caster angles
            (
                uniform(&mut rng, -2.0, 2.0),
                u,
                uniform(&mut rng, -0.01, 0.01),
                oc::PARAM_NOMINAL,
                rng.gen_range(0.005..0.05),
            )
        })
        .collect();
    let mut tw = omni_caster_twist();
    let mut st = omni_caster_step();
    let (mut worst_tw, mut worst_st) = (0.0f64, 0.0f64);
    for (x, u, w, p, dt) in inputs.iter().take(20_000) {
        tw.call(&[u.as_ptr(), p.as_ptr()]);
        let ours_twist = oc::twist(u, p);
        worst_tw = worst_tw.max(disagreement(&ours_twist, &tw.dense(0)));
        if (ours_twist[2] * dt).abs() > 0.05 {
            st.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
            worst_st = worst_st.max(disagreement(&oc::step_exact(x, u, w, p, *dt), &st.dense(0)));
            worst_st = worst_st.max(disagreement(
                &oc::step_exact_jac_p(x, u, w, p, *dt).concat(),
                &st.dense(1),
            ));
        }
    }
    assert!(
        worst_tw < 1e-9 && worst_st < 1e-9,
        "omni_caster: disagreement {worst_tw:.1e} (twist), {worst_st:.1e} (step)"
    );
    let ours = median_ns(N, || {
        inputs
            .iter()
            .map(|(_, u, _, p, _)| oc::twist(black_box(u), black_box(p))[2])
            .sum()
    });
    let theirs = median_ns(N, || {
        inputs
            .iter()
            .map(|(_, u, _, p, _)| {
                let (u, p) = black_box((u, p));
                tw.call(&[u.as_ptr(), p.as_ptr()]);
                tw.out[0][2]
            })
            .sum()
    });
    row("omni_caster twist (least squares)", ours, theirs);
    let ours = median_ns(N, || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                oc::step_exact(x, u, w, p, dt)[0] + oc::step_exact_jac_p(x, u, w, p, dt)[1][0]
            })
            .sum()
    });
    let theirs = median_ns(N, || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, dt));
                st.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
                st.out[0][0] + st.out[1][0]
            })
            .sum()
    });
    row("omni_caster step_exact + jac_p", ours, theirs);
}
