//! `cargo bench -p kinegen-peers`: kinegen's generated kernels against CasADi's
//! generated C and wrenfold's generated Rust for the same math (issue #13's
//! table), in one run, on the same 300,000 random inputs: median ns per call
//! over 9 repetitions taken in turns, and the ratio kinegen / best peer (below 1: kinegen
//! faster). Before timing, the outputs are checked to agree within 1e-9
//! (relative to the output's scale) wherever |omega dt| > 0.05: the peers'
//! exact step is the plain closed form, which loses digits to cancellation near
//! omega = 0 (kinegen switches to a series there).
//!
//! Every output the peers give is kept, on every side: each of kinegen's output arrays goes
//! through its own `black_box`, the peers' outputs are written through `&mut`
//! and their references boxed. Not the whole output tuple at once: boxing a
//! by-value tuple copies it to a stack slot first, which cost about 3 ns a
//! call whichever kernel made it (the two separate landmark kernels, boxed as
//! one tuple: 22.5 -> 25.5 ns), and made the fused landmark kernel look slower
//! than its two parts.
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
const REPS: usize = 9;

/// Median ns per input of each of `runs`, timed in turns (one repetition of
/// each, then the next round), so that a change of clock speed or load during
/// the benchmark touches every side alike rather than whichever ran then.
fn race<const K: usize>(inputs: usize, mut runs: [&mut dyn FnMut() -> f64; K]) -> [f64; K] {
    let mut rounds = [[0.0; K]; REPS];
    for round in rounds.iter_mut() {
        for (k, run) in runs.iter_mut().enumerate() {
            let s = Instant::now();
            black_box(run());
            round[k] = s.elapsed().as_secs_f64() * 1e9 / inputs as f64;
        }
    }
    std::array::from_fn(|k| {
        let mut v: Vec<f64> = rounds.iter().map(|r| r[k]).collect();
        v.sort_by(f64::total_cmp);
        v[REPS / 2]
    })
}

fn row(label: &str, ours: f64, casadi: f64, wrenfold: f64) {
    println!(
        "{label:<44} {ours:>9.1} {casadi:>9.1} {wrenfold:>9.1} {:>8.2}",
        ours / casadi.min(wrenfold)
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
        "{:<44} {:>9} {:>9} {:>9} {:>8}",
        "kernel (ns per call)", "kinegen", "CasADi", "wrenfold", "ratio"
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
        let ours_twist = black_box(dd::twist(u, p));
        if (ours_twist[2] * dt).abs() <= 0.05 {
            continue;
        }
        ca.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
        let a = black_box(dd::step_exact(x, u, w, p, *dt));
        let jx: Vec<f64> = dd::step_exact_jac_x(x, u, w, p, *dt).concat();
        let jp: Vec<f64> = dd::step_exact_jac_p(x, u, w, p, *dt).concat();
        worst = worst
            .max(disagreement(&a, &ca.dense(0)))
            .max(disagreement(&jx, &ca.dense(1)))
            .max(disagreement(&jp, &ca.dense(2)));
        let (mut wa, mut wx, mut wp) = (
            Out::<3, 1>::default(),
            Out::<3, 3>::default(),
            Out::default(),
        );
        wrenfold::dd_step(
            &Col(x),
            &Col(u),
            &Col(w),
            &Col(p),
            *dt,
            &mut wa,
            &mut wx,
            &mut wp,
        );
        worst = worst
            .max(disagreement(&a, &wa.flat()))
            .max(disagreement(&jx, &wx.flat()))
            .max(disagreement(&jp, &wp.flat()));
    }
    assert!(
        worst < 1e-9,
        "diff_drive step: kinegen and a peer disagree by {worst:.1e}"
    );
    let mut ours = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                black_box(dd::step_exact(x, u, w, p, dt))[0]
                    + black_box(dd::step_exact_jac_x(x, u, w, p, dt))[0][2]
                    + black_box(dd::step_exact_jac_p(x, u, w, p, dt))[1][0]
            })
            .sum()
    };
    let mut theirs = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, dt));
                ca.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
                ca.out[0][0] + ca.out[1][0] + ca.out[2][0]
            })
            .sum()
    };
    let (mut wa, mut wx, mut wp) = (
        Out::<3, 1>::default(),
        Out::<3, 3>::default(),
        Out::default(),
    );
    let mut wren = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                wrenfold::dd_step(
                    &Col(x),
                    &Col(u),
                    &Col(w),
                    &Col(p),
                    dt,
                    &mut wa,
                    &mut wx,
                    &mut wp,
                );
                black_box((&wa, &wx, &wp));
                wa.0[0][0] + wx.0[0][2] + wp.0[1][0]
            })
            .sum()
    };
    // the same three outputs from the fused kernel, which shares their work
    let mut fused = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                let (a, b, c) = dd::step_exact_with_jac_p(x, u, w, p, dt);
                black_box(a)[0] + black_box(b)[0][2] + black_box(c)[1][0]
            })
            .sum()
    };
    let [ours, theirs, wren, fused] = race(N, [&mut ours, &mut theirs, &mut wren, &mut fused]);
    row("diff_drive step_exact + jac_x + jac_p", ours, theirs, wren);
    row(
        "diff_drive step_exact_with_jac_p (fused)",
        fused,
        theirs,
        wren,
    );

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
        let (mut h, mut hx) = (Out::<2, 1>::default(), Out::<2, 3>::default());
        wrenfold::uc_landmark(&Col(x), &Col(u), &Col(p), &Col(l), &mut h, &mut hx);
        worst = worst.max(disagreement(&uc::obs_landmark(x, u, p, l), &h.flat()));
        worst = worst.max(disagreement(
            &uc::obs_landmark_jac_x(x, u, p, l).concat(),
            &hx.flat(),
        ));
    }
    assert!(
        worst < 1e-9,
        "landmark: kinegen and a peer disagree by {worst:.1e}"
    );
    let mut ours = || {
        inputs
            .iter()
            .map(|(x, u, p, l)| {
                let (x, u, p, l) = black_box((x, u, p, l));
                black_box(uc::obs_landmark(x, u, p, l))[0]
                    + black_box(uc::obs_landmark_jac_x(x, u, p, l))[1][2]
            })
            .sum()
    };
    let mut theirs = || {
        inputs
            .iter()
            .map(|(x, u, p, l)| {
                let (x, u, p, l) = black_box((x, u, p, l));
                ca.call(&[x.as_ptr(), u.as_ptr(), p.as_ptr(), l.as_ptr()]);
                ca.out[0][0] + ca.out[1][0]
            })
            .sum()
    };
    let (mut h, mut hx) = (Out::<2, 1>::default(), Out::<2, 3>::default());
    let mut wren = || {
        inputs
            .iter()
            .map(|(x, u, p, l)| {
                let (x, u, p, l) = black_box((x, u, p, l));
                wrenfold::uc_landmark(&Col(x), &Col(u), &Col(p), &Col(l), &mut h, &mut hx);
                black_box((&h, &hx));
                h.0[0][0] + hx.0[1][2]
            })
            .sum()
    };
    // the same two outputs from the fused kernel (one call, as an EKF update
    // makes it); its H_p, constant zeros the peers do not output, is left to
    // the optimiser as a caller that does not read it leaves it
    let mut fused = || {
        inputs
            .iter()
            .map(|(x, u, p, l)| {
                let (x, u, p, l) = black_box((x, u, p, l));
                let (h, hx, _) = uc::obs_landmark_linearized(x, u, p, l);
                black_box(h)[0] + black_box(hx)[1][2]
            })
            .sum()
    };
    let [ours, theirs, wren, fused] = race(N, [&mut ours, &mut theirs, &mut wren, &mut fused]);
    row("unicycle_ekf obs_landmark + jac_x", ours, theirs, wren);
    row(
        "unicycle_ekf obs_landmark_linearized (fused)",
        fused,
        theirs,
        wren,
    );

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
        let ours_twist = black_box(oc::twist(u, p));
        worst_tw = worst_tw.max(disagreement(&ours_twist, &tw.dense(0)));
        let mut wt = Out::<3, 1>::default();
        wrenfold::oc_twist(&Col(u), &Col(p), &mut wt);
        worst_tw = worst_tw.max(disagreement(&ours_twist, &wt.flat()));
        if (ours_twist[2] * dt).abs() > 0.05 {
            st.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
            worst_st = worst_st.max(disagreement(&oc::step_exact(x, u, w, p, *dt), &st.dense(0)));
            worst_st = worst_st.max(disagreement(
                &oc::step_exact_jac_p(x, u, w, p, *dt).concat(),
                &st.dense(1),
            ));
            let (mut ws, mut wp) = (Out::<3, 1>::default(), Out::<3, 12>::default());
            wrenfold::oc_step(&Col(x), &Col(u), &Col(w), &Col(p), *dt, &mut ws, &mut wp);
            worst_st = worst_st.max(disagreement(&oc::step_exact(x, u, w, p, *dt), &ws.flat()));
            worst_st = worst_st.max(disagreement(
                &oc::step_exact_jac_p(x, u, w, p, *dt).concat(),
                &wp.flat(),
            ));
        }
    }
    assert!(
        worst_tw < 1e-9 && worst_st < 1e-9,
        "omni_caster: disagreement {worst_tw:.1e} (twist), {worst_st:.1e} (step)"
    );
    let mut ours = || {
        inputs
            .iter()
            .map(|(_, u, _, p, _)| black_box(oc::twist(black_box(u), black_box(p)))[2])
            .sum()
    };
    let mut theirs = || {
        inputs
            .iter()
            .map(|(_, u, _, p, _)| {
                let (u, p) = black_box((u, p));
                tw.call(&[u.as_ptr(), p.as_ptr()]);
                tw.out[0][2]
            })
            .sum()
    };
    let mut wt = Out::<3, 1>::default();
    let mut wren = || {
        inputs
            .iter()
            .map(|(_, u, _, p, _)| {
                wrenfold::oc_twist(&Col(black_box(u)), &Col(black_box(p)), &mut wt);
                black_box(&wt);
                wt.0[2][0]
            })
            .sum()
    };
    let [ours, theirs, wren] = race(N, [&mut ours, &mut theirs, &mut wren]);
    row("omni_caster twist (least squares)", ours, theirs, wren);
    let mut ours = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                black_box(oc::step_exact(x, u, w, p, dt))[0]
                    + black_box(oc::step_exact_jac_p(x, u, w, p, dt))[1][0]
            })
            .sum()
    };
    let mut theirs = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, dt));
                st.call(&[x.as_ptr(), u.as_ptr(), w.as_ptr(), p.as_ptr(), dt]);
                st.out[0][0] + st.out[1][0]
            })
            .sum()
    };
    let (mut ws, mut wp) = (Out::<3, 1>::default(), Out::<3, 12>::default());
    let mut wren = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                wrenfold::oc_step(&Col(x), &Col(u), &Col(w), &Col(p), dt, &mut ws, &mut wp);
                black_box((&ws, &wp));
                ws.0[0][0] + wp.0[1][0]
            })
            .sum()
    };
    // the fused kernel computes F_x too, which the peers do not
    let mut fused = || {
        inputs
            .iter()
            .map(|(x, u, w, p, dt)| {
                let (x, u, w, p, dt) = black_box((x, u, w, p, *dt));
                let (a, b, c) = oc::step_exact_with_jac_p(x, u, w, p, dt);
                black_box(a)[0] + black_box(b)[0][0] + black_box(c)[1][0]
            })
            .sum()
    };
    let [ours, theirs, wren, fused] = race(N, [&mut ours, &mut theirs, &mut wren, &mut fused]);
    row("omni_caster step_exact + jac_p", ours, theirs, wren);
    row(
        "omni_caster step_exact_with_jac_p (fused, +F_x)",
        fused,
        theirs,
        wren,
    );
}
