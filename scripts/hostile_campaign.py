#!/usr/bin/env python3
"""A campaign of hostile inputs over every command (issue 67): mutated logs,
specs, sightings, maps, jobs files, topic mappings, robot descriptions,
ROS 2 bags (their MCAP bytes and their metadata), occupancy grids, paths,
benchmark shards, benchmark configurations and option values, each run
through the command that reads it; with the full build (symbolica), mutated
specs also go through generate and verify.

Each case passes when kinegen ends with exit 0, 1 or 2 within the time limit
and under the memory cap, and
- never panics (exit 101) or dies of a signal (an abort is -6, an OOM kill -9);
- with exit 2 says where (the file, a line/row, or the option) and leaves no
  output file behind (the --json, --out and --report paths it was given);
- with exit 0 writes no NaN or infinity into its JSON document (a silent NaN).
Peak memory (the child's maximum resident set) is reported against the
largest input's size.

Usage: python3 scripts/hostile_campaign.py [--bin target/debug/kinegen]
           [--cases 2000] [--seed 1] [--jobs 2] [--keep DIR]
Failing cases are copied to DIR (default: a temporary folder that is kept
when anything fails), each with the command that reproduces it.
"""
import argparse
import concurrent.futures as cf
import json
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT_S = 120
MEMORY_CAP = 4 << 30  # bytes of address space a case may take
# GNU time (Debian's `time`) measures each case's peak memory; without it
# the campaign still judges every case and says memory was not measured
GNU_TIME = "/usr/bin/time" if os.access("/usr/bin/time", os.X_OK) else None

# ---------------------------------------------------------------- mutations

NUMBERS = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-320", "0", "-0",
           "", " ", "abc", "1,5", "0x10", "1e99999", "9" * 400, "--1", "1e", "∞"]


def mutate_text(text, rng):
    """One structural or byte-level change of a text file."""
    lines = text.splitlines(keepends=True)
    kind = rng.randrange(16)
    if kind == 0 and text:  # truncate anywhere
        return text[: rng.randrange(len(text))]
    if kind == 1:  # random bytes inserted
        at = rng.randrange(len(text) + 1)
        junk = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40)))
        return text[:at] + junk.decode("latin-1") + text[at:]
    if kind == 2 and len(lines) > 2:  # a line removed
        del lines[rng.randrange(len(lines))]
        return "".join(lines)
    if kind == 3 and len(lines) > 2:  # a line repeated
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
        return "".join(lines)
    if kind == 4 and len(lines) > 3:  # two lines swapped
        i, j = rng.randrange(1, len(lines)), rng.randrange(1, len(lines))
        lines[i], lines[j] = lines[j], lines[i]
        return "".join(lines)
    if kind == 5:  # a number replaced by a hostile value
        return replace_number(text, rng, rng.choice(NUMBERS))
    if kind == 6:  # empty
        return ""
    if kind == 7:  # a byte-order mark and CRLF line ends
        return "\ufeff" + text.replace("\n", "\r\n")
    if kind == 8:  # a very long line
        at = rng.randrange(len(text) + 1)
        return text[:at] + "1" * rng.choice([10_000, 1_000_000]) + text[at:]
    if kind == 9:  # a field separator changed
        return text.replace(",", rng.choice([";", "\t", " ", ",,"]), rng.randrange(1, 50))
    if kind == 10:  # invalid UTF-8
        at = rng.randrange(len(text) + 1)
        return text[:at] + "\udcff" + text[at:]
    if kind == 11 and lines:  # the first line (a header) doubled or cut
        return lines[0] + text if rng.random() < 0.5 else "".join(lines[1:])
    if kind == 12:  # a number scaled wildly
        return replace_number(text, rng, None, scale=rng.choice([1e9, -1.0, 1e-9, 0.0]))
    if kind == 13:  # deep nesting (an expression, a TOML array)
        at = rng.randrange(len(text) + 1)
        depth = rng.choice([100, 5000])
        return text[:at] + "(" * depth + "1" + ")" * depth + text[at:]
    if kind == 14:  # NUL bytes
        at = rng.randrange(len(text) + 1)
        return text[:at] + "\0" * rng.randrange(1, 8) + text[at:]
    # several changes at once
    for _ in range(rng.randrange(2, 5)):
        text = mutate_text(text, rng)
    return text


def replace_number(text, rng, value, scale=None):
    import re
    spans = [m.span() for m in re.finditer(r"-?\d+(\.\d+)?([eE]-?\d+)?", text)]
    if not spans:
        return text
    a, b = rng.choice(spans)
    if scale is not None:
        try:
            value = repr(float(text[a:b]) * scale)
        except ValueError:
            value = "nan"
    return text[:a] + value + text[b:]


def write(path, text):
    # surrogate escapes carry invalid UTF-8 bytes through Python's strings
    path.write_bytes(text.encode("utf-8", "surrogateescape"))


# ---------------------------------------------------------------- the cases

class Base:
    """The campaign's clean inputs, made once: a spec, a short log, its
    sightings and map, a jobs file, a topic mapping, a URDF and its
    controller configuration."""

    def __init__(self, bin_, work):
        self.bin, self.dir = bin_, work
        self.spec = (ROOT / "spec" / "diff_drive.toml").read_text()
        lines = (ROOT / "data" / "mystery_robot.csv").read_text().splitlines(keepends=True)
        self.log = "".join(lines[:301])
        subprocess.run([bin_, "simulate", "--spec", str(ROOT / "spec" / "diff_drive.toml"),
                        "--landmarks", str(ROOT / "data" / "beacons.csv"), "--out", "sim.csv",
                        "--observations", "obs.csv"], cwd=work, check=True, capture_output=True)
        sim = (work / "sim.csv").read_text().splitlines(keepends=True)
        self.sim = "".join(sim[:601])
        (work / "sim600.csv").write_text(self.sim)
        self.obs = (work / "obs.csv").read_text()
        self.map = (ROOT / "data" / "beacons.csv").read_text()
        self.urdf = (ROOT / "tests" / "robots" / "burger" / "robot.urdf").read_text()
        self.controllers = (ROOT / "tests" / "robots" / "burger" / "controllers.yaml").read_text()
        self.topics = '[inputs]\nenc_r = "/joint_states:position[0]"\n'
        self.bag = make_bag(work)
        self.job = {"id": "a", "args": ["compare", "--spec", "SPEC", "--data", "LOG"]}
        seed004 = ROOT / "data" / "seed004"
        self.epuck, self.grid = (seed004 / "epuck.toml").read_text(), (seed004 / "arena.txt").read_text()
        tour = (ROOT / "data" / "beacon_tour.csv").read_text().splitlines(keepends=True)
        self.path = "".join(tour[:121])
        self.shards = make_shards(bin_, work)
        self.real = real_optiodom()
        self.benchmark = benchmark_config()
        # generate and verify need the symbolic stage: the light build refuses them
        (work / "specs").mkdir()
        (work / "specs" / "spec.toml").write_text(self.spec)
        self.symbolic = subprocess.run([bin_, "generate", "--spec-dir", str(work / "specs"),
                                        "--out", str(work / "generated")], capture_output=True).returncode == 0


HOSTILE_OPTIONS = {
    "--set": ["b=nan", "b=1e308", "b=-1", "nosuch=1", "b=", "=1", "b=1=2", "b=0"],
    "--noise": ["dv=1e100", "dv=nan", "dv=-1", "dv=0", "nosuch=1", "dv=1e-320"],
    "--gate": ["-1", "nan", "0", "1e308", "inf"],
    "--max-gap": ["nan", "-1", "0", "1e-300", "inf"],
    "--laps": ["0", "-1", "1e9", "nan", "99999999999"],
    "--seed": ["-1", "x", "1e30"],
    "--jobs": ["0", "-1", "100000000", "x"],
    "--value": ["k_slip=nan", "k_slip=1e308", "nosuch=1", "k_slip"],
    "--cell": ["0", "-1", "nan", "1e-300", "1e300", "x"],
    "--recalc": ["0", "-1", "nan", "x", "1e20"],
    "--seeds": ["0", "-1", "x", "1e12"],
    "--shard": ["0/2", "3/2", "1/0", "x", "1/-1", "2"],
}


def case(base, rng, k, tmp):
    """The k-th case: (command line, output paths, largest input size, what
    was mutated)."""
    kind = rng.choice(["log", "log", "spec", "spec", "sightings", "map", "jobs", "topics",
                       "urdf", "controllers", "option", "option", "grid", "path", "shard"]
                      + (["bag", "bag"] if base.bag else []) + (["benchmark"] if base.real else []))
    files = {"spec.toml": base.spec, "log.csv": base.log, "sim.csv": base.sim,
             "obs.csv": base.obs, "map.csv": base.map, "robot.urdf": base.urdf,
             "controllers.yaml": base.controllers, "topics.toml": base.topics,
             "epuck.toml": base.epuck, "arena.txt": base.grid, "path.csv": base.path,
             "benchmark.toml": base.benchmark, **base.shards}
    job = dict(base.job, args=["compare", "--spec", str(tmp / "spec.toml"), "--data", str(tmp / "log.csv")])
    files["jobs.jsonl"] = json.dumps(job) + "\n"
    target = {"log": rng.choice(["log.csv", "sim.csv"]), "spec": "spec.toml", "sightings": "obs.csv",
              "map": "map.csv", "jobs": "jobs.jsonl", "topics": "topics.toml", "urdf": "robot.urdf",
              "controllers": "controllers.yaml", "option": None, "bag": None, "grid": "arena.txt",
              "path": "path.csv", "shard": rng.choice(sorted(base.shards)), "benchmark": "benchmark.toml"}[kind]
    if target:
        files[target] = mutate_text(files[target], rng)
    for name, text in files.items():
        write(tmp / name, text)
    # generate reads a folder of specs: the (mutated) spec alone in one
    (tmp / "specs").mkdir()
    write(tmp / "specs" / "spec.toml", files["spec.toml"])
    if kind == "bag":
        # the MCAP file's bytes, or now and then the metadata's text
        (tmp / "run.bag").mkdir()
        for name, data in base.bag.items():
            if name.endswith(".mcap") and rng.random() < 0.85:
                data = mutate_bytes(data, rng)
            elif name.endswith(".yaml") and rng.random() < 0.5:
                data = mutate_text(data.decode(), rng).encode("utf-8", "surrogateescape")
            (tmp / "run.bag" / name).write_bytes(data)
    out_json, out_file, report = tmp / "out.json", tmp / "out.csv", tmp / "report"
    analysis = ["--spec", "spec.toml", "--data", "log.csv"]
    seen = ["--spec", "spec.toml", "--data", "sim.csv", "--observations", "obs.csv", "--landmarks", "map.csv"]
    commands = {
        "log": [["compare", *analysis], ["fit", *analysis], ["diagnose", *analysis],
                ["compare", *seen], ["localize", *seen]],
        "spec": [["compare", *analysis], ["fit", *analysis], ["simulate", "--spec", "spec.toml", "--out", "out.csv"],
                 ["add-effect", "--spec", "spec.toml", "--effect", "lateral_slip", "--out", "out.toml"]]
                + ([["generate", "--spec-dir", "specs", "--out", "generated"], ["verify", "--spec", "spec.toml"]]
                   if base.symbolic else []),
        "sightings": [["localize", *seen], ["fit", *seen], ["diagnose", *seen]],
        "map": [["localize", *seen], ["compare", *seen]],
        "jobs": [["batch", "jobs.jsonl", "--out", "results.jsonl"]],
        "topics": [["compare", *analysis, "--topics", "topics.toml"]],
        "urdf": [["init", "--urdf", "robot.urdf", "--out", "out.toml"]],
        "controllers": [["init", "--urdf", "robot.urdf", "--controller", "controllers.yaml", "--out", "out.toml"]],
        "bag": [["compare", "--spec", "spec.toml", "--data", "run.bag"], ["fit", "--spec", "spec.toml", "--data", "run.bag"],
                ["diagnose", "--spec", "spec.toml", "--data", "run.bag"]],
        "grid": [["navigate", "--spec", "epuck.toml", "--grid", "arena.txt"],
                 ["navigate", "--spec", "epuck.toml", "--grid", "arena.txt", "--calibrate", "umbmark"]],
        "path": [["inverse", "--spec", str(ROOT / "spec" / "diff_drive.toml"), "--path", "path.csv"],
                 ["inverse", "--spec", str(ROOT / "spec" / "omni3.toml"), "--path", "path.csv"]],
        "shard": [["bench-diagnose", "--merge", *sorted(base.shards)]],
        # the real sessions are read, never written; one session keeps it short
        "benchmark": [["bench-real", str(base.real), "--config", "benchmark.toml", "--session",
                       "diff-square-230620202144", "--quiet"]],
    }
    if kind == "option":
        opt = rng.choice(list(HOSTILE_OPTIONS))
        value = rng.choice(HOSTILE_OPTIONS[opt])
        cmd = {"--set": ["fit", *analysis], "--noise": ["localize", *seen], "--gate": ["localize", *seen],
               "--max-gap": ["compare", *analysis],
               "--laps": ["simulate", "--spec", "spec.toml", "--out", "out.csv"],
               "--seed": ["simulate", "--spec", "spec.toml", "--out", "out.csv"],
               "--jobs": ["batch", "jobs.jsonl", "--out", "results.jsonl"],
               "--value": ["add-effect", "--spec", "spec.toml", "--effect", "lateral_slip", "--out", "out.toml"],
               "--cell": ["navigate", "--spec", "epuck.toml", "--grid", "arena.txt"],
               "--recalc": ["navigate", "--spec", "epuck.toml", "--grid", "arena.txt"],
               "--seeds": ["bench-diagnose", "--spec", "spec.toml", "--effect", "lateral_slip", "--laps", "1"],
               "--shard": ["bench-diagnose", "--spec", "spec.toml", "--effect", "lateral_slip", "--seeds", "1",
                           "--laps", "1"]}[opt]
        args = [*cmd, opt, value]
        what = f"{opt} {value}"
    else:
        args = list(rng.choice(commands[kind]))
        what = f"mutated {target or 'bag'}"
    if args[0] in ("compare", "fit", "diagnose", "localize", "navigate", "inverse", "bench-diagnose",
                   "bench-real"):
        args += ["--json", str(out_json)]
        if rng.random() < 0.2:
            args += ["--report", str(report)]
    outputs = [out_json, report, tmp / "out.toml", tmp / "generated"] + ([out_file] if args[0] == "simulate" else [])
    size = max([(tmp / n).stat().st_size for n in files]
               + [f.stat().st_size for f in (tmp / "run.bag").glob("*")])
    return args, outputs, size, what


def make_shards(bin_, work):
    """Two shards of a small recovery benchmark, for `bench-diagnose --merge`:
    {file name: JSON text}."""
    out = {}
    for k in (1, 2):
        name = f"shard{k}.json"
        subprocess.run([bin_, "bench-diagnose", "--spec", str(ROOT / "spec" / "diff_drive.toml"), "--effect",
                        "lateral_slip", "--seeds", "1", "--laps", "1", "--shard", f"{k}/2", "--json", name],
                       cwd=work, check=True, capture_output=True)
        out[name] = (work / name).read_text()
    return out


def benchmark_config():
    """The bundled bench-real configuration, its spec paths made absolute so
    that a copy anywhere reads the same specs."""
    config = ROOT / "spec" / "benchmarks" / "optiodom" / "benchmark.toml"
    return re.sub(r'^spec = "([^"]+)"', lambda m: f'spec = "{(config.parent / m[1]).resolve()}"',
                  config.read_text(), flags=re.M)


def real_optiodom():
    """The OptiOdom sessions bench-real reads (../shared/real, or
    $KINEGEN_REAL_DATA), or None: the benchmark cases are then left out."""
    real = Path(os.environ.get("KINEGEN_REAL_DATA", ROOT.parent / "shared" / "real")) / "optiodom-dev"
    return real if (real / "published.json").is_file() else None


def make_bag(work):
    """The short simulated log as a ROS 2 bag (joints, pose, gyro and
    sightings), written by the bag tests' own tool: {file name: bytes}, or
    None without its Python packages (the bag cases are then left out)."""
    out = work / "base.bag"
    p = subprocess.run(["python3", str(ROOT / "verify" / "bags" / "csv_to_bag.py"), str(work / "sim600.csv"),
                        str(out), "--joints", "enc_r,enc_l", "--observations", str(work / "obs.csv")],
                       capture_output=True)
    if p.returncode != 0:
        print("note: no bag cases (pip install -r verify/bags/requirements.txt):",
              p.stderr.decode(errors="replace").strip().splitlines()[-1:])
        return None
    return {f.name: f.read_bytes() for f in out.iterdir()}


def mutate_bytes(data, rng):
    """One byte-level change of a binary file: truncated, bytes flipped, a
    length field made huge or zero, a stretch repeated or cut out."""
    kind = rng.randrange(6)
    at = rng.randrange(len(data))
    if kind == 0:
        return data[:at]
    if kind == 1:
        b = bytearray(data)
        for _ in range(rng.randrange(1, 16)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    if kind == 2:  # a little-endian u64 (an MCAP length or count) made huge
        return data[:at] + rng.choice([b"\xff" * 8, (1 << 40).to_bytes(8, "little")]) + data[at + 8:]
    if kind == 3:
        return data[:at] + b"\0" * 8 + data[at + 8:]
    if kind == 4:
        n = rng.randrange(1, 4096)
        return data[:at] + data[at:at + n] + data[at:]
    n = rng.randrange(1, 4096)
    return data[:at] + data[at + n:]


def limit_memory():
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP, MEMORY_CAP))


def run_case(bin_, base, seed, k, keep):
    rng = random.Random(seed * 1_000_003 + k)
    tmp = Path(tempfile.mkdtemp(prefix=f"hostile{k}-"))
    try:
        args, outputs, size, what = case(base, rng, k, tmp)
        started = time.monotonic()
        # GNU time reports the child's own peak resident set (%M, KiB) and the
        # signal that killed it, if one did
        timed = [bin_, *args]
        if GNU_TIME:
            timed = [GNU_TIME, "-f", "%M %x", "-o", str(tmp / ".rss"), *timed]
        # its own process group, so a hang's kill reaches kinegen under time
        p = subprocess.Popen(timed, cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             preexec_fn=limit_memory, start_new_session=True,
                             env=dict(os.environ, NO_COLOR="1"))
        try:
            _, err = p.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.communicate()
            return verdict(k, args, what, "hang", "", size, 0, tmp, keep)
        code, rss = child_status(tmp / ".rss", p.returncode)
        text = err.decode("utf-8", "replace")
        problem = judge(code, text, outputs)
        return verdict(k, args, what, problem, text, size, rss, tmp, keep, code, time.monotonic() - started)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def child_status(path, returncode):
    """kinegen's exit code (negative: the signal that killed it) and peak
    resident set in bytes, from GNU time's report."""
    lines = path.read_text().splitlines() if path.exists() else []
    killed = next((int(l.split()[-1]) for l in lines if "terminated by signal" in l), None)
    figures = lines[-1].split() if lines else []
    rss = int(figures[0]) * 1024 if figures and figures[0].isdigit() else 0
    return (-killed if killed else returncode), rss


def judge(code, text, outputs):
    """What is wrong with a finished run, or None."""
    if code == 101 or "panicked at" in text:
        return "panic"
    if code < 0:
        return f"signal {-code}"
    if code not in (0, 1, 2):
        return f"exit {code}"
    stray = [str(o) for o in outputs if o.exists()]
    if code == 2:
        if stray:
            return "stray output on exit 2: " + ", ".join(stray)
        if not located(text):
            return "unlocated error"
    if code == 0 and outputs[0].exists():
        if not_finite_json(outputs[0].read_text(errors="replace")):
            return "NaN or infinity in the JSON document"
    return None


def not_finite_json(doc):
    """Whether a JSON document holds NaN or an infinity as a number (not as
    text: a landmark may be named `BNaN`), or is no JSON at all."""
    found = []
    try:
        json.loads(doc, parse_constant=lambda c: found.append(c))
    except ValueError:
        return True
    return bool(found)


def located(text):
    """An exit-2 message names a file (with a line, row or column), an
    option, or an input by name."""
    t = text.lower()
    return any(s in t for s in (".csv", ".toml", ".json", ".txt", ".urdf", ".yaml", ".mcap", "bag", "--", "line", "row",
                                "column", "option", "argument", "usage:"))


def verdict(k, args, what, problem, text, size, rss, tmp, keep, code=None, seconds=0.0):
    if problem and keep:
        dest = keep / f"case{k:05d}"
        shutil.copytree(tmp, dest, dirs_exist_ok=True)
        (dest / "REPRODUCE").write_text(f"cd {dest} && kinegen {' '.join(args)}\n# {problem}\n{text}")
    return {"k": k, "command": args[0], "what": what, "problem": problem, "exit": code,
            "size": size, "rss": rss, "seconds": seconds, "message": text.strip().splitlines()[-1:] if text else []}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default=str(ROOT / "target" / "debug" / "kinegen"))
    ap.add_argument("--cases", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--keep", type=Path)
    a = ap.parse_args()
    bin_ = str(Path(a.bin).resolve())
    work = Path(tempfile.mkdtemp(prefix="hostile-base-"))
    keep = a.keep or Path(tempfile.mkdtemp(prefix="hostile-failures-"))
    keep.mkdir(parents=True, exist_ok=True)
    base = Base(bin_, work)
    started = time.monotonic()
    with cf.ThreadPoolExecutor(a.jobs) as pool:
        results = list(pool.map(lambda k: run_case(bin_, base, a.seed, k, keep), range(a.cases)))
    shutil.rmtree(work, ignore_errors=True)
    report(results, time.monotonic() - started, keep)
    failed = [r for r in results if r["problem"]]
    raise SystemExit(1 if failed else 0)


def report(results, seconds, keep):
    by = {}
    for r in results:
        row = by.setdefault(r["command"], {"cases": 0, 0: 0, 1: 0, 2: 0, "failed": 0})
        row["cases"] += 1
        if r["problem"]:
            row["failed"] += 1
        elif r["exit"] in (0, 1, 2):
            row[r["exit"]] += 1
    print(f"{len(results)} hostile cases in {seconds:.0f} s")
    print(f"{'command':<11} {'cases':>6} {'exit 0':>7} {'exit 1':>7} {'exit 2':>7} {'failed':>7}")
    for cmd, row in sorted(by.items()):
        print(f"{cmd:<11} {row['cases']:>6} {row[0]:>7} {row[1]:>7} {row[2]:>7} {row['failed']:>7}")
    failed = [r for r in results if r["problem"]]
    # peak memory as a base (the binary, its tables) plus a multiple of the
    # largest input: the base is the smallest input's peak
    done = [r for r in results if r["rss"]]
    if not done:
        print("peak memory not measured (no GNU time at /usr/bin/time: apt-get install time)")
    if done:
        base = min(r["rss"] for r in done)
        big = [r for r in done if r["size"] >= 1 << 20]
        print(f"peak memory: at most {max(r['rss'] for r in done) >> 20} MB; the base {base >> 20} MB")
        if big:
            worst = max(big, key=lambda r: (r["rss"] - base) / r["size"])
            print(f"  above the base, at most {(worst['rss'] - base) / worst['size']:.1f}x the largest input "
                  f"over the {len(big)} cases with an input of 1 MB or more ({worst['command']})")
    kinds = {}
    for r in results:
        kind = r["what"].split()[-1] if r["what"].startswith("mutated") else "option"
        kinds[kind] = kinds.get(kind, 0) + 1
    print("inputs mutated: " + ", ".join(f"{k} {n}" for k, n in sorted(kinds.items())))
    for r in failed[:20]:
        print(f"FAILED case {r['k']}: {r['command']} ({r['what']}): {r['problem']} {r['message']}")
    if failed:
        print(f"{len(failed)} failed; reproducers in {keep}")
    else:
        shutil.rmtree(keep, ignore_errors=True)


if __name__ == "__main__":
    main()
