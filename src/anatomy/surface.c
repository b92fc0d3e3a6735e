/* surface.c — closed triangulated surfaces: a strict STL reader, the inside
 * test, a truncated signed distance and the ray entry (docs/anatomy.md,
 * "Surface meshes").
 *
 * Reader. No maintained C library for STL ships with Debian (VTK's reader
 * is C++), so this file reads both STL forms itself, strictly: binary when
 * the file size is exactly 84 + 50 N for the count N in bytes 80–83 (some
 * binary files begin with "solid" too), else ASCII, keyword by keyword,
 * every error naming the file and line. A surface must be closed: after
 * welding corners with identical coordinates, every edge is shared by an
 * even number of triangles (2 for a manifold; 4 where two closed pieces
 * touch along an edge). Zero-area triangles are dropped first.
 *
 * Inside test. The parity of the crossings of the ray x + s e_x (s > 0).
 * A triangle is crossed if the ray's (y, z) lies inside its projection: the
 * three edge functions e(u, v; p) = (v_y − u_y)(p_z − u_z) − (v_z − u_z)(p_y −
 * u_y) have one sign. Each edge function is computed with its endpoints in
 * lexicographic order and negated if they were swapped, so the two triangles
 * on an edge see bitwise opposite values, and a zero is resolved as if p were
 * moved by (ε, ε²): sign(−(v_z − u_z)), or sign(v_y − u_y) if that is 0. The
 * decision is then that of a ray in general position: a ray through an edge
 * or a vertex crosses exactly one of the triangles there (or, at a fold of
 * the projection, 0 or 2, which keeps the parity), for slivers as for
 * well-shaped triangles. Triangles are found through a grid over the (y, z)
 * extent that lists every triangle under each grid cell its projected
 * bounding box meets.
 *
 * Distance. The nearest triangle by the closest-point construction on each
 * candidate (Ericson, "Real-Time Collision Detection" §5.1.5), candidates
 * from a 3D grid searched in shells of growing Chebyshev radius r around the
 * point's cell: triangles in shell > r are at least r · (smallest grid edge)
 * away, so the search stops once the best distance is below that, or at the
 * cap. */
#include "anatomy/anatomy.h"

#include <ctype.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void nh_surface_retain(nh_surface *s) {
  if (s) s->refs++;
}

void nh_surface_release(nh_surface **surface) {
  if (!surface || !*surface) return;
  nh_surface *s = *surface;
  *surface = NULL;
  if (--s->refs > 0) return;
  free(s->v), free(s->ball);
  free(s->yz_start), free(s->yz_tri), free(s->xyz_start), free(s->xyz_tri);
  free(s);
}

/* Append triangle (9 doubles, file units) unless its area is zero. */
static int nh_add_triangle(nh_surface *s, int *cap, const double t[9], const char *where) {
  double e1[3], e2[3], n[3], m[9];
  for (int k = 0; k < 9; k++) {
    m[k] = t[k] * s->unit;
    NH_CHECK(isfinite(m[k]), NH_ERR_INPUT,
             "%s: coordinate %g times unit %g m is not a finite length", where, t[k], s->unit);
  }
  for (int k = 0; k < 3; k++) e1[k] = m[3 + k] - m[k], e2[k] = m[6 + k] - m[k];
  nh_vec3_cross(e1, e2, n);
  if (n[0] == 0 && n[1] == 0 && n[2] == 0) return NH_OK;
  NH_CHECK(s->n_tri < INT_MAX / 9, NH_ERR_INPUT, "%s: more than %d triangles are not supported",
           where, INT_MAX / 9);
  if (nh_grow((void **)&s->v, cap, 9 * (s->n_tri + 1), sizeof(double)))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", s->path);
  memcpy(s->v + 9 * (size_t)s->n_tri, m, sizeof m);
  s->n_tri++;
  return NH_OK;
}

/* ---- the file, read through a buffer with a bound ---- */
typedef struct {
  const char *path;
  FILE *f;
  unsigned char buf[65536];
  size_t pos, len;
  double used, max_bytes; /* bytes consumed, and at most this many */
  int over;               /* a byte beyond max_bytes was asked for */
  int line;               /* ASCII: the line of the last byte consumed */
  int eol;                /* ASCII: the last word ended its line (or the file) */
  int newline;            /* ASCII: ... with a newline, counted when the next word starts */
} nh_stl_stream;

/* The next byte, or EOF at the end of the file or past the bound (then over = 1). */
static int nh_stl_getc(nh_stl_stream *r) {
  if (r->pos == r->len) {
    r->len = fread(r->buf, 1, sizeof r->buf, r->f), r->pos = 0;
    if (r->len == 0) return EOF;
  }
  if (r->used + 1 > r->max_bytes) {
    r->over = 1;
    return EOF;
  }
  r->used++;
  return r->buf[r->pos++];
}

/* Up to n bytes into out; how many. */
static size_t nh_stl_read(nh_stl_stream *r, unsigned char *out, size_t n) {
  size_t got = 0;
  int c;
  while (got < n && (c = nh_stl_getc(r)) != EOF) out[got++] = (unsigned char)c;
  return got;
}

/* ---- ASCII STL ---- */

/* A byte that no text file holds (a control byte other than white space). */
static int nh_stl_binary_byte(int c) {
  return c == 0 || (c < 0x20 && !strchr("\t\n\v\f\r", c)) || c == 0x7f;
}

static int nh_stl_text_error(nh_stl_stream *r, int c) {
  if (r->over)
    return NH_ERROR(NH_ERR_INPUT,
                    "%s:%d: the file goes on past limits.max_file_bytes = %.0f bytes (a stream "
                    "that does not end?)",
                    r->path, r->line, r->max_bytes);
  return NH_ERROR(NH_ERR_INPUT,
                  "%s:%d: byte 0x%02x: binary data in an ASCII STL (a binary STL whose size is "
                  "not 84 + 50 x its triangle count?)",
                  r->path, r->line, (unsigned)c);
}

/* Next whitespace-separated word into buf (at most cap - 1 bytes); "" at the end. */
static int nh_stl_word(nh_stl_stream *r, char *buf, size_t cap) {
  int c;
  r->line += r->newline, r->newline = 0;
  while ((c = nh_stl_getc(r)) != EOF && isspace(c)) r->line += c == '\n';
  size_t n = 0;
  while (c != EOF && !isspace(c)) {
    if (nh_stl_binary_byte(c)) return nh_stl_text_error(r, c);
    if (n + 1 == cap) {
      buf[n] = '\0';
      return NH_ERROR(NH_ERR_INPUT, "%s:%d: a word longer than %zu bytes ('%.24s...')", r->path,
                      r->line, cap - 1, buf);
    }
    buf[n++] = (char)c;
    c = nh_stl_getc(r);
  }
  buf[n] = '\0';
  if (r->over) return nh_stl_text_error(r, 0);
  r->newline = c == '\n', r->eol = c == '\n' || c == EOF;
  return NH_OK;
}

static int nh_stl_expect(nh_stl_stream *r, const char *want) {
  char w[64];
  NH_TRY(nh_stl_word(r, w, sizeof w));
  NH_CHECK(!strcmp(w, want), NH_ERR_INPUT, "%s:%d: expected '%s', got '%s'", r->path, r->line, want,
           w[0] ? w : "the end of the file");
  return NH_OK;
}

static int nh_stl_number(nh_stl_stream *r, const char *what, double *out) {
  char w[128], *end;
  NH_TRY(nh_stl_word(r, w, sizeof w));
  *out = strtod(w, &end);
  NH_CHECK(w[0] && *end == '\0' && isfinite(*out), NH_ERR_INPUT,
           "%s:%d: %s: expected a finite number, got '%s'", r->path, r->line, what,
           w[0] ? w : "the end of the file");
  return NH_OK;
}

/* The rest of the current line (the solid's name), unless the last word ended it. */
static int nh_stl_skip_line(nh_stl_stream *r) {
  int c;
  if (r->eol) return NH_OK;
  while ((c = nh_stl_getc(r)) != EOF && c != '\n')
    if (nh_stl_binary_byte(c)) return nh_stl_text_error(r, c);
  if (r->over) return nh_stl_text_error(r, 0);
  r->newline = c == '\n', r->eol = 1;
  return NH_OK;
}

static int nh_stl_ascii(nh_surface *s, nh_stl_stream *r, double max_triangles, int *cap) {
  char w[64], where[NH_ANATOMY_PATH_MAX + 32];
  NH_TRY(nh_stl_expect(r, "solid"));
  NH_TRY(nh_stl_skip_line(r));
  for (double facets = 0;; facets++) {
    NH_TRY(nh_stl_word(r, w, sizeof w));
    if (!strcmp(w, "endsolid")) break;
    NH_CHECK(strcmp(w, ""), NH_ERR_INPUT, "%s:%d: the file ends before 'endsolid'", s->path,
             r->line);
    NH_CHECK(!strcmp(w, "facet"), NH_ERR_INPUT, "%s:%d: expected 'facet' or 'endsolid', got '%s'",
             s->path, r->line, w);
    NH_CHECK(facets < max_triangles, NH_ERR_INPUT,
             "%s:%d: more than limits.max_triangles = %.0f facets", s->path, r->line,
             max_triangles);
    double n[3], t[9];
    NH_TRY(nh_stl_expect(r, "normal"));
    for (int k = 0; k < 3; k++) NH_TRY(nh_stl_number(r, "facet normal", &n[k]));
    NH_TRY(nh_stl_expect(r, "outer"));
    NH_TRY(nh_stl_expect(r, "loop"));
    for (int c = 0; c < 3; c++) {
      NH_TRY(nh_stl_expect(r, "vertex"));
      for (int k = 0; k < 3; k++) NH_TRY(nh_stl_number(r, "vertex", &t[3 * c + k]));
    }
    NH_TRY(nh_stl_expect(r, "endloop"));
    NH_TRY(nh_stl_expect(r, "endfacet"));
    snprintf(where, sizeof where, "%s:%d", s->path, r->line);
    NH_TRY(nh_add_triangle(s, cap, t, where));
  }
  NH_TRY(nh_stl_skip_line(r));
  NH_TRY(nh_stl_word(r, w, sizeof w));
  NH_CHECK(!w[0], NH_ERR_INPUT, "%s:%d: unexpected '%s' after 'endsolid' (one solid per file)",
           s->path, r->line, w);
  return NH_OK;
}

/* ---- binary STL ---- */
static float nh_le_float(const unsigned char *b) {
  uint32_t u = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
  float f;
  memcpy(&f, &u, sizeof f);
  return f;
}

/* `count` records of 50 bytes after the 84-byte header (consumed already),
 * then the end of the file. */
static int nh_stl_binary(nh_surface *s, nh_stl_stream *r, uint32_t count, int *cap) {
  char where[NH_ANATOMY_PATH_MAX + 32];
  for (uint32_t i = 0; i < count; i++) {
    unsigned char rec[50];
    size_t got = nh_stl_read(r, rec, sizeof rec);
    NH_CHECK(got == sizeof rec, NH_ERR_INPUT,
             "%s: the file ends in triangle %u of the %u its header announces (%.0f of %.0f "
             "bytes): truncated",
             s->path, i, count, r->used, 84 + 50.0 * count);
    double t[9];
    for (int k = 0; k < 9; k++) {
      t[k] = nh_le_float(rec + 12 + 4 * k);
      NH_CHECK(isfinite(t[k]), NH_ERR_INPUT, "%s: triangle %u: a corner coordinate is not finite",
               s->path, i);
    }
    snprintf(where, sizeof where, "%s: triangle %u", s->path, i);
    NH_TRY(nh_add_triangle(s, cap, t, where));
  }
  NH_CHECK(nh_stl_getc(r) == EOF && !r->over, NH_ERR_INPUT,
           "%s: the file goes on after the 84 + 50 x %u = %.0f bytes its header announces "
           "(a wrong triangle count, or not STL)",
           s->path, count, 84 + 50.0 * count);
  return NH_OK;
}

/* ---- closedness ---- */
typedef struct {
  double x[3];
  int tri, corner;
} nh_corner_ref;

static int nh_corner_compare(const void *a, const void *b) {
  const nh_corner_ref *p = a, *q = b;
  for (int k = 0; k < 3; k++)
    if (p->x[k] != q->x[k]) return p->x[k] < q->x[k] ? -1 : 1;
  return 0;
}

static int nh_edge_compare(const void *a, const void *b) {
  const long long *p = a, *q = b;
  return (*p > *q) - (*p < *q);
}

static int nh_surface_check_closed(const nh_surface *s) {
  int n = 3 * s->n_tri;
  nh_corner_ref *c = nh_calloc((size_t)n, sizeof *c);
  int *id = nh_calloc((size_t)n, sizeof(int));
  long long *edge = nh_calloc((size_t)n, sizeof(long long));
  if (!c || !id || !edge) {
    free(c), free(id), free(edge);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", s->path);
  }
  for (int i = 0; i < n; i++) {
    memcpy(c[i].x, s->v + 3 * i, sizeof c[i].x);
    c[i].tri = i / 3, c[i].corner = i % 3;
  }
  qsort(c, (size_t)n, sizeof *c, nh_corner_compare);
  int next = -1;
  for (int i = 0; i < n; i++) {
    if (i == 0 || nh_corner_compare(&c[i], &c[i - 1])) next++;
    id[3 * c[i].tri + c[i].corner] = next;
  }
  for (int t = 0; t < s->n_tri; t++)
    for (int e = 0; e < 3; e++) {
      long long a = id[3 * t + e], b = id[3 * t + (e + 1) % 3];
      edge[3 * t + e] = a < b ? a * n + b : b * n + a;
    }
  qsort(edge, (size_t)n, sizeof *edge, nh_edge_compare);
  int rc = NH_OK;
  for (int i = 0; i < n && !rc;) {
    int j = i;
    while (j < n && edge[j] == edge[i]) j++;
    if ((j - i) % 2) {
      /* Find a corner of the open edge for the message. */
      int a = (int)(edge[i] / n);
      double x[3] = {0, 0, 0};
      for (int k = 0; k < n; k++)
        if (id[k] == a) {
          memcpy(x, s->v + 3 * k, sizeof x);
          break;
        }
      rc = NH_ERROR(NH_ERR_INPUT,
                    "%s: not a closed surface: an edge at [%g, %g, %g] m is shared by %d "
                    "triangle%s (a closed surface shares every edge between 2)",
                    s->path, x[0], x[1], x[2], j - i, j - i == 1 ? "" : "s");
    }
    i = j;
  }
  free(c), free(id), free(edge);
  return rc;
}

/* ---- acceleration grids ---- */

/* a · b, inlined in the distance query's inner loops. */
static inline double nh_dot3(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static int nh_clampi(int v, int lo, int hi) {
  return v < lo ? lo : (v > hi ? hi : v);
}

static void nh_tri_box(const double *t, double lo[3], double hi[3]) {
  for (int k = 0; k < 3; k++) {
    lo[k] = fmin(t[k], fmin(t[3 + k], t[6 + k]));
    hi[k] = fmax(t[k], fmax(t[3 + k], t[6 + k]));
  }
}

static int nh_surface_cell_of(const nh_surface *s, int axis, double x) {
  return nh_clampi((int)floor((x - s->min[axis]) / s->cell[axis]), 0, s->g[axis] - 1);
}

/* The index's (triangle, cell) pairs: at most 64 per triangle or 1e7 (40 MB)
 * in all, whichever is more. A fan of long slivers (a cone's or a cap's
 * triangles all from one apex) overlaps many cells each: a double cone of
 * 65 000 segments would need 2e9 pairs, 8 GB, and overflow the int offsets. */
#define NH_SURFACE_PAIRS_PER_TRIANGLE 64
#define NH_SURFACE_PAIRS_MIN          1e7

/* Bucket triangles into the grid cells of `axes` (2: y, z; 3: x, y, z). */
static int nh_surface_bucket(nh_surface *s, int three_d, int **start_out, int **tri_out) {
  const int a0 = three_d ? 0 : 1;
  size_t cells = 1;
  for (int a = a0; a < 3; a++) cells *= (size_t)s->g[a];
  int *start = nh_calloc(cells + 1, sizeof(int));
  if (!start) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", s->path);
  const double most = fmin(
      INT_MAX - 1.0, fmax(NH_SURFACE_PAIRS_PER_TRIANGLE * (double)s->n_tri, NH_SURFACE_PAIRS_MIN));
  double pairs = 0.0;
  for (int pass = 0; pass < 2; pass++) {
    int *fill = NULL;
    if (pass == 1) {
      for (size_t c = 0; c < cells; c++) start[c + 1] += start[c];
      *tri_out = nh_calloc((size_t)(start[cells] + 1), sizeof(int));
      fill = nh_calloc(cells, sizeof(int));
      if (!*tri_out || !fill) {
        free(fill), free(start);
        return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", s->path);
      }
      memcpy(fill, start, sizeof(int) * cells);
    }
    for (int t = 0; t < s->n_tri; t++) {
      double lo[3], hi[3];
      int l[3] = {0, 0, 0}, h[3] = {0, 0, 0};
      nh_tri_box(s->v + 9 * t, lo, hi);
      for (int a = a0; a < 3; a++)
        l[a] = nh_surface_cell_of(s, a, lo[a]), h[a] = nh_surface_cell_of(s, a, hi[a]);
      pairs += pass ? 0.0 : (h[0] - l[0] + 1.0) * (h[1] - l[1] + 1.0) * (h[2] - l[2] + 1.0);
      if (pairs > most) {
        free(start);
        return NH_ERROR(NH_ERR_INPUT,
                        "%s: its %d triangles overlap more than %.0f cells of the reader's %s "
                        "index (%d per triangle or %.0f in all): long sliver triangles, such as "
                        "a fan from one apex across the shape; remesh it into triangles of "
                        "similar size",
                        s->path, s->n_tri, most, three_d ? "(x, y, z)" : "(y, z)",
                        NH_SURFACE_PAIRS_PER_TRIANGLE, NH_SURFACE_PAIRS_MIN);
      }
      for (int k = l[2]; k <= h[2]; k++)
        for (int j = l[1]; j <= h[1]; j++)
          for (int i = l[0]; i <= h[0]; i++) {
            size_t c = three_d ? (size_t)i + (size_t)s->g[0] * (j + (size_t)s->g[1] * k)
                               : (size_t)(j - 0) + (size_t)s->g[1] * k;
            if (pass == 0)
              start[c + 1]++;
            else
              (*tri_out)[fill[c]++] = t;
          }
    }
    free(fill);
  }
  *start_out = start;
  return NH_OK;
}

static int nh_surface_index(nh_surface *s) {
  for (int k = 0; k < 3; k++) s->min[k] = INFINITY, s->max[k] = -INFINITY;
  for (int i = 0; i < 3 * s->n_tri; i++)
    for (int k = 0; k < 3; k++)
      s->min[k] = fmin(s->min[k], s->v[3 * i + k]), s->max[k] = fmax(s->max[k], s->v[3 * i + k]);
  /* Each triangle's bounding ball: its centroid and the farthest corner
   * (grown by 1e-9 against round-off), the distance query's cheap test. */
  s->ball = nh_calloc((size_t)(s->n_tri > 0 ? s->n_tri : 1), 4 * sizeof(double));
  if (!s->ball) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", s->path);
  for (int t = 0; t < s->n_tri; t++) {
    const double *v = s->v + 9 * t;
    double *b = s->ball + 4 * t, r2 = 0.0;
    for (int k = 0; k < 3; k++) b[k] = (v[k] + v[3 + k] + v[6 + k]) / 3.0;
    for (int a = 0; a < 3; a++) {
      const double e[3] = {v[3 * a] - b[0], v[3 * a + 1] - b[1], v[3 * a + 2] - b[2]};
      r2 = fmax(r2, nh_dot3(e, e));
    }
    b[3] = sqrt(r2) * (1 + 1e-9);
  }
  /* About n^(1/3) cells per axis in 3D and n^(1/2) per axis in (y, z). */
  int g3 = nh_clampi((int)ceil(cbrt((double)s->n_tri)), 1, 256);
  double ext = 0.0;
  for (int k = 0; k < 3; k++) ext = fmax(ext, s->max[k] - s->min[k]);
  for (int k = 0; k < 3; k++) {
    double e = fmax(s->max[k] - s->min[k], 1e-9 * ext);
    s->g[k] = nh_clampi((int)ceil(g3 * e / ext), 1, 256);
    s->cell[k] = e / s->g[k] * (1 + 1e-12);
  }
  NH_TRY(nh_surface_bucket(s, 1, &s->xyz_start, &s->xyz_tri));
  /* The (y, z) grid, finer: reuse g[1], g[2] scaled up (cells of the 3D grid
   * are kept in cell[]; the 2D grid uses its own counts below). */
  int g3y = s->g[1], g3z = s->g[2];
  double cy = s->cell[1], cz = s->cell[2];
  int g2 = nh_clampi((int)ceil(sqrt((double)s->n_tri)), 1, 2048);
  double eyz = fmax(s->max[1] - s->min[1], s->max[2] - s->min[2]);
  for (int k = 1; k < 3; k++) {
    double e = fmax(s->max[k] - s->min[k], 1e-9 * ext);
    s->g[k] = nh_clampi((int)ceil(g2 * e / eyz), 1, 2048);
    s->cell[k] = e / s->g[k] * (1 + 1e-12);
  }
  s->yz_g[0] = s->g[1], s->yz_g[1] = s->g[2];
  s->yz_cell[0] = s->cell[1], s->yz_cell[1] = s->cell[2];
  int rc = nh_surface_bucket(s, 0, &s->yz_start, &s->yz_tri);
  s->g[1] = g3y, s->g[2] = g3z, s->cell[1] = cy, s->cell[2] = cz;
  return rc;
}

/* ---- queries ---- */

/* Sign (never 0) of the edge function of u → v at p in the (y, z) plane,
 * computed in the canonical order of the endpoints, zero broken by the
 * perturbation p + (ε, ε²). 0 only if u and v project to the same point. */
static int nh_edge_sign(const double *u, const double *v, double py, double pz) {
  int swap = u[1] > v[1] || (u[1] == v[1] && u[2] > v[2]);
  const double *a = swap ? v : u, *b = swap ? u : v;
  double e = (b[1] - a[1]) * (pz - a[2]) - (b[2] - a[2]) * (py - a[1]);
  int s = e > 0 ? 1 : (e < 0 ? -1 : 0);
  if (!s) {
    double dz = b[2] - a[2], dy = b[1] - a[1];
    s = dz < 0 ? 1 : (dz > 0 ? -1 : (dy > 0 ? 1 : (dy < 0 ? -1 : 0)));
  }
  return swap ? -s : s;
}

/* Whether the ray (·, y, z) + s e_x crosses triangle t (by the rule of the
 * file's header comment), and at which x. */
static int nh_ray_crossing(const double *t, double y, double z, double *hit) {
  int s0 = nh_edge_sign(t, t + 3, y, z);
  int s1 = nh_edge_sign(t + 3, t + 6, y, z);
  int s2 = nh_edge_sign(t + 6, t, y, z);
  if (!s0 || s0 != s1 || s1 != s2) return 0;
  /* Where the ray meets the triangle's plane: barycentric weights from the
   * (y, z) areas (the projection has non-zero area here). */
  double e0 = (t[4] - t[1]) * (z - t[2]) - (t[5] - t[2]) * (y - t[1]);
  double e1 = (t[7] - t[4]) * (z - t[5]) - (t[8] - t[5]) * (y - t[4]);
  double e2 = (t[1] - t[7]) * (z - t[8]) - (t[2] - t[8]) * (y - t[7]);
  double sum = e0 + e1 + e2;
  *hit = sum != 0 ? (e1 * t[0] + e2 * t[3] + e0 * t[6]) / sum : (t[0] + t[3] + t[6]) / 3.0;
  return 1;
}

/* The (y, z) grid cell of a point inside the (y, z) extent. */
static size_t nh_yz_cell(const nh_surface *s, double y, double z) {
  int j = nh_clampi((int)floor((y - s->min[1]) / s->yz_cell[0]), 0, s->yz_g[0] - 1);
  int k = nh_clampi((int)floor((z - s->min[2]) / s->yz_cell[1]), 0, s->yz_g[1] - 1);
  return (size_t)j + (size_t)s->yz_g[0] * k;
}

int nh_surface_inside(const nh_surface *s, const double x[3]) {
  if (!(x[1] >= s->min[1] && x[1] <= s->max[1] && x[2] >= s->min[2] && x[2] <= s->max[2] &&
        x[0] <= s->max[0]))
    return 0;
  size_t c = nh_yz_cell(s, x[1], x[2]);
  int crossings = 0;
  for (int q = s->yz_start[c]; q < s->yz_start[c + 1]; q++) {
    double hit;
    if (nh_ray_crossing(s->v + 9 * s->yz_tri[q], x[1], x[2], &hit) && hit > x[0]) crossings++;
  }
  return crossings & 1;
}

/* Squared distance from p to triangle t (closest-point regions). */
static double nh_tri_dist2(const double *t, const double p[3]) {
  const double *a = t, *b = t + 3, *c = t + 6;
  double ab[3], ac[3], ap[3], q[3];
  for (int k = 0; k < 3; k++) ab[k] = b[k] - a[k], ac[k] = c[k] - a[k], ap[k] = p[k] - a[k];
  double d1 = nh_dot3(ab, ap), d2 = nh_dot3(ac, ap);
  if (d1 <= 0 && d2 <= 0) {
    for (int k = 0; k < 3; k++) q[k] = a[k];
    goto done;
  }
  double bp[3];
  for (int k = 0; k < 3; k++) bp[k] = p[k] - b[k];
  double d3 = nh_dot3(ab, bp), d4 = nh_dot3(ac, bp);
  if (d3 >= 0 && d4 <= d3) {
    for (int k = 0; k < 3; k++) q[k] = b[k];
    goto done;
  }
  double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    double v = d1 / (d1 - d3);
    for (int k = 0; k < 3; k++) q[k] = a[k] + v * ab[k];
    goto done;
  }
  double cp[3];
  for (int k = 0; k < 3; k++) cp[k] = p[k] - c[k];
  double d5 = nh_dot3(ab, cp), d6 = nh_dot3(ac, cp);
  if (d6 >= 0 && d5 <= d6) {
    for (int k = 0; k < 3; k++) q[k] = c[k];
    goto done;
  }
  double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    double w = d2 / (d2 - d6);
    for (int k = 0; k < 3; k++) q[k] = a[k] + w * ac[k];
    goto done;
  }
  double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    for (int k = 0; k < 3; k++) q[k] = b[k] + w * (c[k] - b[k]);
    goto done;
  }
  {
    double den = 1.0 / (va + vb + vc), v = vb * den, w = vc * den;
    for (int k = 0; k < 3; k++) q[k] = a[k] + ab[k] * v + ac[k] * w;
  }
done:;
  double d[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
  return nh_dot3(d, d);
}

double nh_surface_level(const nh_surface *s, const double x[3], double cap) {
  if (!(cap > 0)) cap = INFINITY;
  double sign = nh_surface_inside(s, x) ? -1.0 : 1.0;
  /* Outside the bounding box, its distance is a lower bound. */
  double box2 = 0.0;
  for (int k = 0; k < 3; k++) {
    double e = x[k] < s->min[k] ? s->min[k] - x[k] : (x[k] > s->max[k] ? x[k] - s->max[k] : 0.0);
    box2 += e * e;
  }
  if (sqrt(box2) >= cap) return sign * cap;
  int c[3];
  double hmin = fmin(s->cell[0], fmin(s->cell[1], s->cell[2]));
  for (int k = 0; k < 3; k++) c[k] = nh_surface_cell_of(s, k, x[k]);
  int rmax = s->g[0] + s->g[1] + s->g[2];
  double best2 = INFINITY, best = INFINITY;
  for (int r = 0; r <= rmax; r++) {
    for (int k = c[2] - r; k <= c[2] + r; k++) {
      if (k < 0 || k >= s->g[2]) continue;
      for (int j = c[1] - r; j <= c[1] + r; j++) {
        if (j < 0 || j >= s->g[1]) continue;
        for (int i = c[0] - r; i <= c[0] + r; i++) {
          if (i < 0 || i >= s->g[0]) continue;
          int on_shell = abs(i - c[0]) == r || abs(j - c[1]) == r || abs(k - c[2]) == r;
          if (!on_shell) continue;
          size_t cell = (size_t)i + (size_t)s->g[0] * (j + (size_t)s->g[1] * k);
          for (int q = s->xyz_start[cell]; q < s->xyz_start[cell + 1]; q++) {
            /* every point of the triangle lies within ball[3] of ball[0..2] */
            const int t = s->xyz_tri[q];
            const double *b = s->ball + 4 * t, lim = best + b[3];
            const double e[3] = {x[0] - b[0], x[1] - b[1], x[2] - b[2]};
            if (nh_dot3(e, e) > lim * lim) continue;
            const double d2 = nh_tri_dist2(s->v + 9 * t, x);
            if (d2 < best2) best2 = d2, best = sqrt(d2);
          }
        }
      }
    }
    double reach = r * hmin; /* every unsearched triangle is at least this far */
    if (best2 <= reach * reach || reach >= cap) break;
  }
  return sign * fmin(sqrt(best2), cap);
}

void nh_surface_print(const nh_surface *s, FILE *f) {
  fprintf(f, "surface   %s: %d triangles, box [%g, %g, %g] - [%g, %g, %g] m, volume %.6g m^3\n",
          s->path, s->n_tri, s->min[0], s->min[1], s->min[2], s->max[0], s->max[1], s->max[2],
          nh_surface_volume(s));
}

/* Signed volume by the divergence theorem, Σ a · (b × c) / 6. */
static double nh_surface_signed_volume(const nh_surface *s) {
  double v = 0.0;
  for (int t = 0; t < s->n_tri; t++) {
    const double *a = s->v + 9 * t;
    double bc[3];
    nh_vec3_cross(a + 3, a + 6, bc);
    v += nh_vec3_dot(a, bc);
  }
  return v / 6.0;
}

double nh_surface_volume(const nh_surface *s) {
  return fabs(nh_surface_signed_volume(s));
}

int nh_surface_ray_entry(const nh_surface *s, const double base[3], const double dir[3],
                         double *tau, double point[3], double normal[3]) {
  double best = INFINITY;
  int hit = -1;
  for (int t = 0; t < s->n_tri; t++) {
    const double *a = s->v + 9 * t;
    double e1[3], e2[3], p[3], q[3], r[3];
    for (int k = 0; k < 3; k++) e1[k] = a[3 + k] - a[k], e2[k] = a[6 + k] - a[k];
    nh_vec3_cross(dir, e2, p);
    double det = nh_vec3_dot(e1, p);
    if (det == 0.0) continue;
    for (int k = 0; k < 3; k++) r[k] = base[k] - a[k];
    double u = nh_vec3_dot(r, p) / det;
    if (u < 0 || u > 1) continue;
    nh_vec3_cross(r, e1, q);
    double v = nh_vec3_dot(dir, q) / det;
    if (v < 0 || u + v > 1) continue;
    double tt = nh_vec3_dot(e2, q) / det;
    if (tt > 0 && tt < best) best = tt, hit = t;
  }
  if (hit < 0) return 0;
  const double *a = s->v + 9 * hit;
  double e1[3], e2[3], n[3];
  for (int k = 0; k < 3; k++) e1[k] = a[3 + k] - a[k], e2[k] = a[6 + k] - a[k];
  nh_vec3_cross(e1, e2, n);
  double len = nh_vec3_norm(n);
  double side = nh_vec3_dot(n, dir) > 0 ? -1.0 : 1.0;
  *tau = best;
  for (int k = 0; k < 3; k++) point[k] = base[k] + best * dir[k], normal[k] = side * n[k] / len;
  return 1;
}

int nh_surface_meets_box(const nh_surface *s, const double lo[3], const double hi[3]) {
  int l[3], h[3];
  for (int k = 0; k < 3; k++) {
    if (hi[k] < s->min[k] || lo[k] > s->max[k]) return 0;
    l[k] = nh_surface_cell_of(s, k, lo[k]), h[k] = nh_surface_cell_of(s, k, hi[k]);
  }
  for (int k = l[2]; k <= h[2]; k++)
    for (int j = l[1]; j <= h[1]; j++)
      for (int i = l[0]; i <= h[0]; i++) {
        size_t cell = (size_t)i + (size_t)s->g[0] * (j + (size_t)s->g[1] * k);
        for (int q = s->xyz_start[cell]; q < s->xyz_start[cell + 1]; q++) {
          double tl[3], th[3];
          nh_tri_box(s->v + 9 * s->xyz_tri[q], tl, th);
          if (tl[0] <= hi[0] && th[0] >= lo[0] && tl[1] <= hi[1] && th[1] >= lo[1] &&
              tl[2] <= hi[2] && th[2] >= lo[2])
            return 1;
        }
      }
  return 0;
}

/* ---- what the geometry must be ---- */

/* The volume inside by the inside test: the lengths of the ray segments the
 * parity rule puts inside, integrated over an n[0] x n[1] midpoint grid of
 * rays along +x over the (y, z) extent. The length is continuous and
 * piecewise linear in (y, z) away from faces parallel to x, so the rule's
 * error is that of the silhouette and fold lines it cuts: O(h) on their
 * length, with signs that cancel when the samples are equidistributed
 * across the lines (the golden-ratio shift below). */
double nh_surface_inside_volume(const nh_surface *s, int ny, int nz) {
  int most = 0;
  for (int c = 0; c < s->yz_g[0] * s->yz_g[1]; c++)
    if (s->yz_start[c + 1] - s->yz_start[c] > most) most = s->yz_start[c + 1] - s->yz_start[c];
  double *hit = nh_calloc((size_t)most + 1, sizeof *hit);
  if (!hit) return NAN;
  double hy = (s->max[1] - s->min[1]) / ny, hz = (s->max[2] - s->min[2]) / nz, volume = 0.0;
  for (int j = 0; j < ny; j++) {
    /* One ray per cell, its column shifted along z by the golden ratio's
     * multiples: no straight edge runs along the samples (a grid of cell
     * centres errs systematically along an edge at 45°). */
    double y = s->min[1] + (j + 0.5) * hy, shift = fmod(0.5 + 0.6180339887498949 * j, 1.0);
    for (int k = 0; k < nz; k++) {
      double z = s->min[2] + (k + shift) * hz;
      size_t c = nh_yz_cell(s, y, z);
      int m = 0;
      for (int q = s->yz_start[c]; q < s->yz_start[c + 1]; q++) {
        double x;
        if (!nh_ray_crossing(s->v + 9 * s->yz_tri[q], y, z, &x)) continue;
        int i = m++; /* insertion: a ray meets a few triangles */
        for (; i > 0 && hit[i - 1] > x; i--) hit[i] = hit[i - 1];
        hit[i] = x;
      }
      for (int i = 1; i < m; i += 2) volume += (hit[i] - hit[i - 1]) * hy * hz;
    }
  }
  free(hit);
  return volume;
}

/* The ray grid for nh_surface_inside_volume: about n rays across the larger
 * of the (y, z) extents (at least 16 across the smaller), fewer if the
 * triangles per (y, z) grid cell would make it cost more than ~2e8 crossing
 * tests. */
static void nh_volume_rays(const nh_surface *s, int n, int *ny, int *nz) {
  int cells = s->yz_g[0] * s->yz_g[1];
  double per_ray = (double)s->yz_start[cells] / cells + 1.0;
  double budget = sqrt(2e8 / per_ray);
  if (n > budget) n = (int)fmax(budget, 64.0);
  double ey = s->max[1] - s->min[1], ez = s->max[2] - s->min[2], e = fmax(ey, ez);
  *ny = nh_clampi((int)ceil(n * ey / e), 16, n);
  *nz = nh_clampi((int)ceil(n * ez / e), 16, n);
}

/* The shape is what the file says: a size between `cell` and 10 m, a
 * volume, and the same volume by the inside test and by the divergence
 * theorem (docs/anatomy.md, "Surface meshes"). */
static int nh_surface_check_geometry(const nh_surface *s, double min_extent) {
  double ext[3], big = 0.0;
  for (int k = 0; k < 3; k++) ext[k] = s->max[k] - s->min[k], big = fmax(big, ext[k]);
  NH_CHECK(big <= 10.0, NH_ERR_INPUT,
           "%s: the surface measures %g x %g x %g m with unit %g m per file unit: larger than "
           "10 m (is `unit` right? 0.001 reads millimetres)",
           s->path, ext[0], ext[1], ext[2], s->unit);
  NH_CHECK(big >= min_extent, NH_ERR_INPUT,
           "%s: the surface measures %g x %g x %g m with unit %g m per file unit: smaller than "
           "%g m (is `unit` right? 1 reads metres, 0.001 millimetres)",
           s->path, ext[0], ext[1], ext[2], s->unit, min_extent);
  double enclosed = nh_surface_signed_volume(s);
  NH_CHECK(fabs(enclosed) > 1e-9 * big * big * big, NH_ERR_INPUT,
           "%s: the surface encloses no volume (%g m^3 in a box of %g x %g x %g m): a flat or "
           "doubled sheet, not the boundary of a solid",
           s->path, fabs(enclosed), ext[0], ext[1], ext[2]);
  /* A coarse ray grid first; a difference is measured again on a finer one
   * before it is believed (the rule's error falls with the spacing, a
   * defect's does not). */
  double inside = 0.0, diff = 0.0;
  for (int pass = 0; pass < 2; pass++) {
    int ny, nz;
    nh_volume_rays(s, pass ? 512 : 256, &ny, &nz);
    inside = nh_surface_inside_volume(s, ny, nz);
    if (isnan(inside)) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", s->path);
    diff = fabs(inside - fabs(enclosed)) / fmax(inside, fabs(enclosed));
    if (diff <= 0.01) return NH_OK;
  }
  return NH_ERROR(NH_ERR_INPUT,
                  "%s: the volume inside the surface (%.6g m^3 by the inside test) and the "
                  "volume it encloses (%.6g m^3 by the divergence theorem) differ by %.3g %% "
                  "(at most 1 %%): %s",
                  s->path, inside, fabs(enclosed), 100 * diff,
                  fabs(enclosed) > inside
                      ? "overlapping shells or a self-intersecting surface count some volume "
                        "twice (merge the shells into one closed surface)"
                      : "shells or triangles facing the wrong way subtract volume (inconsistent "
                        "orientation: make every shell face outwards, a cavity inwards), or "
                        "the surface intersects itself");
}

int nh_surface_read(const char *path, double unit, double min_extent, const nh_read_limits *limits,
                    nh_surface **out) {
  *out = NULL;
  limits = nh_read_limits_or_default(limits);
  size_t len = strlen(path);
  NH_CHECK(len < NH_ANATOMY_PATH_MAX, NH_ERR_INPUT, "%s: path too long", path);
  NH_CHECK(unit > 0 && isfinite(unit), NH_ERR_INPUT, "%s: unit %g is not a positive length", path,
           unit);
  FILE *f;
  double size;
  NH_TRY(nh_file_open_limited(path, "surface", limits, &f, &size));
  nh_stl_stream *r = nh_calloc(1, sizeof *r);
  nh_surface *s = nh_calloc(1, sizeof *s);
  if (!r || !s) {
    fclose(f), free(r), free(s);
    return NH_ERR_MEMORY;
  }
  *r = (nh_stl_stream){.path = path, .f = f, .max_bytes = limits->max_file_bytes, .line = 1};
  memcpy(s->path, path, len + 1);
  s->refs = 1;
  s->unit = unit;
  /* The first buffer holds the 84-byte header of a binary file (a stream
   * shorter than that holds neither form). */
  r->len = fread(r->buf, 1, sizeof r->buf, f);
  const unsigned char *head = r->buf;
  size_t got = r->len;
  uint32_t count = 0;
  if (got >= 84)
    count = (uint32_t)head[80] | (uint32_t)head[81] << 8 | (uint32_t)head[82] << 16 |
            (uint32_t)head[83] << 24;
  int solid = got >= 5 && !memcmp(head, "solid", 5);
  int text = solid && !memchr(head, '\0', got < 84 ? got : 84);
  /* Binary: a regular file whose size is 84 + 50 N for the count N in bytes
   * 80-83 (some begin with "solid" too), or a stream that is not text. */
  int binary = got >= 84 && (size >= 0 ? size == 84 + 50.0 * count : !text);
  int tcap = 0, rc;
  if (binary && count > limits->max_triangles)
    rc = NH_ERROR(NH_ERR_INPUT,
                  "%s: its header announces %u triangles, more than limits.max_triangles = %.0f",
                  path, count, limits->max_triangles);
  else if (binary && count > INT_MAX / 9)
    rc = NH_ERROR(NH_ERR_INPUT, "%s: its header announces %u triangles, more than %d", path, count,
                  INT_MAX / 9);
  else if (binary) {
    unsigned char skip[84];
    nh_stl_read(r, skip, sizeof skip);
    rc = nh_stl_binary(s, r, count, &tcap);
  } else if (text)
    rc = nh_stl_ascii(s, r, limits->max_triangles, &tcap);
  else if (solid)
    rc = NH_ERROR(NH_ERR_INPUT,
                  "%s: starts with 'solid' but holds binary bytes, and its size %.0f is not "
                  "84 + 50 x %u (a truncated binary STL?)",
                  path, size, count);
  else if (got < 84)
    rc = NH_ERROR(NH_ERR_INPUT, "%s: %zu bytes: too short for an STL file", path, got);
  else
    rc = NH_ERROR(NH_ERR_INPUT,
                  "%s: not an ASCII STL (no 'solid') and its size %.0f is not 84 + 50 x %u as a "
                  "binary STL of %u triangles needs (truncated or not STL)",
                  path, size, count, count);
  int read_error = ferror(f);
  fclose(f);
  free(r);
  if (!rc && read_error) rc = NH_ERROR(NH_ERR_INPUT, "%s: read error", path);
  if (!rc && s->n_tri < 4)
    rc = NH_ERROR(NH_ERR_INPUT, "%s: %d triangle%s of non-zero area: not a closed surface", path,
                  s->n_tri, s->n_tri == 1 ? "" : "s");
  if (!rc) rc = nh_surface_check_closed(s);
  if (!rc) rc = nh_surface_index(s);
  if (!rc) rc = nh_surface_check_geometry(s, min_extent);
  if (rc) {
    nh_surface_release(&s);
    return rc;
  }
  *out = s;
  return NH_OK;
}
