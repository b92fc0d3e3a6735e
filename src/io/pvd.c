/* pvd.c — ParaView collection files (.pvd): the time series of one object.
 *
 * A PVD is a small XML file listing (time, file) pairs:
 *
 *   <?xml version="1.0"?>
 *   <VTKFile type="Collection" version="0.1" byte_order="LittleEndian">
 *     <Collection>
 *       <DataSet timestep="0.01" group="" part="0" file="tissue_000001.vtu"/>
 *       ...
 *     </Collection>
 *   </VTKFile>
 *
 * ParaView opens it as one time-varying dataset. File names are relative to
 * the PVD's folder, as the caller passes them.
 *
 * Choices:
 * - The collection keeps its frames in memory and every nh_pvd_add rewrites
 *   the whole file through nh_write_text (tmp + rename). Appending in place
 *   would leave the closing tags missing whenever a run is killed; rewriting
 *   keeps the file always valid and listing exactly the frames written so
 *   far. The cost is O(frames) per add, negligible next to a VTU frame.
 * - The frames of DIR/PREFIX.pvd are DIR/PREFIX_NNNNNN.vtu, NNNNNN the step
 *   (six digits or more): nh_pvd_write_frame writes them, nh_pvd_resume
 *   finds them. The resume rebuilds the list of a restarted run from the
 *   frame files on disk (the PVD itself may list frames after the
 *   checkpoint).
 * - nh_pvd_create writes the empty collection at once, so an unwritable
 *   folder fails before the first step rather than after it.
 * - Times are printed with %.17g, which reproduces the double exactly, so a
 *   script can match PVD times against the CSV times bit for bit.
 * - File names are XML-escaped (a tool may be named "a&b"). */
#include "io/io_impl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

struct nh_pvd {
  char *path;
  int n_frames, cap_frames;
  double *times;
  char **files;
};

static int pvd_render(const nh_pvd *pvd, nh_text *b) {
  NH_TRY(nh_text_printf(b, "<?xml version=\"1.0\"?>\n"
                           "<VTKFile type=\"Collection\" version=\"0.1\" "
                           "byte_order=\"LittleEndian\">\n"
                           "  <Collection>\n"));
  for (int i = 0; i < pvd->n_frames; ++i) {
    NH_TRY(nh_text_printf(b, "    <DataSet timestep=\"%.17g\" group=\"\" part=\"0\" file=\"",
                          pvd->times[i]));
    NH_TRY(nh_text_put_xml(b, pvd->files[i]));
    NH_TRY(nh_text_printf(b, "\"/>\n"));
  }
  return nh_text_printf(b, "  </Collection>\n</VTKFile>\n");
}

static int pvd_write(const nh_pvd *pvd) {
  nh_text b = {0};
  int rc = pvd_render(pvd, &b);
  if (rc == NH_OK) rc = nh_write_text(pvd->path, b.s);
  free(b.s);
  return rc;
}

int nh_pvd_create(const char *path, nh_pvd **out) {
  NH_CHECK(path && out, NH_ERR_INTERNAL, "nh_pvd_create: NULL argument");
  *out = NULL;
  nh_pvd *pvd = nh_calloc(1, sizeof *pvd);
  if (!pvd) return NH_ERR_MEMORY;
  pvd->path = nh_calloc(strlen(path) + 1, 1);
  if (!pvd->path) {
    nh_pvd_destroy(&pvd);
    return NH_ERR_MEMORY;
  }
  strcpy(pvd->path, path);
  int rc = pvd_write(pvd);
  if (rc) {
    nh_pvd_destroy(&pvd);
    return rc;
  }
  *out = pvd;
  return NH_OK;
}

int nh_pvd_add(nh_pvd *pvd, double time, const char *file) {
  NH_CHECK(pvd && file, NH_ERR_INTERNAL, "nh_pvd_add: NULL argument");
  if (pvd->n_frames == pvd->cap_frames) {
    int cap = pvd->cap_frames;
    NH_TRY(nh_grow((void **)&pvd->times, &cap, pvd->n_frames + 1, sizeof *pvd->times));
    /* Grow files to the same capacity; keep cap_frames at the smaller of the two. */
    int cap_files = pvd->cap_frames;
    NH_TRY(nh_grow((void **)&pvd->files, &cap_files, cap, sizeof *pvd->files));
    pvd->cap_frames = cap;
  }
  char *copy = nh_calloc(strlen(file) + 1, 1);
  if (!copy) return NH_ERR_MEMORY;
  strcpy(copy, file);
  pvd->times[pvd->n_frames] = time;
  pvd->files[pvd->n_frames] = copy;
  pvd->n_frames++;
  int rc = pvd_write(pvd);
  if (rc) {
    /* Keep memory and disk in agreement: the frame is not in the collection. */
    pvd->n_frames--;
    free(copy);
  }
  return rc;
}

int nh_pvd_write_frame(nh_pvd *pvd, int step, double time, const nh_frame *frame) {
  NH_CHECK(pvd && frame, NH_ERR_INTERNAL, "nh_pvd_write_frame: NULL argument");
  size_t base = strlen(pvd->path);
  NH_CHECK(base > 4 && !strcmp(pvd->path + base - 4, ".pvd"), NH_ERR_INTERNAL,
           "nh_pvd_write_frame: collection '%s' is not a .pvd file", pvd->path);
  base -= 4;
  size_t size = base + 32;
  char *path = nh_calloc(size, 1);
  if (!path) return NH_ERR_MEMORY;
  snprintf(path, size, "%.*s_%06d.vtu", (int)base, pvd->path, step);
  const char *slash = strrchr(path, '/');
  int rc = nh_vtu_write(path, frame);
  if (rc == NH_OK) rc = nh_pvd_add(pvd, time, slash ? slash + 1 : path);
  free(path);
  return rc;
}

void nh_pvd_destroy(nh_pvd **pvd) {
  if (!pvd || !*pvd) return;
  nh_pvd *p = *pvd;
  for (int i = 0; i < p->n_frames; ++i) free(p->files[i]);
  free(p->files);
  free(p->times);
  free(p->path);
  free(p);
  *pvd = NULL;
}

int nh_pvd_resume(const char *dir, const char *prefix, double dt, int step, nh_pvd **out) {
  size_t size = strlen(dir) + strlen(prefix) + 32;
  char *path = nh_calloc(size, 1), *name = nh_calloc(strlen(prefix) + 32, 1);
  int rc = path && name ? NH_OK : NH_ERR_MEMORY;
  if (!rc) {
    snprintf(path, size, "%s/%s.pvd", dir, prefix);
    rc = nh_pvd_create(path, out);
  }
  for (int k = 0; k <= step && !rc; k++) { /* in step order */
    snprintf(name, strlen(prefix) + 32, "%s_%06d.vtu", prefix, k);
    snprintf(path, size, "%s/%s", dir, name);
    if (access(path, R_OK) == 0) rc = nh_pvd_add(*out, k * dt, name);
  }
  free(path);
  free(name);
  return rc;
}
