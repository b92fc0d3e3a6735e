/* test_hdf5 — writes results.h5 / results.xdmf with known contents through
 * the nh_h5 writer and checks its return codes and nh_test_failures; the files are
 * then read back by tests/hdf5_readback.py (h5py and meshio).
 *
 * usage: test_hdf5 DIR            write the known series and frames into DIR
 *        test_hdf5 --endless DIR  write steps, series and frames until killed
 *                                 (the SIGKILL trials of hdf5_readback.py)
 *
 * The values are defined by formulas that tests/hdf5_readback.py repeats
 * exactly (keep the two in step):
 *
 *   root attributes: format "needlehex-results 1", version "9.8.7",
 *     scene SCENE_TEXT (below, with non-ASCII characters and XML specials).
 *   /steps: columns step,time,dofs,eta,t_step; one row per step s = 1..N:
 *     (s, 0.01 s, 3 (s + 7), s % 4 == 0 ? nan : 1 / (s + 1), 1e-3 s^2).
 *   /probes: items "1", "tip probe"; components x,y,z,ux,uy,uz; one sample
 *     per step s = 0..N: time 0.01 s, value(i, k) = 0.001 s + 0.1 i + k.
 *   /tools: item "needle"; components tip_x,depth,axial_force,state; one
 *     sample per step s = 1..N: value(0, k) = s (k + 1) + 0.5.
 *   frames: frame f at step 5 f (f = 0..5; --endless: every 3rd step, f
 *     counting from 0), time 0.01 step, on an nx x ny x nz grid of
 *     hexahedra, nx from NX[] (ny = nz = 1; --endless: nx = 4 + 4 (f % 3),
 *     ny = nz = 8):
 *     point i = ix + (nx+1) (iy + (ny+1) iz) at (0.01 ix + 0.001 f, 0.02 iy, 0.03 iz)
 *     displacement[i] = (0.001 i, -0.002 i, f + 0.5 i)
 *     velocity[i]     = (f, i, -i)
 *     fixed[i]        = (i + f) % 2                               (Int32)
 *     cell c = cx + nx (cy + ny cz): corners in VTK order,
 *       (n(cx,cy,cz), n(cx+1,cy,cz), n(cx+1,cy+1,cz), n(cx,cy+1,cz), same at cz+1)
 *     von_mises[c] = 1000 (c + 1) + f, level[c] = c % 2,
 *     stress[c][k] = 10 c + k + f (6 components).
 *   In the normal run, frames 2 and 5 have the mesh of frames 1 and 4 (NX),
 *   so their connectivity links to the earlier dataset; frames 0, 3 and 4 change the
 *   number of points and cells. N = 25 steps.
 *
 * DIR/resume: a run interrupted and resumed (nh_h5_resume):
 *   first run: the known series for steps 1..10 (probes from 0), frames
 *     f = 0..5 at step 2 f on the grid NX[f] x 1 x 1;
 *   resumed at step 6 (the frames at 8 and 10 and the rows past 6 go), then
 *     steps 7..10 again with every value shifted: /steps dofs + 1000, probe
 *     and tool values + 1000, frames at 8 and 10 built with f = 100 + step / 2
 *     on nx = 3 (the mesh of the frame at 6: linked) and nx = 2.
 * DIR/resume_missing, _damaged, _foreign, _columns: nh_h5_resume at step 3
 *   of no file, a file of garbage bytes (moved to results.h5.damaged), an
 *   HDF5 file without the format attribute and a results file with other
 *   step columns: each becomes a fresh file with steps 4..5 (the known rows)
 *   and no frame. */
#include "check.h"
#include "io/io.h"

#include <dirent.h>
#include <hdf5.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define N_STEPS 25
static const int NX[] = {1, 2, 2, 3, 1, 1};
static const char SCENE_TEXT[] = "name: h5-test\n# \xc3\xbcn\xc3\xaf\x63ode & <xml> \"q\"\n";
static const char *const STEP_COLUMNS[] = {"step", "time", "dofs", "eta", "t_step"};
static const char *const PROBES[] = {"1", "tip probe"};
static const char *const PROBE_COMPONENTS[] = {"x", "y", "z", "ux", "uy", "uz"};
static const char *const TOOLS[] = {"needle"};
static const char *const TOOL_COMPONENTS[] = {"tip_x", "depth", "axial_force", "state"};

/* The arrays of one frame (see the formulas above). */
typedef struct {
  int np, nc;
  double *points, *disp, *vel, *cell;
  int *conn, *offsets, *fixed;
  nh_field pf[2], cf[3];
  nh_frame grid;
} frame_data;

static void frame_build(frame_data *d, int f, int nx, int ny, int nz) {
  d->np = (nx + 1) * (ny + 1) * (nz + 1);
  d->nc = nx * ny * nz;
  d->points = malloc(sizeof(double) * 3 * (size_t)d->np);
  d->disp = malloc(sizeof(double) * 3 * (size_t)d->np);
  d->vel = malloc(sizeof(double) * 3 * (size_t)d->np);
  d->fixed = malloc(sizeof(int) * (size_t)d->np);
  d->cell = malloc(sizeof(double) * 8 * (size_t)d->nc);
  d->conn = malloc(sizeof(int) * 8 * (size_t)d->nc);
  d->offsets = malloc(sizeof(int) * (size_t)d->nc);
  if (!d->points || !d->disp || !d->vel || !d->fixed || !d->cell || !d->conn || !d->offsets) {
    fprintf(stderr, "test_hdf5: out of memory\n");
    exit(1);
  }
  for (int iz = 0; iz <= nz; ++iz)
    for (int iy = 0; iy <= ny; ++iy)
      for (int ix = 0; ix <= nx; ++ix) {
        int i = ix + (nx + 1) * (iy + (ny + 1) * iz);
        double p[3] = {0.01 * ix + 0.001 * f, 0.02 * iy, 0.03 * iz};
        double u[3] = {0.001 * i, -0.002 * i, f + 0.5 * i};
        double v[3] = {f, i, -i};
        for (int k = 0; k < 3; ++k) {
          d->points[3 * i + k] = p[k];
          d->disp[3 * i + k] = u[k];
          d->vel[3 * i + k] = v[k];
        }
        d->fixed[i] = (i + f) % 2;
      }
  double *von_mises = d->cell, *level = d->cell + d->nc, *stress = d->cell + 2 * d->nc;
  for (int cz = 0; cz < nz; ++cz)
    for (int cy = 0; cy < ny; ++cy)
      for (int cx = 0; cx < nx; ++cx) {
        int c = cx + nx * (cy + ny * cz);
        static const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                         {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
        for (int k = 0; k < 8; ++k)
          d->conn[8 * c + k] = (cx + corner[k][0]) +
                               (nx + 1) * ((cy + corner[k][1]) + (ny + 1) * (cz + corner[k][2]));
        d->offsets[c] = 8 * (c + 1);
        von_mises[c] = 1000.0 * (c + 1) + f;
        level[c] = c % 2;
        for (int k = 0; k < 6; ++k) stress[6 * c + k] = 10.0 * c + k + f;
      }
  d->pf[0] = (nh_field){"displacement", 3, d->disp, "m"};
  d->pf[1] = (nh_field){"velocity", 3, d->vel, "m/s"};
  d->cf[0] = (nh_field){"von_mises", 1, von_mises, "Pa"};
  d->cf[1] = (nh_field){"level", 1, level, "1"};
  d->cf[2] = (nh_field){"stress", 6, stress, "Pa"};
  d->grid = (nh_frame){.n_points = d->np,
                       .points = d->points,
                       .n_cells = d->nc,
                       .connectivity = d->conn,
                       .offsets = d->offsets,
                       .type = NH_VTK_HEXAHEDRON,
                       .n_point_fields = 2,
                       .point_fields = d->pf,
                       .n_cell_fields = 3,
                       .cell_fields = d->cf,
                       .point_int_flags = d->fixed,
                       .point_flag_name = "fixed"};
}

static void frame_free(frame_data *d) {
  free(d->points), free(d->disp), free(d->vel), free(d->fixed);
  free(d->cell), free(d->conn), free(d->offsets);
}

static void step_row(int s, double row[5]) {
  row[0] = s;
  row[1] = 0.01 * s;
  row[2] = 3.0 * (s + 7);
  row[3] = s % 4 == 0 ? NAN : 1.0 / (s + 1);
  row[4] = 1e-3 * s * s;
}

/* Added to the values written after a resume (0 before). */
static double shift = 0.0;

static void append_probes(nh_h5 *h, int s) {
  double v[2 * 6];
  for (int i = 0; i < 2; ++i)
    for (int k = 0; k < 6; ++k) v[6 * i + k] = 0.001 * s + 0.1 * i + k + shift;
  CHECK_OK(nh_h5_append_series(h, "probes", s, 0.01 * s, 2, PROBES, 6, PROBE_COMPONENTS, v));
}

static void append_tools(nh_h5 *h, int s) {
  double v[4];
  for (int k = 0; k < 4; ++k) v[k] = s * (k + 1.0) + 0.5 + shift;
  CHECK_OK(nh_h5_append_series(h, "tools", s, 0.01 * s, 1, TOOLS, 4, TOOL_COMPONENTS, v));
}

static void write_frame(nh_h5 *h, int f, int step, int nx, int ny, int nz) {
  frame_data d;
  frame_build(&d, f, nx, ny, nz);
  CHECK_OK(nh_h5_write_frame(h, step, 0.01 * step, &d.grid));
  frame_free(&d);
}

static nh_h5 *create(const char *dir) {
  nh_h5 *h = NULL;
  CHECK_OK(nh_h5_create(dir, SCENE_TEXT, "9.8.7", 5, STEP_COLUMNS, &h));
  return h;
}

/* The run the readback checks: N_STEPS steps, a frame every 5 steps. */
static void write_known(const char *dir) {
  nh_h5 *h = create(dir);
  double row[5];
  append_probes(h, 0);
  write_frame(h, 0, 0, NX[0], 1, 1);
  for (int s = 1; s <= N_STEPS; ++s) {
    step_row(s, row);
    CHECK_OK(nh_h5_append_steps(h, row));
    append_probes(h, s);
    append_tools(h, s);
    if (s % 5 == 0) write_frame(h, s / 5, s, NX[s / 5], 1, 1);
  }
  CHECK_OK(nh_h5_close(&h));
  EXPECT(h == NULL, "nh_h5_close must set the handle to NULL");
}

/* Writes until killed: the SIGKILL trials. */
static void write_endless(const char *dir) {
  nh_h5 *h = create(dir);
  double row[5];
  append_probes(h, 0);
  write_frame(h, 0, 0, 4, 8, 8);
  for (int s = 1;; ++s) {
    step_row(s, row);
    CHECK_OK(nh_h5_append_steps(h, row));
    append_probes(h, s);
    append_tools(h, s);
    if (s % 3 == 0) {
      int f = s / 3;
      write_frame(h, f, s, 4 + 4 * (f % 3), 8, 8);
    }
  }
}

static void append_row(nh_h5 *h, int s) {
  double row[5];
  step_row(s, row);
  row[2] += shift;
  CHECK_OK(nh_h5_append_steps(h, row));
}

/* Interrupted at step 10, resumed at step 6, continued to 10 (see above). */
static void write_resumed(const char *dir) {
  CHECK_OK(nh_mkdir_p(dir));
  nh_h5 *h = create(dir);
  append_probes(h, 0);
  write_frame(h, 0, 0, NX[0], 1, 1);
  for (int s = 1; s <= 10; ++s) {
    append_row(h, s);
    append_probes(h, s);
    append_tools(h, s);
    if (s % 2 == 0) write_frame(h, s / 2, s, NX[s / 2], 1, 1);
  }
  CHECK_OK(nh_h5_close(&h));
  CHECK_OK(nh_h5_resume(dir, SCENE_TEXT, "9.8.7", 5, STEP_COLUMNS, 6, &h));
  EXPECT(h != NULL, "nh_h5_resume must return a handle");
  if (!h) return;
  shift = 1000.0;
  for (int s = 7; s <= 10; ++s) {
    append_row(h, s);
    append_probes(h, s);
    append_tools(h, s);
    if (s % 2 == 0) write_frame(h, 100 + s / 2, s, s == 8 ? 3 : 2, 1, 1);
  }
  shift = 0.0;
  /* The frame at 6 is kept: writing it again is refused. */
  frame_data d;
  frame_build(&d, 0, 1, 1, 1);
  int rc = nh_h5_write_frame(h, 6, 0.06, &d.grid);
  EXPECT(rc == NH_ERR_INTERNAL, "a kept frame written again returned %d", rc);
  frame_free(&d);
  CHECK_OK(nh_h5_close(&h));
}

static void write_bytes(const char *path, const char *bytes) {
  FILE *f = fopen(path, "wb");
  EXPECT(f != NULL, "cannot write %s", path);
  if (!f) return;
  fputs(bytes, f);
  fclose(f);
}

/* nh_h5_resume of a folder whose results.h5 cannot be resumed. */
static void check_resume_fallback(const char *dir, const char *kind) {
  char sub[4200], path[4300];
  snprintf(sub, sizeof sub, "%s/resume_%s", dir, kind);
  CHECK_OK(nh_mkdir_p(sub));
  snprintf(path, sizeof path, "%s/results.h5", sub);
  remove(path);
  char aside[4400];
  snprintf(aside, sizeof aside, "%s.damaged", path);
  remove(aside); /* from an earlier test run */
  if (!strcmp(kind, "damaged")) {
    write_bytes(path, "not an HDF5 file: the bytes a kill left\n");
  } else if (!strcmp(kind, "foreign")) {
    hid_t f = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    EXPECT(f >= 0, "cannot create %s", path);
    if (f >= 0) H5Fclose(f);
  } else if (!strcmp(kind, "columns")) {
    nh_h5 *h = NULL;
    CHECK_OK(nh_h5_create(sub, NULL, NULL, 4, STEP_COLUMNS, &h));
    CHECK_OK(nh_h5_close(&h));
  }
  nh_h5 *h = NULL;
  int rc = nh_h5_resume(sub, SCENE_TEXT, "9.8.7", 5, STEP_COLUMNS, 3, &h);
  EXPECT(rc == NH_OK && h != NULL, "resume of a %s file returned %d", kind, rc);
  if (!h) return;
  for (int s = 4; s <= 5; ++s) append_row(h, s);
  CHECK_OK(nh_h5_close(&h));
}

static int message_has(const char *needle) {
  return strstr(nh_error_message(), needle) != NULL;
}

/* Misuse and failures, in a scratch subfolder of DIR. */
static void check_failures(const char *dir) {
  char sub[4200], missing[4200];
  snprintf(sub, sizeof sub, "%s/failures", dir);
  snprintf(missing, sizeof missing, "%s/no/such/folder", dir);
  CHECK_OK(nh_mkdir_p(sub));

  nh_h5 *h = (nh_h5 *)&nh_test_failures; /* must be reset to NULL on failure */
  int rc = nh_h5_create(missing, NULL, NULL, 5, STEP_COLUMNS, &h);
  EXPECT(rc == NH_ERR_IO, "create in a missing folder returned %d, expected NH_ERR_IO", rc);
  EXPECT(h == NULL, "the handle must be NULL after a failed create");
  EXPECT(message_has(missing) && message_has("results.h5") &&
             message_has("No such file or directory"),
         "the message must name the file and the OS reason");
  EXPECT(!strchr(nh_error_message(), '\n'), "the message must be one line");

  h = create(sub);
  frame_data d;
  frame_build(&d, 0, 2, 1, 1);
  CHECK_OK(nh_h5_write_frame(h, 7, 0.07, &d.grid));
  rc = nh_h5_write_frame(h, 7, 0.07, &d.grid);
  EXPECT(rc == NH_ERR_INTERNAL && message_has("000007"),
         "a frame written twice returned %d, expected NH_ERR_INTERNAL", rc);
  d.grid.type = NH_VTK_VERTEX;
  rc = nh_h5_write_frame(h, 8, 0.08, &d.grid);
  EXPECT(rc == NH_ERR_INTERNAL, "a non-hexahedral grid returned %d, expected NH_ERR_INTERNAL", rc);
  d.grid.type = NH_VTK_HEXAHEDRON;
  d.conn[3] = d.np;
  rc = nh_h5_write_frame(h, 9, 0.09, &d.grid);
  EXPECT(rc == NH_ERR_INTERNAL, "a point index out of range returned %d", rc);
  frame_free(&d);

  append_probes(h, 0);
  double v[3 * 6] = {0};
  rc = nh_h5_append_series(h, "probes", 1, 0.01, 3, (const char *const[]){"1", "2", "3"}, 6,
                           PROBE_COMPONENTS, v);
  EXPECT(rc == NH_ERR_INTERNAL, "a series changing its item count returned %d", rc);
  rc = nh_h5_append_series(h, "probes", 1, 0.01, 2, (const char *const[]){"1", "other"}, 6,
                           PROBE_COMPONENTS, v);
  EXPECT(rc == NH_ERR_INTERNAL, "a series renaming an item returned %d", rc);
  rc = nh_h5_append_series(h, "frames", 1, 0.01, 2, PROBES, 6, PROBE_COMPONENTS, v);
  EXPECT(rc == NH_ERR_INTERNAL, "a series named 'frames' returned %d", rc);
  rc = nh_h5_append_series(h, "a/b", 1, 0.01, 2, PROBES, 6, PROBE_COMPONENTS, v);
  EXPECT(rc == NH_ERR_INTERNAL, "a series named 'a/b' returned %d", rc);
  nh_h5 *other = (nh_h5 *)&nh_test_failures;
  rc = nh_h5_resume(sub, NULL, NULL, 4, STEP_COLUMNS + 1, 0, &other);
  EXPECT(rc == NH_ERR_INTERNAL && other == NULL, "a resume without a 'step' column returned %d",
         rc);
  append_probes(h, 1); /* still usable after refused calls */
  CHECK_OK(nh_h5_flush(h));
  CHECK_OK(nh_h5_close(&h));
  CHECK_OK(nh_h5_close(&h)); /* NULL-safe */
  CHECK_OK(nh_h5_close(NULL));

  /* Nothing temporary is left behind. */
  for (int pass = 0; pass < 2; ++pass) {
    DIR *dp = opendir(pass ? sub : dir);
    EXPECT(dp != NULL, "cannot list %s", pass ? sub : dir);
    if (!dp) continue;
    struct dirent *e;
    while ((e = readdir(dp))) {
      size_t n = strlen(e->d_name);
      EXPECT(n < 4 || strcmp(e->d_name + n - 4, ".tmp") != 0, "'%s' left behind", e->d_name);
    }
    closedir(dp);
  }
}

int main(int argc, char **argv) {
  if (argc == 3 && strcmp(argv[1], "--endless") == 0) {
    CHECK_OK(nh_mkdir_p(argv[2]));
    write_endless(argv[2]);
    return 0;
  }
  if (argc != 2) {
    fprintf(stderr, "usage: test_hdf5 DIR | test_hdf5 --endless DIR\n");
    return 2;
  }
  CHECK_OK(nh_mkdir_p(argv[1]));
  write_known(argv[1]);
  check_failures(argv[1]);
  char sub[4200];
  snprintf(sub, sizeof sub, "%s/resume", argv[1]);
  write_resumed(sub);
  check_resume_fallback(argv[1], "missing");
  check_resume_fallback(argv[1], "damaged");
  check_resume_fallback(argv[1], "foreign");
  check_resume_fallback(argv[1], "columns");
  return nh_test_failures ? 1 : 0;
}
