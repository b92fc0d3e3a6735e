#!/usr/bin/python3
"""bad_files — every file a scene names is checked before it is trusted (issue 31).

tests/bad/files/make_bad_files.py writes a few hundred malformed or unusual
NIfTI images, STL surfaces, refinement templates and checkpoints, each with
a scene naming it; this runs the reader on each through the binary
(`needlehex check SCENE`, or `needlehex run SCENE --restart DIR` for a
checkpoint; a FIFO case is fed by a thread here while it runs) and requires:

  bad case:  exit status 2 and exactly one stderr line "needlehex: ..." that
             names the file, the scene's line and key that name it
             ("scene.yaml:LINE: KEY: ": tissue.domain.mask.file,
             tissue.labels.file, tissue.domain.surface.file, adapt.template;
             --restart for a checkpoint), and the problem (each of
             the case's `expect` strings, written from what the file holds,
             not copied from a run); so nothing from a library before it;
  control:   exit status 0 and an empty stderr;
  both:      under 10 s wall time and 600 MB peak memory (the child's
             ru_maxrss from wait4).

Prints the number of cases, the slowest and the largest; silent otherwise
unless NH_TEST_VERBOSE=1. Environment: NH_BINARY, NH_SOURCE_DIR, NH_WORK.
"""
import errno
import os
import subprocess
import sys
import tempfile
import threading
import time

SRC = os.environ.get("NH_SOURCE_DIR", os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.join(SRC, "tests", "bad", "files"))
import make_bad_files as mbf  # noqa: E402

BIN = os.path.abspath(os.environ.get("NH_BINARY", "needlehex"))
WORK = tempfile.mkdtemp(prefix="nh_bad_files_", dir=os.environ.get("NH_WORK"))
VERBOSE = bool(os.environ.get("NH_TEST_VERBOSE"))
MAX_SECONDS, MAX_MB = 10.0, 600.0


def feeder(path, data, total, stop):
    """Write data (repeated) up to total bytes into the FIFO once a reader
    opens it (once only: a second writer could join the first reader)."""
    chunk = data * max(1, 65536 // len(data))
    while not stop.is_set():
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        except OSError as e:
            if e.errno != errno.ENXIO:
                return
            time.sleep(0.002)
            continue
        os.set_blocking(fd, True)
        written = 0
        try:
            while written < total and not stop.is_set():
                written += os.write(fd, chunk[:total - written])
        except OSError:
            pass
        finally:
            os.close(fd)
        return


def run(c):
    stop = threading.Event()
    thread = None
    if c.feed is not None:
        thread = threading.Thread(target=feeder, daemon=True,
                                  args=(os.path.join(c.dir, c.file), c.feed, c.feed_bytes, stop))
        thread.start()
    start = time.monotonic()
    err_path = os.path.join(c.dir, "stderr.txt")
    with open(err_path, "w") as err, open(os.devnull, "w") as out:
        p = subprocess.Popen(mbf.command(c, BIN), stdout=out, stderr=err, cwd=c.dir)
        killed = False
        while True:
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() - start > 4 * MAX_SECONDS:
                p.kill()
                killed = True
            time.sleep(0.005)
    seconds = time.monotonic() - start
    stop.set()
    rc = os.waitstatus_to_exitcode(status)
    p.returncode = rc
    stderr = open(err_path).read()
    return rc, stderr, seconds, usage.ru_maxrss / 1024.0, killed


def judge(c, rc, stderr, seconds, mb, killed):
    problems = []
    if killed:
        problems.append(f"killed after {seconds:.1f} s (a hang)")
    if seconds > MAX_SECONDS:
        problems.append(f"took {seconds:.2f} s (at most {MAX_SECONDS})")
    if mb > MAX_MB:
        problems.append(f"peak memory {mb:.0f} MB (at most {MAX_MB})")
    lines = stderr.splitlines()
    if c.ok:
        if rc != 0 or stderr:
            problems.append(f"a valid file: expected exit 0 and no stderr, got {rc}: {stderr!r}")
        return problems
    if rc != 2:
        problems.append(f"expected exit 2, got {rc}")
    if len(lines) != 1 or not lines[0].startswith("needlehex: "):
        problems.append(f"expected one stderr line 'needlehex: ...', got {len(lines)}: {stderr!r}")
        return problems
    line = lines[0]
    want = [c.file if c.key != "restart" else "checkpoint.nhc"] + c.expect
    want.append(mbf.KEY[c.key])
    if c.key in mbf.LINE:
        want.append(f"scene.yaml:{mbf.LINE[c.key]}: {mbf.KEY[c.key]}: ")
    missing = [w for w in want if w not in line]
    if missing:
        problems.append(f"the message lacks {missing}: {line}")
    return problems


def main():
    cases = mbf.make_all(WORK, BIN, SRC)
    failures, slowest, largest = [], (0, None), (0, None)
    for c in cases:
        rc, stderr, seconds, mb, killed = run(c)
        slowest = max(slowest, (seconds, c.name))
        largest = max(largest, (mb, c.name))
        problems = judge(c, rc, stderr, seconds, mb, killed)
        if VERBOSE:
            print(f"{c.name}: exit {rc}, {seconds:.3f} s, {mb:.0f} MB: {stderr.strip()}")
        if problems:
            failures.append(f"{c.name} ({c.dir}):\n  " + "\n  ".join(problems))
    bad = sum(not c.ok for c in cases)
    print(f"bad_files: {bad} bad inputs and {len(cases) - bad} controls; slowest "
          f"{slowest[0]:.2f} s ({slowest[1]}), largest {largest[0]:.0f} MB ({largest[1]})")
    for f in failures:
        print("FAIL:", f, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
