"""io_readback.py DIR — read the files tests/test_io.c wrote into DIR back with
VTK's own XML reader and with meshio, and compare every value with the
formulas both programs share (they are copied from the comment at the top of
tests/test_io.c; keep the two in step):

  hex.vtu: 3 x 2 x 2 points, i = ix + 3 iy + 6 iz
    point i         = (0.01 ix, 0.02 iy, 0.03 iz)
    displacement[i] = (0.001 i, -0.002 i, 0.5 + i)
    velocity[i]     = (0.25 i, 1 / (i + 1), -3 i)
    fixed[i]        = 1 if i % 3 == 0 else 0              (Int32)
    cell c = 0, 1: (n(c,0,0), n(c+1,0,0), n(c+1,1,0), n(c,1,0),
                    n(c,0,1), n(c+1,0,1), n(c+1,1,1), n(c,1,1)), VTK_HEXAHEDRON
    von_mises[c] = 1500 (c + 1), level[c] = c
  empty_cells.vtu: points (0.1 i, 0, 0), i < 4, displacement as above, 0 cells.
  empty.vtu: 0 points, 0 cells.
  lines.vtu: points (0.1 i, 0, 0), i < 6; POLY_LINE (0 1 2 3), LINE (3 4),
    LINE (4 5), VERTEX (5); von_mises[c] = 1500 (c + 1).
  vertices.vtu: points (0.1 i, 0.2 i, 0.3 i), i < 3, one VERTEX each.
  single.vtu: the point (0.1, 0.2, 0.3), one VERTEX, displacement(1).
  named.vtu: single.vtu with the Int32 flag target = 1, field data names "STN\n".
  named3.vtu: vertices.vtu with names "a", "probe 2", "STN".
  Units (UNITS_LABEL): displacement m, velocity m/s, von_mises Pa, flags 1,
    Points m; hex.vtu's level has none.
  series.pvd: times {0, 0.05, 0.1 + 0.2}, files series_%06d.vtu (step 5 k),
    displacement of frame k = (displacement above) * (k + 1).
  escape.pvd: one frame at 1.5, file "odd &<name>.vtu".
  table.csv, long.csv, hello.txt: see test_io.c.

Both sides compute the values with the same IEEE double operations, so the
comparison is exact (==), not to a tolerance. Silent on success; prints every
mismatch and exits 1 otherwise.

meshio 5 cannot read a VTU with 0 cells (IndexError in its cell-block split,
whatever the writer); for those two files meshio is only required to fail in
that known way or to agree, and VTK is the reference.
"""
import csv
import os
import sys
import xml.etree.ElementTree as ET

import numpy as np
import vtk
from vtk.util.numpy_support import vtk_to_numpy

try:
    import meshio
except ImportError:  # pragma: no cover - install python3-meshio
    meshio = None

failures = []


def fail(msg):
    failures.append(msg)
    print("FAILED:", msg, file=sys.stderr)


def expect_equal(what, actual, expected):
    actual = np.asarray(actual)
    expected = np.asarray(expected)
    if actual.shape != expected.shape:
        fail(f"{what}: shape {actual.shape}, expected {expected.shape}")
        return
    if not np.array_equal(actual, expected):
        bad = np.argwhere(actual != expected)
        idx = tuple(bad[0])
        fail(f"{what}: {len(bad)} value(s) differ, first at {idx}: "
             f"actual {actual[idx]!r}, expected {expected[idx]!r} (tolerance 0)")


def read_vtk(path):
    """Read a VTU with vtkXMLUnstructuredGridReader; any VTK error or warning fails."""
    messages = []
    reader = vtk.vtkXMLUnstructuredGridReader()
    for event in ("ErrorEvent", "WarningEvent"):
        reader.AddObserver(event, lambda obj, ev: messages.append(ev))
    # Errors raised inside the XML parser go to the output window, not the reader.
    window = vtk.vtkStringOutputWindow()
    vtk.vtkOutputWindow.SetInstance(window)
    reader.SetFileName(path)
    reader.Update()
    text = window.GetOutput()
    if messages or reader.GetErrorCode() or text.strip():
        fail(f"VTK reading {path}: events {messages}, error code {reader.GetErrorCode()}, "
             f"output {text.strip()!r}")
    return reader.GetOutput()


def vtk_points(grid):
    pts = grid.GetPoints()
    if pts is None or grid.GetNumberOfPoints() == 0:
        return np.zeros((0, 3))
    return vtk_to_numpy(pts.GetData())


def vtk_cells(grid):
    """(connectivity, offsets as ends, types) as flat int arrays."""
    n = grid.GetNumberOfCells()
    conn, ends, types = [], [], []
    for c in range(n):
        ids = grid.GetCell(c).GetPointIds()
        conn += [ids.GetId(k) for k in range(ids.GetNumberOfIds())]
        ends.append(len(conn))
        types.append(grid.GetCellType(c))
    return np.array(conn, dtype=int), np.array(ends, dtype=int), np.array(types, dtype=int)


def vtk_array(data, name, dtype_kind=None):
    arr = data.GetArray(name)
    if arr is None:
        fail(f"array {name!r} missing")
        return None
    a = vtk_to_numpy(arr)
    if dtype_kind and a.dtype.kind != dtype_kind:
        fail(f"array {name!r} has dtype {a.dtype}, expected kind {dtype_kind!r}")
    return a


def vtk_unit(arr):
    info = arr.GetInformation() if arr is not None else None
    if info is None or not info.Has(vtk.vtkDataArray.UNITS_LABEL()):
        return None
    return info.Get(vtk.vtkDataArray.UNITS_LABEL())


def check_units(path, grid, expected):
    """expected: {array name: unit or None}; "Points" is the points array."""
    for name, unit in expected.items():
        if name == "Points":
            arr = grid.GetPoints().GetData()
        else:
            arr = grid.GetPointData().GetArray(name) or grid.GetCellData().GetArray(name)
        got = vtk_unit(arr)
        if got != unit:
            fail(f"{path} {name}: UNITS_LABEL {got!r}, expected {unit!r}")


def names_of(field):
    """The names from the UInt8 field data array "names" (each followed by a newline)."""
    if field is None:
        return None
    return bytes(np.asarray(field, dtype=np.uint8)).decode().split("\n")[:-1]


# ---- the shared formulas ----
def displacement(i):
    return [0.001 * i, -0.002 * i, 0.5 + i]


def hex_expected(frame=0):
    HX, HY, HZ = 3, 2, 2
    node = lambda ix, iy, iz: ix + HX * iy + HX * HY * iz  # noqa: E731
    n = HX * HY * HZ
    pts = np.zeros((n, 3))
    disp = np.zeros((n, 3))
    vel = np.zeros((n, 3))
    fixed = np.zeros(n, dtype=np.int32)
    for iz in range(HZ):
        for iy in range(HY):
            for ix in range(HX):
                i = node(ix, iy, iz)
                pts[i] = (0.01 * ix, 0.02 * iy, 0.03 * iz)
                disp[i] = [x * (frame + 1) for x in displacement(i)]
                vel[i] = (0.25 * i, 1.0 / (i + 1), -3.0 * i)
                fixed[i] = 1 if i % 3 == 0 else 0
    conn = []
    for c in range(2):
        conn += [node(c, 0, 0), node(c + 1, 0, 0), node(c + 1, 1, 0), node(c, 1, 0),
                 node(c, 0, 1), node(c + 1, 0, 1), node(c + 1, 1, 1), node(c, 1, 1)]
    return dict(points=pts, displacement=disp, velocity=vel, fixed=fixed,
                connectivity=np.array(conn), offsets=np.array([8, 16]),
                types=np.array([12, 12]),
                von_mises=np.array([1500.0 * (c + 1) for c in range(2)]),
                level=np.array([float(c) for c in range(2)]))


def check_hex(path, frame=0):
    e = hex_expected(frame)
    g = read_vtk(path)
    expect_equal(f"{path} VTK points", vtk_points(g), e["points"])
    conn, ends, types = vtk_cells(g)
    expect_equal(f"{path} VTK connectivity", conn, e["connectivity"])
    expect_equal(f"{path} VTK offsets", ends, e["offsets"])
    expect_equal(f"{path} VTK types", types, e["types"])
    pd, cd = g.GetPointData(), g.GetCellData()
    for name in ("displacement", "velocity"):
        a = vtk_array(pd, name, "f")
        if a is not None:
            expect_equal(f"{path} VTK {name}", a, e[name])
            if pd.GetArray(name).GetNumberOfComponents() != 3:
                fail(f"{path} {name}: NumberOfComponents != 3")
    a = vtk_array(pd, "fixed", "i")
    if a is not None:
        expect_equal(f"{path} VTK fixed", a, e["fixed"])
        if a.dtype != np.int32:
            fail(f"{path} fixed: dtype {a.dtype}, expected int32")
    for name in ("von_mises", "level"):
        a = vtk_array(cd, name, "f")
        if a is not None:
            expect_equal(f"{path} VTK {name}", a, e[name])
    check_units(path, g, {"displacement": "m", "velocity": "m/s", "fixed": "1", "von_mises": "Pa",
                          "level": None, "Points": "m"})

    if meshio is None:
        fail("meshio is not installed (python3-meshio)")
        return
    m = meshio.read(path)
    expect_equal(f"{path} meshio points", m.points, e["points"])
    if [c.type for c in m.cells] != ["hexahedron"]:
        fail(f"{path} meshio cell blocks {[c.type for c in m.cells]}, expected ['hexahedron']")
    else:
        expect_equal(f"{path} meshio hexahedra", m.cells[0].data.ravel(), e["connectivity"])
    for name in ("displacement", "velocity", "fixed"):
        expect_equal(f"{path} meshio {name}", m.point_data.get(name), e[name])
    for name in ("von_mises", "level"):
        got = m.cell_data.get(name)
        expect_equal(f"{path} meshio {name}", got[0] if got else None, e[name])


def meshio_read_empty(path):
    """meshio 5 raises IndexError on 0 cells; accept that, or a correct read."""
    if meshio is None:
        return None
    try:
        return meshio.read(path)
    except IndexError:
        return None


def check_empty_cells(path):
    g = read_vtk(path)
    pts = np.array([(0.1 * i, 0.0, 0.0) for i in range(4)])
    expect_equal(f"{path} VTK points", vtk_points(g), pts)
    if g.GetNumberOfCells() != 0:
        fail(f"{path}: {g.GetNumberOfCells()} cells, expected 0")
    a = vtk_array(g.GetPointData(), "displacement", "f")
    if a is not None:
        expect_equal(f"{path} VTK displacement", a, [displacement(i) for i in range(4)])
    m = meshio_read_empty(path)
    if m is not None:
        expect_equal(f"{path} meshio points", m.points, pts)


def check_empty(path):
    g = read_vtk(path)
    if g.GetNumberOfPoints() != 0 or g.GetNumberOfCells() != 0:
        fail(f"{path}: {g.GetNumberOfPoints()} points, {g.GetNumberOfCells()} cells, expected 0, 0")
    meshio_read_empty(path)


def check_lines(path):
    g = read_vtk(path)
    pts = np.array([(0.1 * i, 0.0, 0.0) for i in range(6)])
    expect_equal(f"{path} VTK points", vtk_points(g), pts)
    conn, ends, types = vtk_cells(g)
    expect_equal(f"{path} VTK connectivity", conn, [0, 1, 2, 3, 3, 4, 4, 5, 5])
    expect_equal(f"{path} VTK offsets", ends, [4, 6, 8, 9])
    expect_equal(f"{path} VTK types", types, [4, 3, 3, 1])
    vm = [1500.0 * (c + 1) for c in range(4)]
    a = vtk_array(g.GetCellData(), "von_mises", "f")
    if a is not None:
        expect_equal(f"{path} VTK von_mises", a, vm)
    a = vtk_array(g.GetPointData(), "displacement", "f")
    if a is not None:
        expect_equal(f"{path} VTK displacement", a, [displacement(i) for i in range(6)])
    # meshio 5 skips poly-lines (type 4, with a warning) but reads the rest.
    if meshio is not None:
        import contextlib
        import io
        with contextlib.redirect_stderr(io.StringIO()) as err:
            m = meshio.read(path)
        if err.getvalue() and "type 4" not in err.getvalue():
            fail(f"{path} meshio: unexpected message {err.getvalue()!r}")
        expect_equal(f"{path} meshio points", m.points, pts)
        blocks = {c.type: c.data for c in m.cells}
        expect_equal(f"{path} meshio lines", blocks.get("line"), [[3, 4], [4, 5]])
        expect_equal(f"{path} meshio vertex", blocks.get("vertex"), [[5]])


def check_vertices(path):
    g = read_vtk(path)
    pts = np.array([(0.1 * i, 0.2 * i, 0.3 * i) for i in range(3)])
    expect_equal(f"{path} VTK points", vtk_points(g), pts)
    conn, ends, types = vtk_cells(g)
    expect_equal(f"{path} VTK connectivity", conn, [0, 1, 2])
    expect_equal(f"{path} VTK types", types, [1, 1, 1])
    a = vtk_array(g.GetPointData(), "displacement", "f")
    if a is not None:
        expect_equal(f"{path} VTK displacement", a, [displacement(i) for i in range(3)])
    if meshio is not None:
        m = meshio.read(path)
        expect_equal(f"{path} meshio points", m.points, pts)
        expect_equal(f"{path} meshio vertices", m.cells[0].data.ravel(), [0, 1, 2])
        expect_equal(f"{path} meshio displacement", m.point_data.get("displacement"),
                     [displacement(i) for i in range(3)])


def read_pvd(path):
    root = ET.parse(path).getroot()
    if root.tag != "VTKFile" or root.get("type") != "Collection":
        fail(f"{path}: root <{root.tag} type={root.get('type')!r}>, expected a VTKFile Collection")
    return [(float(d.get("timestep")), d.get("file"), d.get("timestep"))
            for d in root.iter("DataSet")]


def check_series(d):
    path = os.path.join(d, "series.pvd")
    frames = read_pvd(path)
    times = [0.0, 0.05, 0.1 + 0.2]
    files = [f"series_{5 * k:06d}.vtu" for k in range(3)]
    if [f for _, f, _ in frames] != files:
        fail(f"{path} files {[f for _, f, _ in frames]}, expected {files}")
    if [t for t, _, _ in frames] != times:
        fail(f"{path} times {[t for t, _, _ in frames]}, expected {times} (exact)")
    for k, (_, f, _) in enumerate(frames):
        full = os.path.join(d, f)
        if not os.path.isfile(full):
            fail(f"{path} names {f}, which does not exist")
            continue
        check_hex(full, frame=k)

    path = os.path.join(d, "escape.pvd")
    frames = read_pvd(path)
    if [(t, f) for t, f, _ in frames] != [(1.5, "odd &<name>.vtu")]:
        fail(f"{path}: frames {frames}, expected [(1.5, 'odd &<name>.vtu')]")
    elif os.path.isfile(os.path.join(d, frames[0][1])):
        check_hex(os.path.join(d, frames[0][1]))
    else:
        fail(f"{path} names {frames[0][1]!r}, which does not exist")


def check_text(d):
    path = os.path.join(d, "table.csv")
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header = ["step", "time", "name", "x", "note, quoted"]
    if rows[:1] != [header]:
        fail(f"{path} header {rows[:1]}, expected {header}")
    expected = [[str(i), 0.01 * i, f"p{i}", 1.0 / (i + 3), f"n{i}"] for i in range(5)]
    got = [[r[0], float(r[1]), r[2], float(r[3]), r[4]] for r in rows[1:]]
    if got != expected:
        fail(f"{path} rows {got}, expected {expected}")
    with open(os.path.join(d, "long.csv")) as f:
        text = f.read()
    if text != "long\n" + "x" * 3000 + "\n":
        fail(f"long.csv: {len(text)} characters, expected {5 + 3001}")
    with open(os.path.join(d, "hello.txt")) as f:
        if f.read() != "hello\nworld\n":
            fail("hello.txt content differs")

def check_named(d):
    """single.vtu (one vertex: meshio failed on it when arrays were appended in
    document order), named.vtu and named3.vtu: names, flag and units."""
    for name, pts, disp, names in (
            ("single.vtu", [(0.1, 0.2, 0.3)], [displacement(1)], None),
            ("named.vtu", [(0.1, 0.2, 0.3)], [displacement(1)], ["STN"]),
            ("named3.vtu", [(0.1 * i, 0.2 * i, 0.3 * i) for i in range(3)],
             [displacement(i) for i in range(3)], ["a", "probe 2", "STN"])):
        path = os.path.join(d, name)
        g = read_vtk(path)
        expect_equal(f"{path} VTK points", vtk_points(g), pts)
        a = vtk_array(g.GetPointData(), "displacement", "f")
        if a is not None:
            expect_equal(f"{path} VTK displacement", a, disp)
        fd = g.GetFieldData().GetArray("names")
        got = names_of(vtk_to_numpy(fd)) if fd is not None else None
        if got != names:
            fail(f"{path} VTK names {got!r}, expected {names!r}")
        check_units(path, g, {"displacement": "m", "Points": "m"})
        if meshio is None:
            continue
        m = meshio.read(path)
        expect_equal(f"{path} meshio points", m.points, pts)
        expect_equal(f"{path} meshio displacement", m.point_data.get("displacement"), disp)
        expect_equal(f"{path} meshio vertices", m.cells[0].data.ravel(), list(range(len(pts))))
        got = names_of(m.field_data.get("names"))
        if got != names:
            fail(f"{path} meshio names {got!r}, expected {names!r}")
        if name == "named.vtu":
            expect_equal(f"{path} meshio target", m.point_data.get("target"), [1])


def main():
    if len(sys.argv) != 2:
        print("usage: io_readback.py DIR (the folder test_io wrote)", file=sys.stderr)
        return 2
    d = sys.argv[1]
    checks = [(check_hex, os.path.join(d, "hex.vtu")),
              (check_empty_cells, os.path.join(d, "empty_cells.vtu")),
              (check_empty, os.path.join(d, "empty.vtu")),
              (check_lines, os.path.join(d, "lines.vtu")),
              (check_vertices, os.path.join(d, "vertices.vtu")),
              (check_named, d),
              (check_series, d),
              (check_text, d)]
    for check, arg in checks:
        try:
            check(arg)
        except Exception as e:  # a reader that throws is a failure, keep checking the rest
            fail(f"{check.__name__}({arg}): {type(e).__name__}: {e}")
    leftovers = [f for f in os.listdir(d) if f.endswith(".tmp")]
    if leftovers:
        fail(f"{d}: temporary files left behind: {leftovers}")
    if failures:
        print(f"io_readback: {len(failures)} failure(s)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
