/* patient.c — outputs on the patient's images (docs/anatomy.md,
 * "Displacement fields and shifted images", "Markups"): the tissue
 * displacement sampled at a reference image's voxel centres as an ITK/ANTs
 * displacement field (output.displacement_field), an image resampled to the
 * shifted anatomy (output.warped), and, at the end of the run, the tools'
 * axes and the shifted targets as 3D Slicer markups.
 *
 * Times. A list `at` of times (s) writes at the first step whose time
 * reaches each of them, t_{n−1} < at ≤ t_n (to round-off of the step), and
 * the last step writes in any case. The files carry the step's number, as
 * the VTU frames do: displacement_<step>.nii.gz, warped_<step>.nii.gz;
 * tissue_mask.nii.gz (the rest voxels in the tissue) is the same at every
 * time (the rest tissue does not change) and is written with the first
 * field. The images are read when the run is created, so a missing or bad
 * reference stops the run before its first step, not after its last. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sim/sim_impl.h"

/* Every value an integer and at most this many distinct ones: a label image,
 * resampled by the nearest label (output.warped.interpolation: auto). */
#define NH_LABEL_VALUES_MAX 1000

static int nh_cmp_value(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* A label image: integer values, few of them (values: n of them). */
static int nh_is_label_image(const double *values, size_t n) {
  for (size_t v = 0; v < n; v++)
    if (values[v] != floor(values[v])) return 0;
  double *sorted = nh_calloc(n, sizeof *sorted);
  if (!sorted) return 0; /* linear, the safe choice for an intensity */
  memcpy(sorted, values, n * sizeof *sorted);
  qsort(sorted, n, sizeof *sorted, nh_cmp_value);
  size_t distinct = n > 0;
  for (size_t v = 1; v < n; v++) distinct += sorted[v] != sorted[v - 1];
  free(sorted);
  return distinct <= NH_LABEL_VALUES_MAX;
}

int nh_sim_patient_open(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (sc->output.displacement_field.reference[0])
    NH_TRY(nh_image_read(sc->output.displacement_field.reference, 0, &sc->limits.read,
                         &s->field_reference));
  if (!sc->output.warped.image[0]) return NH_OK;
  NH_TRY(nh_image_read_values(sc->output.warped.image, &sc->limits.read, &s->warp_image,
                              &s->warp_values));
  const nh_image *im = s->warp_image;
  size_t n = (size_t)im->n[0] * im->n[1] * im->n[2];
  int how = sc->output.warped.interpolation;
  s->warp_nearest = how == NH_INTERPOLATION_NEAREST ||
                    (how == NH_INTERPOLATION_AUTO && nh_is_label_image(s->warp_values, n));
  return NH_OK;
}

void nh_sim_patient_close(nh_sim *s) {
  nh_image_release(&s->field_reference);
  nh_image_release(&s->warp_image);
  free(s->warp_values);
  s->warp_values = NULL;
}

/* One of the times `at` falls in this step, (t − dt, t], or it is the last. */
static int nh_patient_due(const nh_sim *s, const double *at, int n_at) {
  const nh_scene *sc = s->scene;
  if (s->step == sc->time.steps) return 1;
  double dt = sc->time.step, eps = 1e-9 * dt;
  for (int k = 0; k < n_at; k++)
    if (at[k] > s->time - dt + eps && at[k] <= s->time + eps) return 1;
  return 0;
}

static int nh_patient_path(const nh_sim *s, const char *stem, int step, char *path, size_t size) {
  int n = step >= 0 ? snprintf(path, size, "%s/%s_%06d.nii.gz", s->scene->output.dir, stem, step)
                    : snprintf(path, size, "%s/%s.nii.gz", s->scene->output.dir, stem);
  return n > 0 && (size_t)n < size
             ? NH_OK
             : NH_ERROR(NH_ERR_IO, "output path too long in %s", s->scene->output.dir);
}

/* displacement_<step>.nii.gz on the reference's grid (and the mask once). */
static int nh_write_displacement_field(nh_sim *s) {
  const nh_image *ref = s->field_reference;
  size_t n = (size_t)ref->n[0] * ref->n[1] * ref->n[2];
  double *u = nh_calloc(3 * n, sizeof *u);
  unsigned char *mask = nh_calloc(n, 1);
  char path[NH_PATH_MAX + 64];
  int rc = u && mask ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: displacement field");
  if (!rc) rc = nh_mesh_sample_image(s->mesh, s->u, ref, u, mask);
  if (!rc) rc = nh_patient_path(s, "displacement", s->step, path, sizeof path);
  if (!rc) rc = nh_nifti_write_displacement(path, ref, u);
  if (!rc && !s->mask_written) {
    rc = nh_patient_path(s, "tissue_mask", -1, path, sizeof path);
    if (!rc) rc = nh_nifti_write_mask(path, ref, mask);
    s->mask_written = !rc;
  }
  free(u), free(mask);
  return rc;
}

/* warped_<step>.nii.gz: the image resampled to the shifted anatomy, in its
 * own data type. */
static int nh_write_warped(nh_sim *s) {
  const nh_image *im = s->warp_image;
  size_t n = (size_t)im->n[0] * im->n[1] * im->n[2];
  double *out = nh_calloc(n, sizeof *out);
  char path[NH_PATH_MAX + 64];
  nh_inverse_stats stats;
  int rc = out ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: warped image");
  if (!rc)
    rc = nh_mesh_warp_image(s->mesh, s->u, im, s->warp_values, s->warp_nearest, NULL, out, &stats);
  if (!rc) rc = nh_patient_path(s, "warped", s->step, path, sizeof path);
  if (!rc) rc = nh_nifti_write_scalar(path, im, out, 0);
  if (!rc && stats.unconverged > 0)
    nh_log_warn("step %d: warped image: the inverse map did not converge at %ld of %ld voxels "
                "(left unshifted)",
                s->step, stats.unconverged, stats.points);
  free(out);
  return rc;
}

/* <tool>.mrk.json (the axis from base to tip, a curve) for each tool and
 * targets.mrk.json (the targets where the tissue carried them). */
static int nh_write_markups_outputs(nh_sim *s) {
  const nh_scene *sc = s->scene;
  char path[NH_PATH_MAX + NH_NAME_MAX + 16];
  int rc = NH_OK;
  for (int k = 0; k < sc->n_tools && !rc; k++) {
    nh_beam *b = nh_contact_beam(s->contact, k);
    snprintf(path, sizeof path, "%s/%s.mrk.json", sc->output.dir, sc->tools[k].name);
    rc = nh_markups_write(path, NH_MARKUP_CURVE, sc->tools[k].name, nh_beam_nodes(b),
                          nh_beam_positions(b), NULL);
  }
  if (rc || sc->n_targets == 0) return rc;
  double *x = nh_calloc(3 * (size_t)sc->n_targets, sizeof *x);
  const char **labels = nh_calloc((size_t)sc->n_targets, sizeof *labels);
  rc = x && labels ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: targets markups");
  for (int i = 0; i < sc->n_targets && !rc; i++) {
    nh_sim_point_position(s, sc->n_probes + i, x + 3 * i);
    labels[i] = sc->targets[i].name;
  }
  snprintf(path, sizeof path, "%s/targets.mrk.json", sc->output.dir);
  if (!rc) rc = nh_markups_write(path, NH_MARKUP_FIDUCIAL, "targets", sc->n_targets, x, labels);
  free(x), free(labels);
  return rc;
}

int nh_sim_patient_write(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (s->field_reference &&
      nh_patient_due(s, sc->output.displacement_field.at, sc->output.displacement_field.n_at))
    NH_TRY(nh_write_displacement_field(s));
  if (s->warp_image && nh_patient_due(s, sc->output.warped.at, sc->output.warped.n_at))
    NH_TRY(nh_write_warped(s));
  if (s->step == sc->time.steps) NH_TRY(nh_write_markups_outputs(s));
  return NH_OK;
}
