//! `cargo bench -p kinegen-peers`: kinegen's generated kernels against every
//! peer build pip and cargo install here (see `kinegen_peers::sides`), in one
//! run, on the same inputs, printed as the README's markdown table.
//!
//! Fairness, point by point:
//! - Every side is called through one opaque function pointer with the same
//!   signature ([`Kernel`]): the same call overhead for all, no side inlined
//!   into the timing loop. Every output a side computes is written to memory.
//! - The inputs come from how robots move (`kinegen_peers::inputs`: real logs
//!   where present, simulated random driving), in their order, and are
//!   reported per class as well: the realistic mix, the steps under the
//!   series switch (|omega dt| <= 0.05; nearly all of them at the logs' own
//!   rates), and steps above it (the same motions over 20 times longer steps).
//! - Every peer switches to a series near omega dt = 0 with its own
//!   conditional (the same switch and order as kinegen), so every side is
//!   accurate there and none is timed on a NaN path.
//! - kinegen is timed in its default `no_std` build (libm, as on firmware)
//!   and with `std`; the ratio that counts is the default build's against
//!   the fastest peer build, whichever it is on that row.
//! - Before timing, each side's outputs are checked to agree with kinegen's
//!   within 1e-9 of each output's scale on every class; a side that does not
//!   is reported and left out of the ratios.
//! - Median of 9 rounds; in each round every side runs once, in turns, so a
//!   change of clock speed touches every side alike.
//!
//! The last rows time the analytic parameter Jacobian against central
//! differences of the step (two steps per parameter), both kinegen no_std.
use kinegen_generated::{diff_drive as dd, omni_caster as oc};
use kinegen_peers::inputs::{self, Sample};
use kinegen_peers::{disagreement, sides, Args, Kernel, Layout, Model, Row, Side};
use rand::SeedableRng;
use std::hint::black_box;
use std::time::Instant;

/// Motions drawn; each class of a step row is at most this long.
const N: usize = 90_000;
const REPS: usize = 9;

/// ns per call of `k` over `args`.
fn time(k: Kernel, args: &[Args], out: &mut [f64]) -> f64 {
    let k = black_box(k);
    let o = out.as_mut_ptr();
    let start = Instant::now();
    for a in args {
        // SAFETY: `a` points into live samples of the row's model and `out`
        // holds more than the row's outputs
        unsafe { k(black_box(a), o) };
    }
    black_box(out);
    start.elapsed().as_secs_f64() * 1e9 / args.len() as f64
}

/// Median ns per call of each kernel, timed in turns.
fn race(kernels: &[Kernel], args: &[Args]) -> Vec<f64> {
    let mut out = vec![0.0; 64];
    let mut rounds = vec![Vec::new(); kernels.len()];
    for _ in 0..REPS {
        for (k, r) in kernels.iter().zip(&mut rounds) {
            r.push(time(*k, args, &mut out));
        }
    }
    rounds
        .into_iter()
        .map(|mut r| {
            r.sort_by(f64::total_cmp);
            r[REPS / 2]
        })
        .collect()
}

/// The input classes of a row: the realistic mix, and for a step each side
/// of the series switch. At the logs' own rates nearly every step is under
/// the switch, so the steps above it come from the same motions over 20
/// times longer steps (a filter predicting only to sightings 0.2-1 s apart),
/// those that turn by more than 0.05 rad.
fn classes<'a>(
    row: Row,
    samples: &'a [Sample],
    long: &'a [Sample],
) -> Vec<(&'static str, Vec<Args>, f64)> {
    let all: Vec<Args> = samples.iter().map(Sample::args).collect();
    if !row.steps() {
        return vec![("mix", all, 1.0)];
    }
    let series: Vec<Args> = samples
        .iter()
        .filter(|s| s.turn.abs() <= 0.05)
        .map(Sample::args)
        .collect();
    let share = series.len() as f64 / samples.len() as f64;
    let closed: Vec<Args> = long
        .iter()
        .filter(|s| s.turn.abs() > 0.05)
        .map(Sample::args)
        .collect();
    vec![
        ("mix", all, 1.0),
        ("series", series, share),
        ("closed form, 20x steps", closed, 1.0 - share),
    ]
}

fn cell(ns: Option<f64>) -> String {
    ns.map_or("-".to_string(), |v| format!("{v:.1}"))
}

/// One row of the table per class: every side's ns per call and the ratios.
fn bench_row(row: Row, samples: &[Sample], long: &[Sample], sides: &[Side]) {
    let classes = classes(row, samples, long);
    let reference = (sides[0].kernel)(row).expect("kinegen has every kernel");
    // a side counts if it has the kernel and agrees with kinegen on every class
    let usable: Vec<Option<Kernel>> = sides
        .iter()
        .map(|side| {
            let k = (side.kernel)(row)?;
            let worst = classes
                .iter()
                .map(|(_, args, _)| {
                    disagreement(
                        row,
                        (reference, Layout::RowMajor),
                        (k, side.layout),
                        &args[..args.len().min(5_000)],
                    )
                })
                .fold(0.0, f64::max);
            if worst > 1e-9 {
                eprintln!(
                    "{}: {} disagrees with kinegen by {worst:.1e}: left out",
                    row.label(),
                    side.name
                );
                return None;
            }
            Some(k)
        })
        .collect();
    let timed: Vec<Kernel> = usable.iter().flatten().copied().collect();
    for (class, args, share) in &classes {
        if args.is_empty() {
            continue;
        }
        let mut ns = race(&timed, args).into_iter();
        let per_side: Vec<Option<f64>> = usable.iter().map(|k| k.and_then(|_| ns.next())).collect();
        let best_peer = sides
            .iter()
            .zip(&per_side)
            .filter(|(s, _)| !s.kinegen)
            .filter_map(|(_, t)| *t)
            .fold(f64::INFINITY, f64::min);
        let ratio = |t: Option<f64>| t.map_or("-".to_string(), |t| format!("{:.2}", t / best_peer));
        let inputs = match *class {
            "mix" => "mix".to_string(),
            _ => format!("{class} ({:.2}% of the mix)", share * 100.0),
        };
        println!(
            "| {} | {inputs} | {} | {} | {} |",
            row.label(),
            per_side
                .iter()
                .map(|t| cell(*t))
                .collect::<Vec<_>>()
                .join(" | "),
            ratio(per_side[0]),
            ratio(per_side[1]),
        );
    }
}

/// # Safety (of the two kernels below)
/// `a` points at a diff_drive (omni_caster) sample and `o` at 15 (36) f64.
unsafe extern "C" fn dd_jac_p_central(a: &Args, o: *mut f64) {
    let (x, u, w) = (
        &*(a.x as *const [f64; 3]),
        &*(a.u as *const [f64; 2]),
        &*(a.w as *const [f64; 2]),
    );
    let p = *(a.p as *const [f64; 5]);
    o.cast::<[[f64; 5]; 3]>()
        .write_unaligned(central(p, |q| dd::step_exact(x, u, w, q, a.dt)));
}

unsafe extern "C" fn oc_jac_p_central(a: &Args, o: *mut f64) {
    let (x, u, w) = (
        &*(a.x as *const [f64; 3]),
        &*(a.u as *const [f64; 9]),
        &*(a.w as *const [f64; 3]),
    );
    let p = *(a.p as *const [f64; 12]);
    o.cast::<[[f64; 12]; 3]>()
        .write_unaligned(central(p, |q| oc::step_exact(x, u, w, q, a.dt)));
}

/// d step / d p by central differences, a relative step of 1e-6 per parameter.
#[inline(always)]
fn central<const P: usize>(p: [f64; P], step: impl Fn(&[f64; P]) -> [f64; 3]) -> [[f64; P]; 3] {
    let mut j = [[0.0; P]; 3];
    for k in 0..P {
        let h = 1e-6 * p[k].abs().max(1e-3);
        let (mut hi, mut lo) = (p, p);
        hi[k] += h;
        lo[k] -= h;
        let (f1, f0) = (step(&hi), step(&lo));
        for r in 0..3 {
            j[r][k] = (f1[r] - f0[r]) / (2.0 * h);
        }
    }
    j
}

fn main() {
    let mut rng = rand::rngs::SmallRng::seed_from_u64(39);
    let (motions, sources) = inputs::motions(N, &mut rng);
    let sides = sides();
    println!(
        "inputs: {}",
        sources
            .used
            .iter()
            .map(|(n, k)| format!("{k} steps of {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for m in &sources.missing {
        println!("left out: {m}");
    }
    if !kinegen_peers::WRENFOLD_CPP {
        println!("left out: wrenfold C++ (its span headers were not found at build time: pip install wrenfold)");
    }
    if !kinegen_peers::SYMFORCE_CPP {
        println!("left out: SymForce C++ (Eigen's headers were not found at build time: apt-get install libeigen3-dev)");
    }
    println!("left out: SymForce Rust (its 0.12 generator's code for these kernels does not compile or computes something else: verify/peers/symforce_kernels.py)\n");
    println!(
        "| kernel (ns per call) | inputs | {} | kinegen no_std / best peer | kinegen std / best peer |",
        sides.iter().map(|s| s.name).collect::<Vec<_>>().join(" | ")
    );
    println!("|---|---|{}---|---|", "---|".repeat(sides.len()));
    let samples = |m: Model| inputs::samples(m, &motions, 7);
    let (dd_s, uc_s, oc_s) = (
        samples(Model::DiffDrive),
        samples(Model::Unicycle),
        samples(Model::OmniCaster),
    );
    let long: Vec<inputs::Motion> = motions
        .iter()
        .map(|m| inputs::Motion {
            dt: m.dt * 20.0,
            ..*m
        })
        .collect();
    let (dd_l, oc_l) = (
        inputs::samples(Model::DiffDrive, &long, 8),
        inputs::samples(Model::OmniCaster, &long, 8),
    );
    for row in Row::ALL {
        let (s, l) = match row.model() {
            Model::DiffDrive => (&dd_s, &dd_l),
            Model::Unicycle => (&uc_s, &uc_s),
            Model::OmniCaster => (&oc_s, &oc_l),
        };
        bench_row(row, s, l, &sides);
    }
    println!("\n| parameter Jacobian, kinegen no_std (ns per call, mix) | analytic | central differences | speed-up |");
    println!("|---|---|---|---|");
    for (row, s, cd) in [
        (Row::DdJacP, &dd_s, dd_jac_p_central as Kernel),
        (Row::OcJacP, &oc_s, oc_jac_p_central as Kernel),
    ] {
        let args: Vec<Args> = s.iter().map(Sample::args).collect();
        let analytic = (sides[0].kernel)(row).unwrap();
        let worst = disagreement(
            row,
            (analytic, Layout::RowMajor),
            (cd, Layout::RowMajor),
            &args,
        );
        let t = race(&[analytic, cd], &args);
        println!(
            "| {} | {:.1} | {:.1} | {:.1}x (agree within {worst:.0e}) |",
            row.label(),
            t[0],
            t[1],
            t[1] / t[0]
        );
    }
}
