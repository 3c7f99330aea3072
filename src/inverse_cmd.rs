//! `kinegen inverse`: the input profiles of one or more robots along a planned
//! path (one call to kinegen_analysis::applications::inverse::profile_files), with the stretches their actuators cannot
//! deliver. Exit 1 when any robot cannot drive the path as planned.
use crate::analysis_cmd::bad;
use crate::output::Out;
use clap::Args;
use kinegen_analysis::applications::inverse::{profile_files, SpecProfile};
use serde_json::json;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct InverseArgs {
    /// A model spec; repeat to compare several robots on the same path.
    #[arg(long, required = true)]
    pub spec: Vec<PathBuf>,
    /// The planned path: CSV `t,x,y,theta` (world frame, t strictly increasing).
    #[arg(long)]
    pub path: PathBuf,
    /// Write a self-contained HTML report to DIR/index.html.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write one JSON document to PATH (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

pub fn run(a: &InverseArgs) -> ExitCode {
    if let Err(e) = crate::output::check_outputs(a.json.as_deref(), a.report.as_deref()) {
        return bad(e);
    }
    let out = Out::new(a.json.as_deref());
    let (path, profiled) =
        match profile_files(&a.path, &a.spec, crate::ir_source::symbolic_deriver()) {
            Ok(p) => p,
            Err(e) => return bad(e),
        };
    let mut profiles = Vec::new();
    let mut specs_json = Vec::new();
    let mut feasible = true;
    for SpecProfile {
        spec,
        runner,
        profile: prof,
    } in profiled
    {
        let name = runner.ir.name.clone();
        out.say(&format!(
            "{name} ({}): {} steps over {:.1} s",
            spec.display(),
            prof.t.len(),
            path.t.last().unwrap() - path.t[0]
        ));
        for i in &prof.inputs {
            let per = if i.kind == kinegen_model::decl::InputKind::Absolute {
                "/s"
            } else {
                ""
            };
            out.say(&format!(
                "  {:<8} peak rate {:.4} {}{per}{}",
                i.name,
                i.peak_rate,
                i.unit,
                i.max_rate
                    .map(|m| format!(" (max_rate {m})"))
                    .unwrap_or_default()
            ));
        }
        if prof.infeasible.is_empty() {
            out.say("  every input within its limits along the whole path");
        } else {
            feasible = false;
            out.say(&format!(
                "  INFEASIBLE in {} stretch(es):",
                prof.infeasible.len()
            ));
            const SHOWN: usize = 12;
            for s in prof.infeasible.iter().take(SHOWN) {
                out.say(&format!(
                    "    {:.2}-{:.2} s  {}: {}",
                    s.t_start, s.t_end, s.input, s.why
                ));
            }
            if prof.infeasible.len() > SHOWN {
                out.say(&format!(
                    "    ... and {} more (all in --json and --report)",
                    prof.infeasible.len() - SHOWN
                ));
            }
        }
        specs_json.push(json!({
            "spec": spec.display().to_string(),
            "model": name,
            "feasible": prof.infeasible.is_empty(),
            "inputs": prof.inputs.iter().map(|i| json!({"name": i.name, "unit": i.unit, "kind": i.kind, "peak_rate": i.peak_rate, "max_rate": i.max_rate, "range": i.range})).collect::<Vec<_>>(),
            "infeasible": prof.infeasible,
            "max_step_miss_m": prof.max_step_miss_m,
            "profile": {
                "t": prof.t,
                "inputs": prof.inputs.iter().map(|i| (i.name.clone(), json!(i.value))).collect::<serde_json::Map<_, _>>(),
            },
        }));
        profiles.push((name, prof));
    }
    let doc = json!({"command": "inverse", "path": a.path.display().to_string(), "feasible": feasible, "specs": specs_json});
    if let Some(dir) = &a.report {
        if let Err(e) = crate::report::inverse::inverse_report(dir, &path, &profiles, &doc) {
            return bad(e);
        }
        out.say(&format!("report: {}", dir.join("index.html").display()));
    }
    if let Err(e) = out.json(a.json.as_deref(), &doc) {
        return bad(e);
    }
    if feasible {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    }
}
