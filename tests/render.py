#!/usr/bin/python3
"""tools/render.py on a short DBS run ($NH_BINARY, in $NH_WORK/render):

 - the run: cases/dbs/dbs.yaml, steps of 0.1 s to t = 2 s, a frame every 5
   steps (5 tissue frames), the cannula moving in at 6 cm/s from t = 0.5 s;
 - `render.py RUN --size 320x200 --frames 3` writes frame_0000..0002.png,
   each a PNG of exactly 320 x 200 pixels (read back with VTK's PNG reader)
   that is not blank (its pixels take more than 20 distinct colours: the
   colour bar alone has more), frames.csv with 3 rows whose steps are frames
   of the run, the last one the run's last, and RUN/view.py that compiles;
 - with ffmpeg on PATH, movie.mp4 exists and is not empty.
Rendering needs a display: skipped (exit 77, with a message) when there is
neither $DISPLAY nor xvfb-run. Silent on success; one line per failure.
"""
import csv
import os
import py_compile
import shutil
import subprocess
import sys

import numpy as np

BIN = os.environ["NH_BINARY"]
SRC = os.environ["NH_SOURCE_DIR"]
WORK = os.path.join(os.environ.get("NH_WORK", "."), "render")
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def main():
    if not os.environ.get("DISPLAY") and not shutil.which("xvfb-run"):
        print("render: skipped: no $DISPLAY and no xvfb-run (tools/install-deps.sh installs xvfb)")
        return 77
    shutil.rmtree(WORK, ignore_errors=True)
    run = os.path.join(WORK, "run")
    p = subprocess.run([BIN, "run", os.path.join(SRC, "cases", "dbs", "dbs.yaml"), "--quiet",
                        "--out", run, "--set", "time.step=0.1", "--set", "time.end=2.0",
                        "--set", "output.every=5", "--set", "adapt.every=1000000",
                        "--set", "tools.0.motion=[{until: 0.5, speed: 0}, {until: target, speed: 0.06}]"],
                       capture_output=True, text=True)
    if p.returncode != 0:
        fail("needlehex run: exit %d: %s" % (p.returncode, p.stderr.strip()))
        return 1
    p = subprocess.run([sys.executable, os.path.join(SRC, "tools", "render.py"), run,
                        "--size", "320x200", "--frames", "3"], capture_output=True, text=True)
    if p.returncode != 0:
        fail("render.py: exit %d: %s" % (p.returncode, p.stderr.strip()[-2000:]))
        return 1
    out = os.path.join(run, "render")
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy
    for k in range(3):
        png = os.path.join(out, "frame_%04d.png" % k)
        if not os.path.isfile(png) or os.path.getsize(png) == 0:
            fail("%s missing or empty" % png)
            continue
        r = vtk.vtkPNGReader()
        r.SetFileName(png)
        r.Update()
        img = r.GetOutput()
        dims = img.GetDimensions()
        if dims[:2] != (320, 200):
            fail("%s: %d x %d pixels, expected 320 x 200" % (png, dims[0], dims[1]))
        pixels = vtk_to_numpy(img.GetPointData().GetScalars())
        colours = len(np.unique(pixels.reshape(len(pixels), -1), axis=0))
        if colours <= 20:
            fail("%s: %d distinct colours, expected more than 20 (a blank picture?)"
                 % (png, colours))
    frames = sorted(f for f in os.listdir(run) if f.startswith("tissue_") and f.endswith(".vtu"))
    steps = [int(f[7:13]) for f in frames]
    with open(os.path.join(out, "frames.csv")) as f:
        rows = list(csv.DictReader(f))
    got = [int(r["step"]) for r in rows]
    if len(rows) != 3 or not set(got) <= set(steps) or got[-1] != steps[-1]:
        fail("frames.csv steps %s, expected 3 of the run's frames %s ending with the last"
             % (got, steps))
    try:
        py_compile.compile(os.path.join(run, "view.py"), doraise=True,
                           cfile=os.path.join(WORK, "view.pyc"))
    except Exception as e:
        fail("view.py: %s" % e)
    if shutil.which("ffmpeg"):
        mp4 = os.path.join(out, "movie.mp4")
        if not os.path.isfile(mp4) or os.path.getsize(mp4) == 0:
            fail("ffmpeg is installed but %s is missing or empty" % mp4)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
