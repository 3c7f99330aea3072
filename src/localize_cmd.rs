//! `kinegen localize`: the EKF of seed 001 over logs with landmark observations
//! (kinegen_analysis::localize), with its consistency checks.
use crate::analysis_cmd::{bad, evaluate, prepare, Common};
use crate::output::Out;
use clap::Args;
use kinegen_analysis::localize::{localize, mean_bounds, EkfOptions};
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct LocalizeArgs {
    /// Reject an observation whose normalised innovation squared exceeds this
    /// (chi-square with 2 degrees of freedom: 9.21 is its 99% point).
    #[arg(long, default_value_t = 9.21, value_parser = crate::analysis_cmd::positive)]
    pub gate: f64,
    /// Write the estimated track with its covariance (t, x, y, theta, var_x,
    /// cov_xy, var_y, var_theta) to this CSV (several runs: one after another,
    /// with a `run` column).
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// Process-noise standard deviation NAME=SIGMA replacing the spec's
    /// `[[noise]]` value (repeatable): a filter whose NEES or NIS lies above its
    /// bounds is overconfident and needs more.
    #[arg(long)]
    pub noise: Vec<String>,
    /// Noise sweep (seed 001 Figs 6-7): drive the first log's robot again with
    /// each [[noise]] sigma in turn raised from 0.001 to 0.1, re-observe its
    /// landmarks, and report the EKF's position error for each.
    #[arg(long)]
    pub sweep: bool,
}

pub fn run(c: Common, a: &LocalizeArgs) -> ExitCode {
    let out = Out::new(c.json.as_deref());
    if let Some(t) = &a.track {
        if let Err(e) = crate::output::check_writable("--track", t) {
            return bad(e);
        }
    }
    let prep = match prepare(&c) {
        Ok(p) => p,
        Err(e) => return bad(e),
    };
    let r = &prep.runner;
    let noise_sigma = match kinegen_analysis::model::parse_pairs("--noise", &a.noise) {
        Ok(v) => v,
        Err(e) => return bad(e),
    };
    for (n, s) in &noise_sigma {
        if !r.ir.noise.iter().any(|x| &x.name == n) {
            let known: Vec<&str> = r.ir.noise.iter().map(|x| x.name.as_str()).collect();
            return bad(format!(
                "--noise {n}: the spec has no [[noise]] `{n}` (it has: {})",
                known.join(", ")
            ));
        }
        if *s < 0.0 {
            return bad(format!(
                "--noise {n}={s}: a standard deviation is 0 or more"
            ));
        }
    }
    let o = EkfOptions {
        gate: a.gate,
        noise_sigma,
        ..EkfOptions::default()
    };
    // mapped landmarks no log ever observes are probably a mapping mistake (an id
    // spelled differently in the map and the observations)
    if let Some(m) = &c.landmarks {
        if let Ok(map) = kinegen_analysis::landmarks::read_map(m) {
            for (i, id) in map.ids.iter().enumerate() {
                let seen = prep
                    .runs
                    .iter()
                    .chain(&prep.holdout)
                    .any(|r| r.landmarks.iter().any(|z| &z.id == id));
                if !seen {
                    eprintln!("warning: {}:{}: landmark `{id}` is never observed in the --observations files", m.display(), i + 2);
                }
            }
        }
    }
    let mut runs_json = Vec::new();
    let mut locs = Vec::new();
    let mut csv = String::from("run,t,x,y,theta,var_x,cov_xy,var_y,var_theta\n");
    for run in prep.runs.iter().chain(&prep.holdout) {
        if run.landmarks.is_empty() {
            return bad(format!(
                "{}: no landmark observations for this log (give --observations OBS.csv --landmarks MAP.csv, one OBS per --data)",
                run.path
            ));
        }
        let loc = match localize(r, run, &o) {
            Ok(l) => l,
            Err(e) => return bad(e),
        };
        let dr = evaluate(r, &r.p, std::slice::from_ref(run));
        let rmse = run.gt.as_ref().map(|g| {
            let s: f64 = loc
                .track
                .iter()
                .zip(g)
                .map(|(x, g)| (x[0] - g[0]).powi(2) + (x[1] - g[1]).powi(2))
                .sum();
            (s / g.len() as f64).sqrt()
        });
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        let (nis, nees) = (mean(&loc.nis), mean(&loc.nees));
        let nis_b = (!loc.nis.is_empty()).then(|| mean_bounds(loc.nis.len(), 2.0));
        let nees_b = (!loc.nees.is_empty()).then(|| mean_bounds(loc.nees.len(), 3.0));
        let verdict = |m: Option<f64>, b: Option<(f64, f64)>| match (m, b) {
            (Some(m), Some((lo, hi))) if m < lo => {
                format!("{m:.2} (below its 95% bounds {lo:.2}..{hi:.2}: the filter is pessimistic)")
            }
            (Some(m), Some((lo, hi))) if m > hi => format!(
                "{m:.2} (above its 95% bounds {lo:.2}..{hi:.2}: the filter is overconfident)"
            ),
            (Some(m), Some((lo, hi))) => format!("{m:.2} (within its 95% bounds {lo:.2}..{hi:.2})"),
            _ => "n/a".into(),
        };
        out.say(&format!(
            "{}: EKF over {} steps; {} landmark observations used, {} rejected by the gate (NIS > {})",
            run.path,
            run.steps(),
            loc.accepted,
            loc.rejected,
            a.gate
        ));
        if let Some(e) = rmse {
            out.say(&format!(
                "  position RMSE {e:.4} m (dead reckoning with the same model: {:.4} m)",
                dr.rmse
            ));
        }
        out.say(&format!("  mean NIS  {}", verdict(nis, nis_b)));
        out.say(&format!("  mean NEES {}", verdict(nees, nees_b)));
        let last = loc.cov.last().unwrap();
        out.say(&format!(
            "  final standard deviations: x {:.4} m, y {:.4} m, theta {:.4} rad",
            last[(0, 0)].sqrt(),
            last[(1, 1)].sqrt(),
            last[(2, 2)].sqrt()
        ));
        for (k, (x, p)) in loc.track.iter().zip(&loc.cov).enumerate() {
            csv += &format!(
                "{},{},{},{},{},{},{},{},{}\n",
                run.path,
                run.t[k],
                x[0],
                x[1],
                x[2],
                p[(0, 0)],
                p[(0, 1)],
                p[(1, 1)],
                p[(2, 2)]
            );
        }
        runs_json.push(json!({
            "path": run.path, "steps": run.steps(),
            "observations_used": loc.accepted, "observations_rejected": loc.rejected,
            "position_rmse_m": rmse, "dead_reckoning_rmse_m": run.gt.as_ref().map(|_| dr.rmse),
            "nis_mean": nis, "nis_bounds": nis_b.map(|b| [b.0, b.1]),
            "nees_mean": nees, "nees_bounds": nees_b.map(|b| [b.0, b.1]),
            "final_pose": loc.track.last(),
            "final_std": [last[(0, 0)].sqrt(), last[(1, 1)].sqrt(), last[(2, 2)].sqrt()],
        }));
        locs.push((run, loc));
    }
    let sweep = if a.sweep {
        match kinegen_analysis::sweep::sweep(r, locs[0].0, &kinegen_analysis::sweep::LEVELS, &o) {
            Ok(s) => s,
            Err(e) => return bad(e),
        }
    } else {
        Vec::new()
    };
    if !sweep.is_empty() {
        out.say(&format!(
            "noise sweep on {} ({} simulated repetitions per level): EKF position RMSE (m)",
            locs[0].0.path,
            kinegen_analysis::sweep::SEEDS
        ));
        let mut names: Vec<&str> = sweep.iter().map(|p| p.noise.as_str()).collect();
        names.dedup();
        out.say(&format!(
            "  {:<10}{}",
            "sigma",
            names.iter().map(|n| format!("{n:>12}")).collect::<String>()
        ));
        for level in kinegen_analysis::sweep::LEVELS {
            let row: String = names
                .iter()
                .map(|n| {
                    let p = sweep
                        .iter()
                        .find(|p| p.noise == *n && p.sigma == level)
                        .unwrap();
                    format!("{:>12.4}", p.position_rmse_m)
                })
                .collect();
            out.say(&format!("  {level:<10}{row}"));
        }
        let top = |n: &str| {
            sweep
                .iter()
                .filter(|p| p.noise == n)
                .map(|p| p.position_rmse_m)
                .fold(0.0, f64::max)
        };
        let mut ranked: Vec<(&str, f64)> = names.iter().map(|n| (*n, top(n))).collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
        if let [(worst, w), .., (least, l)] = ranked.as_slice() {
            out.say(&format!(
                "  at the largest sigma, uncertainty in `{worst}` costs {:.1}x the position error of uncertainty in `{least}`",
                w / l.max(1e-12)
            ));
        }
    }
    if let Some(dir) = &c.report {
        let pairs: Vec<_> = locs.iter().map(|(r, l)| (*r, l)).collect();
        let doc = json!({"model": r.ir.name, "runs": runs_json, "sweep": sweep});
        if let Err(e) = crate::report::localize_report(dir, &pairs, &sweep, &doc) {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    if let Some(t) = &a.track {
        if let Err(e) = kinegen_model::files::write_atomic(t, &csv) {
            return bad(e);
        }
        out.say(&format!("track: {}", t.display()));
    }
    let doc = json!({"model": r.ir.name, "gate": a.gate, "runs": runs_json, "sweep": sweep});
    match out.json(c.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}
