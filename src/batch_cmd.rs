//! `kinegen batch JOBS.jsonl --out RESULTS.jsonl [--jobs N]`: many robots'
//! commands, each a child process of this same binary (a job that fails,
//! panics or runs out of memory cannot take the others down, and symbolic
//! derivation keeps its one machine-wide permit per process), at most N at
//! once, one result line each as it finishes. Results already in RESULTS
//! are not run again, so a killed batch resumes where it stopped.
use crate::analysis_cmd::bad;
use clap::Args;
use serde_json::{json, Value};
use std::collections::{HashSet, VecDeque};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use std::sync::Mutex;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BatchArgs {
    /// The jobs: one JSON object a line, `{"id": "r17-fit", "args": ["fit",
    /// "--spec", "robot.toml", "--data", "r17.csv"]}` (the arguments exactly as
    /// the command line takes them; relative paths from where batch runs).
    /// With --plan: the directory of logs and bags to plan jobs for.
    #[arg(value_name = "JOBS.jsonl | DIR")]
    pub jobs_file: PathBuf,
    /// Where the results go, one JSON line a job: `{"id", "exit", "result"
    /// (the command's own JSON document) or "error" (its message),
    /// "seconds"}`. Appended to: ids already there are not run again. With
    /// --plan: where the jobs go.
    #[arg(long, value_name = "RESULTS.jsonl")]
    pub out: PathBuf,
    /// Write a job for COMMAND (fit, diagnose, compare) on every log in DIR
    /// (CSV files with the spec's input columns; ROS 2 bags, `.mcap`, to one
    /// level down) instead of running jobs: a nightly run is then `batch
    /// --plan fit --spec robot.toml logs/ --out jobs.jsonl` and `batch
    /// jobs.jsonl --out results.jsonl`.
    #[arg(long, value_name = "COMMAND", requires = "spec")]
    pub plan: Option<String>,
    /// The spec of the planned jobs (with --plan).
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// The topic mapping of the planned jobs' bags (with --plan).
    #[arg(long)]
    pub topics: Option<PathBuf>,
    /// At most this many jobs at once (default: the machine's cores).
    #[arg(long = "jobs", value_name = "N", value_parser = crate::at_least_one)]
    pub parallel: Option<usize>,
}

/// One line of JOBS.jsonl.
#[derive(Debug, Clone)]
struct Job {
    id: String,
    args: Vec<String>,
}

/// Commands that write their JSON document with `--json -`.
const WITH_JSON: [&str; 7] = [
    "compare",
    "fit",
    "diagnose",
    "localize",
    "inverse",
    "navigate",
    "bench-diagnose",
];

/// Read JOBS.jsonl: every problem names the file and line.
fn read_jobs(path: &Path) -> Result<Vec<Job>, String> {
    // bounded, and a byte that is not UTF-8 named at its line
    let text = kinegen_model::files::read_text(path).map_err(|(at, e)| match at {
        Some((line, col)) => format!("{}:{line}:{col}: {e}", path.display()),
        None => format!("{}: cannot read the jobs: {e}", path.display()),
    })?;
    let mut jobs = Vec::new();
    let mut seen = HashSet::new();
    for (n, line) in text.lines().enumerate() {
        let at = format!("{}:{}", path.display(), n + 1);
        if line.trim().is_empty() {
            continue;
        }
        let v: Value =
            serde_json::from_str(line).map_err(|e| format!("{at}: not a JSON object: {e}"))?;
        let id = v["id"]
            .as_str()
            .ok_or_else(|| format!("{at}: the job has no string `id`"))?
            .to_string();
        let args: Vec<String> = v["args"]
            .as_array()
            .ok_or_else(|| format!("{at}: job `{id}` has no `args` list"))?
            .iter()
            .map(|a| a.as_str().map(str::to_string))
            .collect::<Option<_>>()
            .ok_or_else(|| format!("{at}: job `{id}`: every argument is a string"))?;
        match args.first().map(String::as_str) {
            None => return Err(format!("{at}: job `{id}` has no command")),
            Some("batch") => return Err(format!("{at}: job `{id}` is a batch itself")),
            Some(_) => {}
        }
        if !seen.insert(id.clone()) {
            return Err(format!("{at}: the id `{id}` is used twice"));
        }
        jobs.push(Job { id, args });
    }
    Ok(jobs)
}

/// What RESULTS.jsonl already holds: the ids of its result lines, and how
/// many of those jobs failed (a resumed batch still owes them in its exit
/// status).
struct Journal {
    done: HashSet<String>,
    failed_before: usize,
}

/// Read the results file through the handle that holds its lock. A last
/// line without its newline (cut short by a kill) is dropped, so its job
/// runs again; any other line that is not a result line (`{"id": "...",
/// "exit": N or null, ...}`) stops the batch at that line: the file is not
/// one kinegen wrote, and resuming from it could skip jobs never run.
fn read_journal(file: &mut std::fs::File, out: &Path) -> Result<Journal, String> {
    use std::io::Read;
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes)
        .map_err(|e| format!("--out {}: {e}", out.display()))?;
    let whole = bytes.iter().rposition(|b| *b == b'\n').map_or(0, |i| i + 1);
    if whole < bytes.len() {
        file.set_len(whole as u64)
            .map_err(|e| format!("--out {}: {e}", out.display()))?;
    }
    let mut journal = Journal {
        done: HashSet::new(),
        failed_before: 0,
    };
    for (k, line) in bytes[..whole].split(|b| *b == b'\n').enumerate() {
        let at = format!("{}:{}", out.display(), k + 1);
        if line.iter().all(u8::is_ascii_whitespace) {
            continue;
        }
        let v: Value = std::str::from_utf8(line)
            .map_err(|_| format!("{at}: not UTF-8: not a result line of kinegen batch"))
            .and_then(|l| {
                serde_json::from_str(l)
                    .map_err(|e| format!("{at}: not a result line of kinegen batch ({e})"))
            })?;
        let (Some(id), Some(exit)) = (v["id"].as_str(), v.get("exit")) else {
            return Err(format!(
                "{at}: a result line has \"id\" and \"exit\": this one does not; is --out the right file?"
            ));
        };
        if !(exit.is_null() || exit.is_i64()) {
            return Err(format!("{at}: \"exit\" is {exit}, not a number or null"));
        }
        journal.done.insert(id.to_string());
        journal.failed_before += usize::from(exit != &json!(0));
    }
    Ok(journal)
}

/// The jobs file and the results file must be two files: appending results
/// to the jobs would destroy them (a hard link or a symbolic link counts as
/// the same file).
fn check_distinct(jobs: &Path, out: &Path) -> Result<(), String> {
    use std::os::unix::fs::MetadataExt;
    let (Ok(a), Ok(b)) = (std::fs::metadata(jobs), std::fs::metadata(out)) else {
        return Ok(()); // the results file does not exist yet
    };
    if a.dev() == b.dev() && a.ino() == b.ino() {
        return Err(format!(
            "--out {}: that is the jobs file {}; the results go to a file of their own",
            out.display(),
            jobs.display()
        ));
    }
    Ok(())
}

/// Run one job and describe its outcome as a result line.
fn run_job(job: &Job) -> Value {
    let t0 = Instant::now();
    let mut args = job.args.clone();
    let json = WITH_JSON.contains(&args[0].as_str());
    if json {
        // the batch reads the document from stdout; a --json of the job's own
        // is replaced (the document lands in RESULTS)
        if let Some(k) = args.iter().position(|a| a == "--json") {
            args.drain(k..(k + 2).min(args.len()));
        }
        args.retain(|a| !a.starts_with("--json="));
        args.extend(["--json".into(), "-".into()]);
    }
    let exe = std::env::current_exe().unwrap_or_else(|_| PathBuf::from("kinegen"));
    let mut cmd = Command::new(exe);
    cmd.args(&args);
    // a job dies with the batch (SIGTERM when the thread that started it
    // ends, as it does when the batch is killed): a killed batch leaves no
    // job running for nobody. Linux's prctl; the closure runs in the child
    // between fork and exec and calls only that async-signal-safe function.
    #[cfg(target_os = "linux")]
    unsafe {
        use std::os::unix::process::CommandExt;
        cmd.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
            Ok(())
        });
    }
    let out = cmd.output();
    let seconds = t0.elapsed().as_secs_f64();
    let out = match out {
        Ok(o) => o,
        Err(e) => {
            return json!({"id": job.id, "exit": null, "error": format!("cannot run: {e}"), "seconds": seconds})
        }
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    let message = failure_message(&stderr, &out.status);
    let doc: Option<Value> = json
        .then(|| serde_json::from_slice(&out.stdout).ok())
        .flatten();
    let mut line = json!({"id": job.id, "exit": out.status.code(), "seconds": seconds});
    match doc {
        Some(d) => line["result"] = d,
        None if out.status.success() => {
            line["result"] = json!({"stdout": String::from_utf8_lossy(&out.stdout)})
        }
        None => {
            line["error"] = json!(if message.is_empty() {
                format!(
                    "ended by signal or exit {:?} without a message",
                    out.status.code()
                )
            } else {
                message
            })
        }
    }
    line
}

/// Why a job failed, in one line: its located error; for a crash, the
/// panic's message (not rust's "note: run with RUST_BACKTRACE=1" after it);
/// for a process ended by a signal, the signal.
fn failure_message(stderr: &str, status: &std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    let lines: Vec<&str> = stderr.lines().collect();
    if let Some(l) = lines.iter().rev().find(|l| l.starts_with("error")) {
        return l.to_string();
    }
    if let Some(k) = lines
        .iter()
        .position(|l| l.starts_with("thread '") && l.contains("panicked"))
    {
        let what = lines.get(k + 1).copied().unwrap_or("").trim();
        return format!(
            "kinegen crashed (a bug: please report it): {} {what}",
            lines[k].trim()
        );
    }
    if let Some(sig) = status.signal() {
        return format!(
            "ended by signal {sig}{}",
            if sig == 9 {
                " (killed: out of memory?)"
            } else {
                ""
            }
        );
    }
    lines
        .iter()
        .rev()
        .find(|l| !l.trim().is_empty() && !l.starts_with("note: run with"))
        .unwrap_or(&"")
        .to_string()
}

/// The logs of `dir` a spec with these input `columns` can read: CSV files
/// whose header has them, and `.mcap` bags, to one level down, sorted; and
/// the CSV files left out, each with why.
fn logs_in(dir: &Path, columns: &[String]) -> Result<(Vec<PathBuf>, Vec<String>), String> {
    let list = |d: &Path| -> Result<Vec<PathBuf>, String> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(d)
            .map_err(|e| format!("{}: {e}", d.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        v.sort();
        Ok(v)
    };
    let mut files = Vec::new();
    for p in list(dir)? {
        if p.is_dir() {
            files.extend(list(&p)?.into_iter().filter(|q| q.is_file()));
        } else {
            files.push(p);
        }
    }
    let (mut logs, mut left_out) = (Vec::new(), Vec::new());
    for p in files {
        // a job's arguments are JSON strings: a name that is not UTF-8 cannot
        // be written into one
        if p.to_str().is_none() {
            left_out.push(format!("{} (its name is not UTF-8)", p.display()));
            continue;
        }
        // a named pipe or a device would never end being read
        if !std::fs::metadata(&p).is_ok_and(|m| m.is_file()) {
            if matches!(p.extension().and_then(|e| e.to_str()), Some("csv" | "mcap")) {
                left_out.push(format!("{} (not a regular file)", p.display()));
            }
            continue;
        }
        match p.extension().and_then(|e| e.to_str()) {
            Some("mcap") => logs.push(p),
            // the header as every command reads it (comment lines before
            // it, a header written as a comment, a byte-order mark), without
            // reading the rows
            Some("csv") => match kinegen_analysis::logs::log::read_csv(&p, "log") {
                Ok((header, _)) => {
                    let missing: Vec<&str> = columns
                        .iter()
                        .filter(|c| !header.names.contains(c))
                        .map(String::as_str)
                        .collect();
                    if missing.is_empty() {
                        logs.push(p);
                    } else {
                        left_out.push(format!(
                            "{} (no column {})",
                            p.display(),
                            missing.join(", ")
                        ));
                    }
                }
                Err(e) => left_out.push(format!("{e}")),
            },
            _ => {}
        }
    }
    Ok((logs, left_out))
}

/// `--plan`: write a job for every log of the directory.
fn plan(a: &BatchArgs, command: &str) -> ExitCode {
    if !["fit", "diagnose", "compare"].contains(&command) {
        return bad(format!(
            "--plan {command}: plans are for fit, diagnose and compare"
        ));
    }
    let spec = a.spec.as_ref().expect("clap requires --spec with --plan");
    // every job would fail on a mapping that is not there
    if let Some(t) = a.topics.as_ref().filter(|t| !t.is_file()) {
        return bad(format!("--topics {}: no such file", t.display()));
    }
    let model = match kinegen_model::spec::Model::load(spec) {
        Ok(m) => m,
        Err(e) => return bad(e),
    };
    let columns: Vec<String> = model.inputs.iter().map(|i| i.column.clone()).collect();
    let (logs, left_out) = match logs_in(&a.jobs_file, &columns) {
        Ok(l) => l,
        Err(e) => return bad(e),
    };
    if !left_out.is_empty() {
        // the first few by name: a folder of hundreds of other CSVs is one
        // short warning, not a screenful
        const NAMED: usize = 3;
        let more = match left_out.len().saturating_sub(NAMED) {
            0 => String::new(),
            k => format!(" and {k} more"),
        };
        let w = format!(
            "{} CSV file(s) left out, not logs for this spec: {}{more}",
            left_out.len(),
            left_out[..left_out.len().min(NAMED)].join("; ")
        );
        let text = format!("warning: {w}");
        let wrapped = textwrap::wrap(&text, textwrap::Options::new(100).subsequent_indent("  "));
        for line in wrapped {
            eprintln!("{line}");
        }
    }
    if logs.is_empty() {
        return bad(format!(
            "{}: no log there has the spec's input columns ({}) and no .mcap bag",
            a.jobs_file.display(),
            columns.join(", ")
        ));
    }
    // ids from the file names, or, when two logs share a name (run-01.csv
    // of two robots' folders, run1.csv beside run1.mcap), from their paths
    // below DIR as they are (two paths are never the same, and `x/run.csv`
    // stays apart from `x-run.csv`)
    let stem = |p: &Path| {
        p.file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default()
    };
    let below = |p: &Path| p.strip_prefix(&a.jobs_file).unwrap_or(p).to_path_buf();
    let dashed = |p: &Path| {
        below(p)
            .with_extension("")
            .to_string_lossy()
            .replace(['/', '\\'], "-")
    };
    let unique = |f: &dyn Fn(&Path) -> String| {
        logs.iter().map(|l| f(l)).collect::<HashSet<String>>().len() == logs.len()
    };
    let (by_stem, by_dashes) = (unique(&stem), unique(&dashed));
    let mut text = String::new();
    for log in &logs {
        let name = if by_stem {
            stem(log)
        } else if by_dashes {
            dashed(log)
        } else {
            below(log).to_string_lossy().to_string()
        };
        let id = format!("{name}-{command}");
        let mut args = vec![
            command.to_string(),
            "--spec".into(),
            spec.display().to_string(),
            "--data".into(),
            log.display().to_string(),
        ];
        if let Some(t) = &a.topics {
            args.extend(["--topics".into(), t.display().to_string()]);
        }
        text += &format!("{}\n", json!({"id": id, "args": args}));
    }
    if let Err(e) = kinegen_model::files::write_atomic(&a.out, &text) {
        return bad(e);
    }
    eprintln!(
        "batch: {} job(s) for {command} written to {}",
        logs.len(),
        a.out.display()
    );
    ExitCode::SUCCESS
}

pub fn run(a: &BatchArgs) -> ExitCode {
    if let Some(command) = &a.plan {
        return plan(a, command);
    }
    let jobs = match read_jobs(&a.jobs_file) {
        Ok(j) => j,
        Err(e) => return bad(e),
    };
    // results are a journal in a file: a device or a pipe is none
    if std::fs::metadata(&a.out).is_ok_and(|m| !m.is_file()) {
        return bad(format!(
            "--out {}: not a regular file; the results go to a file of their own",
            a.out.display()
        ));
    }
    if let Err(e) = check_distinct(&a.jobs_file, &a.out)
        .and_then(|_| crate::output::check_writable("--out", &a.out))
    {
        return bad(e);
    }
    let file = match std::fs::OpenOptions::new()
        .create(true)
        .read(true)
        .append(true)
        .open(&a.out)
    {
        Ok(f) => f,
        Err(e) => return bad(format!("--out {}: {e}", a.out.display())),
    };
    // one batch at a time per results file: two would run every job twice
    let mut lock = fd_lock::RwLock::new(file);
    let Ok(mut file) = lock.try_write() else {
        return bad(format!(
            "--out {}: another kinegen batch is writing to it; wait for it to end, or give another results file",
            a.out.display()
        ));
    };
    let journal = match read_journal(&mut file, &a.out) {
        Ok(j) => j,
        Err(e) => return bad(e),
    };
    let pending: VecDeque<Job> = jobs
        .iter()
        .filter(|j| !journal.done.contains(&j.id))
        .cloned()
        .collect();
    let to_run = pending.len();
    // never more workers than jobs: a huge --jobs would spawn threads for
    // nothing
    let n = a
        .parallel
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .min(pending.len())
        .max(1);
    eprintln!(
        "batch: {} job(s), {} already in {}, {} to run, {} at once",
        jobs.len(),
        jobs.len() - pending.len(),
        a.out.display(),
        pending.len(),
        n
    );
    let bar = crate::progress::Progress::bar(pending.len() as u64, "batch", false);
    let queue = Mutex::new(pending);
    let sink = Mutex::new((&mut *file, 0usize, None::<String>));
    std::thread::scope(|s| {
        for _ in 0..n {
            s.spawn(|| loop {
                let Some(job) = queue.lock().unwrap().pop_front() else {
                    return;
                };
                let line = run_job(&job);
                let failed = line["exit"] != json!(0);
                let mut g = sink.lock().unwrap();
                let text = format!("{line}\n");
                if let Err(e) = g.0.write_all(text.as_bytes()).and_then(|_| g.0.flush()) {
                    g.2.get_or_insert(format!("--out {}: {e}", a.out.display()));
                }
                g.1 += usize::from(failed);
                bar.inc();
            });
        }
    });
    let (_, failed, write_error) = sink.into_inner().unwrap();
    if let Some(e) = write_error {
        return bad(e);
    }
    let earlier = match journal.failed_before {
        0 => String::new(),
        k => format!(", and {k} failed in an earlier run"),
    };
    eprintln!(
        "batch: {to_run} job(s) run, {failed} failed{earlier}; results in {}",
        a.out.display()
    );
    if failed + journal.failed_before > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::process::ExitStatusExt;

    #[test]
    fn a_crashed_job_is_said_by_its_panic_or_its_signal() {
        let panic = "thread 'main' (1) panicked at src/x.rs:3:5:\nindex out of bounds\nnote: run with `RUST_BACKTRACE=1` environment variable to display a backtrace\n";
        let m = failure_message(panic, &std::process::ExitStatus::from_raw(101 << 8));
        assert!(
            m.contains("crashed") && m.contains("index out of bounds"),
            "{m}"
        );
        let m = failure_message("", &std::process::ExitStatus::from_raw(9));
        assert!(m.contains("signal 9"), "{m}");
        let m = failure_message(
            "warning: x\nerror: a.csv:3:2: bad\n",
            &std::process::ExitStatus::from_raw(2 << 8),
        );
        assert_eq!(m, "error: a.csv:3:2: bad");
    }
}
