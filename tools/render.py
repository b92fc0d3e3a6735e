#!/usr/bin/python3
"""Pictures of a run: PNG frames (and an MP4) of the tissue, tools and points,
and a ParaView state that opens them together.

    tools/render.py RUN_DIR [--out DIR] [--size 1280x720] [--every N] [--frames N]
                            [--no-movie] [--view-only]

RUN_DIR is the output folder of `needlehex run`. For every tissue frame
listed in RUN_DIR/tissue.pvd (every N-th with --every, at most --frames of
them, always the last) it draws, with VTK off screen:

- the tissue clipped by the plane through the first tool's axis (the
  trajectory plane; without tools the plane x = centre of the tissue), the
  half behind the plane kept, coloured by |displacement| in mm (one colour
  scale for all frames, with its bar), the cell edges drawn so that refined
  cells show as a denser mesh (refinement level as edges);
- each tool (RUN_DIR/<tool>.pvd: line cells base to tip) as a tube;
- targets as red spheres and probes as white ones, each labelled with its
  name (the points' field data `names`, docs/outputs.md);
- the time in s.

The camera looks along the normal of the clipping plane, so the trajectory
lies in the picture. The PNGs are DIR/frame_0000.png, ... (DIR defaults to
RUN_DIR/render), listed with their step and time in DIR/frames.csv; when
ffmpeg is on PATH, DIR/movie.mp4 (10 frames/s, H.264) is made from them.
RUN_DIR/view.py, a ParaView Python state, opens tissue, tools and points
together (`paraview --script=RUN_DIR/view.py`, or `pvpython RUN_DIR/view.py`
for a screenshot).

A display is needed for VTK's OpenGL context (Debian's VTK has no EGL or
OSMesa build). Without $DISPLAY the script runs itself again under
`xvfb-run -a` when xvfb-run is installed (tools/install-deps.sh installs it);
else it stops with exit 2 and says so. Needs python3-vtk9 and numpy; use
/usr/bin/python3.
"""
import argparse
import csv
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np

VIEW_PY = '''# ParaView state of a needlehex run (written by tools/render.py).
#   paraview --script=view.py     opens tissue, tools and points together
#   pvpython view.py              the same, and saves view.png here
import glob
import os

from paraview.simple import (ColorBy, ExtractSurface, GetActiveViewOrCreate, GetAnimationScene,
                             GetColorTransferFunction, OpenDataFile, Render, ResetCamera,
                             SaveScreenshot, Show, Tube)

here = os.path.dirname(os.path.abspath(__file__)) if "__file__" in globals() else os.getcwd()
view = GetActiveViewOrCreate("RenderView")
tissue = OpenDataFile(os.path.join(here, "tissue.pvd"))
shown = Show(tissue, view)
shown.SetRepresentationType("Surface With Edges")
ColorBy(shown, ("POINTS", "displacement", "Magnitude"))
shown.SetScalarBarVisibility(view, True)
GetColorTransferFunction("displacement").RescaleTransferFunction(0.0, %(umax)r)
shown.Opacity = 0.35
for pvd in sorted(glob.glob(os.path.join(here, "*.pvd"))):
    name = os.path.basename(pvd)[:-4]
    if name in ("tissue", "points"):
        continue
    tube = Tube(Input=ExtractSurface(Input=OpenDataFile(pvd)))  # Tube takes polydata
    tube.Radius = %(tube)r
    tool = Show(tube, view)
    tool.DiffuseColor = [0.85, 0.85, 0.9]
if os.path.exists(os.path.join(here, "points.pvd")):
    points = Show(OpenDataFile(os.path.join(here, "points.pvd")), view)
    points.SetRepresentationType("Points")
    points.PointSize = 12
    points.RenderPointsAsSpheres = 1
    ColorBy(points, ("POINTS", "target"))
GetAnimationScene().UpdateAnimationUsingDataTimeSteps()
GetAnimationScene().GoToLast()
ResetCamera()
Render()
if __name__ == "__main__" and "__file__" in globals():
    try:
        SaveScreenshot(os.path.join(here, "view.png"), view, ImageResolution=[1280, 720])
    except Exception:
        pass
'''


def pvd_frames(path):
    """[(time, file)] of a PVD collection, in its order."""
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]


def need_display(argv):
    """Re-run under xvfb-run when there is no display; exit 2 if impossible."""
    if os.environ.get("DISPLAY") or os.environ.get("NH_RENDER_UNDER_XVFB"):
        return
    xvfb = shutil.which("xvfb-run")
    if not xvfb:
        print("render.py: no display ($DISPLAY unset) and no xvfb-run: install xvfb "
              "(tools/install-deps.sh) or run under a display", file=sys.stderr)
        sys.exit(2)
    env = dict(os.environ, NH_RENDER_UNDER_XVFB="1")
    cmd = [xvfb, "-a", "-s", "-screen 0 1920x1080x24", sys.executable, os.path.abspath(__file__)]
    sys.exit(subprocess.call(cmd + argv, env=env))


def read_vtu(vtk, path):
    r = vtk.vtkXMLUnstructuredGridReader()
    r.SetFileName(path)
    r.Update()
    return r.GetOutput()


def names_of(grid):
    from vtk.util.numpy_support import vtk_to_numpy
    a = grid.GetFieldData().GetArray("names")
    if a is None:
        return [""] * grid.GetNumberOfPoints()
    return bytes(vtk_to_numpy(a).astype(np.uint8)).decode().split("\n")[:-1]


def clip_plane(tool_points, bounds):
    """(origin, normal) of the plane through the tool's axis (base -> tip);
    without a tool, the plane x = centre of the bounds."""
    centre = np.array([(bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2,
                       (bounds[4] + bounds[5]) / 2])
    if tool_points is None or len(tool_points) < 2:
        return centre, np.array([1.0, 0.0, 0.0])
    axis = tool_points[-1] - tool_points[0]
    axis /= np.linalg.norm(axis)
    least = np.argmin(np.abs(axis))  # the coordinate axis least aligned with the tool
    e = np.zeros(3)
    e[least] = 1.0
    normal = np.cross(axis, e)
    normal /= np.linalg.norm(normal)
    return tool_points[-1], normal


def render(a):
    import vtk
    from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy

    run = a.run_dir
    tissue = pvd_frames(os.path.join(run, "tissue.pvd"))
    if not tissue:
        print("render.py: %s lists no frames" % os.path.join(run, "tissue.pvd"), file=sys.stderr)
        return 1
    tools = sorted(f[:-4] for f in os.listdir(run) if f.endswith(".pvd")
                   and f[:-4] not in ("tissue", "points"))
    by_time = {}
    for name in tools + (["points"] if os.path.exists(os.path.join(run, "points.pvd")) else []):
        by_time[name] = dict(pvd_frames(os.path.join(run, name + ".pvd")))

    # One colour scale: the largest |u| over the frames drawn (mm).
    picked = list(range(0, len(tissue), max(1, a.every)))
    if picked[-1] != len(tissue) - 1:
        picked.append(len(tissue) - 1)
    if a.frames and len(picked) > a.frames:
        if a.frames == 1:
            picked = picked[-1:]
        else:
            idx = np.unique(np.linspace(0, len(picked) - 1, a.frames).round().astype(int))
            picked = [picked[i] for i in idx]
    grids = {}
    umax = 0.0
    for k in picked:
        g = read_vtu(vtk, os.path.join(run, tissue[k][1]))
        u = vtk_to_numpy(g.GetPointData().GetArray("displacement"))
        mag = 1e3 * np.linalg.norm(u, axis=1)
        arr = numpy_to_vtk(mag, deep=True)
        arr.SetName("|u| mm")
        g.GetPointData().AddArray(arr)
        grids[k] = g
        umax = max(umax, float(mag.max()) if len(mag) else 0.0)
    umax = umax if umax > 0 else 1e-3
    bounds = grids[picked[0]].GetBounds()
    diag = float(np.linalg.norm([bounds[1] - bounds[0], bounds[3] - bounds[2],
                                 bounds[5] - bounds[4]]))

    # The clipping plane from the first tool at the last frame (its whole path).
    tool_pts = None
    if tools:
        t_last = tissue[-1][0]
        f = by_time[tools[0]].get(t_last) or list(by_time[tools[0]].values())[-1]
        tool_pts = vtk_to_numpy(read_vtu(vtk, os.path.join(run, f)).GetPoints().GetData()).copy()
    origin, normal = clip_plane(tool_pts, bounds)

    w, h = a.size
    out = a.out or os.path.join(run, "render")
    os.makedirs(out, exist_ok=True)
    for old in os.listdir(out):
        if old.startswith("frame_") and old.endswith(".png"):
            os.remove(os.path.join(out, old))

    ren = vtk.vtkRenderer()
    ren.SetBackground(0.12, 0.13, 0.16)
    win = vtk.vtkRenderWindow()
    win.SetOffScreenRendering(1)
    win.SetSize(w, h)
    win.AddRenderer(ren)

    lut = vtk.vtkLookupTable()
    lut.SetHueRange(0.667, 0.0)
    lut.SetTableRange(0.0, umax)
    lut.Build()
    bar = vtk.vtkScalarBarActor()
    bar.SetLookupTable(lut)
    bar.SetTitle("|displacement|\n[mm]")
    bar.SetNumberOfLabels(5)
    bar.SetLabelFormat("%.2g")
    bar.SetPosition(0.86, 0.1)
    bar.SetWidth(0.08)
    bar.SetHeight(0.8)
    bar.UnconstrainedFontSizeOn()
    for prop in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
        prop.SetFontSize(16)
        prop.SetColor(1, 1, 1)
        prop.ShadowOff()
    ren.AddActor2D(bar)
    clock = vtk.vtkTextActor()
    clock.GetTextProperty().SetFontSize(20)
    clock.GetTextProperty().SetColor(1, 1, 1)
    clock.SetPosition(12, 12)
    ren.AddActor2D(clock)
    title = vtk.vtkTextActor()
    title.SetInput("%s: tissue clipped through the %s" % (
        os.path.basename(os.path.normpath(run)),
        "trajectory plane of " + tools[0] if tools else "plane x = centre"))
    title.GetTextProperty().SetFontSize(16)
    title.GetTextProperty().SetColor(0.9, 0.9, 0.9)
    title.SetPosition(12, h - 30)
    ren.AddActor2D(title)

    plane = vtk.vtkPlane()
    plane.SetOrigin(*origin)
    plane.SetNormal(*normal)
    dynamic = []
    rows = []
    for n, k in enumerate(picked):
        for actor in dynamic:
            ren.RemoveActor(actor)
        dynamic = []
        t, _ = tissue[k]
        g = grids[k]
        g.GetPointData().SetActiveScalars("|u| mm")
        clip = vtk.vtkTableBasedClipDataSet()
        clip.SetInputData(g)
        clip.SetClipFunction(plane)
        clip.InsideOutOn()
        surf = vtk.vtkDataSetSurfaceFilter()
        surf.SetInputConnection(clip.GetOutputPort())
        m = vtk.vtkDataSetMapper()
        m.SetInputConnection(surf.GetOutputPort())
        m.SetLookupTable(lut)
        m.SetScalarRange(0.0, umax)
        m.SetScalarModeToUsePointFieldData()
        m.SelectColorArray("|u| mm")
        actor = vtk.vtkActor()
        actor.SetMapper(m)
        actor.GetProperty().EdgeVisibilityOn()
        actor.GetProperty().SetEdgeColor(0.15, 0.15, 0.15)
        actor.GetProperty().SetLineWidth(1.0)
        dynamic.append(actor)
        # The unclipped outline, faint, for context.
        outline = vtk.vtkDataSetMapper()
        outline_surf = vtk.vtkDataSetSurfaceFilter()
        outline_surf.SetInputData(g)
        outline.SetInputConnection(outline_surf.GetOutputPort())
        outline.ScalarVisibilityOff()
        ghost = vtk.vtkActor()
        ghost.SetMapper(outline)
        ghost.GetProperty().SetOpacity(0.08)
        dynamic.append(ghost)
        for name in tools:
            f = by_time[name].get(t)
            if f is None:
                continue
            line = read_vtu(vtk, os.path.join(run, f))
            poly = vtk.vtkGeometryFilter()
            poly.SetInputData(line)
            tube = vtk.vtkTubeFilter()
            tube.SetInputConnection(poly.GetOutputPort())
            tube.SetRadius(0.004 * diag)
            tube.SetNumberOfSides(16)
            tm = vtk.vtkPolyDataMapper()
            tm.SetInputConnection(tube.GetOutputPort())
            tm.ScalarVisibilityOff()
            ta = vtk.vtkActor()
            ta.SetMapper(tm)
            ta.GetProperty().SetColor(0.85, 0.85, 0.9)
            dynamic.append(ta)
        f = by_time.get("points", {}).get(t)
        if f is not None:
            pts = read_vtu(vtk, os.path.join(run, f))
            xyz = vtk_to_numpy(pts.GetPoints().GetData())
            flag = pts.GetPointData().GetArray("target")
            flag = vtk_to_numpy(flag) if flag is not None else np.zeros(len(xyz), dtype=int)
            for x, is_target, name in zip(xyz, flag, names_of(pts)):
                s = vtk.vtkSphereSource()
                s.SetCenter(*x)
                s.SetRadius(0.008 * diag)
                s.SetThetaResolution(24)
                s.SetPhiResolution(16)
                sm = vtk.vtkPolyDataMapper()
                sm.SetInputConnection(s.GetOutputPort())
                sa = vtk.vtkActor()
                sa.SetMapper(sm)
                sa.GetProperty().SetColor(*((1.0, 0.2, 0.2) if is_target else (1.0, 1.0, 1.0)))
                dynamic.append(sa)
                label = vtk.vtkBillboardTextActor3D()
                label.SetInput(name)
                label.SetPosition(*(x + 0.012 * diag * np.array([1.0, 1.0, 1.0])))
                label.GetTextProperty().SetFontSize(20)
                label.GetTextProperty().SetColor(1, 1, 0.6)
                dynamic.append(label)
        for actor in dynamic:
            ren.AddActor(actor)
        clock.SetInput("t = %.3f s" % t)
        if n == 0:
            cam = ren.GetActiveCamera()
            centre = np.array([(bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2,
                               (bounds[4] + bounds[5]) / 2])
            focus = centre - np.dot(centre - origin, normal) * normal  # on the plane
            cam.SetFocalPoint(*focus)
            cam.SetPosition(*(focus + 2.2 * diag * normal))  # facing the kept half's cut face
            up = np.array([0.0, 0.0, 1.0]) if abs(normal[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
            cam.SetViewUp(*up)
            ren.ResetCamera()
            cam.Zoom(1.3)
        win.Render()
        shot = vtk.vtkWindowToImageFilter()
        shot.SetInput(win)
        shot.ReadFrontBufferOff()
        shot.Update()
        png = vtk.vtkPNGWriter()
        png.SetFileName(os.path.join(out, "frame_%04d.png" % n))
        png.SetInputConnection(shot.GetOutputPort())
        png.Write()
        step = os.path.basename(tissue[k][1])[len("tissue_"):-len(".vtu")]
        rows.append((n, int(step), t))
    with open(os.path.join(out, "frames.csv"), "w", newline="") as f:
        wr = csv.writer(f)
        wr.writerow(["frame", "step", "time"])
        wr.writerows(rows)
    print("render.py: %d frames (%dx%d) in %s" % (len(rows), w, h, out), file=sys.stderr)
    if a.movie and shutil.which("ffmpeg"):
        p = subprocess.run(["ffmpeg", "-y", "-loglevel", "error", "-framerate", "10", "-i",
                            os.path.join(out, "frame_%04d.png"), "-c:v", "libx264",
                            "-pix_fmt", "yuv420p", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",
                            os.path.join(out, "movie.mp4")], capture_output=True, text=True)
        if p.returncode != 0:
            print("render.py: ffmpeg failed (%s); the PNGs are there" % p.stderr.strip(),
                  file=sys.stderr)
        else:
            print("render.py: %s" % os.path.join(out, "movie.mp4"), file=sys.stderr)
    write_view(run, umax * 1e-3, 0.004 * diag)
    return 0


def write_view(run, umax_m, tube_radius):
    with open(os.path.join(run, "view.py"), "w") as f:
        f.write(VIEW_PY % {"umax": umax_m, "tube": tube_radius})


def parse_size(text):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError("expected WIDTHxHEIGHT, got %r" % text)
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError("at least 16x16, got %r" % text)
    return w, h


def main(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run_dir", help="output folder of needlehex run")
    ap.add_argument("--out", help="where the PNGs go (default RUN_DIR/render)")
    ap.add_argument("--size", type=parse_size, default=(1280, 720), help="WIDTHxHEIGHT")
    ap.add_argument("--every", type=int, default=1, help="every N-th tissue frame")
    ap.add_argument("--frames", type=int, default=0, help="at most N frames (0: no limit)")
    ap.add_argument("--no-movie", dest="movie", action="store_false", help="no MP4")
    ap.add_argument("--view-only", action="store_true", help="only write RUN_DIR/view.py")
    a = ap.parse_args(argv)
    if not os.path.isfile(os.path.join(a.run_dir, "tissue.pvd")):
        print("render.py: %s has no tissue.pvd (not a needlehex output folder)" % a.run_dir,
              file=sys.stderr)
        return 2
    if a.view_only:
        write_view(a.run_dir, 1e-3, 1e-3)
        return 0
    need_display(argv)
    return render(a)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
