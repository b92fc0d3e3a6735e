/* keys.c — the scene key table: the tables of docs/scene.md, compiled in.
 *
 * docs/scene.md is the one home of what each key means, its type, default
 * and unit. The build embeds it (cmake/embed_text.cmake: nh_scene_md) and
 * this file reads its tables, so that
 *  - `needlehex keys` prints every key with its type, default, unit and
 *    notes (as deal.II's print_parameters), from the installed binary alone;
 *  - the reader refuses to accept a key the docs do not describe:
 *    nh_read_keys (read.c) asks nh_scene_keys_check for every key of a
 *    mapping's table (scene_impl.h), before reading it, and an undocumented
 *    one is NH_ERR_INTERNAL naming the key and docs/scene.md. Every scene
 *    the tests read walks the sections it has, so a key added to the
 *    reader without its row fails the suite (tests/docs.py reads scenes
 *    that have every section).
 *
 * Table rows. A row of a table whose header starts `| key |` is
 *   | `KEY`[, `.SIBLING` ...] | type | default | unit | notes |
 * where `.SIBLING` replaces KEY's last component (`tissue.buoyancy.before`,
 * `.after`), and a KEY starting with "…" is a suffix, found under any parent
 * (`….box.min`: the box of every region list, `….point.voxel`: of every
 * point). List indices are N (or K)
 * and material labels LABEL in the docs, numbers in the reader's paths: all
 * compare as N. A
 * documented key documents its parents (tools.N.material.young documents
 * tools.N.material). Cells split at '|' not preceded by '\'. */
#include "scene/scene.h"

#include <ctype.h>
#include <stdio.h>
#include <string.h>

extern const char nh_scene_md[]; /* generated: docs/scene.md */

#define NH_KEYS_CELL 2048

/* The text of a cell (without the outer spaces), and where the row goes on. */
static const char *next_cell(const char *p, const char *end, char *out, size_t size) {
  const char *start = p;
  while (p < end && !(*p == '|' && (p == start || p[-1] != '\\'))) p++;
  const char *a = start, *b = p;
  while (a < b && isspace((unsigned char)*a)) a++;
  while (b > a && isspace((unsigned char)b[-1])) b--;
  size_t n = (size_t)(b - a) < size - 1 ? (size_t)(b - a) : size - 1;
  memcpy(out, a, n);
  out[n] = '\0';
  return p < end ? p + 1 : p;
}

/* Dotted path with every numeric component, N or K, as "N". */
static void normalise(const char *in, char *out, size_t size) {
  size_t o = 0;
  for (const char *p = in; *p && o + 2 < size;) {
    const char *q = p;
    while (*q && *q != '.') q++;
    int numeric = q > p, letter = (q == p + 1 && (*p == 'N' || *p == 'K')) ||
                                  (q == p + 5 && !strncmp(p, "LABEL", 5));
    for (const char *r = p; r < q; r++) numeric &= isdigit((unsigned char)*r) != 0;
    if (numeric || letter) {
      out[o++] = 'N';
    } else {
      for (const char *r = p; r < q && o + 1 < size; r++) out[o++] = *r;
    }
    if (*q == '.' && o + 1 < size) out[o++] = '.';
    p = *q ? q + 1 : q;
  }
  out[o] = '\0';
}

/* Calls visit(key, cells, n_cells, arg) for each documented key (expanded,
 * normalised); stops when visit returns non-zero and returns that. */
typedef int (*nh_key_visit)(const char *key, char cells[][NH_KEYS_CELL], int n, void *arg);

static int each_key(nh_key_visit visit, void *arg) {
  char cells[5][NH_KEYS_CELL];
  int in_table = 0;
  for (const char *line = nh_scene_md; *line;) {
    const char *end = strchr(line, '\n');
    if (!end) end = line + strlen(line);
    if (!strncmp(line, "| key |", 7))
      in_table = 1;
    else if (line[0] != '|')
      in_table = 0;
    if (in_table && !strncmp(line, "| `", 3)) {
      const char *p = line + 1;
      int n = 0;
      while (n < 5 && p < end) p = next_cell(p, end, cells[n++], NH_KEYS_CELL);
      /* The key cell: `A`, `.B`, ... */
      char first[256] = "", key[300], norm[300];
      for (const char *q = cells[0]; (q = strchr(q, '`'));) {
        const char *r = strchr(q + 1, '`');
        if (!r) break;
        char name[256];
        snprintf(name, sizeof name, "%.*s", (int)(r - q - 1), q + 1);
        q = r + 1;
        if (name[0] == '.' && first[0]) {
          const char *dot = strrchr(first, '.');
          snprintf(key, sizeof key, "%.*s%s", dot ? (int)(dot - first) : 0, first, name);
        } else {
          snprintf(first, sizeof first, "%s", name);
          snprintf(key, sizeof key, "%s", name);
        }
        if (!strncmp(key, "\xe2\x80\xa6", 3)) { /* "…": a suffix, under any parent */
          norm[0] = '.';
          normalise(key + 4, norm + 1, sizeof norm - 1);
        } else {
          normalise(key, norm, sizeof norm);
        }
        int rc = visit(norm, cells, n, arg);
        if (rc) return rc;
      }
    }
    line = *end ? end + 1 : end;
  }
  return 0;
}

typedef struct {
  const char *want;
} nh_key_find;

/* Found: want is the key or one of its parents. A key ".S" (written …S)
 * stands for S under any parent: want is found when one of its tails (from a
 * component on) is S or a parent of S. */
static int find_key(const char *key, char cells[][NH_KEYS_CELL], int n, void *arg) {
  (void)cells, (void)n;
  const char *want = ((nh_key_find *)arg)->want;
  if (key[0] != '.') {
    size_t len = strlen(want);
    return !strncmp(key, want, len) && (key[len] == '\0' || key[len] == '.');
  }
  for (const char *tail = want; tail; tail = strchr(tail, '.') ? strchr(tail, '.') + 1 : NULL) {
    size_t len = strlen(tail);
    if (!strncmp(key + 1, tail, len) && (key[1 + len] == '\0' || key[1 + len] == '.')) return 1;
  }
  return 0;
}

int nh_scene_keys_check(const char *path, const char *const *allowed) {
  char full[512], norm[512];
  for (const char *const *a = allowed; *a; a++) {
    snprintf(full, sizeof full, "%s%s%s", path, path[0] ? "." : "", *a);
    normalise(full, norm, sizeof norm);
    nh_key_find f = {norm};
    NH_CHECK(each_key(find_key, &f), NH_ERR_INTERNAL,
             "the scene reader accepts %s but docs/scene.md has no row for it: document it "
             "there (the program's key table is built from it)",
             norm);
  }
  return NH_OK;
}

/* Markdown to plain text: no backticks, "\|" as "|". */
static void plain(FILE *f, const char *s) {
  for (; *s; s++) {
    if (*s == '`') continue;
    if (*s == '\\' && s[1] == '|') continue;
    fputc(*s, f);
  }
}

typedef struct {
  FILE *f;
  char last[NH_KEYS_CELL]; /* the key cell printed last */
} nh_key_printer;

static int print_key(const char *key, char cells[][NH_KEYS_CELL], int n, void *arg) {
  nh_key_printer *pr = arg;
  FILE *f = pr->f;
  (void)key;
  if (!strcmp(pr->last, cells[0])) return 0; /* one block per row, not per expanded key */
  snprintf(pr->last, sizeof pr->last, "%s", cells[0]);
  plain(f, cells[0]);
  fputc('\n', f);
  static const char *const label[] = {"", "type", "default", "unit", ""};
  fputs("   ", f);
  for (int k = 1; k < 4 && k < n; k++) {
    fprintf(f, " %s: ", label[k]);
    plain(f, cells[k][0] ? cells[k] : "-");
    if (k < 3) fputc(';', f);
  }
  fputc('\n', f);
  if (n > 4 && cells[4][0]) {
    fputs("    ", f);
    plain(f, cells[4]);
    fputc('\n', f);
  }
  return 0;
}

void nh_scene_keys_print(void *stdio_file) {
  static nh_key_printer pr; /* 2 kB: off the stack */
  pr.f = stdio_file;
  pr.last[0] = '\0';
  fputs("Scene keys, from docs/scene.md. N is a list index (0-based); a key starting\n"
        "with … is found under several parents (regions, points: see its notes).\n\n",
        pr.f);
  each_key(print_key, &pr);
}
