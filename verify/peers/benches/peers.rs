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
//! - Every step row comes twice. Its peers as their users write them: the
//!   chord form (x + (vx (sin(th + a) - sin th) + ...)/omega), straight
//!   where |omega| < 1e-6 rad/s, with each tool's own conditional. And
//!   accuracy-matched: the same series switch near omega dt = 0 as kinegen's,
//!   so that every side is as accurate there. A table gives each side's
//!   error near omega dt = 0 against a 50-digit reference.
//! - kinegen is timed in its default `no_std` build (libm, as on firmware)
//!   and with `std`; the ratio that counts is the default build's against
//!   the fastest peer build, whichever it is on that row.
//! - Before timing, each side's outputs are checked to agree with kinegen's
//!   within 1e-9 of each output's scale (the chord form where it is well
//!   conditioned, |omega dt| > 0.05); a side that does not is reported and
//!   left out of the ratios.
//! - Median of 9 rounds; in each round every side runs once, in turns, so a
//!   change of clock speed touches every side alike. Each round is timed in
//!   the thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`), so time the thread
//!   spent descheduled under load is not counted, in blocks of [`BLOCK`]
//!   calls whose inputs are read, untimed, just before: every side finds
//!   its inputs in cache, as in a filter, and no side is timed on the
//!   memory's speed (one measured pair of clock reads is taken off each
//!   block).
//! - The whole measurement runs in [`PROCESSES`] processes one after the
//!   other (code placement, alignment and the allocator's addresses differ
//!   between processes); every cell is the median of the processes' figures
//!   with their range, and every ratio the range of the processes' own
//!   ratios.
//! - The inputs of every row are also timed shuffled (random driving in
//!   random order: no branch predictor or cache is helped by the order of
//!   real motion).
//!
//! The last rows time the analytic parameter Jacobian against central
//! differences of the step (two steps per parameter), both kinegen no_std.
use kinegen_generated::{diff_drive as dd, omni_caster as oc};
use kinegen_peers::inputs::{self, Sample};
use kinegen_peers::{disagreement, ops, sides, Args, Kernel, Layout, Model, Row, Side};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::hint::black_box;

/// Motions drawn; each class of a step row is at most this long.
const N: usize = 90_000;
const REPS: usize = 9;

/// Processes the measurement runs in, one after the other
/// (`PEERS_PROCESSES` overrides).
const PROCESSES: usize = 3;

/// Whether row `label` is measured: every row, or those whose label holds
/// `PEERS_ROWS` (one kernel over many processes in seconds, e.g.
/// `PEERS_ROWS=obs_landmark PEERS_PROCESSES=10`: the ranges show how its
/// time varies between processes).
fn measured(label: &str) -> bool {
    std::env::var("PEERS_ROWS").map_or(true, |only| label.contains(&only))
}

/// The calling thread's CPU time, ns: what it ran, not what the clock on
/// the wall did while it waited (libc's `clock_gettime`; std has no thread
/// clock).
fn thread_cpu_ns() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid timespec for the call to fill
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0, "CLOCK_THREAD_CPUTIME_ID is not available");
    ts.tv_sec as f64 * 1e9 + ts.tv_nsec as f64
}

/// Calls timed between two reads of the clock, whose inputs are read just
/// before (untimed): 1,024 samples of the largest model hold about 400 KB,
/// within a core's L2. A filter calls its kernels on a state it has just
/// computed, in cache; timing one stream through 16 MB of inputs timed the
/// memory instead, which other tenants of a shared L3 slow in some
/// processes and not others (speed.md, "The landmark's two speeds are the
/// memory's"). `PEERS_BLOCK=0` times the whole stream at once, as before.
const BLOCK: usize = 1024;

/// The calls timed between two reads of the clock: [`BLOCK`], or every
/// call of a class where `PEERS_BLOCK` says 0 (or another size).
fn block() -> usize {
    match std::env::var("PEERS_BLOCK")
        .ok()
        .and_then(|b| b.parse().ok())
    {
        Some(0) => usize::MAX,
        Some(b) => b,
        None => BLOCK,
    }
}

/// What one pair of clock reads adds to a block's time: the median of 99
/// back-to-back pairs (the thread clock is a system call, about 0.5 us on a
/// virtual machine: 13% of a block of the fastest kernel).
fn clock_cost() -> f64 {
    let mut pairs: Vec<f64> = (0..99)
        .map(|_| {
            let start = thread_cpu_ns();
            thread_cpu_ns() - start
        })
        .collect();
    pairs.sort_by(f64::total_cmp);
    pairs[pairs.len() / 2]
}

/// How a race times its calls: the model's `lengths` (what each block's
/// inputs hold), the calls in a block, and what a pair of clock reads adds
/// to a block's time (found once a race).
struct Timing {
    lengths: [usize; 5],
    block: usize,
    clock_cost: f64,
}

/// ns per call of `k` over `args`, in the thread's CPU time, block by block
/// with each block's inputs read first.
fn time(k: Kernel, args: &[Args], t: &Timing, out: &mut [f64]) -> f64 {
    let (k, o) = (black_box(k), out.as_mut_ptr());
    let mut total = 0.0;
    for block in args.chunks(t.block) {
        // SAFETY: every sample holds its model's lengths of values
        let read: f64 = block.iter().map(|a| unsafe { a.touch(t.lengths) }).sum();
        black_box(read);
        let start = thread_cpu_ns();
        for a in block {
            // SAFETY: `a` points into live samples of the row's model and
            // `out` holds more than the row's outputs
            unsafe { k(black_box(a), o) };
        }
        total += thread_cpu_ns() - start - t.clock_cost;
    }
    black_box(out);
    total / args.len() as f64
}

/// Median ns per call of each kernel, timed in turns.
fn race(kernels: &[Kernel], args: &[Args], model: Model) -> Vec<f64> {
    let mut out = vec![0.0; 64];
    let mut rounds = vec![Vec::new(); kernels.len()];
    let timing = Timing {
        lengths: model.lengths(),
        block: block(),
        clock_cost: clock_cost(),
    };
    for _ in 0..REPS {
        for (k, r) in kernels.iter().zip(&mut rounds) {
            r.push(time(*k, args, &timing, &mut out));
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

/// The inputs of one model, owned: in time order, the same in random
/// order, the same motions over 20 times longer steps, and half of them
/// under the series switch and half over it, in random order.
struct Inputs {
    time_order: Vec<Sample>,
    random_order: Vec<Sample>,
    long: Vec<Sample>,
    halves: Vec<Sample>,
}

impl Inputs {
    fn of(time_order: Vec<Sample>, long: Vec<Sample>) -> Inputs {
        let under = time_order.iter().filter(|s| s.turn.abs() <= 0.05);
        let over: Vec<&Sample> = long.iter().filter(|s| s.turn.abs() > 0.05).collect();
        let n = over.len().min(time_order.len() / 2);
        let halves: Vec<Sample> = under
            .take(n)
            .chain(over.into_iter().take(n))
            .cloned()
            .collect();
        Inputs {
            random_order: shuffled(&time_order),
            halves: shuffled(&halves),
            time_order,
            long,
        }
    }
}

/// The input classes of a row: the realistic mix in time order and in
/// random order, and for a step each side of the series switch alone and
/// both in equal parts in random order (a filter predicting to sightings
/// at irregular intervals: the switch's branch at its least predictable).
/// At the logs' own rates nearly every step is under the switch, so the
/// steps above it come from the same motions over 20 times longer steps (a
/// filter predicting only to sightings 0.2-1 s apart), those that turn by
/// more than 0.05 rad.
fn classes(row: Row, inputs: &Inputs) -> Vec<(&'static str, Vec<Args>, f64)> {
    let args = |v: &[Sample]| v.iter().map(Sample::args).collect::<Vec<Args>>();
    let (all, shuffled) = (args(&inputs.time_order), args(&inputs.random_order));
    if !row.steps() {
        return vec![("mix", all, 1.0), ("mix, random order", shuffled, 1.0)];
    }
    let series: Vec<Args> = (inputs.time_order.iter())
        .filter(|s| s.turn.abs() <= 0.05)
        .map(Sample::args)
        .collect();
    let share = series.len() as f64 / inputs.time_order.len() as f64;
    let closed: Vec<Args> = (inputs.long.iter())
        .filter(|s| s.turn.abs() > 0.05)
        .map(Sample::args)
        .collect();
    vec![
        ("mix", all, 1.0),
        ("mix, random order", shuffled, 1.0),
        ("series", series, share),
        ("closed form, 20x steps", closed, 1.0 - share),
        ("half each side, random order", args(&inputs.halves), 1.0),
    ]
}

/// One measurement of one process: a table's row (its kernel and inputs),
/// a side, and its ns per call (None: the side lacks the kernel or was left
/// out). Written one per line, tab-separated, by a child process.
struct Record {
    row: String,
    side: String,
    ns: Option<f64>,
}

impl Record {
    fn line(&self) -> String {
        let ns = self.ns.map_or("-".to_string(), |v| format!("{v}"));
        format!("{}\t{}\t{ns}", self.row, self.side)
    }

    fn parse(line: &str) -> Option<Record> {
        let mut f = line.split('\t');
        let (row, side, ns) = (f.next()?, f.next()?, f.next()?);
        Some(Record {
            row: row.to_string(),
            side: side.to_string(),
            ns: ns.parse().ok(),
        })
    }
}

/// Every class of `row` timed on every side that has it and agrees with
/// kinegen: one record per side and class.
fn bench_row(row: Row, inputs: &Inputs, sides: &[Side]) -> Vec<Record> {
    let classes = classes(row, inputs);
    let reference = (sides[0].kernel)(row).expect("kinegen has every kernel");
    // a side counts if it has the kernel and agrees with kinegen on every class
    let usable: Vec<Option<Kernel>> = sides
        .iter()
        .map(|side| {
            let k = (side.kernel)(row)?;
            // where the row's peers must agree (the users' chord form only
            // away from omega dt = 0: its error there is the accuracy table's)
            let checked: Vec<Args> = (inputs.time_order.iter().chain(&inputs.long))
                .filter(|s| row.agrees_at(s.turn))
                .take(10_000)
                .map(Sample::args)
                .collect();
            let worst = disagreement(
                row,
                (reference, Layout::RowMajor),
                (k, side.layout),
                &checked,
            );
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
    let mut records = Vec::new();
    for (class, args, share) in &classes {
        if args.is_empty() {
            continue;
        }
        let mut ns = race(&timed, args, row.model()).into_iter();
        let inputs = match *class {
            "series" | "closed form, 20x steps" => {
                format!("{class} ({:.2}% of the mix)", share * 100.0)
            }
            _ => class.to_string(),
        };
        for (side, k) in sides.iter().zip(&usable) {
            records.push(Record {
                row: format!("{} | {inputs}", row.label()),
                side: side.name.to_string(),
                ns: k.and_then(|_| ns.next()),
            });
        }
    }
    records
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

/// The same samples in random order (a fixed seed: every side and every
/// process gets the same order), copied so that they lie in memory in that
/// order: what is timed is the order of the values (the branch predictor
/// and the series switch), not cache misses on scattered samples.
fn shuffled(samples: &[Sample]) -> Vec<Sample> {
    let mut order: Vec<usize> = (0..samples.len()).collect();
    order.shuffle(&mut rand::rngs::SmallRng::seed_from_u64(66));
    order.iter().map(|&i| samples[i].clone()).collect()
}

/// One step of the 50-digit reference: its inputs, and the pose and d pose
/// / d p it should give (row-major).
struct NearZero {
    x: Vec<f64>,
    u: Vec<f64>,
    dt: f64,
    pose: Vec<f64>,
    jac_p: Vec<f64>,
}

/// Each side's error near omega dt = 0 on the diff_drive step and its
/// parameter Jacobian, in both forms: the largest over the 13 steps of
/// verify/precision/near_zero.json (omega dt from 0 to 1, a 50-digit mpmath
/// reference), relative to each output's largest entry. A record per side,
/// its figure in place of a time.
fn accuracy(sides: &[Side]) -> Vec<Record> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../precision/near_zero.json");
    let text = std::fs::read_to_string(path).expect("verify/precision/near_zero.json");
    let doc: serde_json::Value = serde_json::from_str(&text).expect("near_zero.json is JSON");
    let num = |v: &serde_json::Value| -> f64 {
        v.as_f64()
            .or_else(|| v.as_str().and_then(|s| s.parse().ok()))
            .expect("a number")
    };
    let p: Vec<f64> = doc["params"].as_array().unwrap().iter().map(num).collect();
    let cases = doc["cases"].as_array().unwrap();
    let arrays: Vec<NearZero> = cases
        .iter()
        .map(|c| {
            let v = |k: &str| {
                c[k].as_array()
                    .unwrap()
                    .iter()
                    .map(num)
                    .collect::<Vec<f64>>()
            };
            let jac: Vec<f64> = (c["jac_p"].as_array().unwrap().iter())
                .flat_map(|r| r.as_array().unwrap().iter().map(num))
                .collect();
            NearZero {
                x: v("x"),
                u: v("u"),
                dt: num(&c["dt"]),
                pose: v("pose"),
                jac_p: jac,
            }
        })
        .collect();
    let w = [0.0; 2];
    let mut records = Vec::new();
    for row in [Row::DdStepUsers, Row::DdStep, Row::DdJacPUsers, Row::DdJacP] {
        for side in sides {
            let err = (side.kernel)(row).map(|k| {
                let mut out = vec![0.0; 64];
                let mut worst = 0.0f64;
                for case in &arrays {
                    let a = Args {
                        x: case.x.as_ptr(),
                        u: case.u.as_ptr(),
                        w: w.as_ptr(),
                        p: p.as_ptr(),
                        lm: w.as_ptr(),
                        dt: case.dt,
                    };
                    // SAFETY: the arrays hold the diff_drive kernel's inputs
                    // and `out` more than its outputs
                    unsafe { k(&a, out.as_mut_ptr()) };
                    let got = kinegen_peers::dense(row, side.layout, &out);
                    let want = if row.matched() == Row::DdStep {
                        &case.pose
                    } else {
                        &case.jac_p
                    };
                    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    for (g, r) in got.iter().zip(want) {
                        let e = if g.is_finite() {
                            (g - r).abs() / scale
                        } else {
                            f64::INFINITY
                        };
                        worst = worst.max(e);
                    }
                }
                worst
            });
            records.push(Record {
                row: format!("accuracy | {}", row.label()),
                side: side.name.to_string(),
                ns: err,
            });
        }
    }
    records
}

/// What one process measures: the inputs' provenance lines, then every
/// record.
fn measure() -> (Vec<String>, Vec<Record>) {
    let mut rng = rand::rngs::SmallRng::seed_from_u64(39);
    let (motions, sources) = inputs::motions(N, &mut rng);
    let sides = sides();
    let mut notes = vec![format!(
        "inputs: {}",
        sources
            .used
            .iter()
            .map(|(n, k)| format!("{k} steps of {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    )];
    notes.extend(sources.missing.iter().map(|m| format!("left out: {m}")));
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
    let mut records = accuracy(&sides);
    let dd = Inputs::of(dd_s.clone(), dd_l);
    let uc = Inputs::of(uc_s.clone(), uc_s.clone());
    let oc = Inputs::of(oc_s.clone(), oc_l);
    for row in Row::ALL.into_iter().filter(|r| measured(&r.label())) {
        let inputs = match row.model() {
            Model::DiffDrive => &dd,
            Model::Unicycle => &uc,
            Model::OmniCaster => &oc,
        };
        records.extend(bench_row(row, inputs, &sides));
    }
    for (row, s, cd) in [
        (Row::DdJacP, &dd_s, dd_jac_p_central as Kernel),
        (Row::OcJacP, &oc_s, oc_jac_p_central as Kernel),
    ]
    .into_iter()
    .filter(|(row, ..)| measured(&row.label()))
    {
        let args: Vec<Args> = s.iter().map(Sample::args).collect();
        let analytic = (sides[0].kernel)(row).unwrap();
        // per call: central differences lose digits where the step is small
        // (1e-9 on a parameter whose value is 0), so the worst call alone
        // would read as a wrong Jacobian
        let mut per_call: Vec<f64> = (args.iter())
            .map(|a| {
                let one = std::slice::from_ref(a);
                disagreement(
                    row,
                    (analytic, Layout::RowMajor),
                    (cd, Layout::RowMajor),
                    one,
                )
            })
            .collect();
        let (median, _, worst) = spread(&mut per_call);
        let t = race(&[analytic, cd], &args, row.model());
        let label = format!(
            "{} (apart by {median:.0e} in the median call, {worst:.0e} at worst: central differences' round-off)",
            row.what()
        );
        for (side, ns) in [("analytic", t[0]), ("central differences", t[1])] {
            records.push(Record {
                row: label.clone(),
                side: side.to_string(),
                ns: Some(ns),
            });
        }
    }
    (notes, records)
}

/// The median and the range of `v` (sorted here).
fn spread(v: &mut [f64]) -> (f64, f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0], v[v.len() - 1])
}

/// "median (lo-hi)" at `digits` decimals, or the one figure when all agree
/// to them.
fn cell(v: &mut [f64], digits: usize) -> String {
    if v.is_empty() {
        return "-".into();
    }
    let (m, lo, hi) = spread(v);
    let (lo_s, hi_s) = (format!("{lo:.digits$}"), format!("{hi:.digits$}"));
    if lo_s == hi_s {
        lo_s
    } else {
        format!("{m:.digits$} ({lo_s}-{hi_s})")
    }
}

/// Every process's figures by (row, side), one per process, and the rows
/// in the order the processes wrote them.
struct Figures {
    rows: Vec<String>,
    by: BTreeMap<(String, String), Vec<Option<f64>>>,
}

impl Figures {
    fn of(runs: &[Vec<Record>]) -> Figures {
        let mut f = Figures {
            rows: Vec::new(),
            by: BTreeMap::new(),
        };
        for r in runs.iter().flatten() {
            if !f.rows.contains(&r.row) {
                f.rows.push(r.row.clone());
            }
            (f.by.entry((r.row.clone(), r.side.clone())).or_default()).push(r.ns);
        }
        f
    }

    /// The figures of `side` on `row`, one per process.
    fn get(&self, row: &str, side: &str) -> Vec<Option<f64>> {
        (self.by.get(&(row.to_string(), side.to_string())))
            .cloned()
            .unwrap_or_default()
    }
}

/// The tables of every process's records: each cell the median of the
/// processes' figures and their range; each ratio the range of the
/// processes' own ratios to the fastest peer of that process.
fn render(runs: &[Vec<Record>], side_names: &[&str]) -> String {
    let figures = Figures::of(runs);
    let mut t = String::new();
    let _ = writeln!(
        t,
        "| kernel (ns per call, thread CPU time; median of {} processes, range) | inputs | {} | kinegen no_std / best peer | kinegen std / best peer |",
        runs.len(),
        side_names.join(" | ")
    );
    let _ = writeln!(t, "|---|---|{}---|---|", "---|".repeat(side_names.len()));
    let peers: Vec<&str> = side_names
        .iter()
        .copied()
        .filter(|n| !n.starts_with("kinegen"))
        .collect();
    let (mut central, mut accuracy) = (Vec::new(), Vec::new());
    for row in &figures.rows {
        if figures.get(row, "analytic").iter().any(Option::is_some) {
            central.push(row.clone());
            continue;
        }
        if let Some(label) = row.strip_prefix("accuracy | ") {
            let errors: Vec<String> = (side_names.iter())
                .map(|side| {
                    let e = figures.get(row, side).first().copied().flatten();
                    e.map_or("-".to_string(), |e| format!("{e:.0e}"))
                })
                .collect();
            accuracy.push(format!("| {label} | {} |", errors.join(" | ")));
            continue;
        }
        let mut cells = Vec::new();
        for side in side_names {
            let mut v: Vec<f64> = figures.get(row, side).into_iter().flatten().collect();
            cells.push(cell(&mut v, 1));
        }
        // per process: kinegen's figure over that process's fastest peer
        let ratio = |side: &str| {
            let mut v: Vec<f64> = (0..runs.len())
                .filter_map(|k| {
                    let mine = *figures.get(row, side).get(k)?;
                    let best = (peers.iter())
                        .filter_map(|p| *figures.get(row, p).get(k)?)
                        .fold(f64::INFINITY, f64::min);
                    mine.map(|m| m / best)
                })
                .collect();
            cell(&mut v, 2)
        };
        let (label, inputs) = row.split_once(" | ").unwrap_or((row, ""));
        let _ = writeln!(
            t,
            "| {label} | {inputs} | {} | {} | {} |",
            cells.join(" | "),
            ratio("kinegen no_std"),
            ratio("kinegen std")
        );
    }
    let _ = writeln!(
        t,
        "\n| error near omega dt = 0 (largest over 13 steps with omega dt from 0 to 1, against 50 digits, relative to each output's largest entry) | {} |",
        side_names.join(" | ")
    );
    let _ = writeln!(t, "|---|{}", "---|".repeat(side_names.len()));
    accuracy.iter().for_each(|l| {
        let _ = writeln!(t, "{l}");
    });
    t + &operations_table(side_names) + &central_table(&central, &figures)
}

/// Each side's operation count on every row ([`ops::operations`]).
fn operations_table(side_names: &[&str]) -> String {
    let mut t = format!(
        "\n| operations in the generated code, as each tool counts them (`kinegen_peers::ops`) | {} |\n|---|{}\n",
        side_names.join(" | "),
        "---|".repeat(side_names.len())
    );
    for row in Row::ALL {
        let counts: Vec<String> = (side_names.iter())
            .map(|side| ops::operations(row, side).map_or("-".into(), |n| n.to_string()))
            .collect();
        let _ = writeln!(t, "| {} | {} |", row.label(), counts.join(" | "));
    }
    t
}

/// The analytic parameter Jacobians against central differences.
fn central_table(rows: &[String], figures: &Figures) -> String {
    let mut t = String::from("\n| parameter Jacobian, kinegen no_std (ns per call, mix) | analytic | central differences | speed-up |\n|---|---|---|---|\n");
    for row in rows {
        let (a, c) = (
            figures.get(row, "analytic"),
            figures.get(row, "central differences"),
        );
        let mut speedup: Vec<f64> = (a.iter().zip(&c))
            .filter_map(|(a, c)| Some((*c)? / (*a)?))
            .collect();
        let (mut a, mut c): (Vec<f64>, Vec<f64>) = (
            a.into_iter().flatten().collect(),
            c.into_iter().flatten().collect(),
        );
        let (label, agree) = row.split_once(" (").unwrap_or((row, ""));
        let _ = writeln!(
            t,
            "| {label} | {} | {} | {}x ({} |",
            cell(&mut a, 1),
            cell(&mut c, 1),
            cell(&mut speedup, 1),
            agree
        );
    }
    t
}

/// The machine and the build, as the table was measured: the CPU, the load
/// when the processes started, and the vector instructions the compiler
/// was allowed (a generic x86-64 build has SSE2 only; `-C
/// target-cpu=native` adds what this CPU has).
fn machine() -> String {
    let read = |p: &str| std::fs::read_to_string(p).unwrap_or_default();
    let cpu = (read("/proc/cpuinfo").lines())
        .find_map(|l| {
            l.strip_prefix("model name")
                .map(|v| v.trim_start_matches([' ', '\t', ':']).to_string())
        })
        .unwrap_or_else(|| "unknown".into());
    let load = read("/proc/loadavg");
    let load: Vec<&str> = load.split_whitespace().take(3).collect();
    let features: Vec<&str> = [
        ("sse4.2", cfg!(target_feature = "sse4.2")),
        ("avx", cfg!(target_feature = "avx")),
        ("avx2", cfg!(target_feature = "avx2")),
        ("fma", cfg!(target_feature = "fma")),
        ("avx512f", cfg!(target_feature = "avx512f")),
    ]
    .into_iter()
    .filter_map(|(n, on)| on.then_some(n))
    .collect();
    format!(
        "- machine: {cpu}; load average {} when the processes started; built with {}; the C and C++ peers with {}",
        load.join(" "),
        if features.is_empty() {
            "the target's baseline instructions only".to_string()
        } else {
            features.join(", ")
        },
        env!("PEERS_C_MARCH")
    )
}

fn main() {
    // a child process: measure, and write the records for the parent
    if std::env::var_os("KINEGEN_PEERS_CHILD").is_some() {
        let (notes, records) = measure();
        notes.iter().for_each(|n| println!("#{n}"));
        records.iter().for_each(|r| println!("{}", r.line()));
        return;
    }
    let processes: usize = std::env::var("PEERS_PROCESSES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(PROCESSES)
        .max(1);
    let exe = std::env::current_exe().expect("the bench's own executable");
    let mut notes = Vec::new();
    let mut runs = Vec::new();
    // one after the other: two at once would share the cores they time on
    for _ in 0..processes {
        let out = std::process::Command::new(&exe)
            .env("KINEGEN_PEERS_CHILD", "1")
            .stderr(std::process::Stdio::inherit())
            .output()
            .expect("the bench runs itself as a child process");
        assert!(out.status.success(), "a measuring process failed");
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        notes = text
            .lines()
            .filter_map(|l| l.strip_prefix('#').map(str::to_string))
            .collect();
        runs.push(text.lines().filter_map(Record::parse).collect::<Vec<_>>());
    }
    println!("{}", machine());
    notes.iter().for_each(|n| println!("{n}"));
    if !kinegen_peers::WRENFOLD_CPP {
        println!("left out: wrenfold C++ (its span headers were not found at build time: pip install wrenfold)");
    }
    if !kinegen_peers::SYMFORCE_CPP {
        println!("left out: SymForce C++ (Eigen's headers were not found at build time: apt-get install libeigen3-dev)");
    }
    println!("left out: SymForce Rust (its 0.12 generator's code for these kernels does not compile or computes something else: verify/peers/symforce_kernels.py)\n");
    let side_names: Vec<&str> = sides().iter().map(|s| s.name).collect();
    print!("{}", render(&runs, &side_names));
}
