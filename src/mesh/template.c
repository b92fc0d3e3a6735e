/* template.c — refinement templates: reading a .tmpl file and proving that
 * its children partition the parent cell before any mesh uses it.
 *
 * A template (format in templates/README.md) lists nodes in the natural
 * coordinates ξ ∈ [-1, 1]³ of a parent hexahedron and child hexahedra as 8
 * node indices in VTK order. Refinement maps each template node through the
 * parent's trilinear map, so a child's shape in the parent's natural space is
 * the trilinear map
 *     ξ(s) = Σ_a N_a(s) ξ_a,   s ∈ [-1, 1]³,
 * of its 8 template nodes ξ_a. Everything below is computed on that map.
 *
 * The proof, in the order the checks run (the first failure is reported):
 *  1. parse: every line has the expected tokens; coordinates lie in [-1, 1];
 *     no two nodes coincide (within 1e-12 in every coordinate); indices are
 *     in range; no child names a node twice.
 *  2. the 8 corners of the parent are nodes.
 *  3. every child has det ∂ξ/∂s > 0 at its 2×2×2 Gauss points. The same
 *     points integrate the child's volume exactly: det ∂ξ/∂s is of degree 2
 *     in each of s, t, u (each column of the Jacobian is linear in the two
 *     other variables), and the 2-point Gauss rule is exact to degree 3.
 *  4. no child's centre ξ(0) lies strictly inside another child (inverse
 *     map by nh_hex_invert, |s_k| < 1 - 1e-9).
 *  5. the children's volumes sum to 8, the parent's, within 1e-12 relative.
 *  6. every child face (its 4 node indices as a set) is either on the parent
 *     boundary — all 4 nodes on the same plane ξ_k = ±1 — or shared by
 *     exactly one face of one other child. Together with 3 and 5 this proves
 *     a partition: conforming faces make the union of the children a closed
 *     surface over the parent's boundary, so every point of the cube is
 *     covered the same number of times d ≥ 1, and a total volume of 8 forces
 *     d = 1. Check 4 is redundant with it and cheap; it names the culprits.
 *  7. every node is a corner of some child (a stray node would become a
 *     mesh node that no cell owns).
 *  8. on each of the 6 parent faces the nodes lying on it form a tensor
 *     product grid {a_i} × {b_j} (every combination present, ±1 among both
 *     lists). Opposite faces may carry different grids (graded templates).
 *     This is what the hanging-node module relies on: a node on a parent
 *     face is the bilinear interpolation of the face's corners at (a_i, b_j).
 *
 * Messages. Every failure is NH_ERR_INPUT with one message
 *     FILE:LINE: reason
 * where LINE is the line of the offending node or child, or of the section
 * header for a missing line, or 0 for a property of the whole file (a
 * missing corner, the volume sum, a face grid). Lines are counted from 1,
 * comments and blank lines included, so the number is what an editor shows.
 *
 * Costs: O(N²) for duplicate nodes and O(M²) for the centre test, N nodes
 * and M children; templates are small (hex4: 125 nodes, 64 children) and
 * read once per run. */
#include "mesh/mesh.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define NH_TMPL_TOL        1e-12    /* equal coordinates; nodes on a plane */
#define NH_TMPL_MAX_TOKENS 9        /* one more than a cell line holds */
#define NH_TMPL_MAX_COUNT  10000    /* nodes or cells (hex4: 125, 64); the checks are O(N²) */
#define NH_TMPL_MAX_LINE   4096     /* bytes of a line */
#define NH_TMPL_MAX_BYTES  16777216 /* bytes of a file: 16 MB, far above any template */

/* The line-by-line reader of one template file. */
typedef struct {
  const char *path;
  FILE *f;
  char buf[NH_TMPL_MAX_LINE + 1];
  double bytes;                      /* bytes read so far */
  int line;                          /* number of the line last read */
  int read_errno;                    /* errno of a failed read, 0 at a clean end */
  char why[96];                      /* a line that no template has: too long, binary, ... */
  int n_tok;                         /* tokens on it (capped at NH_TMPL_MAX_TOKENS) */
  char *tok[NH_TMPL_MAX_TOKENS + 1]; /* pointers into buf */
} nh_tmpl_reader;

/* What a loaded template knows beyond nh_template, for messages. */
typedef struct {
  const char *path;
  int *node_line;  /* line of each node */
  int *child_line; /* line of each child */
} nh_tmpl_lines;

/* Record "PATH:LINE: reason" and return NH_ERR_INPUT. */
static int bad(const char *path, int line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static int bad(const char *path, int line, const char *fmt, ...) {
  char msg[1024];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  return NH_ERROR(NH_ERR_INPUT, "%s:%d: %s", path, line, msg);
}

/* Read one line into r->buf, at most NH_TMPL_MAX_LINE bytes of text.
 * Returns its length, -1 at the end of the file or on a line that no
 * template has (then r->why says what). */
static int read_line(nh_tmpl_reader *r) {
  int n = 0, c;
  while ((c = getc(r->f)) != EOF) {
    if (++r->bytes > NH_TMPL_MAX_BYTES) {
      snprintf(r->why, sizeof r->why, "the file goes on past %d bytes: not a template",
               NH_TMPL_MAX_BYTES);
      return -1;
    }
    if (c == '\n') break;
    if (c == 0 || (c < 0x20 && !strchr("\t\r\v\f", c)) || c == 0x7f) {
      snprintf(r->why, sizeof r->why, "byte 0x%02x: a template is a text file", (unsigned)c);
      return -1;
    }
    if (n == NH_TMPL_MAX_LINE) {
      snprintf(r->why, sizeof r->why, "a line longer than %d bytes", NH_TMPL_MAX_LINE);
      return -1;
    }
    r->buf[n++] = (char)c;
  }
  r->buf[n] = '\0';
  if (c == EOF && ferror(r->f)) r->read_errno = errno ? errno : EIO;
  return c == EOF && n == 0 ? -1 : n;
}

/* Read the next line that holds tokens once its comment is cut off.
 * Returns 1 with the tokens in r->tok, 0 at the end of the file (or a line
 * no template has: r->why). */
static int next_line(nh_tmpl_reader *r) {
  for (;;) {
    errno = 0;
    if (r->why[0]) return 0;
    if (read_line(r) < 0) {
      r->line += r->why[0] != 0; /* the bad line's number */
      return 0;
    }
    r->line++;
    char *hash = strchr(r->buf, '#');
    if (hash) *hash = '\0';
    r->n_tok = 0;
    char *save = NULL;
    for (char *t = strtok_r(r->buf, " \t\r\n\v\f", &save); t && r->n_tok < NH_TMPL_MAX_TOKENS;
         t = strtok_r(NULL, " \t\r\n\v\f", &save))
      r->tok[r->n_tok++] = t;
    if (r->n_tok > 0) return 1;
  }
}

/* A decimal integer token, entirely consumed. */
static int parse_int(const char *text, long *out) {
  char *end = NULL;
  errno = 0;
  long v = strtol(text, &end, 10);
  if (end == text || *end || errno) return 0;
  *out = v;
  return 1;
}

/* A finite number token, entirely consumed. */
static int parse_number(const char *text, double *out) {
  char *end = NULL;
  double v = strtod(text, &end);
  if (end == text || *end || !isfinite(v)) return 0;
  *out = v;
  return 1;
}

/* A header line "KEYWORD VALUE": the name for `template`, a count otherwise. */
static int read_header(nh_tmpl_reader *r, const char *keyword, char *name, size_t name_cap,
                       int *count) {
  const char *what = count ? "N" : "NAME";
  if (!next_line(r))
    return bad(r->path, r->line, "expected '%s %s', but the file ends here", keyword, what);
  if (strcmp(r->tok[0], keyword) != 0)
    return bad(r->path, r->line, "expected '%s %s', got '%s'", keyword, what, r->tok[0]);
  if (r->n_tok != 2)
    return bad(r->path, r->line, "expected '%s %s': one value after '%s', got %d", keyword, what,
               keyword, r->n_tok - 1);
  if (name) {
    snprintf(name, name_cap, "%s", r->tok[1]);
    return NH_OK;
  }
  long n = 0;
  if (!parse_int(r->tok[1], &n) || n < 1 || n > NH_TMPL_MAX_COUNT)
    return bad(r->path, r->line, "%s: '%s' is not a count between 1 and %d", keyword, r->tok[1],
               NH_TMPL_MAX_COUNT);
  *count = (int)n;
  return NH_OK;
}

static int read_nodes(nh_tmpl_reader *r, nh_template *t, nh_tmpl_lines *lines) {
  NH_TRY(read_header(r, "nodes", NULL, 0, &t->n_nodes));
  int header = r->line;
  t->xi = nh_calloc((size_t)t->n_nodes * 3, sizeof *t->xi);
  lines->node_line = nh_calloc((size_t)t->n_nodes, sizeof *lines->node_line);
  if (!t->xi || !lines->node_line) return NH_ERR_MEMORY;
  for (int i = 0; i < t->n_nodes; i++) {
    if (!next_line(r))
      return bad(r->path, header, "'nodes %d' announces %d nodes, but the file ends after %d",
                 t->n_nodes, t->n_nodes, i);
    lines->node_line[i] = r->line;
    if (r->n_tok != 3)
      return bad(r->path, r->line, "node %d: expected 3 coordinates, got %s%d value%s", i,
                 r->n_tok == NH_TMPL_MAX_TOKENS ? "at least " : "", r->n_tok,
                 r->n_tok == 1 ? "" : "s");
    double *x = &t->xi[3 * i];
    for (int k = 0; k < 3; k++) {
      if (!parse_number(r->tok[k], &x[k]))
        return bad(r->path, r->line, "node %d: '%s' is not a number", i, r->tok[k]);
      if (fabs(x[k]) > 1)
        return bad(r->path, r->line, "node %d: coordinate %.17g lies outside the parent's [-1, 1]",
                   i, x[k]);
    }
    for (int j = 0; j < i; j++) {
      const double *y = &t->xi[3 * j];
      if (fabs(x[0] - y[0]) <= NH_TMPL_TOL && fabs(x[1] - y[1]) <= NH_TMPL_TOL &&
          fabs(x[2] - y[2]) <= NH_TMPL_TOL)
        return bad(r->path, r->line, "node %d repeats node %d (line %d) at (%g, %g, %g)", i, j,
                   lines->node_line[j], x[0], x[1], x[2]);
    }
  }
  return NH_OK;
}

static int read_cells(nh_tmpl_reader *r, nh_template *t, nh_tmpl_lines *lines) {
  NH_TRY(read_header(r, "cells", NULL, 0, &t->n_children));
  int header = r->line;
  t->children = nh_calloc((size_t)t->n_children * 8, sizeof *t->children);
  lines->child_line = nh_calloc((size_t)t->n_children, sizeof *lines->child_line);
  if (!t->children || !lines->child_line) return NH_ERR_MEMORY;
  for (int c = 0; c < t->n_children; c++) {
    if (!next_line(r))
      return bad(r->path, header, "'cells %d' announces %d cells, but the file ends after %d",
                 t->n_children, t->n_children, c);
    lines->child_line[c] = r->line;
    if (r->n_tok != 8)
      return bad(r->path, r->line, "child %d: expected 8 node indices, got %s%d value%s", c,
                 r->n_tok == NH_TMPL_MAX_TOKENS ? "at least " : "", r->n_tok,
                 r->n_tok == 1 ? "" : "s");
    int *v = &t->children[8 * c];
    for (int a = 0; a < 8; a++) {
      long n = 0;
      if (!parse_int(r->tok[a], &n))
        return bad(r->path, r->line, "child %d: '%s' is not a node index", c, r->tok[a]);
      if (n < 0 || n >= t->n_nodes)
        return bad(r->path, r->line, "child %d: node index %ld is out of range [0, %d)", c, n,
                   t->n_nodes);
      v[a] = (int)n;
      for (int b = 0; b < a; b++)
        if (v[b] == v[a])
          return bad(r->path, r->line, "child %d names node %d twice (positions %d and %d)", c,
                     v[a], b, a);
    }
  }
  if (next_line(r))
    return bad(r->path, r->line, "unexpected '%s' after the %d cells announced at line %d",
               r->tok[0], t->n_children, header);
  return NH_OK;
}

static int parse(const char *path, nh_template *t, nh_tmpl_lines *lines) {
  nh_tmpl_reader *r = nh_calloc(1, sizeof *r);
  if (!r) return NH_ERR_MEMORY;
  r->path = path;
  r->f = fopen(path, "r");
  if (!r->f) {
    int err = errno;
    free(r);
    return bad(path, 0, "cannot open the template: %s", strerror(err));
  }
  struct stat st;
  int rc = NH_OK;
  if (fstat(fileno(r->f), &st) == 0 && S_ISREG(st.st_mode) && st.st_size > NH_TMPL_MAX_BYTES)
    rc = bad(path, 0, "%lld bytes: a template has at most %d", (long long)st.st_size,
             NH_TMPL_MAX_BYTES);
  char name[NH_NAME_MAX];
  if (!rc) rc = read_header(r, "template", name, sizeof name, NULL);
  if (!rc) rc = read_nodes(r, t, lines);
  if (!rc) rc = read_cells(r, t, lines);
  /* A read error (a directory, an I/O failure) or a line no template has
   * looks like an early end to the readers above: replace their message. */
  if (r->read_errno)
    rc = bad(path, r->line, "cannot read the template: %s", strerror(r->read_errno));
  else if (r->why[0])
    rc = bad(path, r->line, "%s", r->why);
  fclose(r->f);
  free(r);
  return rc;
}

/* ---- geometry of a child in the parent's natural space ---- */

static void child_coords(const nh_template *t, int c, double Xe[24]) {
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) Xe[3 * a + k] = t->xi[3 * t->children[8 * c + a] + k];
}

static double child_det(const double Xe[24], const double s[3]) {
  double dN[8][3], J[9] = {0};
  nh_hex_dshape(s, dN);
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) J[3 * i + j] += Xe[3 * a + i] * dN[a][j];
  return nh_mat3_det(J);
}

static int find_node(const nh_template *t, const double x[3]) {
  for (int i = 0; i < t->n_nodes; i++) {
    const double *y = &t->xi[3 * i];
    if (fabs(x[0] - y[0]) <= NH_TMPL_TOL && fabs(x[1] - y[1]) <= NH_TMPL_TOL &&
        fabs(x[2] - y[2]) <= NH_TMPL_TOL)
      return i;
  }
  return -1;
}

static int check_corners(const nh_template *t, const nh_tmpl_lines *l) {
  for (int a = 0; a < 8; a++)
    if (find_node(t, nh_hex_corner[a]) < 0)
      return bad(l->path, 0, "the parent's corner (%g, %g, %g) is not a node", nh_hex_corner[a][0],
                 nh_hex_corner[a][1], nh_hex_corner[a][2]);
  return NH_OK;
}

/* Check 3 and the volumes for check 5. */
static int check_jacobians(const nh_template *t, const nh_tmpl_lines *l, double *volume) {
  const double g = 1.0 / sqrt(3.0);
  *volume = 0;
  for (int c = 0; c < t->n_children; c++) {
    double Xe[24];
    child_coords(t, c, Xe);
    for (int q = 0; q < 8; q++) {
      double s[3] = {g * nh_hex_corner[q][0], g * nh_hex_corner[q][1], g * nh_hex_corner[q][2]};
      double det = child_det(Xe, s);
      /* A child of a sensible template has det >= (1/100)³; 1e-12 only
       * refuses the degenerate and the inverted. */
      if (!(det > NH_TMPL_TOL))
        return bad(l->path, l->child_line[c],
                   "child %d: Jacobian determinant %g at Gauss point (%+.3f, %+.3f, %+.3f) is "
                   "not positive (an inverted or degenerate child; nodes must follow the VTK "
                   "hexahedron order)",
                   c, det, s[0], s[1], s[2]);
      *volume += det; /* Gauss weights are 1 */
    }
  }
  return NH_OK;
}

/* True if x lies strictly inside child c. */
static int strictly_inside(const nh_template *t, int c, const double x[3]) {
  double Xe[24], s[3], lo[3] = {2, 2, 2}, hi[3] = {-2, -2, -2};
  child_coords(t, c, Xe);
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) {
      lo[k] = fmin(lo[k], Xe[3 * a + k]);
      hi[k] = fmax(hi[k], Xe[3 * a + k]);
    }
  for (int k = 0; k < 3; k++)
    if (x[k] <= lo[k] || x[k] >= hi[k]) return 0; /* the trilinear cell lies in its box */
  if (nh_hex_invert(Xe, x, s) != NH_OK) return 0;
  return fabs(s[0]) < 1 - 1e-9 && fabs(s[1]) < 1 - 1e-9 && fabs(s[2]) < 1 - 1e-9;
}

static void child_centre(const nh_template *t, int c, double x[3]) {
  double Xe[24];
  child_coords(t, c, Xe);
  x[0] = x[1] = x[2] = 0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) x[k] += 0.125 * Xe[3 * a + k];
}

/* Check 4; reported at the later child of the pair. */
static int check_centres(const nh_template *t, const nh_tmpl_lines *l) {
  for (int j = 1; j < t->n_children; j++) {
    double xj[3];
    child_centre(t, j, xj);
    for (int i = 0; i < j; i++) {
      double xi[3];
      child_centre(t, i, xi);
      if (strictly_inside(t, i, xj) || strictly_inside(t, j, xi))
        return bad(l->path, l->child_line[j],
                   "child %d overlaps child %d (line %d): the centre of one lies inside the other",
                   j, i, l->child_line[i]);
    }
  }
  return NH_OK;
}

typedef struct {
  int key[4]; /* node indices, sorted */
  int child, face;
} nh_tmpl_face;

static int compare_faces(const void *pa, const void *pb) {
  const nh_tmpl_face *a = pa, *b = pb;
  for (int i = 0; i < 4; i++)
    if (a->key[i] != b->key[i]) return a->key[i] < b->key[i] ? -1 : 1;
  return a->child != b->child ? (a->child < b->child ? -1 : 1)
                              : (a->face > b->face) - (a->face < b->face);
}

/* True if the 4 nodes of the face all lie on one plane ξ_k = ±1. */
static int on_parent_boundary(const nh_template *t, const int key[4]) {
  for (int k = 0; k < 3; k++)
    for (int side = -1; side <= 1; side += 2) {
      int all = 1;
      for (int i = 0; i < 4; i++) all &= fabs(t->xi[3 * key[i] + k] - side) <= NH_TMPL_TOL;
      if (all) return 1;
    }
  return 0;
}

/* Check 6. */
static int check_faces(const nh_template *t, const nh_tmpl_lines *l) {
  int n = 6 * t->n_children, rc = NH_OK;
  nh_tmpl_face *f = nh_calloc((size_t)n, sizeof *f);
  if (!f) return NH_ERR_MEMORY;
  for (int c = 0; c < t->n_children; c++)
    for (int q = 0; q < 6; q++) {
      nh_tmpl_face *e = &f[6 * c + q];
      e->child = c, e->face = q;
      for (int i = 0; i < 4; i++) e->key[i] = t->children[8 * c + nh_hex_face[q][i]];
      for (int i = 1; i < 4; i++) /* insertion sort of 4 */
        for (int j = i; j > 0 && e->key[j - 1] > e->key[j]; j--) {
          int tmp = e->key[j];
          e->key[j] = e->key[j - 1], e->key[j - 1] = tmp;
        }
    }
  qsort(f, (size_t)n, sizeof *f, compare_faces);
  for (int s = 0; s < n && !rc;) {
    int e = s + 1;
    while (e < n && !memcmp(f[e].key, f[s].key, sizeof f[s].key)) e++;
    const nh_tmpl_face *a = &f[s], *last = &f[e - 1];
    int boundary = on_parent_boundary(t, a->key);
    if (e - s == 1 && !boundary)
      rc = bad(l->path, l->child_line[a->child],
               "child %d: its face %d (nodes %d %d %d %d) lies inside the parent but belongs to "
               "no other child: the children do not conform (or one is missing)",
               a->child, a->face, a->key[0], a->key[1], a->key[2], a->key[3]);
    else if (e - s == 2 && boundary)
      rc = bad(l->path, l->child_line[last->child],
               "child %d overlaps child %d (line %d): both have the face (nodes %d %d %d %d) on "
               "the parent's boundary",
               last->child, a->child, l->child_line[a->child], a->key[0], a->key[1], a->key[2],
               a->key[3]);
    else if (e - s > 2)
      rc = bad(l->path, l->child_line[last->child],
               "child %d overlaps: the face (nodes %d %d %d %d) belongs to %d children "
               "(%d, %d, ...), not 2",
               last->child, a->key[0], a->key[1], a->key[2], a->key[3], e - s, a->child,
               f[s + 1].child);
    s = e;
  }
  free(f);
  return rc;
}

/* Check 7. */
static int check_used(const nh_template *t, const nh_tmpl_lines *l) {
  unsigned char *used = nh_calloc((size_t)t->n_nodes, 1);
  if (!used) return NH_ERR_MEMORY;
  for (int i = 0; i < 8 * t->n_children; i++) used[t->children[i]] = 1;
  int stray = -1;
  for (int i = 0; i < t->n_nodes && stray < 0; i++)
    if (!used[i]) stray = i;
  free(used);
  if (stray >= 0)
    return bad(l->path, l->node_line[stray], "node %d is not a corner of any child", stray);
  return NH_OK;
}

static int compare_doubles(const void *pa, const void *pb) {
  double a = *(const double *)pa, b = *(const double *)pb;
  return (a > b) - (a < b);
}

/* Sorted distinct values (merged within the tolerance) of v[0..n), in place;
 * returns how many. */
static int distinct(double *v, int n) {
  qsort(v, (size_t)n, sizeof *v, compare_doubles);
  int m = 0;
  for (int i = 0; i < n; i++)
    if (m == 0 || v[i] - v[m - 1] > NH_TMPL_TOL) v[m++] = v[i];
  return m;
}

/* Check 8. */
static int check_face_grids(const nh_template *t, const nh_tmpl_lines *l) {
  static const char *const axis[3] = {"xi", "eta", "zeta"};
  double *a = nh_calloc((size_t)t->n_nodes, sizeof *a);
  double *b = nh_calloc((size_t)t->n_nodes, sizeof *b);
  int rc = NH_OK;
  if (!a || !b) rc = NH_ERR_MEMORY;
  for (int k = 0; k < 3 && !rc; k++)
    for (int side = -1; side <= 1 && !rc; side += 2) {
      int ka = k == 0 ? 1 : 0, kb = k == 2 ? 1 : 2, n = 0;
      for (int i = 0; i < t->n_nodes; i++)
        if (fabs(t->xi[3 * i + k] - side) <= NH_TMPL_TOL) {
          a[n] = t->xi[3 * i + ka], b[n] = t->xi[3 * i + kb];
          n++;
        }
      int na = distinct(a, n), nb = distinct(b, n);
      if (na < 2 || nb < 2 || fabs(a[0] + 1) > NH_TMPL_TOL || fabs(a[na - 1] - 1) > NH_TMPL_TOL ||
          fabs(b[0] + 1) > NH_TMPL_TOL || fabs(b[nb - 1] - 1) > NH_TMPL_TOL) {
        rc = bad(l->path, 0,
                 "the nodes on the parent face %s = %+d do not include the face's 4 corners",
                 axis[k], side);
        break;
      }
      for (int i = 0; i < na && !rc; i++)
        for (int j = 0; j < nb && !rc; j++) {
          double x[3];
          x[k] = side, x[ka] = a[i], x[kb] = b[j];
          if (find_node(t, x) < 0)
            rc = bad(l->path, 0,
                     "the nodes on the parent face %s = %+d are not a tensor-product grid: their "
                     "%s values (%d distinct) and %s values (%d distinct) combine to (%s, %s) = "
                     "(%g, %g), which is not a node",
                     axis[k], side, axis[ka], na, axis[kb], nb, axis[ka], axis[kb], a[i], b[j]);
        }
    }
  free(a);
  free(b);
  return rc;
}

static int validate(const nh_template *t, const nh_tmpl_lines *l) {
  double volume = 0;
  NH_TRY(check_corners(t, l));
  NH_TRY(check_jacobians(t, l, &volume));
  NH_TRY(check_centres(t, l));
  if (!(fabs(volume - 8) <= 1e-12 * 8))
    return bad(l->path, 0,
               "the children's volumes sum to %.15g, not 8 (the parent's): the children %s", volume,
               volume < 8 ? "leave a gap" : "overlap");
  NH_TRY(check_faces(t, l));
  NH_TRY(check_used(t, l));
  return check_face_grids(t, l);
}

int nh_template_load(const char *path, nh_template **out) {
  *out = NULL;
  if (!path) return NH_ERROR(NH_ERR_INPUT, "no template file given");
  if (strlen(path) >= NH_PATH_MAX)
    return NH_ERROR(NH_ERR_INPUT, "%.64s...: the template path is longer than %d characters", path,
                    NH_PATH_MAX - 1);
  nh_template *t = nh_calloc(1, sizeof *t);
  if (!t) return NH_ERR_MEMORY;
  memcpy(t->path, path, strlen(path) + 1);
  nh_tmpl_lines lines = {.path = path};
  int rc = parse(path, t, &lines);
  if (!rc) rc = validate(t, &lines);
  free(lines.node_line);
  free(lines.child_line);
  if (rc) {
    nh_template_destroy(&t);
    return rc;
  }
  *out = t;
  return NH_OK;
}

void nh_template_destroy(nh_template **tmpl) {
  if (!tmpl || !*tmpl) return;
  free((*tmpl)->xi);
  free((*tmpl)->children);
  free(*tmpl);
  *tmpl = NULL;
}

double nh_template_child_ratio(const nh_template *t) {
  double ratio = 1.0;
  for (int c = 0; c < t->n_children; c++)
    for (int k = 0; k < 3; k++) {
      double lo = INFINITY, hi = -INFINITY;
      for (int a = 0; a < 8; a++) {
        double x = t->xi[3 * t->children[8 * c + a] + k];
        lo = fmin(lo, x), hi = fmax(hi, x);
      }
      ratio = fmin(ratio, 0.5 * (hi - lo));
    }
  return ratio;
}
