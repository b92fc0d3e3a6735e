#!/usr/bin/python3
"""install.py CMAKE BUILD_DIR — `cmake --install` into a scratch prefix and use
the installed program from another folder, with no NH_TEMPLATES_DIR:

 - PREFIX/bin/needlehex, PREFIX/share/needlehex/templates/hex2.tmpl,
   PREFIX/share/needlehex/tools/render.py, PREFIX/share/doc/needlehex/
   {LICENSE, README.md, docs/scene.md} exist;
 - `needlehex --version` prints "needlehex X.Y.Z (git REV)" with REV the
   source tree's `git describe --always --dirty --abbrev=12` at build time
   (a commit of the source's repository; "unknown" outside a checkout);
 - `needlehex check` of an adaptive scene naming the template hex2, run from
   an empty folder, resolves it to PREFIX/share/needlehex/templates/hex2.tmpl
   (the templates are found next to the binary: neither the source tree nor
   the build's copy is on its search path).
Silent on success; one line per failure, exit 1.
"""
import os
import re
import shutil
import subprocess
import sys

failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def main():
    cmake, build = sys.argv[1], sys.argv[2]
    src = os.environ["NH_SOURCE_DIR"]
    work = os.path.join(os.environ.get("NH_WORK", "."), "install")
    shutil.rmtree(work, ignore_errors=True)
    prefix = os.path.join(work, "prefix")
    p = subprocess.run([cmake, "--install", build, "--prefix", prefix], capture_output=True,
                       text=True)
    if p.returncode != 0:
        fail("cmake --install: exit %d: %s" % (p.returncode, p.stderr.strip()))
        return
    binary = os.path.join(prefix, "bin", "needlehex")
    for f in ("bin/needlehex", "share/needlehex/templates/hex2.tmpl",
              "share/needlehex/tools/render.py", "share/doc/needlehex/LICENSE",
              "share/doc/needlehex/README.md", "share/doc/needlehex/docs/scene.md",
              "share/needlehex/cases/dbs/dbs.yaml"):
        if not os.path.isfile(os.path.join(prefix, f)):
            fail("PREFIX/%s not installed" % f)
    env = {k: v for k, v in os.environ.items() if k != "NH_TEMPLATES_DIR"}
    v = subprocess.run([binary, "--version"], capture_output=True, text=True, env=env)
    g = subprocess.run(["git", "-C", src, "describe", "--always", "--dirty", "--abbrev=12"],
                       capture_output=True, text=True)
    rev = g.stdout.strip() if g.returncode == 0 and g.stdout.strip() else "unknown"
    m = re.fullmatch(r"needlehex \d+\.\d+\.\d+ \(git (\S+)\)\n", v.stdout)
    if v.returncode != 0 or not m:
        fail("--version: exit %d, output %r, expected 'needlehex X.Y.Z (git REV)'"
             % (v.returncode, v.stdout))
    elif m.group(1) != rev and rev != "unknown":
        # The revision is taken when the program is built: after a commit without a rebuild
        # it is an earlier commit of this repository, never an invented one.
        known = subprocess.run(["git", "-C", src, "cat-file", "-e",
                                m.group(1).replace("-dirty", "") + "^{commit}"],
                               capture_output=True).returncode == 0
        if not known:
            fail("--version: revision %s is no commit of %s (git describe: %s)"
                 % (m.group(1), src, rev))
    run_dir = os.path.join(work, "elsewhere")
    os.makedirs(run_dir)
    with open(os.path.join(run_dir, "s.yaml"), "w") as f:
        f.write("name: s\ntissue:\n  domain: {box: {min: [0, 0, 0], max: [1, 1, 1]}}\n"
                "  material: {young: 1000, poisson: 0.3}\n"
                "  fixed: [{box: {min: [-1, -1, -1], max: [0.01, 2, 2]}}]\n"
                "adapt: {template: hex2}\n")
    c = subprocess.run([binary, "check", "s.yaml"], cwd=run_dir, capture_output=True,
                       text=True, env=env)
    want = os.path.join(prefix, "share", "needlehex", "templates", "hex2.tmpl")
    if c.returncode != 0:
        fail("installed check: exit %d: %s" % (c.returncode, c.stderr.strip()))
    elif os.path.realpath(want) not in [os.path.realpath(w) for w in
                                        re.findall(r"(/\S+\.tmpl)", c.stdout)]:
        fail("installed check does not name %s as the template:\n%s" % (want, c.stdout))


if __name__ == "__main__":
    main()
    sys.exit(1 if failures else 0)
