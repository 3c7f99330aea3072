//! `kinegen bench-diagnose`: how often diagnosis names what was hidden
//! (the benchmark itself: `kinegen_analysis::applications::diagnose_bench`).
//! This file reads the options and the specs, runs the benchmark or merges
//! its shards, and says the table.
use crate::analysis_cmd::bad;
use crate::output::Out;
use clap::Args;
use kinegen_analysis::applications::diagnose_bench::{bench, merge, Rate, Settings, Shard, Table};
use kinegen_model::spec::Model;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Args, Debug)]
pub struct BenchDiagnoseArgs {
    /// Specs to benchmark (repeatable). Default: spec/*.toml and
    /// tests/user_specs/*.toml under the working directory, or the bundled
    /// specs (built in) elsewhere.
    #[arg(long)]
    pub spec: Vec<PathBuf>,
    /// Only these effects, of the catalogue or of --beyond (repeatable;
    /// default: every applicable one).
    #[arg(long)]
    pub effect: Vec<String>,
    /// Folders of effects written for the benchmark, outside the catalogue
    /// (repeatable; `--effects` format): each is hidden at each magnitude
    /// too, and the table scores the diagnosis's proposals beyond the
    /// catalogue (recovered, and false proposals on the other cases).
    #[arg(long, value_name = "DIR")]
    pub beyond: Vec<PathBuf>,
    /// Seeds per case (the full benchmark: 5).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=50))]
    pub seeds: u64,
    /// Laps of the random trajectory per log: 1 is 91 s (1,820 rows at 20 Hz);
    /// 6 is 546 s (10,921 rows), the size of diagnosis' speed target.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=100))]
    pub laps: u64,
    /// Run only slice K of N (K from 1): case number i (in the benchmark's
    /// fixed order) belongs to slice i mod N + 1. Shards run on different
    /// machines; `--merge` joins their JSON documents into the whole table.
    #[arg(long, value_name = "K/N", value_parser = clap::value_parser!(Shard))]
    pub shard: Option<Shard>,
    /// Join the JSON documents of shards (`--shard K/N --json FILE`) into the
    /// table the unsharded run gives; nothing is diagnosed.
    #[arg(long, value_name = "FILE", num_args = 1.., conflicts_with = "shard")]
    pub merge: Vec<PathBuf>,
    /// Write one JSON document to PATH (`-`: stdout).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// The bundled specs, built in so that the benchmark runs from any directory.
const BUNDLED: [(&str, &str); 6] = [
    ("diff_drive", include_str!("../spec/diff_drive.toml")),
    ("tricycle", include_str!("../spec/tricycle.toml")),
    ("tricycle_fwd", include_str!("../spec/tricycle_fwd.toml")),
    ("omni3", include_str!("../spec/omni3.toml")),
    ("omni_caster", include_str!("../spec/omni_caster.toml")),
    ("unicycle_ekf", include_str!("../spec/unicycle_ekf.toml")),
];

/// spec/*.toml and tests/user_specs/*.toml under the working directory (a
/// checkout), else the built-in bundled specs (named `NAME.toml (built into
/// kinegen)`: they have no file, and none is written).
fn default_specs() -> Result<Vec<Model>, String> {
    let local = local_specs();
    if !local.is_empty() {
        return local
            .iter()
            .map(|p| Model::load(p).map_err(|e| e.to_string()))
            .collect();
    }
    BUNDLED
        .iter()
        .map(|(name, text)| {
            let label = PathBuf::from(format!("{name}.toml (built into kinegen)"));
            Model::parse(&label, text).map_err(|e| e.to_string())
        })
        .collect()
}

fn local_specs() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for dir in ["spec", "tests/user_specs"] {
        if let Ok(rd) = std::fs::read_dir(dir) {
            let mut files: Vec<PathBuf> = rd
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|e| e == "toml"))
                .collect();
            files.sort();
            v.extend(files);
        }
    }
    v
}

pub fn run(a: &BenchDiagnoseArgs) -> ExitCode {
    let out = Out::new(a.json.as_deref());
    let table = if a.merge.is_empty() {
        let specs = if a.spec.is_empty() {
            default_specs()
        } else {
            (a.spec.iter())
                .map(|p| Model::load(p).map_err(|e| e.to_string()))
                .collect()
        };
        let specs = match specs {
            Ok(s) => s,
            Err(e) => return bad(e),
        };
        let settings = Settings {
            seeds: a.seeds,
            laps: a.laps,
            shard: a.shard,
            effects: a.effect.clone(),
            beyond: a.beyond.clone(),
        };
        let failed = |case: &str| out.say(&format!("  {case}"));
        bench(
            &specs,
            &settings,
            crate::ir_source::analysis_deriver(),
            &failed,
        )
    } else {
        merge(&a.merge)
    };
    match table {
        Ok(t) => say_table(&out, &t, a),
        Err(e) => bad(e),
    }
}

/// One line per model, and the JSON document.
fn say_table(out: &Out, t: &Table, a: &BenchDiagnoseArgs) -> ExitCode {
    let pct = |r: Rate| {
        if r.of == 0 {
            "-".to_string()
        } else {
            format!(
                "{:.0}% ({}/{})",
                100.0 * r.found as f64 / r.of as f64,
                r.found,
                r.of
            )
        }
    };
    for m in &t.models {
        out.say(&format!(
            "{:<14} top-1 {:<14} full chain {:<14} false alarms {:<12} redundant {:<3} median {:.1} s, slowest {:.1} s per diagnosis",
            m.model,
            pct(m.top1),
            pct(m.full_chain),
            pct(m.false_alarms),
            m.redundant_cases,
            m.median_seconds,
            m.slowest_seconds
        ));
        if m.beyond_recovered.of > 0 || m.false_proposals.found > 0 {
            out.say(&format!(
                "{:<14} beyond the catalogue: recovered {:<14} false proposals {}",
                "",
                pct(m.beyond_recovered),
                pct(m.false_proposals)
            ));
        }
    }
    let doc = serde_json::to_value(t).expect("the table serialises");
    match out.json(a.json.as_deref(), &doc) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => bad(e),
    }
}
