/* obstacle.c — plan.obstacles: how far a path keeps from them.
 *
 * The clearance of a path (the tip's path in the tissue: the axis of the
 * channel it cut) is the least signed distance from its points to the
 * surfaces of the obstacles, in the tissue's rest frame (the frame the
 * obstacles are given in). For the shapes (box, sphere, finite cylinder) it
 * is exact (mesh/region.c, nh_region_distance). A label obstacle is the set
 * of voxels of the scene's label image holding the label, each the box
 * centred at its index (docs/anatomy.md): the distance from a point outside
 * is the distance to the nearest voxel box on the region's surface (a voxel
 * of the label with a face neighbour that is not, or on the image's border);
 * inside a voxel of the label it is minus the distance to the nearest
 * surface voxel's centre. The boxes are exact for images whose voxel axes
 * are orthogonal (the point is clamped to the box in index space and the
 * difference mapped to the world); the surface is the voxels' staircase, not
 * the smooth level χ = 1/2 the immersed domain uses: the two differ by less
 * than a voxel.
 *
 * The surface voxels are kept in blocks of 8 × 8 × 8 voxels, each with its
 * world bounding box; a query visits only the blocks whose box is nearer
 * than the best distance found, so a path of n points against a region of m
 * surface voxels costs about n times the voxels near the path. */
#include "mesh/mesh.h"
#include "plan/plan_impl.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { NH_BLOCK = 8 };

typedef struct {
  double lo[3], hi[3]; /* world bounding box of its voxels' boxes */
  int start, count;    /* its voxels in the label's list */
} nh_voxel_block;

typedef struct {
  const nh_region *region; /* a shape (its distance is exact) ... */
  int label;               /* ... or a label (region->kind == NH_REGION_LABEL) */
  int n_vox, n_blocks;
  int *vox; /* 3 per surface voxel: its index, ordered by block */
  nh_voxel_block *blocks;
  double lo[3], hi[3]; /* world bounding box of the surface voxels */
} nh_obstacle;

struct nh_obstacles {
  int n;
  nh_obstacle *o;
  nh_image *image; /* the label image, if a label obstacle needs it */
};

static int nh_label_of(const nh_image *im, int i, int j, int k) {
  if (i < 0 || j < 0 || k < 0 || i >= im->n[0] || j >= im->n[1] || k >= im->n[2]) return INT32_MIN;
  return im->label[((size_t)k * im->n[1] + j) * im->n[0] + i];
}

/* World bounding box of the index box [lo − ½, hi + ½]. */
static void nh_index_box_world(const nh_image *im, const int lo[3], const int hi[3], double wlo[3],
                               double whi[3]) {
  for (int k = 0; k < 3; k++) wlo[k] = INFINITY, whi[k] = -INFINITY;
  for (int c = 0; c < 8; c++) {
    double ijk[3], x[3];
    for (int k = 0; k < 3; k++) ijk[k] = ((c >> k) & 1) ? hi[k] + 0.5 : lo[k] - 0.5;
    nh_image_to_world(im, ijk, x);
    for (int k = 0; k < 3; k++) wlo[k] = fmin(wlo[k], x[k]), whi[k] = fmax(whi[k], x[k]);
  }
}

/* The surface voxels of label o->label, in blocks. */
static int nh_label_surface(const nh_image *im, nh_obstacle *o) {
  const int nb[3] = {(im->n[0] + NH_BLOCK - 1) / NH_BLOCK, (im->n[1] + NH_BLOCK - 1) / NH_BLOCK,
                     (im->n[2] + NH_BLOCK - 1) / NH_BLOCK};
  const size_t n_all_blocks = (size_t)nb[0] * nb[1] * nb[2];
  int *count = nh_calloc(n_all_blocks + 1, sizeof(int));
  if (!count) return NH_ERR_MEMORY;
  static const int nbr[6][3] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},
                                {0, -1, 0}, {0, 0, 1},  {0, 0, -1}};
  /* two passes: count per block, then fill */
  for (int pass = 0; pass < 2; pass++) {
    for (int k = 0; k < im->n[2]; k++)
      for (int j = 0; j < im->n[1]; j++)
        for (int i = 0; i < im->n[0]; i++) {
          if (nh_label_of(im, i, j, k) != o->label) continue;
          int surface = 0;
          for (int q = 0; q < 6 && !surface; q++)
            surface = nh_label_of(im, i + nbr[q][0], j + nbr[q][1], k + nbr[q][2]) != o->label;
          if (!surface) continue;
          size_t b = ((size_t)(k / NH_BLOCK) * nb[1] + j / NH_BLOCK) * nb[0] + i / NH_BLOCK;
          if (pass == 0) {
            count[b + 1]++;
          } else {
            int *v = o->vox + 3 * count[b]++;
            v[0] = i, v[1] = j, v[2] = k;
          }
        }
    if (pass == 0) {
      for (size_t b = 0; b < n_all_blocks; b++) count[b + 1] += count[b];
      o->n_vox = count[n_all_blocks];
      o->vox = nh_calloc(3 * (size_t)(o->n_vox ? o->n_vox : 1), sizeof(int));
      o->blocks = nh_calloc(n_all_blocks, sizeof *o->blocks);
      if (!o->vox || !o->blocks) {
        free(count);
        return NH_ERR_MEMORY;
      }
      for (size_t b = 0; b < n_all_blocks; b++) {
        o->blocks[b].start = count[b];
        o->blocks[b].count = count[b + 1] - count[b];
      }
    }
  }
  free(count);
  /* keep the non-empty blocks, with their world boxes */
  int kept = 0;
  for (int k = 0; k < 3; k++) o->lo[k] = INFINITY, o->hi[k] = -INFINITY;
  for (size_t b = 0; b < n_all_blocks; b++) {
    nh_voxel_block B = o->blocks[b];
    if (!B.count) continue;
    int lo[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, hi[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
    for (int v = B.start; v < B.start + B.count; v++)
      for (int k = 0; k < 3; k++)
        lo[k] = lo[k] < o->vox[3 * v + k] ? lo[k] : o->vox[3 * v + k],
        hi[k] = hi[k] > o->vox[3 * v + k] ? hi[k] : o->vox[3 * v + k];
    nh_index_box_world(im, lo, hi, B.lo, B.hi);
    for (int k = 0; k < 3; k++)
      o->lo[k] = fmin(o->lo[k], B.lo[k]), o->hi[k] = fmax(o->hi[k], B.hi[k]);
    o->blocks[kept++] = B;
  }
  o->n_blocks = kept;
  return NH_OK;
}

int nh_obstacles_create(const nh_scene *s, nh_obstacles **out) {
  *out = NULL;
  nh_obstacles *ob = nh_calloc(1, sizeof *ob);
  if (!ob) return NH_ERR_MEMORY;
  ob->n = s->plan.n_obstacles;
  ob->o = nh_calloc((size_t)(ob->n ? ob->n : 1), sizeof *ob->o);
  if (!ob->o) {
    nh_obstacles_destroy(&ob);
    return NH_ERR_MEMORY;
  }
  const char *file = s->tissue.mask_file[0] ? s->tissue.mask_file : s->tissue.labels_file;
  int rc = NH_OK;
  for (int i = 0; i < ob->n && !rc; i++) {
    const nh_region *r = &s->plan.obstacles[i];
    nh_obstacle *o = &ob->o[i];
    o->region = r;
    if (r->kind != NH_REGION_LABEL) continue;
    o->label = r->label;
    if (!ob->image && nh_image_read(file, 1, NULL, &ob->image)) {
      char why[512];
      snprintf(why, sizeof why, "%s", nh_error_message());
      rc = NH_ERROR(NH_ERR_INPUT, "%s: %s", r->where, why);
      break;
    }
    rc = nh_label_surface(ob->image, o);
    if (!rc && o->n_vox == 0)
      rc =
          NH_ERROR(NH_ERR_INPUT, "%s: label %d: no voxel of %s holds it", r->where, r->label, file);
  }
  if (rc) {
    nh_obstacles_destroy(&ob);
    return rc;
  }
  *out = ob;
  return NH_OK;
}

void nh_obstacles_destroy(nh_obstacles **obstacles) {
  if (!obstacles || !*obstacles) return;
  nh_obstacles *ob = *obstacles;
  for (int i = 0; ob->o && i < ob->n; i++) free(ob->o[i].vox), free(ob->o[i].blocks);
  free(ob->o);
  nh_image_release(&ob->image);
  free(ob);
  *obstacles = NULL;
}

int nh_obstacles_count(const nh_obstacles *ob) {
  return ob ? ob->n : 0;
}

/* Distance from x to the world box [lo, hi] (0 inside). */
static double nh_box_gap(const double lo[3], const double hi[3], const double x[3]) {
  double d2 = 0.0;
  for (int k = 0; k < 3; k++) {
    double q = fmax(lo[k] - x[k], x[k] - hi[k]);
    if (q > 0) d2 += q * q;
  }
  return sqrt(d2);
}

/* Distance from world x to the box of voxel v (index space clamp, mapped). */
static double nh_voxel_gap(const nh_image *im, const int *v, const double ijk[3], int centre) {
  double d[3], w[3];
  for (int k = 0; k < 3; k++) {
    double q = ijk[k] - v[k];
    d[k] = centre ? q : (q > 0.5 ? q - 0.5 : (q < -0.5 ? q + 0.5 : 0.0));
  }
  for (int r = 0; r < 3; r++)
    w[r] = im->A[3 * r] * d[0] + im->A[3 * r + 1] * d[1] + im->A[3 * r + 2] * d[2];
  return sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
}

/* Least distance from x to a surface voxel of o (boxes, or centres), below
 * `best` (returned unchanged if none is nearer). */
static double nh_label_gap(const nh_image *im, const nh_obstacle *o, const double x[3], double best,
                           int centre) {
  double ijk[3];
  nh_image_to_voxel(im, x, ijk);
  for (int b = 0; b < o->n_blocks; b++) {
    const nh_voxel_block *B = &o->blocks[b];
    if (nh_box_gap(B->lo, B->hi, x) >= best) continue;
    for (int v = B->start; v < B->start + B->count; v++)
      best = fmin(best, nh_voxel_gap(im, o->vox + 3 * v, ijk, centre));
  }
  return best;
}

double nh_obstacle_distance(const nh_obstacles *ob, int i, const double x[3]) {
  const nh_obstacle *o = &ob->o[i];
  if (o->region->kind != NH_REGION_LABEL) return nh_region_distance(o->region, x);
  if (nh_image_label_at(ob->image, x) == o->label)
    return -nh_label_gap(ob->image, o, x, INFINITY, 1);
  return nh_label_gap(ob->image, o, x, INFINITY, 0);
}

double nh_obstacles_clearance(const nh_obstacles *ob, int n, const double *x, int *which) {
  double best = INFINITY;
  int w = -1;
  for (int i = 0; ob && i < ob->n; i++) {
    const nh_obstacle *o = &ob->o[i];
    for (int p = 0; p < n; p++) {
      const double *xp = x + 3 * p;
      double d;
      if (o->region->kind != NH_REGION_LABEL) {
        d = nh_region_distance(o->region, xp);
      } else if (nh_image_label_at(ob->image, xp) == o->label) {
        d = -nh_label_gap(ob->image, o, xp, INFINITY, 1);
      } else {
        if (nh_box_gap(o->lo, o->hi, xp) >= best) continue; /* cannot beat the best */
        d = nh_label_gap(ob->image, o, xp, best, 0);
      }
      if (d < best) best = d, w = i;
    }
  }
  if (which) *which = w;
  return best;
}
