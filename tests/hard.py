"""Hard scenes (issue 27) that must run to completion: tests/hard/NAME.yaml
for each NAME given (NAME:END: only up to time.end = END). Asserted per scene: exit status 0; steps.csv has every
step of time.end / time.step (counted from the scene, not from the run);
every step's constraint_residual is at most the solver's tolerance 1e-10
(docs/interaction.md, Stopping rule), i.e. no stalled solve was accepted.
Silent on success."""
import csv
import os
import subprocess
import sys
import tempfile

SRC = os.environ.get("NH_SOURCE_DIR", os.path.join(os.path.dirname(__file__), ".."))
BIN = os.environ.get("NH_BINARY", "needlehex")
WORK = os.environ.get("NH_WORK", tempfile.gettempdir())
TOLERANCE = 1e-10
failed = 0


def fail(msg):
    global failed
    failed += 1
    print("hard: " + msg, file=sys.stderr)


def expected_steps(path, end=None):
    """time.end (or end) / time.step from the scene's one-line time mapping."""
    for line in open(path):
        if line.startswith("time:"):
            kv = dict(p.split(":") for p in line.split("{")[1].split("}")[0].split(","))
            return round(float(end or kv[" end"]) / float(kv[" step"]))
    raise ValueError(path + ": no time line")


for arg in sys.argv[1:]:
    name, _, end = arg.partition(":")
    scene = os.path.join(SRC, "tests", "hard", name + ".yaml")
    out = os.path.join(WORK, "hard_" + name + ("_" + end if end else ""))
    extra = ["--set", "time.end=" + end] if end else []
    p = subprocess.run([BIN, "run", scene, "--out", out, "--overwrite", "--quiet"] + extra,
                       capture_output=True, text=True)
    if p.returncode != 0:
        fail("%s: exit %d, expected 0: %s" % (name, p.returncode, p.stderr.strip()[-400:]))
        continue
    rows = list(csv.DictReader(open(os.path.join(out, "steps.csv"))))
    n = expected_steps(scene, end)
    last = int(float(rows[-1]["step"])) if rows else -1
    if last != n:
        fail("%s: last step %d, expected %d" % (name, last, n))
    for r in rows:
        res = float(r["constraint_residual"])
        if not res <= TOLERANCE:
            fail("%s: step %s constraint_residual %g > tolerance %g"
                 % (name, r["step"], res, TOLERANCE))
sys.exit(1 if failed else 0)
