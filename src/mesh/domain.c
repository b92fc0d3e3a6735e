/* domain.c — the shape the tissue fills: a box or the analytic brain, as an
 * implicit function F (F < 0 inside), and what the mesh and the tools need of
 * it: fill fractions of cells, the entry point of a ray, a reference volume
 * (docs/theory.md, "Immersed domain").
 *
 * The brain. With a, b, c the half sizes of the bounding box along x
 * (left–right), y (posterior–anterior), z (up) and (X, Y, Z) =
 * (|x − cx|, y − cy, z − cz) relative to its centre:
 *   hemispheres  E = ρ (q − 1),
 *                q = √(((X − eₓ)/rₓ)² + (Y/r_y)² + ((Z − e_z)/r_z)²),
 *                rₓ = 0.55 a, eₓ = 0.45 a, r_y = b, r_z = 0.7 c, e_z = 0.3 c,
 *                ρ = min(rₓ, r_y, r_z)
 *                (one ellipsoid per side: evaluating at |x − cx| is the union
 *                of the ellipsoid and its mirror image, which overlap for
 *                X < 0.1 a)
 *   brainstem    S = max(√(X² + (Y − y_s)²) − r_s, −c − Z, Z − e_z),
 *                y_s = −0.15 b, r_s = 0.18 min(a, b)  (a vertical cylinder
 *                from the bottom of the box up into the hemispheres)
 *   union        U = smin(E, S) = min(E, S) − k h² / 4,
 *                h = max(k − |E − S|, 0) / k, k = 0.25 r_s
 *   fissure      P = max(X − w, e_z − Z), w = 0.02 a  (the slab |x − cx| < w
 *                above z = cz + e_z)
 *   F = max(U, −P).
 * U alone is the brain's outer hull (nh_domain_hull_level): the shape with
 * its fissure filled, whose offset is the skull (contact/skull.c; the falx
 * in the fissure is not modelled). Every other kind is its own hull.
 * The extremes are exact: x = cx ± a and z = cz + c at the hemispheres'
 * outer poles, y = cy ± b at their front and back, z = cz − c at the
 * brainstem's flat bottom, so `size` is the bounding box of the shape.
 * F depends on x only through |x − cx|, so F(mirror x) = F(x) bit for bit
 * when x − cx is computed exactly (the lattice samples of nh_mesh_create).
 * Every piece is 1-Lipschitz (|∇E| ≤ ρ / min r = 1, S and P are maxima of
 * distances, smin's gradient is a convex combination of its arguments'), so
 * F is: F(x) > 0 bounds the distance from x to the shape from below. That
 * makes the test "a cell may meet the shape" conservative: a cell all of
 * whose sub-cell midpoints have F above their sub-cell's circumradius does
 * not meet it.
 *
 * The sphere (tests): F = |x − c| − R, the signed distance.
 *
 * The box: F = maxₖ (|xₖ − cₖ| − hₖ); its ray entry and distances keep the
 * exact formulas the tools used before this module existed. */
#include "mesh/mesh.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void nh_domain_box(const double min[3], const double max[3], nh_domain *d) {
  memset(d, 0, sizeof *d);
  d->kind = NH_DOMAIN_BOX;
  for (int k = 0; k < 3; k++) {
    d->min[k] = min[k];
    d->max[k] = max[k];
    d->center[k] = 0.5 * (min[k] + max[k]);
    d->half[k] = 0.5 * (max[k] - min[k]);
  }
}

void nh_domain_brain(const double center[3], const double size[3], nh_domain *d) {
  memset(d, 0, sizeof *d);
  d->kind = NH_DOMAIN_BRAIN;
  for (int k = 0; k < 3; k++) {
    d->center[k] = center[k];
    d->half[k] = 0.5 * size[k];
    d->min[k] = center[k] - d->half[k];
    d->max[k] = center[k] + d->half[k];
  }
}

/* Prefix the current error message with `where` (the scene's key). */
static int nh_domain_fail(const char *where) {
  char msg[1024];
  snprintf(msg, sizeof msg, "%s", nh_error_message());
  return NH_ERROR(NH_ERR_INPUT, "%s: %s", where, msg);
}

/* Every label of labels[0..n) is held by some voxel of the image. */
static int nh_labels_present(const nh_image *im, const int *want, int n, const char *where) {
  NH_CHECK(im, NH_ERR_INPUT,
           "%s: labels need a label image: give tissue.domain.mask or tissue.labels", where);
  int *labels, nl;
  long *counts;
  NH_TRY(nh_image_labels(im, &labels, &counts, &nl));
  int rc = NH_OK;
  for (int i = 0; i < n && !rc; i++) {
    int found = 0;
    for (int j = 0; j < nl && !found; j++) found = labels[j] == want[i];
    if (!found) {
      char have[256] = "";
      for (int j = 0; j < nl && strlen(have) < 200; j++)
        snprintf(have + strlen(have), sizeof have - strlen(have), "%s%d", j ? ", " : "", labels[j]);
      rc = NH_ERROR(NH_ERR_INPUT, "%s: label %d is held by no voxel of %s (its labels: %s)", where,
                    want[i], im->path, have);
    }
  }
  free(labels), free(counts);
  return rc;
}

static void nh_domain_set_box(nh_domain *d, const double min[3], const double max[3]) {
  for (int k = 0; k < 3; k++) {
    d->min[k] = min[k], d->max[k] = max[k];
    d->center[k] = 0.5 * (min[k] + max[k]);
    d->half[k] = 0.5 * (max[k] - min[k]);
  }
}

static int nh_domain_load(const nh_scene *s, nh_domain *d) {
  const int n_mat = s->tissue.n_materials;
  if (s->tissue.domain == NH_DOMAIN_MASK) {
    d->kind = NH_DOMAIN_MASK;
    if (nh_image_read(s->tissue.mask_file, 1, &s->limits.read, &d->image))
      return nh_domain_fail(s->tissue.where_domain);
    NH_TRY(nh_labels_present(d->image, s->tissue.mask_labels, s->tissue.n_mask_labels,
                             s->tissue.where_labels));
    NH_TRY(nh_image_select(d->image, s->tissue.mask_labels, s->tissue.n_mask_labels));
    nh_domain_set_box(d, d->image->box_min, d->image->box_max);
    nh_image_retain(d->image);
    d->labels = d->image;
  } else if (s->tissue.domain == NH_DOMAIN_SURFACE) {
    d->kind = NH_DOMAIN_SURFACE;
    if (nh_surface_read(s->tissue.surface_file, s->tissue.surface_unit, 0, &s->limits.read,
                        &d->surface))
      return nh_domain_fail(s->tissue.where_domain);
    nh_domain_set_box(d, d->surface->min, d->surface->max);
    /* Truncation of the distance: far above the sub-cell radii the mesh
     * compares F with, small enough to keep the search local. */
    d->cap = 0.25 * fmax(d->half[0], fmax(d->half[1], d->half[2]));
  }
  if (s->tissue.labels_file[0]) {
    if (nh_image_read(s->tissue.labels_file, 1, &s->limits.read, &d->labels))
      return nh_domain_fail(s->tissue.where_labels);
  }
  for (int i = 0; i < n_mat; i++)
    NH_TRY(nh_labels_present(d->labels, &s->tissue.materials[i].label, 1,
                             s->tissue.materials[i].where));
  for (int i = 0; i < s->tissue.n_fixed; i++)
    if (s->tissue.fixed[i].kind == NH_REGION_LABEL)
      NH_TRY(nh_labels_present(d->labels, &s->tissue.fixed[i].label, 1, s->tissue.fixed[i].where));
  for (int i = 0; i < s->tissue.n_loads; i++)
    if (s->tissue.loads[i].region.kind == NH_REGION_LABEL)
      NH_TRY(nh_labels_present(d->labels, &s->tissue.loads[i].region.label, 1,
                               s->tissue.loads[i].region.where));
  return NH_OK;
}

void nh_domain_sphere(const double center[3], double radius, nh_domain *d) {
  memset(d, 0, sizeof *d);
  d->kind = NH_DOMAIN_SPHERE;
  for (int k = 0; k < 3; k++) {
    d->center[k] = center[k];
    d->half[k] = radius;
    d->min[k] = center[k] - radius;
    d->max[k] = center[k] + radius;
  }
}

int nh_domain_from_scene(const nh_scene *s, nh_domain *d) {
  if (s->tissue.domain == NH_DOMAIN_BRAIN)
    nh_domain_brain(s->tissue.brain_center, s->tissue.brain_size, d);
  else
    nh_domain_box(s->tissue.box_min, s->tissue.box_max, d);
  d->cut_cells = s->tissue.cut_cells;
  int rc = nh_domain_load(s, d);
  if (rc) nh_domain_release(d);
  return rc;
}

int nh_domain_integrates_cuts(const nh_domain *d) {
  return d->kind != NH_DOMAIN_BOX && d->cut_cells == NH_CUT_CELLS_INTEGRATED;
}

void nh_domain_copy(nh_domain *dst, const nh_domain *src) {
  *dst = *src;
  nh_image_retain(dst->image);
  nh_image_retain(dst->labels);
  nh_surface_retain(dst->surface);
}

void nh_domain_release(nh_domain *d) {
  nh_image_release(&d->image);
  nh_image_release(&d->labels);
  nh_surface_release(&d->surface);
}

const char *nh_domain_name(const nh_domain *d) {
  static const char *const names[] = {"box", "brain", "mask", "surface", "sphere"};
  return names[d->kind];
}

/* U of the brain (its outer hull: hemispheres and brainstem, the fissure
 * filled) at (X, Y, Z) relative to the centre, X = |x − cx| >= 0. */
static double nh_brain_hull(const double half[3], double X, double Y, double Z) {
  const double a = half[0], b = half[1], c = half[2];
  const double rx = 0.55 * a, ex = 0.45 * a, ry = b, rz = 0.7 * c, ez = 0.3 * c;
  const double rho = fmin(rx, fmin(ry, rz));
  const double ys = -0.15 * b, rs = 0.18 * fmin(a, b), k = 0.25 * rs;
  double qx = (X - ex) / rx, qy = Y / ry, qz = (Z - ez) / rz;
  double E = rho * (sqrt(qx * qx + qy * qy + qz * qz) - 1.0);
  double S = fmax(sqrt(X * X + (Y - ys) * (Y - ys)) - rs, fmax(-c - Z, Z - ez));
  double h = fmax(k - fabs(E - S), 0.0) / k;
  return fmin(E, S) - 0.25 * k * h * h;
}

/* F of the brain at (X, Y, Z) relative to the centre, X = |x − cx| >= 0. */
static double nh_brain_level(const double half[3], double X, double Y, double Z) {
  const double w = 0.02 * half[0], ez = 0.3 * half[2];
  double P = fmax(X - w, ez - Z);
  return fmax(nh_brain_hull(half, X, Y, Z), -P);
}

/* F at centre + r (hull: U for the brain, F for the other kinds). */
static double nh_level_rel(const nh_domain *d, const double r[3], int hull) {
  if (d->kind == NH_DOMAIN_BRAIN)
    return (hull ? nh_brain_hull : nh_brain_level)(d->half, fabs(r[0]), r[1], r[2]);
  if (d->kind == NH_DOMAIN_MASK || d->kind == NH_DOMAIN_SURFACE) {
    double x[3] = {d->center[0] + r[0], d->center[1] + r[1], d->center[2] + r[2]};
    return d->kind == NH_DOMAIN_MASK ? nh_image_level(d->image, x)
                                     : nh_surface_level(d->surface, x, d->cap);
  }
  if (d->kind == NH_DOMAIN_SPHERE)
    return sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) - d->half[0];
  double f = -INFINITY;
  for (int k = 0; k < 3; k++) f = fmax(f, fabs(r[k]) - d->half[k]);
  return f;
}

double nh_domain_level(const nh_domain *d, const double x[3]) {
  double r[3] = {x[0] - d->center[0], x[1] - d->center[1], x[2] - d->center[2]};
  return nh_level_rel(d, r, 0);
}

double nh_domain_hull_level(const nh_domain *d, const double x[3]) {
  double r[3] = {x[0] - d->center[0], x[1] - d->center[1], x[2] - d->center[2]};
  return nh_level_rel(d, r, 1);
}

int nh_domain_inside(const nh_domain *d, const double x[3]) {
  if (d->kind == NH_DOMAIN_BOX) {
    int inside = 1;
    for (int i = 0; i < 3; i++) inside &= x[i] > d->min[i] && x[i] < d->max[i];
    return inside;
  }
  if (d->kind == NH_DOMAIN_SURFACE) return nh_surface_inside(d->surface, x);
  return nh_domain_level(d, x) < 0.0;
}

/* Entry of the ray base + τ dir into the box: τ, point and outward normal. */
static int nh_box_entry(const double lo[3], const double hi[3], const double base[3],
                        const double dir[3], double *tau, double X[3], double n_out[3]) {
  double tmin = -INFINITY, tmax = INFINITY;
  int axis = -1, side = 0;
  for (int i = 0; i < 3; i++) {
    if (fabs(dir[i]) < 1e-300) {
      if (base[i] < lo[i] || base[i] > hi[i]) return 0;
      continue;
    }
    double a = (lo[i] - base[i]) / dir[i], b = (hi[i] - base[i]) / dir[i];
    int s = dir[i] > 0 ? -1 : 1;
    if (a > b) {
      double t = a;
      a = b, b = t;
    }
    if (a > tmin) tmin = a, axis = i, side = s;
    tmax = fmin(tmax, b);
  }
  if (tmin > tmax || tmin < 0 || axis < 0) return 0;
  for (int i = 0; i < 3; i++) X[i] = base[i] + tmin * dir[i], n_out[i] = 0.0;
  X[axis] = side < 0 ? lo[axis] : hi[axis];
  n_out[axis] = side;
  *tau = tmin;
  return 1;
}

static double nh_largest_edge(const nh_domain *d) {
  return 2.0 * fmax(d->half[0], fmax(d->half[1], d->half[2]));
}

static void nh_ray_point(const double base[3], const double dir[3], double t, double x[3]) {
  for (int i = 0; i < 3; i++) x[i] = base[i] + t * dir[i];
}

int nh_domain_ray_entry(const nh_domain *d, const double base[3], const double dir[3], double *tau,
                        double point[3], double normal[3]) {
  if (d->kind == NH_DOMAIN_BOX) return nh_box_entry(d->min, d->max, base, dir, tau, point, normal);
  if (d->kind == NH_DOMAIN_SURFACE) /* the triangles themselves: exact entry and normal */
    return !nh_surface_inside(d->surface, base) &&
           nh_surface_ray_entry(d->surface, base, dir, tau, point, normal);
  double x[3];
  if (nh_domain_level(d, base) <= 0.0) return 0;
  /* Where the ray crosses the bounding box (slightly enlarged): [t0, t1]. */
  const double L = nh_largest_edge(d), pad = 1e-3 * L;
  double t0 = 0.0, t1 = INFINITY, speed = nh_vec3_norm(dir);
  if (!(speed > 0)) return 0;
  for (int i = 0; i < 3; i++) {
    double lo = d->min[i] - pad, hi = d->max[i] + pad;
    if (fabs(dir[i]) < 1e-300) {
      if (base[i] < lo || base[i] > hi) return 0;
      continue;
    }
    double a = (lo - base[i]) / dir[i], b = (hi - base[i]) / dir[i];
    t0 = fmax(t0, fmin(a, b));
    t1 = fmin(t1, fmax(a, b));
  }
  if (t0 > t1) return 0;
  /* March in steps of 1e-3 L (as a length along the ray), then bisect. */
  const double dt = 1e-3 * L / speed;
  double lo = t0, hi = -1.0;
  for (double t = t0;; t += dt) {
    double tt = fmin(t, t1);
    nh_ray_point(base, dir, tt, x);
    if (nh_domain_level(d, x) <= 0.0) {
      hi = tt;
      break;
    }
    lo = tt;
    if (tt >= t1) break;
  }
  if (hi < 0) return 0;
  const double tol = 1e-13 * L / speed;
  for (int it = 0; it < 200 && hi - lo > tol; it++) {
    double mid = 0.5 * (lo + hi);
    if (mid <= lo || mid >= hi) break;
    nh_ray_point(base, dir, mid, x);
    if (nh_domain_level(d, x) <= 0.0)
      hi = mid;
    else
      lo = mid;
  }
  *tau = 0.5 * (lo + hi);
  nh_ray_point(base, dir, *tau, point);
  double g[3];
  nh_domain_gradient(d, point, g);
  double n = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  for (int i = 0; i < 3; i++) normal[i] = n > 0 ? g[i] / n : 0.0;
  return 1;
}

/* level(x) and its gradient by central differences of step 1e-6 of the
 * largest edge. */
static double nh_level_gradient(const nh_domain *d,
                                double (*level)(const nh_domain *, const double *),
                                const double x[3], double g[3]) {
  const double e = 1e-6 * nh_largest_edge(d);
  for (int i = 0; i < 3; i++) {
    double p[3] = {x[0], x[1], x[2]}, m[3] = {x[0], x[1], x[2]};
    p[i] += e, m[i] -= e;
    g[i] = (level(d, p) - level(d, m)) / (2 * e);
  }
  return level(d, x);
}

double nh_domain_gradient(const nh_domain *d, const double x[3], double g[3]) {
  return nh_level_gradient(d, nh_domain_level, x, g);
}

double nh_domain_hull_gradient(const nh_domain *d, const double x[3], double g[3]) {
  return nh_level_gradient(d, nh_domain_hull_level, x, g);
}

double nh_domain_segment_distance(const nh_domain *d, const double a[3], const double b[3]) {
  double best = INFINITY;
  if (d->kind == NH_DOMAIN_BOX) {
    const double *lo = d->min, *hi = d->max;
    for (int k = 0; k <= 200; k++) {
      double d2 = 0.0;
      for (int i = 0; i < 3; i++) {
        double x = a[i] + (b[i] - a[i]) * k / 200.0;
        double e = x < lo[i] ? lo[i] - x : (x > hi[i] ? x - hi[i] : 0.0);
        d2 += e * e;
      }
      best = fmin(best, sqrt(d2));
    }
    return best;
  }
  double ab[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, tau, p[3], n[3];
  if (nh_domain_level(d, a) <= 0.0) return 0.0;
  if (nh_domain_ray_entry(d, a, ab, &tau, p, n) && tau <= 1.0) return 0.0;
  /* F alone underestimates the distance where F is flatter than a distance
   * (|∇F| < 1, along the ellipsoids' long axes); F / |∇F| is the first-order
   * estimate, never below F itself. */
  const double e = 1e-6 * nh_largest_edge(d);
  for (int k = 0; k <= 200; k++) {
    double x[3], g2 = 0.0;
    for (int i = 0; i < 3; i++) x[i] = a[i] + ab[i] * k / 200.0;
    double f = nh_domain_level(d, x);
    for (int i = 0; i < 3; i++) {
      double p[3] = {x[0], x[1], x[2]}, m[3] = {x[0], x[1], x[2]};
      p[i] += e, m[i] -= e;
      double g = (nh_domain_level(d, p) - nh_domain_level(d, m)) / (2 * e);
      g2 += g * g;
    }
    double g = sqrt(g2);
    best = fmin(best, fmax(f, 0.0) / (g > 0 && g < 1 ? g : 1.0));
  }
  return best;
}

/* Length of {t ∈ [0, len] : F(x0 + t e_x) < 0} for the brain's line at
 * (Y, Z) on the half X >= 0: sign changes at n points, then bisection. */
static double nh_line_inside(const nh_domain *d, double Y, double Z, double len, int n) {
  double total = 0.0, prev_t = 0.0, prev_f = nh_brain_level(d->half, 0.0, Y, Z);
  double start = prev_f < 0 ? 0.0 : -1.0;
  for (int i = 1; i <= n; i++) {
    double t = len * i / n, f = nh_brain_level(d->half, t, Y, Z);
    if ((f < 0) != (prev_f < 0)) {
      double lo = prev_t, hi = t; /* F(lo) has the sign of prev_f */
      for (int it = 0; it < 60; it++) {
        double mid = 0.5 * (lo + hi);
        if ((nh_brain_level(d->half, mid, Y, Z) < 0) == (prev_f < 0))
          lo = mid;
        else
          hi = mid;
      }
      double root = 0.5 * (lo + hi);
      if (f < 0)
        start = root;
      else
        total += root - start, start = -1.0;
    }
    prev_t = t, prev_f = f;
  }
  if (start >= 0) total += len - start;
  return total;
}

/* Volume of {χ > 1/2} of a mask: 4³ midpoints per voxel over the selected
 * voxels' index box grown by one voxel. */
static double nh_mask_volume(const nh_image *im) {
  const int n = 4;
  long inside = 0;
  for (int k = n * (im->lo[2] - 1); k < n * (im->hi[2] + 2); k++)
    for (int j = n * (im->lo[1] - 1); j < n * (im->hi[1] + 2); j++)
      for (int i = n * (im->lo[0] - 1); i < n * (im->hi[0] + 2); i++) {
        double ijk[3] = {(i + 0.5) / n - 0.5, (j + 0.5) / n - 0.5, (k + 0.5) / n - 0.5}, x[3];
        nh_image_to_world(im, ijk, x);
        inside += nh_image_indicator(im, x) > 0.5;
      }
  return inside * fabs(nh_mat3_det(im->A)) / (n * n * n);
}

double nh_domain_volume(const nh_domain *d) {
  if (d->kind == NH_DOMAIN_SPHERE) return 4.0 / 3.0 * NH_PI * d->half[0] * d->half[0] * d->half[0];
  if (d->kind == NH_DOMAIN_BOX)
    return (d->max[0] - d->min[0]) * (d->max[1] - d->min[1]) * (d->max[2] - d->min[2]);
  if (d->kind == NH_DOMAIN_MASK) return nh_mask_volume(d->image);
  if (d->kind == NH_DOMAIN_SURFACE) return nh_surface_volume(d->surface);
  const int n = 256;
  const double hy = 2 * d->half[1] / n, hz = 2 * d->half[2] / n;
  double sum = 0.0;
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++) {
      double Y = -d->half[1] + (j + 0.5) * hy, Z = -d->half[2] + (k + 0.5) * hz;
      sum += nh_line_inside(d, Y, Z, d->half[0] * (1 + 1e-9), 256);
    }
  return 2.0 * sum * hy * hz; /* both halves: F is even in x − cx */
}

/* Mask and surface: may the box [lo, hi] meet the shape? Conservative:
 * χ's support for a mask, a triangle's bounding box for a surface. */
static int nh_domain_box_may_meet(const nh_domain *d, const double lo[3], const double hi[3]) {
  return d->kind == NH_DOMAIN_MASK ? nh_image_meets_box(d->image, lo, hi)
                                   : nh_surface_meets_box(d->surface, lo, hi);
}

double nh_domain_cell_fill(const nh_domain *d, const double Xe[24], int *meets) {
  const int n = NH_FILL_SAMPLES;
  double inside = 0.0, total = 0.0;
  int near = 0;
  const int sampled = d->kind == NH_DOMAIN_SURFACE || d->kind == NH_DOMAIN_MASK;
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++)
      for (int k = 0; k < n; k++) {
        double xi[3] = {-1 + (2 * i + 1.0) / n, -1 + (2 * j + 1.0) / n, -1 + (2 * k + 1.0) / n};
        double N[8], dN[8][3], r[3] = {0, 0, 0}, J[9] = {0};
        nh_hex_shape(xi, N);
        nh_hex_dshape(xi, dN);
        for (int a = 0; a < 8; a++)
          for (int p = 0; p < 3; p++) {
            r[p] += N[a] * (Xe[3 * a + p] - d->center[p]);
            for (int q = 0; q < 3; q++) J[3 * p + q] += Xe[3 * a + p] * dN[a][q];
          }
        /* The sub-cell's circumradius: half the length of J (2/n, 2/n, 2/n). */
        double radius = 0.0;
        for (int p = 0; p < 3; p++) {
          double c = (J[3 * p] + J[3 * p + 1] + J[3 * p + 2]) / n;
          double c1 = (J[3 * p] - J[3 * p + 1] + J[3 * p + 2]) / n;
          double c2 = (J[3 * p] + J[3 * p + 1] - J[3 * p + 2]) / n;
          double c3 = (-J[3 * p] + J[3 * p + 1] + J[3 * p + 2]) / n;
          radius += fmax(fmax(c * c, c1 * c1), fmax(c2 * c2, c3 * c3));
        }
        radius = sqrt(radius);
        double dv = fabs(nh_mat3_det(J));
        total += dv;
        if (sampled) { /* the inside test only; whether the cell meets the shape, below */
          double x[3] = {d->center[0] + r[0], d->center[1] + r[1], d->center[2] + r[2]};
          if (nh_domain_inside(d, x)) inside += dv, near = 1;
          continue;
        }
        double f = nh_level_rel(d, r, 0);
        if (f < 0) inside += dv;
        if (f <= radius * (1 + 1e-12)) near = 1;
      }
  if (sampled && !near) { /* no sample inside: may it meet the shape all the same? */
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int a = 0; a < 8; a++)
      for (int p = 0; p < 3; p++)
        lo[p] = fmin(lo[p], Xe[3 * a + p]), hi[p] = fmax(hi[p], Xe[3 * a + p]);
    near = nh_domain_box_may_meet(d, lo, hi);
  }
  if (meets) *meets = near;
  return total > 0 ? inside / total : 0.0;
}

double nh_domain_lattice_fill(const nh_domain *d, const int grid[3], const int ijk[3], int *meets) {
  const int n = NH_FILL_SAMPLES;
  /* Sample m of axis p (m = n i + s) lies at (2m + 1 − n g)/(2 n g) of the
   * box's edge from the centre: an exact integer numerator, so the mirror
   * sample (m' = n g − 1 − m) is exactly the negated offset. */
  double off[3][NH_FILL_SAMPLES], radius = 0.0;
  for (int p = 0; p < 3; p++) {
    double edge = 2.0 * d->half[p], h = edge / grid[p] / n;
    radius += 0.25 * h * h;
    for (int s = 0; s < n; s++)
      off[p][s] = (double)(2 * (n * ijk[p] + s) + 1 - n * grid[p]) / (2.0 * n * grid[p]) * edge;
  }
  radius = sqrt(radius) * (1 + 1e-12);
  int inside = 0, near = 0;
  if (d->kind == NH_DOMAIN_SURFACE || d->kind == NH_DOMAIN_MASK) {
    double lo[3], hi[3];
    for (int k = 0; k < n; k++)
      for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
          double x[3] = {d->center[0] + off[0][i], d->center[1] + off[1][j],
                         d->center[2] + off[2][k]};
          inside += nh_domain_inside(d, x);
        }
    for (int p = 0; p < 3; p++) {
      double h = 2.0 * d->half[p] / grid[p];
      lo[p] = d->min[p] + h * ijk[p], hi[p] = lo[p] + h;
    }
    near = inside > 0 || nh_domain_box_may_meet(d, lo, hi);
    if (meets) *meets = near;
    return (double)inside / (n * n * n);
  }
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++) {
        double r[3] = {off[0][i], off[1][j], off[2][k]}, f = nh_level_rel(d, r, 0);
        inside += f < 0;
        near |= f <= radius;
      }
  if (meets) *meets = near;
  return (double)inside / (n * n * n);
}
