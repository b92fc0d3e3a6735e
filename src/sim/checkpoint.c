/* checkpoint.c — restart files: the whole state of a run at the end of a
 * step, so that `needlehex run SCENE --restart DIR` continues exactly where
 * it was written (docs/outputs.md, "Checkpoints").
 *
 * Format (little-endian, native doubles; a file from a machine of another
 * byte order is refused, not converted):
 *   "NHCKPT\0\1"   8-byte magic
 *   u32 version    8 (1: no tools, still read; 2 to 7: an older tools' state
 *                  without the channel points' hand-over offsets (2, 3),
 *                  the quasi-static prediction (4), the anchors' errors
 *                  (5, contact/anchor.c) or the shaft points' axial data
 *                  errors (6), or without the goal estimate's state (7),
 *                  refused)
 *   u32 0x01020304 byte-order marker
 *   u64 size       bytes of payload
 *   u64 checksum   FNV-1a 64 of the payload
 *   payload:       u64 hash of the scene as run (its YAML text),
 *                  i32 step, f64 time,
 *                  the mesh: i32 grid[3], f64 origin[3], f64 spacing[3],
 *                    i32 n_nodes, f64 X[3 n], i32 n_cells, i32 cells[8 n],
 *                    i32 level[n], parent[n], first_child[n], n_children[n],
 *                    f64 fill[n],
 *                  f64 u[3 n_nodes], f64 v[3 n_nodes],
 *                  (2) u64 length, the tools' state (contact/state.c),
 *                  (3) u64 length, the factor reuse (solve/reuse.c: whether
 *                    a factor exists, its age and the renewal rule's
 *                    counters, the u and coefficients of the A it factorises),
 *                  (8) u64 length, the goal estimate's carried state
 *                    (adapt/refine.c: the combined dual's weights, the
 *                    memory term's links).
 * Everything else (element data, hanging nodes, the linear system and the
 * reused factor, load vectors, probe cells, the lattice-to-cell map
 * mesh->root, the domain, which the scene gives) is rebuilt from the mesh
 * and that state, deterministically, so the continued run is the
 * uninterrupted one bit for bit (tests/restart.py, tests/restart_tools.py).
 * Two things make that so: the element data are a function of each cell's
 * own corners (fem/tissue.c), not of the order the cells were met in across
 * refinements; and the factor a reused step preconditions with is made
 * again from the same A, not replaced by a new one.
 *
 * The file is written to "<path>.tmp", flushed with fsync and renamed
 * (nh_atomic_open with sync, io/file.c), so a kill at any instant leaves
 * either the previous checkpoint or the new one.
 * Reading checks magic, version, byte order, size, checksum and scene hash:
 * a foreign, truncated, corrupted or other-scene file is an input error
 * (exit 2) naming the file and what is wrong. */
#include "sim/sim_impl.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char nh_magic[8] = {'N', 'H', 'C', 'K', 'P', 'T', 0, 1};

static uint64_t nh_fnv1a(const void *data, size_t n, uint64_t h) {
  const unsigned char *p = data;
  for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

#define NH_FNV_SEED 14695981039346656037ull

static void nh_put_i32(nh_bytes *b, int v) {
  int32_t x = v;
  nh_bytes_put(b, &x, 4);
}

/* ---- the scene as run ---- */

/* Append n bytes of t to the text *out of length *len (capacity *cap). */
static int nh_text_put(char **out, int *len, int *cap, const char *t, size_t n) {
  NH_TRY(nh_grow((void **)out, cap, *len + (int)n + 1, 1));
  memcpy(*out + *len, t, n);
  *len += (int)n;
  (*out)[*len] = '\0';
  return NH_OK;
}

/* The file a scene key names, resolved by the scene reader, for the dotted
 * keys whose value is a file (NULL: not such a key; adapt.template only when
 * it is a path, not a template's name). */
static const char *nh_scene_file_of(const nh_scene *sc, const char *key, const char *value,
                                    char *buf, size_t size) {
  if (!strcmp(key, "output.displacement_field.reference"))
    return sc->output.displacement_field.reference;
  if (!strcmp(key, "output.warped.image")) return sc->output.warped.image;
  size_t k = strlen(key);
  if (k >= 8 && !strcmp(key + k - 8, ".markups")) { /* a point's markups file: the scene's folder */
    size_t v = strlen(value);
    if (v >= 2 && (value[0] == '"' || value[0] == '\'') && value[v - 1] == value[0])
      value++, v -= 2;
    const char *slash = strrchr(sc->file, '/');
    if (value[0] == '/' || !slash)
      snprintf(buf, size, "%.*s", (int)v, value);
    else
      snprintf(buf, size, "%.*s/%.*s", (int)(slash - sc->file), sc->file, (int)v, value);
    return buf;
  }
  if (!strcmp(key, "tissue.domain.mask.file")) return sc->tissue.mask_file;
  if (!strcmp(key, "tissue.domain.surface.file")) return sc->tissue.surface_file;
  if (!strcmp(key, "tissue.labels.file")) return sc->tissue.labels_file;
  size_t n = strlen(value);
  if (!strcmp(key, "adapt.template") &&
      (strchr(value, '/') || (n >= 5 && !strcmp(value + n - 5, ".tmpl"))))
    return sc->adapt.template_path;
  return NULL;
}

int nh_scene_text_absolute(const nh_scene *sc, char **out) {
  const char *y = sc->yaml ? sc->yaml : "";
  char *text = NULL;
  int len = 0, cap = 0, depth = 0, rc = NH_OK;
  struct {
    int indent;
    char key[64];
  } stack[32];
  NH_TRY(nh_text_put(&text, &len, &cap, "", 0));
  while (*y && !rc) {
    size_t n = strcspn(y, "\n");
    const char *line = y, *at = y;
    y += n + (y[n] == '\n');
    /* A block-style line of the scene's own emitter: INDENT [- ]KEY: [VALUE]. */
    while (at < line + n && *at == ' ') at++;
    while (at + 1 < line + n && at[0] == '-' && at[1] == ' ') at += 2; /* sequence item */
    int indent = (int)(at - line);
    const char *colon = at;
    while (colon < line + n && *colon != ':') colon++;
    int is_key = colon < line + n && (colon + 1 == line + n || colon[1] == ' ');
    const char *file = NULL;
    char markups[2 * NH_PATH_MAX];
    if (is_key) {
      while (depth > 0 && stack[depth - 1].indent >= indent) depth--;
      char key[512] = "";
      for (int d = 0; d < depth; d++)
        snprintf(key + strlen(key), sizeof key - strlen(key), "%s.", stack[d].key);
      snprintf(key + strlen(key), sizeof key - strlen(key), "%.*s", (int)(colon - at), at);
      const char *v = colon + 1 + (colon + 1 < line + n);
      char value[NH_PATH_MAX];
      snprintf(value, sizeof value, "%.*s", (int)(line + n - v), v);
      if (colon + 1 >= line + n - 0 && depth < 32) { /* KEY: alone opens a mapping */
        stack[depth].indent = indent;
        snprintf(stack[depth].key, sizeof stack[depth].key, "%.*s", (int)(colon - at), at);
        depth++;
      } else {
        file = nh_scene_file_of(sc, key, value, markups, sizeof markups);
      }
    }
    if (!file || !file[0]) {
      rc = nh_text_put(&text, &len, &cap, line, (size_t)(y - line));
      continue;
    }
    char abs[2 * NH_PATH_MAX];
    const char *path = nh_path_absolute(file, abs, sizeof abs);
    rc = nh_text_put(&text, &len, &cap, line, (size_t)(colon + 1 - line));
    if (!rc) rc = nh_text_put(&text, &len, &cap, " \"", 2);
    for (const char *c = path; *c && !rc; c++) {
      if (*c == '"' || *c == '\\') rc = nh_text_put(&text, &len, &cap, "\\", 1);
      if (!rc) rc = nh_text_put(&text, &len, &cap, c, 1);
    }
    if (!rc) rc = nh_text_put(&text, &len, &cap, "\"\n", 2);
  }
  if (rc) {
    free(text);
    return rc;
  }
  *out = text;
  return NH_OK;
}

/* The hash a checkpoint carries of the scene as run (its absolute form: the
 * same for the scene first run and for DIR/scene.yaml run again). */
static int nh_scene_hash(const nh_scene *sc, uint64_t *hash) {
  char *text;
  NH_TRY(nh_scene_text_absolute(sc, &text));
  *hash = nh_fnv1a(text, strlen(text), NH_FNV_SEED);
  free(text);
  return NH_OK;
}

void nh_checkpoint_path(const char *dir, char *path, size_t size) {
  snprintf(path, size, "%s/checkpoint.nhc", dir);
}

int nh_checkpoint_write(const nh_sim *s) {
  const nh_mesh *m = s->mesh;
  nh_bytes b = {0};
  uint64_t scene_hash;
  NH_TRY(nh_scene_hash(s->scene, &scene_hash));
  nh_bytes_put(&b, &scene_hash, 8);
  nh_put_i32(&b, s->step);
  nh_bytes_put(&b, &s->time, 8);
  for (int k = 0; k < 3; k++) nh_put_i32(&b, m->grid[k]);
  nh_bytes_put(&b, m->origin, 24);
  nh_bytes_put(&b, m->spacing, 24);
  nh_put_i32(&b, m->n_nodes);
  nh_bytes_put(&b, m->X, sizeof(double) * 3 * (size_t)m->n_nodes);
  nh_put_i32(&b, m->n_cells);
  for (int c = 0; c < 8 * m->n_cells; c++) nh_put_i32(&b, m->cells[c]);
  for (int c = 0; c < m->n_cells; c++) nh_put_i32(&b, m->level[c]);
  for (int c = 0; c < m->n_cells; c++) nh_put_i32(&b, m->parent[c]);
  for (int c = 0; c < m->n_cells; c++) nh_put_i32(&b, m->first_child[c]);
  for (int c = 0; c < m->n_cells; c++) nh_put_i32(&b, m->n_children[c]);
  nh_bytes_put(&b, m->fill, sizeof(double) * (size_t)m->n_cells);
  nh_bytes_put(&b, s->u, sizeof(double) * 3 * (size_t)m->n_nodes);
  nh_bytes_put(&b, s->v, sizeof(double) * 3 * (size_t)m->n_nodes);
  unsigned char *tools = NULL;
  size_t tools_size = 0;
  if (s->contact) {
    int rc = nh_contact_state_save(s->contact, &tools, &tools_size);
    if (rc) {
      free(b.data);
      return rc;
    }
  }
  uint64_t tools_len = tools_size;
  nh_bytes_put(&b, &tools_len, 8);
  nh_bytes_put(&b, tools, tools_size);
  free(tools);
  /* the factor reuse (solve/reuse.c), as a length and its bytes */
  size_t at = b.len;
  uint64_t solver_len = 0;
  nh_bytes_put(&b, &solver_len, 8);
  if (s->solver_past) /* a step interrupted inside: the state at its start */
    nh_bytes_put(&b, s->solver_start.data, s->solver_start.len);
  else
    nh_system_reuse_save(s->system, &b);
  if (!b.failed) {
    solver_len = b.len - at - 8;
    memcpy(b.data + at, &solver_len, 8);
  }
  /* the goal estimate's carried state (adapt/refine.c), likewise */
  at = b.len;
  uint64_t adapt_len = 0;
  nh_bytes_put(&b, &adapt_len, 8);
  nh_adapt_state_save(s->adapt, &b);
  if (!b.failed) {
    adapt_len = b.len - at - 8;
    memcpy(b.data + at, &adapt_len, 8);
  }
  if (b.failed) {
    free(b.data);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory writing a checkpoint");
  }
  char path[NH_PATH_MAX + 32];
  nh_checkpoint_path(s->scene->output.dir, path, sizeof path);
  uint32_t version = 8, order = 0x01020304;
  uint64_t size = b.len, sum = nh_fnv1a(b.data, b.len, NH_FNV_SEED);
  nh_atomic_file af;
  int rc = nh_atomic_open(path, "checkpoint", 1, &af);
  if (!rc) {
    FILE *f = af.file;
    int ok = fwrite(nh_magic, 8, 1, f) == 1 && fwrite(&version, 4, 1, f) == 1 &&
             fwrite(&order, 4, 1, f) == 1 && fwrite(&size, 8, 1, f) == 1 &&
             fwrite(&sum, 8, 1, f) == 1 && fwrite(b.data, 1, b.len, f) == b.len;
    rc = nh_atomic_commit(&af, !ok);
  }
  free(b.data);
  return rc;
}

static int nh_get_i32(nh_byte_reader *c) {
  int32_t x;
  nh_bytes_get(c, &x, 4);
  return x;
}

/* A block of the payload: u64 length, then that many bytes into *out (NULL
 * when empty). Nonzero: out of memory; a length past the end is a short read. */
static int nh_get_block(nh_byte_reader *c, unsigned char **out, size_t *size) {
  uint64_t n = 0;
  nh_bytes_get(c, &n, 8);
  if (c->short_read || n == 0) return 0;
  if (n > (uint64_t)(c->end - c->p)) {
    c->short_read = 1;
    return 0;
  }
  if (!(*out = nh_calloc((size_t)n, 1))) return NH_ERR_MEMORY;
  *size = (size_t)n;
  nh_bytes_get(c, *out, (size_t)n);
  return 0;
}

/* The payload of `path` after its 32-byte header (read already from f):
 * exactly `size` bytes, then the end of the file. A regular file's size is
 * compared first; a stream is read in chunks that grow as data arrive, so a
 * header that claims more than the file holds costs what it holds. */
static int nh_checkpoint_payload(const char *path, FILE *f, double file_size, uint64_t size,
                                 unsigned char **out) {
  const nh_read_limits *limits = nh_read_limits_or_default(NULL);
  *out = NULL;
  if (file_size >= 0 && (double)size != file_size - 32)
    return NH_ERROR(NH_ERR_INPUT,
                    "--restart: %s: the checkpoint is corrupted (%s: its header announces %llu "
                    "bytes of payload, the file holds %.0f)",
                    path, (double)size > file_size - 32 ? "truncated" : "trailing bytes",
                    (unsigned long long)size, file_size - 32);
  if ((double)size > limits->max_file_bytes)
    return NH_ERROR(NH_ERR_INPUT,
                    "--restart: %s: the checkpoint is corrupted (implausible payload size %llu, "
                    "more than limits.max_file_bytes = %.0f)",
                    path, (unsigned long long)size, limits->max_file_bytes);
  unsigned char *data = NULL;
  size_t got = 0, cap = 0;
  while (got < size) {
    if (got == cap) {
      cap = cap ? 2 * cap : 1 << 20;
      if (cap > size) cap = (size_t)size;
      int rc = nh_realloc((void **)&data, cap, 1);
      if (rc) {
        free(data);
        return rc;
      }
    }
    size_t n = fread(data + got, 1, cap - got, f);
    if (n == 0) break;
    got += n;
  }
  int extra = got == size && fgetc(f) != EOF;
  if (got != size || extra) {
    free(data);
    return NH_ERROR(NH_ERR_INPUT, "--restart: %s: the checkpoint is corrupted (%s)", path,
                    got != size ? "truncated" : "trailing bytes");
  }
  *out = data ? data : nh_calloc(1, 1);
  return *out ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory reading a checkpoint");
}

static int nh_finite_all(const double *x, size_t n) {
  for (size_t i = 0; i < n; i++)
    if (!isfinite(x[i])) return 0;
  return 1;
}

/* Every value of a checkpoint's mesh and state in range, the refinement tree
 * consistent (a checksum-valid file of a buggy writer must not crash the run
 * it continues): "" if so, else what is wrong, into why. `grid` is the
 * scene's tissue.grid, the lattice its mesh was built on. */
static void nh_checkpoint_check(const nh_mesh *m, const nh_checkpoint *ck, const int grid[3],
                                char *why, size_t n) {
  const size_t nc = (size_t)m->n_cells, nn = (size_t)m->n_nodes;
  why[0] = '\0';
  if (ck->step < 0 || !isfinite(ck->time)) snprintf(why, n, "step %d, time %g", ck->step, ck->time);
  for (int k = 0; k < 3 && !why[0]; k++)
    if (m->grid[k] < 1 || !isfinite(m->origin[k]) || !(m->spacing[k] > 0) ||
        !isfinite(m->spacing[k]))
      snprintf(why, n, "grid axis %d: %d cells from %g, spacing %g", k, m->grid[k], m->origin[k],
               m->spacing[k]);
  /* The lattice is the scene's (what bounds the root index's allocation): an
   * immersed domain keeps only the cells that touch it, so a mesh may have
   * fewer level-0 cells than the lattice (904 of dbs.yaml's 10 x 12 x 8);
   * nh_mesh_index_roots checks that each is a distinct lattice cell. */
  if (!why[0] && (m->grid[0] != grid[0] || m->grid[1] != grid[1] || m->grid[2] != grid[2]))
    snprintf(why, n, "a %d x %d x %d grid, the scene's tissue.grid is %d x %d x %d", m->grid[0],
             m->grid[1], m->grid[2], grid[0], grid[1], grid[2]);
  if (!why[0] && !nh_finite_all(m->X, 3 * nn)) snprintf(why, n, "a node position is not finite");
  /* Every node lies in the grid's box (refinement only adds nodes inside
   * its cells): what lets the lattice index of a root cell be computed. */
  for (size_t i = 0; i < nn && !why[0]; i++)
    for (int k = 0; k < 3 && !why[0]; k++) {
      double lo = m->origin[k], len = m->grid[k] * m->spacing[k], x = m->X[3 * i + k];
      if (!(x >= lo - 1e-6 * len && x <= lo + len * (1 + 1e-6)))
        snprintf(why, n, "node %zu at %g outside the grid's [%g, %g] along axis %d", i, x, lo,
                 lo + len, k);
    }
  if (!why[0] && !(nh_finite_all(ck->u, 3 * nn) && nh_finite_all(ck->v, 3 * nn)))
    snprintf(why, n, "a displacement or velocity is not finite");
  for (size_t i = 0; i < 8 * nc && !why[0]; i++)
    if (m->cells[i] < 0 || (size_t)m->cells[i] >= nn)
      snprintf(why, n, "cell %zu: node %d out of [0, %zu)", i / 8, m->cells[i], nn);
  for (size_t c = 0; c < nc && !why[0]; c++) {
    int p = m->parent[c], f = m->first_child[c], k = m->n_children[c];
    if (!(m->fill[c] >= 0 && m->fill[c] <= 1))
      snprintf(why, n, "cell %zu: fill %g outside [0, 1]", c, m->fill[c]);
    else if (m->level[c] < 0 || m->level[c] > 60 || (p < 0) != (m->level[c] == 0))
      snprintf(why, n, "cell %zu: level %d with parent %d", c, m->level[c], p);
    else if (p < -1 || p >= (int)nc ||
             (p >= 0 && (m->level[p] != m->level[c] - 1 || (size_t)m->first_child[p] > c ||
                         c >= (size_t)m->first_child[p] + (size_t)m->n_children[p])))
      snprintf(why, n, "cell %zu: parent %d does not list it as a child", c, p);
    else if (f < -1 || k < 0 || (f < 0) != (k == 0) || (f >= 0 && (size_t)f + (size_t)k > nc))
      snprintf(why, n, "cell %zu: %d children from %d of %zu cells", c, k, f, nc);
    for (int j = 0; j < k && f >= 0 && !why[0]; j++)
      if ((size_t)m->parent[f + j] != c)
        snprintf(why, n, "cell %zu: its child %d has parent %d", c, f + j, m->parent[f + j]);
  }
}

int nh_checkpoint_read(const char *dir, const nh_scene *scene, nh_checkpoint *ck) {
  memset(ck, 0, sizeof *ck);
  char path[NH_PATH_MAX + 32];
  nh_checkpoint_path(dir, path, sizeof path);
  FILE *f;
  double file_size;
  if (nh_file_open_limited(path, "checkpoint", NULL, &f, &file_size)) {
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", nh_error_message());
    return NH_ERROR(NH_ERR_INPUT, "--restart: %s", msg);
  }
  char magic[8];
  uint32_t version = 0, order = 0;
  uint64_t size = 0, sum = 0;
  int head = fread(magic, 8, 1, f) == 1 && fread(&version, 4, 1, f) == 1 &&
             fread(&order, 4, 1, f) == 1 && fread(&size, 8, 1, f) == 1 && fread(&sum, 8, 1, f) == 1;
  if (!head || memcmp(magic, nh_magic, 8) != 0) {
    fclose(f);
    return NH_ERROR(NH_ERR_INPUT, "--restart: %s: not a needlehex checkpoint", path);
  }
  if ((version != 1 && version != 8) || order != 0x01020304) {
    fclose(f);
    return NH_ERROR(NH_ERR_INPUT,
                    "--restart: %s: checkpoint format %u (byte order %#x) is not the one this "
                    "needlehex reads (1 or 8, %#x)%s",
                    path, version, order, 0x01020304u,
                    version >= 2 && version <= 7
                        ? ": written by an older needlehex, whose state this one does not "
                          "read; run the scene again from the start"
                        : "");
  }
  unsigned char *data;
  int rc = nh_checkpoint_payload(path, f, file_size, size, &data);
  fclose(f);
  NH_TRY(rc);
  if (nh_fnv1a(data, size, NH_FNV_SEED) != sum) {
    free(data);
    return NH_ERROR(NH_ERR_INPUT, "--restart: %s: the checkpoint is corrupted (checksum mismatch)",
                    path);
  }
  nh_byte_reader c = {data, data + size, 0};
  uint64_t scene_hash;
  nh_bytes_get(&c, &scene_hash, 8);
  uint64_t want = 0;
  if ((rc = nh_scene_hash(scene, &want))) {
    free(data);
    return rc;
  }
  if (scene_hash != want) {
    free(data);
    return NH_ERROR(
        NH_ERR_INPUT,
        "--restart: %s: the checkpoint was written for another scene (the scene as run, overrides "
        "included, must be the same: compare %s/scene.yaml)",
        path, dir);
  }
  ck->step = nh_get_i32(&c);
  nh_bytes_get(&c, &ck->time, 8);
  nh_mesh *m = nh_calloc(1, sizeof *m);
  char why[160] = "";
  if (!m) {
    free(data);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory reading a checkpoint");
  }
  for (int k = 0; k < 3; k++) m->grid[k] = nh_get_i32(&c);
  nh_bytes_get(&c, m->origin, 24);
  nh_bytes_get(&c, m->spacing, 24);
  /* Counts against the bytes that follow, before anything is allocated. */
  m->n_nodes = m->cap_nodes = nh_get_i32(&c);
  if (c.short_read || m->n_nodes <= 0 || (size_t)m->n_nodes > size / 24) {
    snprintf(why, sizeof why, "%d nodes in a payload of %llu bytes", m->n_nodes,
             (unsigned long long)size);
    goto malformed;
  }
  m->X = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  if (!m->X) goto oom;
  nh_bytes_get(&c, m->X, sizeof(double) * 3 * (size_t)m->n_nodes);
  m->n_cells = m->cap_cells = nh_get_i32(&c);
  if (c.short_read || m->n_cells <= 0 || (size_t)m->n_cells > size / 32) {
    snprintf(why, sizeof why, "%d cells in a payload of %llu bytes", m->n_cells,
             (unsigned long long)size);
    goto malformed;
  }
  size_t nc = (size_t)m->n_cells;
  m->cells = nh_calloc(8 * nc, sizeof(int));
  m->level = nh_calloc(nc, sizeof(int));
  m->parent = nh_calloc(nc, sizeof(int));
  m->first_child = nh_calloc(nc, sizeof(int));
  m->n_children = nh_calloc(nc, sizeof(int));
  m->fill = nh_calloc(nc, sizeof(double));
  ck->u = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  ck->v = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  if (!m->cells || !m->level || !m->parent || !m->first_child || !m->n_children || !m->fill ||
      !ck->u || !ck->v)
    goto oom;
  for (size_t i = 0; i < 8 * nc; i++) m->cells[i] = nh_get_i32(&c);
  for (size_t i = 0; i < nc; i++) m->level[i] = nh_get_i32(&c);
  for (size_t i = 0; i < nc; i++) m->parent[i] = nh_get_i32(&c);
  for (size_t i = 0; i < nc; i++) m->first_child[i] = nh_get_i32(&c);
  for (size_t i = 0; i < nc; i++) m->n_children[i] = nh_get_i32(&c);
  nh_bytes_get(&c, m->fill, sizeof(double) * nc);
  nh_bytes_get(&c, ck->u, sizeof(double) * 3 * (size_t)m->n_nodes);
  nh_bytes_get(&c, ck->v, sizeof(double) * 3 * (size_t)m->n_nodes);
  /* the tools' state (contact/state.c), the factor reuse (solve/reuse.c) */
  if ((version >= 2 && nh_get_block(&c, &ck->tools, &ck->tools_size)) ||
      (version >= 3 && nh_get_block(&c, &ck->solver, &ck->solver_size)) ||
      (version >= 8 && nh_get_block(&c, &ck->adapt, &ck->adapt_size)))
    goto oom;
  if (c.short_read || c.p != c.end)
    snprintf(why, sizeof why, "the payload %s", c.short_read ? "ends early" : "goes on");
  else
    nh_checkpoint_check(m, ck, scene->tissue.grid, why, sizeof why);
  if (why[0]) goto malformed;
  rc = nh_mesh_update_leaves(m);
  if (!rc) rc = nh_domain_from_scene(scene, &m->domain);
  if (!rc && (rc = nh_mesh_index_roots(m)) == NH_ERR_INPUT) {
    snprintf(why, sizeof why, "%s", nh_error_message());
    goto malformed;
  }
  goto done;
malformed:
  rc = NH_ERROR(NH_ERR_INPUT, "--restart: %s: the checkpoint is malformed (%s)", path, why);
  goto done;
oom:
  rc = NH_ERROR(NH_ERR_MEMORY, "out of memory reading a checkpoint");
done:
  free(data);
  if (rc) {
    nh_mesh_destroy(&m);
    free(ck->u), free(ck->v), free(ck->tools), free(ck->solver), free(ck->adapt);
    ck->u = ck->v = NULL;
    ck->tools = ck->solver = ck->adapt = NULL;
    return rc;
  }
  ck->mesh = m;
  return NH_OK;
}
