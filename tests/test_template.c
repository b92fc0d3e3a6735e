/* test_template — refinement templates: the four shipped templates load with
 * the expected counts and partition the parent cube; every broken file in
 * templates/bad/ is refused with NH_ERR_INPUT and "FILE:LINE: reason".
 *
 * The partition is checked by a path independent of the loader's proof. The
 * shipped templates are tensor-product subdivisions, so every child is an
 * axis-aligned box in the parent's natural coordinates: its volume is the
 * product of its extents (no Jacobian involved), the volumes must sum to 8,
 * and a few thousand pseudo-random points of the cube must each fall inside
 * exactly one child (closed boxes, so points are drawn off the breakpoints).
 * The regular templates hexN must moreover have every child of volume
 * (2/N)³ and every node on the breakpoints -1 + 2i/N.
 *
 * The expected line of each bad file was read off the file by hand (each
 * file says its defect and line in its first comment); the test also fails if
 * templates/bad/ holds a file without a case here. Templates are read from
 * $NH_SOURCE_DIR/templates. Silent on success. */
#include "mesh/mesh.h"

#include "check.h"

#include <dirent.h>
#include <string.h>

static char tmpl_dir[NH_PATH_MAX];

static int box_of_child(const nh_template *t, int c, double lo[3], double hi[3]) {
  for (int k = 0; k < 3; k++) lo[k] = 2, hi[k] = -2;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) {
      double x = t->xi[3 * t->children[8 * c + a] + k];
      lo[k] = fmin(lo[k], x), hi[k] = fmax(hi[k], x);
    }
  /* An axis-aligned box has each of its 8 nodes at a corner of [lo, hi]. */
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) {
      double x = t->xi[3 * t->children[8 * c + a] + k];
      double want = nh_hex_corner[a][k] < 0 ? lo[k] : hi[k];
      if (x != want) return 0;
    }
  return 1;
}

static void check_good(const char *name, int n_nodes, int n_children, int n) {
  char path[NH_PATH_MAX + 32];
  snprintf(path, sizeof path, "%s/%s.tmpl", tmpl_dir, name);
  nh_template *t = NULL;
  int rc = nh_template_load(path, &t);
  CHECK(rc == NH_OK && t, "%s: expected to load, got %d: %s", path, rc, nh_error_message());
  if (!t) return;
  CHECK(!strcmp(t->path, path), "%s: path '%s'", name, t->path);
  CHECK(t->n_nodes == n_nodes, "%s: expected %d nodes, got %d", name, n_nodes, t->n_nodes);
  CHECK(t->n_children == n_children, "%s: expected %d children, got %d", name, n_children,
        t->n_children);
  if (t->n_nodes != n_nodes || t->n_children != n_children) {
    nh_template_destroy(&t);
    return;
  }

  /* Volumes by box extents. */
  double sum = 0;
  double(*lo)[3] = malloc(sizeof *lo * (size_t)t->n_children);
  double(*hi)[3] = malloc(sizeof *hi * (size_t)t->n_children);
  for (int c = 0; c < t->n_children; c++) {
    CHECK(box_of_child(t, c, lo[c], hi[c]), "%s: child %d is not an axis-aligned box in VTK order",
          name, c);
    double v = (hi[c][0] - lo[c][0]) * (hi[c][1] - lo[c][1]) * (hi[c][2] - lo[c][2]);
    CHECK(v > 0, "%s: child %d has volume %g", name, c, v);
    if (n > 0) {
      char what[96];
      snprintf(what, sizeof what, "%s: volume of child %d = (2/%d)^3", name, c, n);
      CHECK_CLOSE(v, 8.0 / (n * n * n), 1e-14, what);
    }
    sum += v;
  }
  char what[96];
  snprintf(what, sizeof what, "%s: sum of the children's volumes", name);
  CHECK_CLOSE(sum, 8.0, 1e-12 * 8, what);

  /* Every point of the cube in exactly one child. */
  int bad_points = 0;
  for (int p = 0; p < 4000; p++) {
    double x[3] = {nh_rand(), nh_rand(), nh_rand()};
    int count = 0;
    for (int c = 0; c < t->n_children; c++)
      count += x[0] >= lo[c][0] && x[0] <= hi[c][0] && x[1] >= lo[c][1] && x[1] <= hi[c][1] &&
               x[2] >= lo[c][2] && x[2] <= hi[c][2];
    if (count != 1 && bad_points++ < 3)
      CHECK(count == 1, "%s: point (%.17g, %.17g, %.17g) lies in %d children, expected 1", name,
            x[0], x[1], x[2], count);
  }
  free(lo);
  free(hi);

  /* Regular templates: nodes exactly on the breakpoints (2i - n) / n. */
  if (n > 0)
    for (int i = 0; i < 3 * t->n_nodes; i++) {
      double s = (t->xi[i] + 1) * n / 2;
      CHECK(fabs(s - round(s)) <= 1e-15 * n, "%s: coordinate %.17g is not a breakpoint of hex%d",
            name, t->xi[i], n);
    }
  nh_template_destroy(&t);
  CHECK(t == NULL, "%s: destroy must set the pointer to NULL", name);
  nh_template_destroy(&t); /* NULL is accepted */
}

/* The bad files: name, expected line, a phrase of the reason. */
static const struct {
  const char *file;
  int line;
  const char *reason;
} bad_cases[] = {
    {"syntax.tmpl", 8, "node 3: '0.5x' is not a number"},
    {"extra_token.tmpl", 13, "child 0: expected 8 node indices, got at least 9"},
    {"truncated.tmpl", 13, "'cells 2' announces 2 cells, but the file ends after 1"},
    {"index_range.tmpl", 14, "child 0: node index 8 is out of range [0, 8)"},
    {"duplicate_node.tmpl", 12, "node 8 repeats node 6 (line 10)"},
    {"no_corner.tmpl", 0, "the parent's corner (1, 1, 1) is not a node"},
    {"inverted.tmpl", 20, "child 1: Jacobian determinant -"},
    {"overlap.tmpl", 24, "child 1 overlaps child 0 (line 23)"},
    {"gap.tmpl", 0, "volumes sum to 4, not 8"},
    {"nonconforming.tmpl", 24, "child 0: its face 1 (nodes 1 4 9 12) lies inside the parent"},
    {"not_tensor.tmpl", 0, "(xi, eta) = (-0.5, 1), which is not a node"},
    {"orphan_node.tmpl", 12, "node 8 is not a corner of any child"},
};

static void check_bad(void) {
  int n = (int)(sizeof bad_cases / sizeof bad_cases[0]);
  for (int i = 0; i < n; i++) {
    char path[NH_PATH_MAX + 64], prefix[NH_PATH_MAX + 96];
    snprintf(path, sizeof path, "%s/bad/%s", tmpl_dir, bad_cases[i].file);
    snprintf(prefix, sizeof prefix, "%s:%d: ", path, bad_cases[i].line);
    nh_template *t = NULL;
    nh_error_clear();
    int rc = nh_template_load(path, &t);
    const char *msg = nh_error_message();
    CHECK(rc == NH_ERR_INPUT && t == NULL, "%s: expected NH_ERR_INPUT (%d), got %d: %s",
          bad_cases[i].file, NH_ERR_INPUT, rc, msg);
    CHECK(!strncmp(msg, prefix, strlen(prefix)),
          "%s: message\n  expected to start with: %s\n  got:                    %s",
          bad_cases[i].file, prefix, msg);
    CHECK(strstr(msg, bad_cases[i].reason), "%s: message\n  expected to contain: %s\n  got: %s",
          bad_cases[i].file, bad_cases[i].reason, msg);
    CHECK(!strchr(msg, '\n'), "%s: the message must be one line: %s", bad_cases[i].file, msg);
    nh_template_destroy(&t);
  }

  /* Every file in templates/bad/ has a case above. */
  char bad_dir[NH_PATH_MAX + 8];
  snprintf(bad_dir, sizeof bad_dir, "%s/bad", tmpl_dir);
  DIR *d = opendir(bad_dir);
  CHECK(d != NULL, "cannot open %s", bad_dir);
  if (!d) return;
  for (struct dirent *e; (e = readdir(d));) {
    size_t len = strlen(e->d_name);
    if (len < 5 || strcmp(e->d_name + len - 5, ".tmpl")) continue;
    int found = 0;
    for (int i = 0; i < n; i++) found |= !strcmp(e->d_name, bad_cases[i].file);
    CHECK(found, "templates/bad/%s has no case in test_template.c", e->d_name);
  }
  closedir(d);

  /* A file that does not exist. */
  char missing[NH_PATH_MAX + 32];
  snprintf(missing, sizeof missing, "%s/no_such.tmpl", tmpl_dir);
  nh_template *t = NULL;
  int rc = nh_template_load(missing, &t);
  char prefix[NH_PATH_MAX + 64];
  snprintf(prefix, sizeof prefix, "%s:0: cannot open", missing);
  CHECK(rc == NH_ERR_INPUT && t == NULL && !strncmp(nh_error_message(), prefix, strlen(prefix)),
        "missing file: rc %d, message '%s'", rc, nh_error_message());
}

int main(void) {
  const char *src = getenv("NH_SOURCE_DIR");
  if (!src || !src[0]) {
    fprintf(stderr, "test_template: set NH_SOURCE_DIR to the source tree\n");
    return 1;
  }
  snprintf(tmpl_dir, sizeof tmpl_dir, "%s/templates", src);
  check_good("hex2", 27, 8, 2);
  check_good("hex3", 64, 27, 3);
  check_good("hex4", 125, 64, 4);
  check_good("graded", 36, 12, 0);
  check_bad();
  TEST_END();
}
