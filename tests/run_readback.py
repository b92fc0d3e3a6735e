"""run_readback.py — end to end: the simulator's output files agree with each other.

usage:
  run_readback.py            run $NH_BINARY on $NH_SOURCE_DIR/cases/phantom-tissue.yaml
                             into a scratch folder under $NH_WORK, then check it
  run_readback.py --check DIR [--steps N]
                             check an existing output folder only (no run)

The run is
  $NH_BINARY run cases/phantom-tissue.yaml --out DIR --quiet
             --set time.steps=20 --set output.every=5
and the checks follow the output contract of docs/outputs.md:

- tissue.pvd lists frames; each tissue_NNNNNN.vtu (NNNNNN = step, 6 digits)
  exists and is read by VTK's XML reader and by meshio with identical points
  and `displacement`; it has point data displacement (3), velocity (3), the
  Int32 flag `fixed`, cell data von_mises, level, fill (1 component each),
  only VTK_HEXAHEDRON cells, and points = current positions.
- points.pvd / points_NNNNNN.vtu hold the probes (then targets) as
  VTK_VERTEX cells in scene order, with point data `displacement` and
  `target` (0 for a probe) and the probes' names (probes.csv's, in order)
  as the field data `names`; meshio reads them with the same points.
- probes.csv (step,time,name,x,y,z,ux,uy,uz) rows at each frame's step equal
  the points VTU's positions and displacements to 1e-12 relative (both are
  printed from the same doubles).
- probe "1" of the phantom case sits at a mesh node: the tissue node whose
  rest position (points - displacement) equals the probe's rest position
  (x - u from the CSV) has the CSV displacement to 1e-12.
- steps.csv has one row per step (N, default 20) and at least the columns
  step,time,dofs,cells,t_assemble,t_factor,t_solve,t_step; each PVD timestep
  equals steps.csv `time` at that frame's step.
- every column of every CSV file written has its row in docs/outputs.md
  (the table of its section, or the `a,b,...` header line the section gives).

The step of a frame is read from its file name. Silent on success; prints
every mismatch and exits 1. Exit 77 (ctest: skipped) when the case file does
not exist yet; a missing or failing binary is a failure.
"""
import csv
import os
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy

try:
    import meshio
except ImportError:  # pragma: no cover - install python3-meshio
    meshio = None

RTOL = 1e-12
VTK_VERTEX, VTK_HEXAHEDRON = 1, 12
failures = []


def fail(msg):
    failures.append(msg)
    print("FAILED:", msg, file=sys.stderr)


def vector_scale(a, b, floor):
    """Per tuple (last axis): the larger Euclidean norm of a and b, at least `floor`."""
    if a.ndim == 0:
        return max(abs(float(a)), abs(float(b)), floor)
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    return np.maximum(np.maximum(na, nb), floor)


def close(a, b, rtol=RTOL, floor=1e-300):
    """|a - b| <= rtol * max(|a|, |b|, floor), the norms taken over each tuple
    (a 3-vector is compared relative to its length, not per component: an
    interpolated component that should be 0 carries round-off of the order of
    1e-16 times the vector)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != b.shape:
        return False
    return bool(np.all(np.abs(a - b) <= rtol * vector_scale(a, b, floor)))


def expect_close(what, actual, expected, rtol=RTOL, floor=1e-300):
    actual = np.asarray(actual, dtype=float)
    expected = np.asarray(expected, dtype=float)
    if actual.shape != expected.shape:
        fail(f"{what}: shape {actual.shape}, expected {expected.shape}")
    elif not close(actual, expected, rtol, floor):
        rel = np.abs(actual - expected) / vector_scale(actual, expected, floor)
        idx = np.unravel_index(np.argmax(rel), rel.shape)
        fail(f"{what}: worst at {idx}: actual {actual[idx]!r}, expected {expected[idx]!r}, "
             f"relative difference {rel[idx]:.3g} > tolerance {rtol:g}")


def read_vtk(path):
    """vtkXMLUnstructuredGridReader output; any VTK error or warning fails."""
    events = []
    reader = vtk.vtkXMLUnstructuredGridReader()
    for event in ("ErrorEvent", "WarningEvent"):
        reader.AddObserver(event, lambda obj, ev: events.append(ev))
    window = vtk.vtkStringOutputWindow()
    vtk.vtkOutputWindow.SetInstance(window)
    reader.SetFileName(path)
    reader.Update()
    text = window.GetOutput().strip()
    if events or reader.GetErrorCode() or text:
        fail(f"VTK reading {path}: events {events}, error code {reader.GetErrorCode()}, "
             f"output {text!r}")
    return reader.GetOutput()


def vtk_points(grid):
    if grid.GetPoints() is None or grid.GetNumberOfPoints() == 0:
        return np.zeros((0, 3))
    return vtk_to_numpy(grid.GetPoints().GetData()).astype(float)


def vtk_cell_types(grid):
    return np.array([grid.GetCellType(c) for c in range(grid.GetNumberOfCells())], dtype=int)


def get_array(data, name, components, path, kind="f"):
    arr = data.GetArray(name)
    if arr is None:
        fail(f"{path}: array {name!r} missing")
        return None
    if arr.GetNumberOfComponents() != components:
        fail(f"{path}: {name!r} has {arr.GetNumberOfComponents()} components, "
             f"expected {components}")
    a = vtk_to_numpy(arr)
    if a.dtype.kind != kind:
        fail(f"{path}: {name!r} has dtype {a.dtype}, expected kind {kind!r}")
    return a


def read_pvd(path):
    """[(time, file, step)] from a PVD, step parsed from the file name."""
    if not os.path.isfile(path):
        fail(f"{path} does not exist")
        return []
    root = ET.parse(path).getroot()
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        fail(f"{path}: root <{root.tag} type={root.get('type')!r}>, expected a Collection")
    frames = []
    base = os.path.basename(path)[:-len(".pvd")]
    for ds in root.iter("DataSet"):
        f = ds.get("file")
        m = re.fullmatch(re.escape(base) + r"_(\d{6})\.vtu", f or "")
        if not m:
            fail(f"{path}: file {f!r} is not {base}_NNNNNN.vtu")
            continue
        frames.append((float(ds.get("timestep")), f, int(m.group(1))))
    if not frames:
        fail(f"{path} lists no frames")
    steps = [s for _, _, s in frames]
    if steps != sorted(set(steps)):
        fail(f"{path}: steps {steps} are not increasing")
    return frames


def read_csv(path):
    if not os.path.isfile(path):
        fail(f"{path} does not exist")
        return [], []
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        fail(f"{path} is empty")
        return [], []
    header = rows[0]
    body = [dict(zip(header, r)) for r in rows[1:]]
    for k, r in enumerate(rows[1:]):
        if len(r) != len(header):
            fail(f"{path} line {k + 2}: {len(r)} fields, header has {len(header)}")
    return header, body


def check_tissue(out, frames):
    """Each tissue frame: VTK and meshio agree, the arrays of the contract exist."""
    grids = {}
    for t, f, step in frames:
        path = os.path.join(out, f)
        if not os.path.isfile(path):
            fail(f"tissue.pvd names {f}, which does not exist")
            continue
        g = read_vtk(path)
        pts = vtk_points(g)
        if g.GetNumberOfCells() == 0:
            fail(f"{path}: no cells")
        types = vtk_cell_types(g)
        if np.any(types != VTK_HEXAHEDRON):
            fail(f"{path}: cell types {sorted(set(types.tolist()))}, expected only "
                 f"{VTK_HEXAHEDRON} (hexahedron)")
        pd, cd = g.GetPointData(), g.GetCellData()
        disp = get_array(pd, "displacement", 3, path)
        get_array(pd, "velocity", 3, path)
        fixed = get_array(pd, "fixed", 1, path, kind="i")
        if fixed is not None and fixed.dtype != np.int32:
            fail(f"{path}: fixed has dtype {fixed.dtype}, expected int32")
        for name in ("von_mises", "level", "fill"):
            get_array(cd, name, 1, path)
        if meshio is not None and disp is not None:
            try:
                m = meshio.read(path)
                if not np.array_equal(m.points, pts):
                    fail(f"{path}: meshio and VTK points differ")
                if not np.array_equal(m.point_data.get("displacement"), disp):
                    fail(f"{path}: meshio and VTK displacement differ")
                if [c.type for c in m.cells] != ["hexahedron"]:
                    fail(f"{path}: meshio cell blocks {[c.type for c in m.cells]}")
            except Exception as e:
                fail(f"{path}: meshio cannot read it: {type(e).__name__}: {e}")
        elif meshio is None:
            fail("meshio is not installed (python3-meshio)")
        grids[step] = (pts, disp)
    return grids


def check_points(out, frames, probe_rows, n_probes):
    """points_NNNNNN.vtu: probes first, in scene (= CSV) order, as vertices."""
    for t, f, step in frames:
        path = os.path.join(out, f)
        if not os.path.isfile(path):
            fail(f"points.pvd names {f}, which does not exist")
            continue
        g = read_vtk(path)
        pts = vtk_points(g)
        types = vtk_cell_types(g)
        if len(types) != g.GetNumberOfPoints() or np.any(types != VTK_VERTEX):
            fail(f"{path}: {len(types)} cells of types {sorted(set(types.tolist()))} for "
                 f"{g.GetNumberOfPoints()} points, expected one VTK_VERTEX per point")
        disp = get_array(g.GetPointData(), "displacement", 3, path)
        rows = [r for r in probe_rows if int(r["step"]) == step]
        if len(rows) != n_probes:
            fail(f"probes.csv has {len(rows)} rows at step {step}, expected {n_probes}")
            continue
        if pts.shape[0] < n_probes:
            fail(f"{path}: {pts.shape[0]} points, expected at least {n_probes} probes")
            continue
        names = [r["name"] for r in rows]
        fd = g.GetFieldData().GetArray("names")
        got = bytes(vtk_to_numpy(fd)).decode().split("\n")[:n_probes] if fd else None
        if got != names:
            fail(f"{path}: names {got!r}, expected probes.csv's {names!r}")
        kind = get_array(g.GetPointData(), "target", 1, path, kind="i")
        if kind is not None and np.any(kind[:n_probes] != 0):
            fail(f"{path}: target flag {kind[:n_probes]} for the probes, expected 0")
        if meshio is not None:
            m = meshio.read(path)
            if not np.array_equal(m.points, pts):
                fail(f"{path}: meshio and VTK points differ")
            got = bytes(m.field_data.get("names", [])).decode().split("\n")[:n_probes]
            if got != names:
                fail(f"{path}: meshio names {got!r}, expected {names!r}")
        x = np.array([[float(r[k]) for k in ("x", "y", "z")] for r in rows])
        u = np.array([[float(r[k]) for k in ("ux", "uy", "uz")] for r in rows])
        expect_close(f"{path} probe positions vs probes.csv at step {step}", pts[:n_probes], x)
        if disp is not None:
            expect_close(f"{path} probe displacements vs probes.csv at step {step}",
                         disp[:n_probes], u)


def check_probe_at_node(tissue, probe_rows, name="1"):
    """The probe sits on a node: that node's displacement equals the CSV's."""
    rows = {int(r["step"]): r for r in probe_rows if r["name"] == name}
    if not rows:
        fail(f"probes.csv has no probe named {name!r}")
        return
    for step, (pts, disp) in sorted(tissue.items()):
        r = rows.get(step)
        if r is None:
            fail(f"probes.csv has no row for probe {name!r} at frame step {step}")
            continue
        if disp is None:
            continue
        x = np.array([float(r[k]) for k in ("x", "y", "z")])
        u = np.array([float(r[k]) for k in ("ux", "uy", "uz")])
        rest = pts - disp
        probe_rest = x - u
        dist = np.linalg.norm(rest - probe_rest, axis=1)
        k = int(np.argmin(dist))
        size = max(np.ptp(rest, axis=0).max(), 1e-300)
        if dist[k] > 1e-9 * size:
            fail(f"step {step}: no tissue node at probe {name!r}'s rest position {probe_rest} "
                 f"(nearest node {k} at {rest[k]}, distance {dist[k]:.3g})")
            continue
        # Relative to the largest displacement of the frame: the probe's value is
        # interpolated, so a component that is 0 at the node comes out as round-off.
        floor = float(np.abs(disp).max()) if disp.size else 0.0
        expect_close(f"step {step}: tissue displacement at node {k} vs probe {name!r}",
                     disp[k], u, floor=max(floor, 1e-300))


def check_steps(out, n_steps, pvd_frames):
    header, rows = read_csv(os.path.join(out, "steps.csv"))
    if not header:
        return
    need = ["step", "time", "dofs", "cells", "t_assemble", "t_factor", "t_solve", "t_step"]
    missing = [c for c in need if c not in header]
    if missing:
        fail(f"steps.csv header lacks {missing}: {header}")
        return
    if n_steps is not None and len(rows) != n_steps:
        fail(f"steps.csv has {len(rows)} rows, expected {n_steps} (one per step)")
    steps = [int(r["step"]) for r in rows]
    if steps != sorted(set(steps)):
        fail(f"steps.csv steps are not increasing: {steps}")
    time_at = {int(r["step"]): float(r["time"]) for r in rows}
    # The initial state may be written as frame 0, before the first step.
    time_at.setdefault(0, 0.0)
    for pvd, frames in pvd_frames.items():
        for t, f, step in frames:
            if step not in time_at:
                fail(f"{pvd}: frame {f} at step {step}, which steps.csv lacks")
            elif not close(t, time_at[step]):
                fail(f"{pvd}: frame {f} timestep {t!r} != steps.csv time {time_at[step]!r}")


def documented_columns(name):
    """The column names docs/outputs.md gives in the section "## `NAME`": the
    backticked names of its table's first cells and of its `a,b,...` header
    lines (a bracketed optional part included)."""
    source = os.environ.get("NH_SOURCE_DIR", os.path.join(os.path.dirname(__file__), ".."))
    with open(os.path.join(source, "docs", "outputs.md")) as f:
        text = f.read()
    m = re.search(r"^## `%s`\n(.*?)(?=^## )" % re.escape(name), text, re.S | re.M)
    if not m:
        return None
    names = set()
    for line in m.group(1).split("\n"):
        if line.startswith("|"):
            cells = [line.split("|")[1]]
        elif re.match(r"^`[a-z_]+,[a-z_,\[\]]+`", line):
            cells = [line.split("`")[1]]
        else:
            continue
        for cell in cells:
            for tick in re.findall(r"`([^`]+)`", cell) or [cell]:
                names.update(re.split(r"[,\[\]\s]+", tick.strip()))
    return names


def check_documented(out):
    """Every column of every CSV file of the run has its row (or its place in
    the header line) in docs/outputs.md."""
    for name in sorted(os.listdir(out)):
        if not name.endswith(".csv"):
            continue
        header, _ = read_csv(os.path.join(out, name))
        names = documented_columns(name)
        if names is None:
            fail(f"{name}: docs/outputs.md has no section \"## `{name}`\"")
            continue
        missing = [c for c in header if c not in names]
        if missing:
            fail(f"{name}: columns without a row in docs/outputs.md: {missing}")


def check_folder(out, n_steps):
    tissue_frames = read_pvd(os.path.join(out, "tissue.pvd"))
    point_frames = read_pvd(os.path.join(out, "points.pvd"))
    header, probe_rows = read_csv(os.path.join(out, "probes.csv"))
    want = ["step", "time", "name", "x", "y", "z", "ux", "uy", "uz"]
    if header and header != want:
        fail(f"probes.csv header {header}, expected {want}")
        probe_rows = []
    names = []
    for r in probe_rows:
        if r["name"] in names:
            break
        names.append(r["name"])
    # The time in probes.csv equals the PVD time of the same step.
    probe_time = {int(r["step"]): float(r["time"]) for r in probe_rows}
    for t, f, step in point_frames:
        if step in probe_time and not close(t, probe_time[step]):
            fail(f"points.pvd {f}: timestep {t!r} != probes.csv time {probe_time[step]!r}")
    if [s for _, _, s in tissue_frames] != [s for _, _, s in point_frames]:
        fail(f"tissue.pvd steps {[s for _, _, s in tissue_frames]} != points.pvd steps "
             f"{[s for _, _, s in point_frames]}")
    tissue = check_tissue(out, tissue_frames)
    check_points(out, point_frames, probe_rows, len(names))
    check_probe_at_node(tissue, probe_rows)
    check_steps(out, n_steps, {"tissue.pvd": tissue_frames, "points.pvd": point_frames})
    check_documented(out)
    leftovers = [f for f in os.listdir(out) if f.endswith(".tmp")]
    if leftovers:
        fail(f"{out}: temporary files left behind: {leftovers}")


def run_case(steps, every):
    source = os.environ.get("NH_SOURCE_DIR", os.path.join(os.path.dirname(__file__), ".."))
    case = os.path.join(source, "cases", "phantom-tissue.yaml")
    if not os.path.isfile(case):
        print(f"run_readback: skipped: {case} does not exist yet", file=sys.stderr)
        sys.exit(77)
    binary = os.environ.get("NH_BINARY")
    if not binary or not os.access(binary, os.X_OK):
        fail(f"NH_BINARY={binary!r} is not an executable")
        return None
    work = os.environ.get("NH_WORK") or "/tmp"
    out = os.path.join(work, "run_readback_out")
    if os.path.isdir(out):
        # Only files the run writes: stale frames must not pass for new ones.
        for f in os.listdir(out):
            if re.search(r"\.(vtu|pvd|csv|h5|xdmf|yaml|tmp)$", f):
                os.remove(os.path.join(out, f))
    cmd = [binary, "run", case, "--out", out, "--quiet", "--overwrite",
           "--set", f"time.steps={steps}", "--set", f"output.every={every}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=540)
    if proc.returncode != 0:
        fail(f"{' '.join(cmd)} exited {proc.returncode}\nstdout: {proc.stdout[-2000:]}\n"
             f"stderr: {proc.stderr[-2000:]}")
        return None
    return out


def main(argv):
    steps, every = 20, 5
    if len(argv) >= 3 and argv[1] == "--check":
        out = argv[2]
        n_steps = int(argv[4]) if len(argv) >= 5 and argv[3] == "--steps" else None
    elif len(argv) == 1:
        out = run_case(steps, every)
        n_steps = steps
    else:
        print(__doc__, file=sys.stderr)
        return 2
    if out is not None:
        try:
            check_folder(out, n_steps)
        except Exception as e:
            fail(f"checking {out}: {type(e).__name__}: {e}")
            raise
    if failures:
        print(f"run_readback: {len(failures)} failure(s) in {out}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
