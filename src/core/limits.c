/* limits.c — the bounds every reader of a user's file applies, and opening
 * such a file with them (core.h, "limits on the files a scene names").
 *
 * The defaults are sized for the largest input a DBS study meets, a 0.5 mm
 * whole-head acquisition: a 256 mm field of view at 0.5 mm is 512³ = 1.34e8
 * voxels (below max_voxels = 2e8; 1.07 GB as float64, below
 * max_file_bytes = 4e9), and a surface extracted from it at that resolution
 * (a pial surface of both hemispheres, ~0.2 m², is ~1.6e6 marching-cubes
 * triangles; FreeSurfer's has ~6e5) stays an order of magnitude below
 * max_triangles = 2e7. Beyond them a file is far more likely corrupt (a
 * header's dimension of 999 or 2³¹) than a real image, and reading it would
 * take minutes and tens of GB before any other check could refuse it. */
#include "core/core.h"

#include <errno.h>
#include <string.h>
#include <sys/stat.h>

const nh_read_limits nh_read_limits_default = {
    .max_voxels = 2e8, .max_triangles = 2e7, .max_file_bytes = 4e9};

const nh_read_limits *nh_read_limits_or_default(const nh_read_limits *limits) {
  return limits ? limits : &nh_read_limits_default;
}

int nh_file_open_limited(const char *path, const char *what, const nh_read_limits *limits, FILE **f,
                         double *size) {
  limits = nh_read_limits_or_default(limits);
  *f = NULL, *size = -1;
  FILE *file = fopen(path, "rb");
  if (!file)
    return NH_ERROR(NH_ERR_INPUT, "%s: cannot open the %s: %s", path, what, strerror(errno));
  struct stat st;
  if (fstat(fileno(file), &st) != 0) {
    int err = errno;
    fclose(file);
    return NH_ERROR(NH_ERR_INPUT, "%s: cannot read the %s: %s", path, what, strerror(err));
  }
  if (S_ISDIR(st.st_mode)) {
    fclose(file);
    return NH_ERROR(NH_ERR_INPUT, "%s: a folder, not a%s %s file", path,
                    strchr("aeiou", what[0]) ? "n" : "", what);
  }
  if (S_ISREG(st.st_mode)) {
    *size = (double)st.st_size;
    if (*size > limits->max_file_bytes) {
      fclose(file);
      return NH_ERROR(NH_ERR_INPUT,
                      "%s: %.0f bytes exceed limits.max_file_bytes = %.0f (a %s this large is "
                      "refused before it is read; raise the limit if it is genuine)",
                      path, *size, limits->max_file_bytes, what);
    }
  }
  *f = file;
  return NH_OK;
}
