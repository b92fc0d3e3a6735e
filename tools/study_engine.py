"""The engine of tools/study.py: runs the variants of a study (each one
`needlehex run` into its own folder) through dask.distributed, on a
LocalCluster of N worker processes on this machine or on an existing
cluster (docs/performance.md, "Studies on a cluster"), and gives the
studies (tools/study_*.py) their folders and report.

    jobs = [Job(name, out, cmd), ...]
    done = run_jobs(jobs, workers=2)              # LocalCluster of 2 workers
    done = run_jobs(jobs, scheduler="tcp://127.0.0.1:8786")
    done = run_jobs(jobs, workers=0)              # serial, in this process, no Dask

A study, with the parsed options `a` of tools/study.py:

    out = out_dir(a, "phantom")                   # --out, else out/study/phantom
    img = plot_dir(a, out)                        # --img, docs/img with --docs, else OUT/img
    infos = run_variants(a, binary, scene, out, [(name, sets), ...])
    write_report(out, lines)                      # printed and OUT/report.md

Each variant runs in OUT.partial and is renamed to OUT once needlehex exits
0, with OUT/run.json recording its command, wall time, CPU time (user +
sys), host, date, exit code and the machine's 1-minute load average at its
start and end: a
folder OUT with a run.json is a complete variant, anything else is not.
With skip_complete, a variant whose OUT/run.json records the same command
is not run again (a restart after an interruption, or a sweep grown by new
values). A variant that fails (exit code != 0, or its worker lost more
often than the scheduler allows, e.g. killed by the cluster) is reported
with its reason and the others go on; run_jobs returns the results of all
and the caller reports the failed ones. A worker killed mid-variant is
replaced by the LocalCluster's nanny and the variant rescheduled (Dask's
distributed.scheduler.allowed-failures, default 3); the needlehex process
of the killed worker dies with it (PR_SET_PDEATHSIG) and only ever wrote to
its own partial folder.

Each run is single-threaded by default (OMP_NUM_THREADS=1,
OPENBLAS_NUM_THREADS=1): N workers on N cores then do not compete for
cores inside one run. The LocalCluster's scheduler and workers listen on
127.0.0.1 only, their HTTP servers included (tests/plan_sweep.py checks).
Only the standard library at import (the engine uploads itself to a
cluster's workers); needs Debian's python3-distributed for Dask; use
/usr/bin/python3.
"""
import ctypes
import json
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections import namedtuple

# accept: the exit codes that make a variant complete (a plan that did not converge exits 1
# and is a result, not a failure: tools/study_sweep.py, `command: plan`)
Job = namedtuple("Job", "name out cmd accept", defaults=((0,),))
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _die_with_parent():
    """In the child: receive SIGKILL when the worker process that started it dies (Linux)."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def execute(name, out, cmd, threads=1, accept=(0,)):
    """Runs one variant (in a worker, or in this process): needlehex into OUT.partial, then
    renamed to OUT. Returns its run.json record (with the exit code, and the last lines of
    stderr if it is not 0); raises RuntimeError on an exit code not in `accept`."""
    part = out + ".partial"
    shutil.rmtree(part, ignore_errors=True)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS=str(threads))
    argv = list(cmd) + ["--out", part]
    t0, load0 = time.time(), os.getloadavg()[0]
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    p = subprocess.run(argv, env=env, capture_output=True, text=True, preexec_fn=_die_with_parent)
    wall = time.time() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)  # the run's CPU: load does not inflate it
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    tail = " / ".join((p.stderr or p.stdout).strip().splitlines()[-3:])
    if p.returncode not in accept:
        raise RuntimeError("needlehex exit %d: %s" % (p.returncode, tail))
    info = {"cmd": list(cmd), "wall": wall, "cpu": cpu, "host": socket.gethostname(), "pid": os.getpid(),
            "date": time.strftime("%Y-%m-%d %H:%M:%S"), "returncode": p.returncode,
            "load": [load0, os.getloadavg()[0]]}  # 1-min load average at the start and end
    if p.returncode != 0:
        info["message"] = tail
    with open(os.path.join(part, "run.json"), "w") as f:
        json.dump(info, f)
    shutil.rmtree(out, ignore_errors=True)
    os.replace(part, out)
    return info


def complete(job, same_command=True):
    """The run.json record of a complete variant (with the same command), else None."""
    try:
        with open(os.path.join(job.out, "run.json")) as f:
            info = json.load(f)
    except (OSError, ValueError):
        return None
    return info if not same_command or info.get("cmd") == list(job.cmd) else None


class Progress:
    """One line per finished variant on stderr: count, name, wall time, failures so far."""

    def __init__(self, total, quiet=False):
        self.total, self.done, self.failed, self.quiet, self.t0 = total, 0, 0, quiet, time.time()

    def update(self, name, info=None, error=None):
        self.done += 1
        self.failed += error is not None
        if self.quiet:
            return
        width = 24
        bar = "#" * (width * self.done // max(self.total, 1))
        what = ("FAILED: %s" % error) if error else ("%.1f s" % info["wall"])
        print("[%-*s] %d/%d %s %s (%.0f s elapsed, %d failed)" % (
            width, bar, self.done, self.total, name, what, time.time() - self.t0, self.failed),
            file=sys.stderr, flush=True)


def _client(workers, scheduler):
    from distributed import Client, LocalCluster
    if scheduler:
        client = Client(scheduler)
        client.upload_file(os.path.abspath(__file__))  # the workers import `execute` from it
        return client, None
    # every listening socket on loopback: host for the scheduler's and workers' TCP, and the HTTP
    # servers (metrics, health) that scheduler and workers start even without a dashboard,
    # which otherwise listen on all interfaces (distributed 2022.12)
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address=None,
                           scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                           worker_dashboard_address="127.0.0.1:0", silence_logs=40)
    return Client(cluster), cluster


def run_jobs(jobs, workers=1, scheduler=None, skip_complete=False, same_command=True, threads=1,
             quiet=False):
    """Runs every job; returns ({name: run.json record}, {name: reason}) for the complete and the
    failed ones. workers = 0 runs them one after another in this process (no Dask).
    skip_complete: a job already complete in its folder (with the same command, unless
    same_command is False) is not run again."""
    done, failed, todo = {}, {}, []
    for j in jobs:
        info = complete(j, same_command) if skip_complete else None
        if info is not None:
            done[j.name] = dict(info, skipped=True)
        else:
            todo.append(j)
    if skip_complete and done and not quiet:
        print("%d of %d variants already complete: skipped" % (len(done), len(jobs)),
              file=sys.stderr)
    bar = Progress(len(todo), quiet)
    if not todo:
        return done, failed
    if workers == 0 and not scheduler:
        for j in todo:
            try:
                done[j.name] = execute(j.name, j.out, j.cmd, threads, j.accept)
                bar.update(j.name, done[j.name])
            except RuntimeError as e:
                failed[j.name] = str(e)
                bar.update(j.name, error=str(e))
        return done, failed
    from distributed import as_completed
    client, cluster = _client(workers, scheduler)
    try:
        futures = {client.submit(execute, j.name, j.out, j.cmd, threads, j.accept,
                                 key="variant-%s-%s" % (j.name, os.urandom(4).hex()), pure=False): j
                   for j in todo}
        for fut in as_completed(futures):
            j = futures[fut]
            try:
                done[j.name] = fut.result()
                bar.update(j.name, done[j.name])
            except Exception as e:  # needlehex failed, or the worker was lost (KilledWorker)
                reason = "%s: %s" % (type(e).__name__, e)
                failed[j.name] = reason
                bar.update(j.name, error=reason)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return done, failed


def report_failures(failed):
    """Prints the failed variants; returns the exit status (1 if any failed)."""
    for name in sorted(failed):
        print("variant %s failed: %s" % (name, failed[name]), file=sys.stderr)
    return 1 if failed else 0


def add_arguments(ap, default_workers):
    """The engine's command-line options."""
    g = ap.add_argument_group("execution (dask.distributed)")
    g.add_argument("--workers", type=int, default=default_workers,
                   help="LocalCluster worker processes (0: serial, no Dask; default: the cores "
                   "for a sweep, 1 for the timing studies)")
    g.add_argument("--scheduler", default=None,
                   help="an existing Dask scheduler, tcp://HOST:PORT, instead of a LocalCluster")
    g.add_argument("--threads", type=int, default=1,
                   help="OpenMP/BLAS threads per run (default 1)")
    g.add_argument("--restart", action="store_true",
                   help="skip variants already complete in OUT (same command)")


# ---- the studies' side: folders, variants from the options, the report ----

def find_binary(given):
    """The needlehex binary: GIVEN (--binary), else build/needlehex of the source tree."""
    for b in ([given] if given else [os.path.join(ROOT, "build", "needlehex")]):
        if b and os.path.exists(b):
            return os.path.abspath(b)
    raise SystemExit("no needlehex binary (build it: tools/run-case.sh, or pass --binary)")


def out_dir(a, study):
    """The study's folder: --out, else out/study/STUDY of the source tree, with the values of
    the --set overrides appended (out/study/dbs-goal-mortar), so that runs with and without
    them do not share a folder."""
    if a.out:
        return a.out
    tag = "-".join([study] + [s.split("=", 1)[-1] for s in a.sets])
    return os.path.join(ROOT, "out", "study", re.sub(r"[^A-Za-z0-9_.-]", "_", tag))


def plot_dir(a, out):
    """Where the PNGs go: --img, else docs/img with --docs, else OUT/img."""
    img = a.img or (os.path.join(ROOT, "docs", "img") if a.docs else os.path.join(out, "img"))
    os.makedirs(img, exist_ok=True)
    return img


def run_variants(a, binary, scene, out, variants):
    """Runs the variants [(name, sets)] of a study into OUT/NAME through the engine
    (--workers, --scheduler, --threads; --set: overrides after each variant's own; --steps:
    time.steps for every variant); with --reuse
    a variant already complete in OUT is reported on, not run again (--restart: only if its
    command is the same). Returns {name: run.json record} of the complete ones; failed ones
    are reported."""
    jobs = []
    for name, sets in variants:
        cmd = [binary, "run", scene, "--quiet"]
        for s in sets + a.sets + (["time.steps=%d" % a.steps] if a.steps else []):
            cmd += ["--set", s]
        jobs.append(Job(name, os.path.join(out, name), cmd))
    done, failed = run_jobs(jobs, workers=a.workers, scheduler=a.scheduler,
                            skip_complete=a.reuse or a.restart, same_command=not a.reuse,
                            threads=a.threads)
    report_failures(failed)
    return done


def run_with_reference(a, binary, st, out):
    """Runs the study's selected variants (--only) of st["variants"] [(name, label, sets,
    kind)] and, when missing or with --fresh-reference, its reference st["reference"] (name,
    label, sets), or each of its cached runs st["references"] [(name, label, sets)], first
    (the longest runs); returns the (first) reference's name, label and folder and the runs'
    records."""
    refs = st.get("references") or [st["reference"]]
    selected = [(name, sets) for name, _, sets, _ in st["variants"] if not a.only or name in a.only]
    for rname, _, rsets in reversed(refs):
        if a.fresh_reference or not os.path.exists(os.path.join(out, rname, "run.json")):
            selected.insert(0, (rname, rsets))  # the longest runs first
    infos = run_variants(a, binary, st["scene"], out, selected)
    for rname, _, _ in refs:
        if not os.path.exists(os.path.join(out, rname, "run.json")):
            raise SystemExit("no reference run in %s" % os.path.join(out, rname))
    rname, rlabel, _ = refs[0]
    return rname, rlabel, os.path.join(out, rname), infos


def table_head(*columns):
    """The first two lines of a Markdown table of the report: the columns' names and the rule."""
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]


def write_report(out, lines):
    """Prints the report and writes it to OUT/report.md."""
    report = "\n".join(lines)
    print(report)
    with open(os.path.join(out, "report.md"), "w") as f:
        f.write(report + "\n")
