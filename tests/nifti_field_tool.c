/* nifti_field_tool — the driver of tests/nifti_field.py: a displacement of
 * known closed form on a small box mesh, sampled on a reference image's
 * voxel centres through the mesh (nh_mesh_sample_image) and written as
 * NIfTI (io/nifti.c).
 *
 *   nifti_field_tool field REF OUT lo(3) hi(3) grid(3) t(3) eps c(3) sigma e(3)
 *       the box mesh [lo, hi] (metres) of grid cells, its cell at the lattice
 *       origin refined by hex2 (hanging nodes on its faces), nodal values
 *       u(X) = t + eps exp(−|X − c|²/σ²) e (metres) at the non-hanging nodes
 *       and their masters' interpolation at the hanging ones; writes
 *       OUT/displacement.nii.gz and OUT/tissue_mask.nii.gz on REF's grid.
 *   nifti_field_tool scalar REF OUT [float]
 *       reads REF's voxels (nh_image_read_values) and writes them back as
 *       OUT (nh_nifti_write_scalar, REF's type or float32).
 *   nifti_field_tool fail REF OUT [OTHER]
 *       writes a field of zeros to OUT on REF's grid (read from REF, then
 *       named OTHER if given: a reference that changed since it was read),
 *       which must fail: prints the error and exits 3 on NH_ERR_IO
 *       (anything else: 1).
 * Exit 0 on success, 1 on an error (printed). */
#include "hanging_mesh.h"
#include "io/io.h"

#include <string.h>

static double arg(char **argv, int i) {
  return strtod(argv[i], NULL);
}

static int field(int argc, char **argv) {
  if (argc != 24) {
    fprintf(stderr, "field: 24 arguments expected, got %d\n", argc);
    return 1;
  }
  const char *ref_path = argv[2], *out = argv[3];
  double lo[3], hi[3], t[3], c[3], e[3];
  int grid[3];
  for (int k = 0; k < 3; k++) {
    lo[k] = arg(argv, 4 + k), hi[k] = arg(argv, 7 + k), grid[k] = atoi(argv[10 + k]);
    t[k] = arg(argv, 13 + k), c[k] = arg(argv, 17 + k), e[k] = arg(argv, 21 + k);
  }
  double eps = arg(argv, 16), sigma = arg(argv, 20);
  nh_image *ref;
  CHECK_OK(nh_image_read(ref_path, 0, NULL, &ref));
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_template *tmpl = regular_template(2);
  int first = 0;
  CHECK_OK(nh_mesh_refine(m, tmpl, &first, 1, NULL));
  nh_template_destroy(&tmpl);
  nh_hanging *hang;
  CHECK_OK(nh_hanging_detect(m, NULL, &hang));
  double *u = malloc(sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) {
    const double *X = m->X + 3 * i;
    double r2 = 0.0;
    for (int k = 0; k < 3; k++) r2 += (X[k] - c[k]) * (X[k] - c[k]);
    double g = eps * exp(-r2 / (sigma * sigma));
    for (int k = 0; k < 3; k++) u[3 * i + k] = t[k] + g * e[k];
  }
  nh_hanging_interpolate(hang, u, 3);
  size_t nv = (size_t)ref->n[0] * ref->n[1] * ref->n[2];
  double *values = malloc(sizeof(double) * 3 * nv);
  unsigned char *mask = malloc(nv);
  CHECK_OK(nh_mesh_sample_image(m, u, ref, values, mask));
  char path[2048];
  snprintf(path, sizeof path, "%s/displacement.nii.gz", out);
  CHECK_OK(nh_nifti_write_displacement(path, ref, values));
  snprintf(path, sizeof path, "%s/tissue_mask.nii.gz", out);
  CHECK_OK(nh_nifti_write_mask(path, ref, mask));
  printf("%d hanging nodes\n", hang->n_hanging);
  free(u), free(values), free(mask);
  nh_hanging_destroy(&hang);
  nh_mesh_destroy(&m);
  nh_image_release(&ref);
  return 0;
}

static int scalar(int argc, char **argv) {
  nh_image *ref;
  double *values;
  CHECK_OK(nh_image_read_values(argv[2], NULL, &ref, &values));
  CHECK_OK(nh_nifti_write_scalar(argv[3], ref, values, argc > 4 && strcmp(argv[4], "float") == 0));
  free(values);
  nh_image_release(&ref);
  return 0;
}

static int fail(char **argv) {
  nh_image *ref;
  CHECK_OK(nh_image_read(argv[2], 0, NULL, &ref));
  if (argv[4]) snprintf(ref->path, sizeof ref->path, "%s", argv[4]);
  size_t nv = (size_t)ref->n[0] * ref->n[1] * ref->n[2];
  double *zero = calloc(3 * nv, sizeof(double));
  int rc = nh_nifti_write_displacement(argv[3], ref, zero);
  free(zero);
  nh_image_release(&ref);
  printf("%s\n", nh_error_message());
  return rc == NH_ERR_IO ? 3 : 1;
}

int main(int argc, char **argv) {
  (void)nh_test_failures; /* CHECK_OK exits at once */
  if (argc >= 4 && strcmp(argv[1], "field") == 0) return field(argc, argv);
  if (argc >= 4 && strcmp(argv[1], "scalar") == 0) return scalar(argc, argv);
  if ((argc == 4 || argc == 5) && strcmp(argv[1], "fail") == 0) return fail(argv);
  fprintf(stderr, "usage: nifti_field_tool field|scalar|fail REF OUT ...\n");
  return 2;
}
