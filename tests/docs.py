#!/usr/bin/python3
"""Every snippet of README.md and docs/*.md runs (docs that hold).

The fenced blocks of each file are taken in order:

- ```sh  blocks run with bash -e, one block at a time, in a scratch tree
  ($NH_WORK/docs/tree) that looks like the source tree: cases/ and
  templates/ linked, tools/ copied (scripts write next to themselves), an
  empty docs/img/, and build/needlehex linked to $NH_BINARY. Exit 0 needed.
- ```python blocks run with /usr/bin/python3 in the same tree, after the
  blocks before them (a snippet that reads out/X runs after the one that
  made it). Exit 0 needed.
- ```yaml blocks: a complete scene (it has `name`) is written to a file and
  `needlehex check` must accept it; a fragment (no `name`) replaces its
  top-level keys in the last complete scene of the same file, and that
  must pass `check`.
- ```text blocks are command synopses (usage lines); not run.
- Untagged blocks are output, file listings and formulas; none may hold a
  command (a line starting build/needlehex, needlehex, /usr/bin/python3,
  python3, tools/, cmake or a Python import): a runnable snippet must be
  tagged, so it is run.

A comment on the line before a fence changes how its block is run:
  <!-- docs-test: help (WHY) -->   each command's program is run with --help
                                   instead of its arguments (studies and
                                   plans that take minutes; their work is
                                   tested elsewhere, named in the comment)
  <!-- docs-test: skip REASON -->  not run (the CI commands themselves)
The counts of blocks run, --help only and skipped are printed when
NH_TEST_VERBOSE is set. Silent on success; one line per failure, exit 1.
"""
import glob
import os
import re
import shlex
import shutil
import subprocess
import sys
import time

import yaml

SRC = os.environ["NH_SOURCE_DIR"]
BIN = os.environ["NH_BINARY"]
WORK = os.path.join(os.environ.get("NH_WORK", "."), "docs")
TREE = os.path.join(WORK, "tree")
COMMAND = re.compile(r"^\s*(build/needlehex|needlehex |/usr/bin/python3|python3 |tools/|cmake |"
                     r"import |from \S+ import )")
failures = []
counts = {"run": 0, "help": 0, "skip": 0}


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def blocks(path):
    """(line, language, directive, text) of each fenced block."""
    out = []
    lines = open(path, encoding="utf-8").read().split("\n")
    i = 0
    while i < len(lines):
        m = re.match(r"^```(\S*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        lang, start = m.group(1), i
        prev = lines[i - 1].strip() if i > 0 else ""
        d = re.match(r"<!-- docs-test: (.*?) -->", prev)
        j = i + 1
        while j < len(lines) and not lines[j].startswith("```"):
            j += 1
        out.append((start + 1, lang, d.group(1) if d else None, "\n".join(lines[i + 1:j])))
        i = j + 1
    return out


def make_tree():
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(os.path.join(TREE, "docs", "img"))
    os.makedirs(os.path.join(TREE, "build"))
    for d in ("cases", "templates", "tests"):
        os.symlink(os.path.join(SRC, d), os.path.join(TREE, d))
    shutil.copytree(os.path.join(SRC, "tools"), os.path.join(TREE, "tools"))
    # The pages run some cases more than once (README and cases.md both run
    # the cantilever into out/cantilever), as a reader going through them
    # would after clearing the folder: the tree's needlehex replaces a
    # previous run's outputs (--overwrite). The refusal itself is
    # tests/output_folder.py's.
    wrapper = os.path.join(TREE, "build", "needlehex")
    with open(wrapper, "w") as f:
        f.write('#!/bin/sh\nif [ "$1" = run ]; then shift; exec "%s" run --overwrite "$@"; fi\n'
                'exec "%s" "$@"\n' % (BIN, BIN))
    os.chmod(wrapper, 0o755)
    # the test programs the pages drive (build/tests/refine_cells_tool)
    tests = os.path.join(os.path.dirname(BIN), "tests")
    if os.path.isdir(tests):
        os.symlink(tests, os.path.join(TREE, "build", "tests"))


def run(where, cmd, **kw):
    env = dict(os.environ, MPLBACKEND="Agg")
    env.pop("NH_TEMPLATES_DIR", None)
    t0 = time.time()
    p = subprocess.run(cmd, cwd=TREE, capture_output=True, text=True, env=env, timeout=900, **kw)
    if os.environ.get("NH_TEST_VERBOSE") and time.time() - t0 > 5:
        print("docs: %s took %.0f s" % (where, time.time() - t0))
    if p.returncode != 0:
        fail("%s: exit %d: %s" % (where, p.returncode, (p.stderr or p.stdout).strip()[-1500:]))
    return p.returncode == 0


def help_only(where, text):
    """Each command's program (the interpreter and its script) with --help."""
    for line in text.replace("\\\n", " ").split("\n"):
        line = line.split("#")[0].strip()
        if not line:
            continue
        tokens = shlex.split(line)
        n = 2 if tokens[0].endswith("python3") else 3 if tokens[0].endswith("needlehex") else 1
        if tokens[0].endswith("needlehex"):
            n = 2  # needlehex COMMAND --help
        run(where, tokens[:n] + ["--help"])


def check_scene(where, scene):
    path = os.path.join(WORK, "scene-%d.yaml" % len(os.listdir(WORK)))
    with open(path, "w") as f:
        yaml.safe_dump(scene, f, sort_keys=False)
    run(where, [BIN, "check", path])


def main():
    make_tree()
    files = [os.path.join(SRC, "README.md")] + sorted(glob.glob(os.path.join(SRC, "docs", "*.md")))
    for path in files:
        rel = os.path.relpath(path, SRC)
        complete = None
        for line, lang, directive, text in blocks(path):
            where = "%s:%d (```%s)" % (rel, line, lang)
            if directive and directive.startswith("skip"):
                if len(directive.split(None, 1)) < 2:
                    fail("%s: docs-test: skip needs a reason" % where)
                counts["skip"] += 1
                continue
            if directive and directive.startswith("help"):
                counts["help"] += 1
                help_only(where, text)
                continue
            if directive:
                fail("%s: unknown docs-test directive %r" % (where, directive))
                continue
            if lang in ("sh", "bash"):
                counts["run"] += 1
                run(where, ["bash", "-e", "-c", text])
            elif lang == "python":
                counts["run"] += 1
                run(where, ["/usr/bin/python3", "-c", text])
            elif lang == "yaml":
                counts["run"] += 1
                doc = yaml.safe_load(text)
                if isinstance(doc, dict) and "name" in doc:
                    complete = doc
                    check_scene(where, doc)
                elif complete is None:
                    fail("%s: a scene fragment with no complete scene before it in the file"
                         % where)
                else:
                    merged = dict(complete)
                    merged.update(doc)
                    check_scene(where, merged)
            elif lang == "text":
                pass  # a synopsis: usage lines, not a command to run
            elif lang == "":
                for k, ln in enumerate(text.split("\n")):
                    if COMMAND.match(ln):
                        fail("%s:+%d: an untagged block holds a command (%r): tag it ```sh or "
                             "```python so that it is run" % (where, k + 1, ln.strip()))
                        break
            else:
                fail("%s: unknown block language %r" % (where, lang))
    if os.environ.get("NH_TEST_VERBOSE"):
        print("docs: %(run)d blocks run, %(help)d with --help only, %(skip)d skipped" % counts)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
