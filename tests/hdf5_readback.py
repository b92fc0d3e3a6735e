"""Reads back what tests/test_hdf5.c wrote, with h5py and meshio.

usage: hdf5_readback.py check DIR
         every dataset, attribute and length of DIR/results.h5 against the
         formulas of test_hdf5.c, and DIR/results.xdmf with meshio's
         TimeSeriesReader (points, cells and fields of every frame); then
         the resumed file DIR/resume (steps 1..10, the values of the second
         run after step 6, its frames <= 6 and the new ones, the XDMF series
         with meshio) and the fresh files of DIR/resume_* (a damaged file
         moved to results.h5.damaged, unchanged).
       hdf5_readback.py kill TEST_HDF5 WORKDIR TRIALS
         TRIALS times: run `TEST_HDF5 --endless WORKDIR/trial_NN`, SIGKILL it
         after a random delay, then check that results.h5 opens and that
         every frame results.xdmf lists, and every /steps row up to the last
         listed frame, reads back exactly. A file that does not open, or a
         listed frame that does not read, fails the trial (none tolerated).

Silent on success; loud (expected, actual) on failure. The formulas are the
ones documented at the top of test_hdf5.c: keep the two in step."""
import math
import os
import random
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

import h5py
import meshio
import numpy as np

N_STEPS = 25
NX = [1, 2, 2, 3, 1, 1]
SCENE_TEXT = 'name: h5-test\n# \u00fcn\u00efcode & <xml> "q"\n'
STEP_COLUMNS = ["step", "time", "dofs", "eta", "t_step"]
PROBES = ["1", "tip probe"]
PROBE_COMPONENTS = ["x", "y", "z", "ux", "uy", "uz"]
TOOLS = ["needle"]
TOOL_COMPONENTS = ["tip_x", "depth", "axial_force", "state"]
CORNERS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]

failures = []
corrupt = []  # kill trials whose file HDF5 itself reported as damaged


def fail(what, expected, actual):
    failures.append(f"{what}: expected {expected!r}, got {actual!r}")


def expect_equal(what, actual, expected):
    """Exact equality (NaN equals NaN), with shapes."""
    a = np.asarray(actual)
    e = np.asarray(expected)
    if a.shape != e.shape:
        fail(f"{what} shape", e.shape, a.shape)
    elif not np.array_equal(a, e, equal_nan=a.dtype.kind == "f"):
        same = a == e
        if a.dtype.kind == "f" and e.dtype.kind == "f":
            same |= np.isnan(a) & np.isnan(e)
        i = tuple(np.argwhere(~same)[0]) if a.ndim else ()
        fail(f"{what}[{','.join(map(str, i))}]", e[i], a[i])


def step_row(s):
    return [s, 0.01 * s, 3.0 * (s + 7), math.nan if s % 4 == 0 else 1.0 / (s + 1), 1e-3 * s * s]


def probe_values(s):
    return [[0.001 * s + 0.1 * i + k for k in range(6)] for i in range(2)]


def tool_values(s):
    return [[s * (k + 1.0) + 0.5 for k in range(4)]]


def frame_expected(f, nx, ny, nz):
    """points, connectivity, point fields, cell fields of frame f."""
    np_ = (nx + 1) * (ny + 1) * (nz + 1)
    # Index order i = ix + (nx+1) (iy + (ny+1) iz): iz slowest, ix fastest.
    iz, iy, ix = (
        a.ravel()
        for a in np.meshgrid(np.arange(nz + 1), np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    )
    points = np.column_stack([0.01 * ix + 0.001 * f, 0.02 * iy, 0.03 * iz])
    i = np.arange(np_, dtype=float)
    point = {
        "displacement": np.column_stack([0.001 * i, -0.002 * i, f + 0.5 * i]),
        "velocity": np.column_stack([np.full(np_, float(f)), i, -i]),
        "fixed": ((np.arange(np_) + f) % 2).astype(np.int32),
    }
    cz, cy, cx = (
        a.ravel() for a in np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    )
    conn = np.column_stack(
        [(cx + a) + (nx + 1) * ((cy + b) + (ny + 1) * (cz + c)) for a, b, c in CORNERS]
    )
    nc = nx * ny * nz
    c = np.arange(nc, dtype=float)
    cell = {
        "von_mises": 1000.0 * (c + 1) + f,
        "level": c % 2,
        "stress": 10.0 * c[:, None] + np.arange(6)[None, :] + f,
    }
    return points, conn.astype(np.int32).reshape(nc, 8), point, cell


def check_frame(h5, name, f, step, grid):
    """Frame /frames/<name> equals frame f at `step` on grid (nx, ny, nz)."""
    where = f"/frames/{name}"
    if name not in h5["frames"]:
        fail(f"{where} exists", True, False)
        return
    g = h5["frames"][name]
    expect_equal(f"{where} attribute step", g.attrs["step"], step)
    expect_equal(f"{where} attribute time", g.attrs["time"], 0.01 * step)
    points, conn, point, cell = frame_expected(f, *grid)
    expect_equal(f"{where}/points", g["points"][()], points)
    expect_equal(f"{where}/connectivity", g["connectivity"][()], conn)
    if g["connectivity"].dtype != np.int32:
        fail(f"{where}/connectivity dtype", "int32", g["connectivity"].dtype)
    if sorted(g["point_data"]) != sorted(point):
        fail(f"{where}/point_data names", sorted(point), sorted(g["point_data"]))
    if sorted(g["cell_data"]) != sorted(cell):
        fail(f"{where}/cell_data names", sorted(cell), sorted(g["cell_data"]))
    for k, v in point.items():
        if k in g["point_data"]:
            expect_equal(f"{where}/point_data/{k}", g["point_data"][k][()], v)
    for k, v in cell.items():
        if k in g["cell_data"]:
            expect_equal(f"{where}/cell_data/{k}", g["cell_data"][k][()], v)


def xdmf_frames(path):
    """(name, time) of every grid the XDMF collection lists."""
    root = ET.parse(path).getroot()
    out = []
    for grid in root.iter("Grid"):
        if grid.get("GridType") == "Uniform":
            out.append((grid.get("Name"), float(grid.find("Time").get("Value"))))
    return out


def check_known(d):
    frames = [(f, 5 * f, (NX[f], 1, 1)) for f in range(len(NX))]
    with h5py.File(os.path.join(d, "results.h5"), "r") as h5:
        # Root attributes.
        expect_equal("attribute format", h5.attrs["format"], "needlehex-results 1")
        expect_equal("attribute version", h5.attrs["version"], "9.8.7")
        expect_equal("attribute scene", h5.attrs["scene"], SCENE_TEXT)
        expect_equal("root members", sorted(h5), ["frames", "probes", "steps", "tools"])

        # /steps: one row per step.
        steps = h5["steps"]
        expect_equal("/steps columns", list(steps.attrs["columns"]), STEP_COLUMNS)
        expect_equal("/steps", steps[()], np.array([step_row(s) for s in range(1, N_STEPS + 1)]))
        if steps.maxshape != (None, 5) or steps.chunks is None:
            fail("/steps maxshape, chunked", ((None, 5), True), (steps.maxshape, steps.chunks))

        # Series.
        for group, first, items, comps, values in (
            ("probes", 0, PROBES, PROBE_COMPONENTS, probe_values),
            ("tools", 1, TOOLS, TOOL_COMPONENTS, tool_values),
        ):
            g = h5[group]
            s = np.arange(first, N_STEPS + 1)
            expect_equal(f"/{group}/step", g["step"][()], s.astype(np.int32))
            expect_equal(f"/{group}/time", g["time"][()], 0.01 * s)
            expect_equal(f"/{group}/values", g["values"][()], np.array([values(k) for k in s]))
            expect_equal(f"/{group}/values names", list(g["values"].attrs["names"]), items)
            expect_equal(
                f"/{group}/values components", list(g["values"].attrs["components"]), comps
            )

        # Frames.
        expect_equal("/frames members", sorted(h5["frames"]), [f"{s:06d}" for _, s, _ in frames])
        for f, s, grid in frames:
            check_frame(h5, f"{s:06d}", f, s, grid)
        # Unchanged meshes share their connectivity (an external link to the one dataset), changed ones do not.
        conn = {s: h5["frames"][f"{s:06d}"]["connectivity"] for _, s, _ in frames}
        linked = [conn[frames[k][1]].id == conn[frames[k - 1][1]].id for k in range(1, len(frames))]
        expect_equal("connectivity shared with the previous frame", linked,
                     [NX[k] == NX[k - 1] for k in range(1, len(NX))])

    # XDMF: the frame list, then meshio's time-series reader.
    xdmf = os.path.join(d, "results.xdmf")
    expect_equal(
        "XDMF frames", xdmf_frames(xdmf), [(f"frame_{s:06d}", 0.01 * s) for _, s, _ in frames]
    )
    with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
        points, cells = reader.read_points_cells()  # the first frame's mesh
        expect_equal("meshio first frame points", points, frame_expected(0, NX[0], 1, 1)[0])
        if reader.num_steps != len(frames):
            fail("meshio num_steps", len(frames), reader.num_steps)
        for k, (f, s, grid) in enumerate(frames):
            # The reader keeps one mesh; pointing it at frame k reads that
            # frame's own (possibly refined) mesh.
            reader.mesh_grid = reader.collection[k]
            points, cells = reader.read_points_cells()
            t, point_data, cell_data = reader.read_data(k)
            e_points, e_conn, e_point, e_cell = frame_expected(f, *grid)
            expect_equal(f"meshio frame {k} time", t, 0.01 * s)
            expect_equal(f"meshio frame {k} points", points, e_points)
            expect_equal(f"meshio frame {k} cell types", [c.type for c in cells], ["hexahedron"])
            expect_equal(f"meshio frame {k} connectivity", cells[0].data, e_conn)
            expect_equal(f"meshio frame {k} point data names", sorted(point_data), sorted(e_point))
            expect_equal(f"meshio frame {k} cell data names", sorted(cell_data), sorted(e_cell))
            for name, v in e_point.items():
                expect_equal(f"meshio frame {k} point_data {name}", point_data.get(name), v)
            for name, v in e_cell.items():
                got = cell_data.get(name)
                expect_equal(f"meshio frame {k} cell_data {name}", got[0] if got else None, v)


def check_meshio_series(xdmf, frames):
    """meshio reads every frame (f, step, grid) of the XDMF series exactly."""
    with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
        reader.read_points_cells()
        if reader.num_steps != len(frames):
            fail(f"{xdmf}: meshio num_steps", len(frames), reader.num_steps)
            return
        for k, (f, s, grid) in enumerate(frames):
            reader.mesh_grid = reader.collection[k]
            points, cells = reader.read_points_cells()
            t, point_data, cell_data = reader.read_data(k)
            e_points, e_conn, e_point, e_cell = frame_expected(f, *grid)
            expect_equal(f"{xdmf}: meshio frame {k} time", t, 0.01 * s)
            expect_equal(f"{xdmf}: meshio frame {k} points", points, e_points)
            expect_equal(f"{xdmf}: meshio frame {k} connectivity", cells[0].data, e_conn)
            for name, v in e_point.items():
                expect_equal(f"{xdmf}: meshio frame {k} point_data {name}", point_data.get(name), v)
            for name, v in e_cell.items():
                got = cell_data.get(name)
                expect_equal(f"{xdmf}: meshio frame {k} cell_data {name}", got[0] if got else None, v)


def check_resumed(d):
    """DIR/resume: 10 steps and frames at even steps, resumed at step 6 and
    continued to 10 with values shifted by 1000 (test_hdf5.c)."""
    shift = lambda s: 1000.0 if s > 6 else 0.0  # noqa: E731
    frames = [(f, 2 * f, (NX[f], 1, 1)) for f in range(4)]  # steps 0, 2, 4, 6
    frames += [(104, 8, (3, 1, 1)), (105, 10, (2, 1, 1))]
    with h5py.File(os.path.join(d, "results.h5"), "r") as h5:
        expect_equal(f"{d}: attribute scene", h5.attrs["scene"], SCENE_TEXT)
        rows = np.array([step_row(s) for s in range(1, 11)])
        rows[:, 2] += [shift(s) for s in range(1, 11)]
        expect_equal(f"{d}: /steps", h5["steps"][()], rows)
        for group, first, values in (("probes", 0, probe_values), ("tools", 1, tool_values)):
            g = h5[group]
            s = np.arange(first, 11)
            expect_equal(f"{d}: /{group}/step", g["step"][()], s.astype(np.int32))
            expect_equal(f"{d}: /{group}/time", g["time"][()], 0.01 * s)
            expect_equal(f"{d}: /{group}/values", g["values"][()],
                         np.array([np.array(values(k)) + shift(k) for k in s]))
        expect_equal(f"{d}: /frames members", sorted(h5["frames"]),
                     [f"{s:06d}" for _, s, _ in frames])
        for f, s, grid in frames:
            check_frame(h5, f"{s:06d}", f, s, grid)
        # The frame at 8 is on the mesh of the kept frame at 6: linked to its dataset.
        if h5["frames/000008/connectivity"].id != h5["frames/000006/connectivity"].id:
            fail(f"{d}: /frames/000008/connectivity linked to 000006's", True, False)
    xdmf = os.path.join(d, "results.xdmf")
    expect_equal(f"{d}: XDMF frames", xdmf_frames(xdmf),
                 [(f"frame_{s:06d}", 0.01 * s) for _, s, _ in frames])
    check_meshio_series(xdmf, frames)

    # Files that cannot be resumed: a fresh file with the rows of steps 4, 5.
    for kind in ("missing", "damaged", "foreign", "columns"):
        sub = f"{d}_{kind}"
        with h5py.File(os.path.join(sub, "results.h5"), "r") as h5:
            expect_equal(f"{sub}: format", h5.attrs["format"], "needlehex-results 1")
            expect_equal(f"{sub}: /steps", h5["steps"][()], np.array([step_row(4), step_row(5)]))
            expect_equal(f"{sub}: frames", list(h5["frames"]), [])
        expect_equal(f"{sub}: XDMF frames", xdmf_frames(os.path.join(sub, "results.xdmf")), [])
        aside = os.path.join(sub, "results.h5.damaged")
        if kind == "damaged":
            with open(aside, "rb") as f:
                expect_equal(f"{aside} (kept as it was)", f.read(),
                             b"not an HDF5 file: the bytes a kill left\n")
        elif os.path.exists(aside):
            fail(f"{aside} exists", False, True)


def check_killed(d):
    """After a SIGKILL: what the XDMF lists must read back exactly.
    Returns (frames listed, steps rows) or None if nothing was promised yet."""
    xdmf = os.path.join(d, "results.xdmf")
    if not os.path.exists(xdmf):
        return None  # killed before nh_h5_create finished: nothing promised
    listed = xdmf_frames(xdmf)
    try:
        h5 = h5py.File(os.path.join(d, "results.h5"), "r")
    except Exception as e:  # noqa: BLE001 - any failure to open is the finding
        corrupt.append(f"{d}: results.h5 does not open ({len(listed)} frames listed): {e}")
        return len(listed), -1
    with h5:
        try:
            for name, t in listed:
                step = int(name.split("_")[1])
                f = step // 3
                check_frame(h5, f"{step:06d}", f, step, (4 + 4 * (f % 3), 8, 8))
                expect_equal(f"{d}: XDMF time of {name}", t, 0.01 * step)
            rows = h5["steps"].shape[0]
            last = int(listed[-1][0].split("_")[1]) if listed else 0
            if rows < last:
                fail(f"{d}: /steps rows up to the last listed frame", f">= {last}", rows)
            expected = np.array([step_row(s) for s in range(1, rows + 1)]).reshape(rows, 5)
            expect_equal(f"{d}: /steps", h5["steps"][()], expected)
            for group in ("probes", "tools"):
                n = h5[group]["step"].shape[0] if group in h5 else 0
                if n < last:
                    fail(f"{d}: /{group} samples up to step {last}", f">= {last}", n)
            # meshio reads the series that the XDMF lists.
            if listed:
                with meshio.xdmf.TimeSeriesReader(xdmf) as reader:
                    reader.mesh_grid = reader.collection[len(listed) - 1]
                    points, _ = reader.read_points_cells()
                    reader.read_data(len(listed) - 1)
            return len(listed), rows
        except Exception as e:  # noqa: BLE001
            corrupt.append(f"{d}: reading the listed frames: {e!r}")
            return len(listed), -1


def kill_trials(binary, work, trials):
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    rng = random.Random(20240611)
    summary = []
    for k in range(trials):
        d = os.path.join(work, f"trial_{k:03d}")
        delay = rng.uniform(0.01, 0.5)
        proc = subprocess.Popen([binary, "--endless", d], stderr=subprocess.PIPE)
        time.sleep(delay)
        if proc.poll() is not None:
            fail(f"trial {k}: the writer was still running", "running",
                 f"exit {proc.returncode}: {proc.stderr.read().decode()}")
            continue
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        proc.stderr.close()
        before = len(failures) + len(corrupt)
        res = check_killed(d)
        summary.append((k, delay, res, len(failures) + len(corrupt) == before))
    # Every file is written whole and renamed into place (results.h5 and each
    # frame file): a kill leaves no damaged file, and none is tolerated.
    failures.extend(corrupt)
    if os.environ.get("NH_VERBOSE") or failures:
        for k, delay, res, ok in summary:
            print(f"trial {k:2d}: killed after {delay:.3f} s: (frames listed, steps rows) = {res}: "
                  f"{'ok' if ok else 'FAILED'}")
    if not failures and not corrupt:
        shutil.rmtree(work, ignore_errors=True)


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "check":
        check_known(sys.argv[2])
        check_resumed(os.path.join(sys.argv[2], "resume"))
    elif len(sys.argv) == 5 and sys.argv[1] == "kill":
        kill_trials(sys.argv[2], sys.argv[3], int(sys.argv[4]))
    else:
        print(__doc__, file=sys.stderr)
        return 2
    for f in failures:
        print(f, file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
