#!/usr/bin/python3
"""Output folder hygiene: a fresh run into a folder holding another run's
files is refused (exit 2, naming --restart and --overwrite); --overwrite
removes the previous run's files (not the user's) and runs; --restart
continues into it.

cases/phantom-tissue.yaml: a first run of 20 steps with a checkpoint every
10; a second run into the same folder must be refused and leave it
untouched; a run with --overwrite and 5 steps must leave exactly its own
frames 0 and 5 (none of the first run's 10, 15, 20) and the user's notes.txt;
--restart of a 20-step run (checkpoint at 10) must be accepted.
Silent on success; loud on failure."""
import os
import shutil
import subprocess
import sys
import tempfile

BIN, SRC = os.environ["NH_BINARY"], os.environ["NH_SOURCE_DIR"]
SCENE = os.path.join(SRC, "cases", "phantom-tissue.yaml")
failures = []


def run(out, *extra):
    return subprocess.run([BIN, "run", SCENE, "--out", out, "--quiet", *extra],
                          capture_output=True, text=True, timeout=300)


def frames(out):
    return sorted(f for f in os.listdir(out) if f.startswith("tissue_") and f.endswith(".vtu"))


def main():
    tmp = tempfile.mkdtemp(prefix="nh-folder-")
    try:
        out = os.path.join(tmp, "run")
        long_run = ["--set", "time.steps=20", "--set", "output.checkpoint=10"]
        r = run(out, *long_run)
        if r.returncode != 0:
            failures.append(f"first run: exit {r.returncode}: {r.stderr}")
            return 1
        with open(os.path.join(out, "notes.txt"), "w") as f:
            f.write("the user's own file\n")
        before = sorted(os.listdir(out))
        r = run(out, *long_run)
        if r.returncode != 2 or "--overwrite" not in r.stderr or "--restart" not in r.stderr:
            failures.append(f"second run: expected exit 2 naming --overwrite and --restart, got "
                            f"{r.returncode}: {r.stderr}")
        if sorted(os.listdir(out)) != before:
            failures.append("the refused run changed the folder")
        r = run(out, "--restart", out, *long_run)
        if r.returncode != 0:
            failures.append(f"--restart: exit {r.returncode}: {r.stderr}")
        r = run(out, "--overwrite", "--set", "time.steps=5")
        expected = ["tissue_000000.vtu", "tissue_000005.vtu"]  # output.every: 5
        if r.returncode != 0 or frames(out) != expected:
            failures.append(f"--overwrite: exit {r.returncode}, frames {frames(out)}, expected "
                            f"{expected}: {r.stderr}")
        if not os.path.exists(os.path.join(out, "notes.txt")):
            failures.append("--overwrite removed the user's notes.txt")
        if os.path.exists(os.path.join(out, "checkpoint.nhc")):
            failures.append("--overwrite left the previous run's checkpoint.nhc")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    for f in failures:
        print(f, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
