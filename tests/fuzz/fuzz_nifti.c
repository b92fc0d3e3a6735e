/* fuzz_nifti.c — fuzz target: the NIfTI label-image reader (nh_image_read)
 * on any bytes, written as a .nii (or a .nii.gz when they start with the
 * gzip magic). Every input must either read (then its labels are listed and
 * the first one selected as an organ, whose level function is evaluated at
 * the image's centre) or fail with "PATH: ..." (fuzz_common.h). Limits are
 * small (1e5 voxels, 1e8 bytes) to keep each run short; the full defaults
 * only scale the same checks. See fuzz_scene.c. */
#include "anatomy/anatomy.h"
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  int gz = size >= 2 && data[0] == 0x1f && data[1] == 0x8b;
  const char *path = nh_fuzz_file(data, size, gz ? ".nii.gz" : ".nii");
  const nh_read_limits limits = {.max_voxels = 1e5, .max_triangles = 1e5, .max_file_bytes = 1e8};
  nh_image *im = NULL;
  int rc = nh_image_read(path, 1, &limits, &im);
  nh_fuzz_check_prefix(rc, path, 0);
  if (!rc) {
    int *labels = NULL, n = 0;
    long *counts = NULL;
    if (!nh_image_labels(im, &labels, &counts, &n) && n > 0 && !nh_image_select(im, labels, 1)) {
      double ijk[3] = {0.5 * (im->n[0] - 1), 0.5 * (im->n[1] - 1), 0.5 * (im->n[2] - 1)}, x[3];
      nh_image_to_world(im, ijk, x);
      (void)nh_image_level(im, x);
      (void)nh_image_label_at(im, x);
    }
    free(labels), free(counts);
  }
  nh_image_release(&im);
  nh_error_clear();
  return 0;
}
