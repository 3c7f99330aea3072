#!/usr/bin/env python3
"""Run `kinegen batch` jobs on a Dask cluster: the fleet beyond one machine.

Each job of JOBS.jsonl becomes one Dask task. The task runs, on whichever
worker gets it, `kinegen batch` on a file holding that one job, so a result
line is made by the same code as on one machine. Result lines are appended
to RESULTS.jsonl as tasks finish; ids already there are skipped (resumable),
as with `kinegen batch`.

    python3 scripts/dask_batch.py jobs.jsonl --out results.jsonl --local 2
    python3 scripts/dask_batch.py jobs.jsonl --out results.jsonl --scheduler tcp://head:8786

A worker needs the kinegen binary (--kinegen, or `kinegen` on its PATH) and
the jobs' files at the same paths as the machine that submits them (a shared
filesystem, or absolute paths to data every worker has). Start a real
cluster with Dask's own tools (`dask scheduler` and `dask worker ADDRESS` on
each machine, dask-jobqueue on a batch system, or the Dask Kubernetes
operator) and pass the scheduler's address.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile


def run_one(job, kinegen, cwd):
    """One job through `kinegen batch` on the worker; its result line."""
    with tempfile.TemporaryDirectory(prefix="kinegen-dask-") as tmp:
        jobs = os.path.join(tmp, "job.jsonl")
        out = os.path.join(tmp, "result.jsonl")
        with open(jobs, "w") as f:
            f.write(json.dumps(job) + "\n")
        proc = subprocess.run(
            [kinegen, "batch", jobs, "--out", out, "--jobs", "1"],
            cwd=cwd,
            capture_output=True,
            text=True,
        )
        try:
            with open(out) as f:
                return json.loads(f.readline())
        except (OSError, ValueError):
            return {"id": job["id"], "exit": None, "error": proc.stderr.strip()[-2000:], "seconds": None}


def read_jobs(path):
    jobs = []
    with open(path) as f:
        for n, line in enumerate(f, 1):
            if line.strip():
                try:
                    job = json.loads(line)
                except ValueError as e:
                    sys.exit(f"{path}:{n}: not a JSON object: {e}")
                jobs.append(job)
    return jobs


def done_ids(path):
    """Ids already in RESULTS; a last line cut short is dropped (as kinegen batch does)."""
    if not os.path.exists(path):
        return set()
    with open(path) as f:
        text = f.read()
    whole = text.rfind("\n") + 1
    if whole < len(text):
        with open(path, "w") as f:
            f.write(text[:whole])
    ids = set()
    for line in text[:whole].splitlines():
        try:
            ids.add(json.loads(line)["id"])
        except (ValueError, KeyError):
            pass
    return ids


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("jobs", help="JOBS.jsonl, as for kinegen batch")
    ap.add_argument("--out", required=True, help="RESULTS.jsonl (appended to)")
    where = ap.add_mutually_exclusive_group(required=True)
    where.add_argument("--scheduler", help="address of a running Dask scheduler")
    where.add_argument("--local", type=int, metavar="N", help="start a local cluster of N workers")
    ap.add_argument("--kinegen", default="kinegen", help="the kinegen binary on the workers")
    a = ap.parse_args()

    from dask.distributed import Client, LocalCluster, as_completed

    jobs = read_jobs(a.jobs)
    done = done_ids(a.out)
    todo = [j for j in jobs if j.get("id") not in done]
    cwd = os.getcwd()
    kinegen = os.path.abspath(a.kinegen) if os.path.sep in a.kinegen else a.kinegen
    if a.local:
        # one thread per worker: each task is a process that may use the cores itself
        cluster = LocalCluster(n_workers=a.local, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    else:
        cluster = None
        client = Client(a.scheduler)
    print(f"dask_batch: {len(jobs)} job(s), {len(jobs) - len(todo)} already in {a.out}, {len(todo)} to run", file=sys.stderr)
    failed = 0
    try:
        futures = [client.submit(run_one, j, kinegen, cwd, key=f"kinegen-{j['id']}", pure=False) for j in todo]
        with open(a.out, "a") as out:
            for fut in as_completed(futures):
                line = fut.result()
                failed += line.get("exit") != 0
                out.write(json.dumps(line) + "\n")
                out.flush()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    print(f"dask_batch: {len(todo)} job(s) run, {failed} failed; results in {a.out}", file=sys.stderr)
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
