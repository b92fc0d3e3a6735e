#!/usr/bin/python3
"""cholmod_memory.py — a factorisation that does not fit in memory is named
(issue 31): the phantom on 64 x 32 x 32 cells (209088 unknowns, a factor of
about 1.9 GB by CHOLMOD's own count) under an address-space limit of 1.2 GB
stops with exit 1 and one line naming CHOLMOD, "out of memory", the step and
the unknowns — not "status -2". Silent on success; exit 1 on failure.
"""
import os
import resource
import subprocess
import sys

BIN = sys.argv[1]
SRC = os.environ["NH_SOURCE_DIR"]
OUT = os.path.join(os.environ.get("NH_WORK", "."), "cholmod_memory")
LIMIT = 1200 * 1024 * 1024


def limit():
    resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))


p = subprocess.run([BIN, "run", os.path.join(SRC, "cases", "phantom", "phantom.yaml"), "--out", OUT,
                    "--overwrite", "--quiet", "--set", "tissue.grid=[64,32,32]",
                    "--set", "time.end=0.01"], capture_output=True, text=True, preexec_fn=limit)
lines = p.stderr.strip().splitlines()
ok = (p.returncode == 1 and len(lines) == 1 and "CHOLMOD ran out of memory" in lines[0]
      and "step 1" in lines[0] and "209088 unknowns" in lines[0] and "status" not in lines[0])
if not ok:
    print("FAIL: exit %d, stderr:\n%s" % (p.returncode, p.stderr), file=sys.stderr)
sys.exit(0 if ok else 1)
