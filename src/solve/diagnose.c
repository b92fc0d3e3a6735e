/* diagnose.c — where and why a solve of the tissue's system failed
 * (docs/reliability.md, "Failures diagnosed"): the text a factorisation
 * that is not positive definite (cholesky.c) and a static Newton that makes
 * no progress (integrate.c) add to their message, so a failed run names the
 * node, the cells around it and the likely cause instead of iterating.
 *
 * Three facts are gathered, each in a few sparse products or a scan of the
 * leaves (milliseconds next to the factorisation that failed):
 *
 * - The rigid modes. With x₀ the tissue's current centroid, the six rigid
 *   fields r = e_k (translations) and r = e_k × (x − x₀) (rotations) are
 *   restricted to the unknowns (r at the free DOFs: the hanging nodes'
 *   interpolation reproduces a linear field, a fixed DOF is 0 in it) and
 *   their Rayleigh quotient ρ = rᵀAr / (rᵀr d̄), d̄ the mean diagonal of A,
 *   compared, each rotation about its best centre (plus the translation
 *   that minimises its energy, −(TᵀAT)⁻¹TᵀAr with T the translations), so
 *   that a support off the centroid is measured by what it holds: an
 *   element's own deformation has ρ of order 1, the softest
 *   deformation of a body of N cells across about 1/N². A rigid mode with
 *   ρ ≤ NH_DIAG_FREE is not held at all (only round-off: A is singular),
 *   with ρ ≤ NH_DIAG_WEAK it is held by a support far softer than the body
 *   (a tie region small for its load, or a support on one side only).
 * - The cells around the node the failure points at (the factorisation's
 *   column, or the largest residual entry): each leaf with that corner, its
 *   tissue fraction (the cut-cell data's, else the fill fraction), which
 *   fixed region ties it, and whether it is inverted where it holds tissue
 *   (nh_tissue_cell_inverted, the check of sim/guard.c: a cut cell's
 *   fictitious part may fold, a cell without tissue is never inverted); with the
 *   step's constraint rows, those at the node (skull, each tool).
 * - The smallest tissue fraction of all leaves, and its cell.
 *
 * The likely cause is the first that applies of: a rigid mode not held; a
 * rigid mode weakly held, in stiffness (ρ ≤ NH_DIAG_WEAK) or for the load (the
 * first linearised step turns the body by more than NH_DIAG_TURN rad: the
 * load's moment rᵀb over rᵀAr; whose huge steps then invert cells: the cause,
 * not the symptom); an inverted cell at the node; a cut cell at the node
 * with tissue fraction ≤ NH_DIAG_SMALL_FILL; otherwise the message says so. */
#include "solve/system_impl.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#define NH_DIAG_FREE 1e-10
#define NH_DIAG_WEAK 1e-6
/* A rotation the first linearised step makes above this (rad) is beyond
 * what a Newton from rest on the corotational tangent comes back from: a
 * rotation by θ moves a point at distance d by 2 d sin(θ/2), not θ d. */
#define NH_DIAG_TURN       1.0
#define NH_DIAG_SMALL_FILL 0.1
#define NH_DIAG_CELLS      4 /* cells listed around the node */

/* printf to the end of the text in buf. */
static void nh_diag_add(char *buf, size_t size, const char *fmt, ...) {
  size_t len = strlen(buf);
  if (len + 1 >= size) return;
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(buf + len, size - len, fmt, ap);
  va_end(ap);
}

static double nh_diag_fraction(const nh_system *s, int c) {
  const nh_tissue_cut *cut = nh_tissue_cell_cut(s->tissue, c);
  return cut ? cut->fraction : s->tissue->mesh->fill[c];
}

/* The fixed region (tissue.fixed index) that ties cell c, or -1. */
static int nh_diag_tied(const nh_system *s, int c) {
  const nh_tissue *t = s->tissue;
  return t->cell_tie && c < t->cap_cell_tie && t->cell_tie[c] >= 0 ? t->cell_tie_region[c] : -1;
}

/* The fixed regions that tie cells, each with its count of leaves: "; the
 * fixed regions tie tissue.fixed[0]: 1 leaf cell, tissue.fixed[2]: 14 leaf
 * cells"; nothing without ties. */
static void nh_diag_ties(const nh_system *s, char *buf, size_t size) {
  enum { REGIONS = 16 };
  const nh_mesh *m = s->tissue->mesh;
  int count[REGIONS] = {0}, any = 0, more = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    const int r = nh_diag_tied(s, m->leaves[l]);
    if (r >= 0 && r < REGIONS) count[r]++, any = 1;
    more |= r >= REGIONS;
  }
  if (!any) return;
  nh_diag_add(buf, size, "; the fixed regions tie");
  for (int r = 0, first = 1; r < REGIONS; r++) {
    if (!count[r]) continue;
    nh_diag_add(buf, size, "%s tissue.fixed[%d]: %d leaf cell%s", first ? "" : ",", r, count[r],
                count[r] == 1 ? "" : "s");
    first = 0;
  }
  if (more) nh_diag_add(buf, size, ", and further regions");
}

/* The constraint rows whose tissue part has `node`: how many, how many of
 * them press or stick (λ ≠ 0 in the last solve), of the skull (no tool
 * part) and of each tool. */
static void nh_diag_rows(const nh_rows *rows, int node, char *buf, size_t size) {
  enum { TOOLS = 8 };
  if (!rows) return;
  int skull = 0, skull_on = 0, tool[TOOLS] = {0}, tool_on[TOOLS] = {0}, other = 0;
  for (int i = 0; i < rows->m; i++) {
    int has = 0;
    for (int k = rows->start[i]; k < rows->start[i + 1] && !has; k++)
      has = rows->node[k] == node && rows->N[k] != 0.0;
    if (!has) continue;
    const int on = rows->lambda[i] != 0.0, k = rows->tool[i];
    if (k < 0)
      skull++, skull_on += on;
    else if (k < TOOLS)
      tool[k]++, tool_on[k] += on;
    else
      other++;
  }
  nh_diag_add(buf, size, "; constraint rows at that node:");
  if (skull + other == 0) {
    int any = 0;
    for (int k = 0; k < TOOLS; k++) any |= tool[k];
    if (!any) {
      nh_diag_add(buf, size, " none (%d in all)", rows->m);
      return;
    }
  }
  if (skull) nh_diag_add(buf, size, " %d of the skull (%d pressing)", skull, skull_on);
  for (int k = 0; k < TOOLS; k++)
    if (tool[k]) nh_diag_add(buf, size, " %d of tool %d (%d with a force)", tool[k], k, tool_on[k]);
  if (other) nh_diag_add(buf, size, " %d of further tools", other);
  nh_diag_add(buf, size, " (%d rows in all)", rows->m);
}

nh_rigid nh_system_rigid(nh_system *s, const double *u, const double *b) {
  nh_rigid out = {.mode = -1, .rho = INFINITY, .loose = 0, .turn_mode = -1, .turn = 0.0};
  const int n = s->n_free, nn = s->n_nodes;
  const int *Ap = s->A->p, *Ai = s->A->i;
  const double *Ax = s->A->x, *X = s->tissue->mesh->X;
  double *r = s->pcg[0], *Ar = s->pcg[1];
  if (n == 0) return out;
  double diag = 0.0, c[3] = {0, 0, 0}, Gtt[9] = {0}, Gti[9], count[3] = {0, 0, 0};
  for (int j = 0; j < n; j++)
    for (int p = Ap[j]; p < Ap[j + 1]; p++)
      if (Ai[p] == j) diag += fabs(Ax[p]);
  diag = fmax(diag / n, 1e-300);
  for (int v = 0; v < nn; v++)
    for (int i = 0; i < 3; i++) c[i] += (X[3 * v + i] + u[3 * v + i]) / nn;
  for (int i = 0; i < n; i++) count[s->dof_of[i] % 3] += 1.0;
  for (int k = 0; k < 6; k++) {
    double rr = 0.0, rAr = 0.0, rb = 0.0, TAr[3] = {0, 0, 0}, Tr[3] = {0, 0, 0}, Tb[3] = {0, 0, 0};
    for (int i = 0; i < n; i++) {
      const int dof = s->dof_of[i], v = dof / 3, comp = dof % 3;
      if (k < 3) {
        r[i] = comp == k;
      } else { /* (e_a × d)_comp, a = k − 3 */
        const int a = k - 3, b = (a + 1) % 3, e = (a + 2) % 3;
        double d[3];
        for (int q = 0; q < 3; q++) d[q] = X[3 * v + q] + u[3 * v + q] - c[q];
        r[i] = comp == b ? -d[e] : comp == e ? d[b] : 0.0;
      }
      rr += r[i] * r[i];
      Tr[comp] += r[i];
      if (b) rb += r[i] * b[i], Tb[comp] += b[i];
    }
    if (rr == 0.0) continue; /* every DOF of that field is fixed */
    nh_system_apply(s, r, Ar);
    for (int i = 0; i < n; i++) rAr += r[i] * Ar[i], TAr[s->dof_of[i] % 3] += Ar[i];
    if (k < 3)
      for (int q = 0; q < 3; q++) Gtt[3 * q + k] = TAr[q];
    else if (k == 3 && nh_mat3_inverse(Gtt, Gti) != NH_OK)
      memset(Gti, 0, sizeof Gti); /* a translation is not held: rotations as they are */
    if (k >= 3) {                 /* the rotation about the best centre: plus the translation t that
                                     minimises its energy, t = −G_tt⁻¹ Tᵀ A r */
      double t[3];
      nh_mat3_vec(Gti, TAr, t);
      for (int q = 0; q < 3; q++) {
        rAr -= t[q] * TAr[q];
        rr += -2.0 * t[q] * Tr[q] + t[q] * t[q] * count[q];
        rb -= t[q] * Tb[q];
      }
      /* the angle the linearised step turns the body by in this mode: the
       * load's moment over the mode's stiffness (rad, r per unit angle) */
      const double turn = b && rAr > 0.0 ? fabs(rb) / rAr : 0.0;
      if (turn > out.turn) out.turn = turn, out.turn_mode = k;
    }
    double q = fabs(rAr) / (fmax(rr, 1e-300) * diag);
    if (q <= NH_DIAG_FREE) out.loose |= 1 << k;
    if (q < out.rho) out.rho = q, out.mode = k;
  }
  return out;
}

nh_cause nh_system_diagnose(nh_system *s, const double *u, int dof, const nh_rigid *rigid,
                            const nh_rows *rows, char *buf, size_t size) {
  const nh_mesh *m = s->tissue->mesh;
  static const char *const mode_name[6] = {"translation along x", "translation along y",
                                           "translation along z", "rotation about x",
                                           "rotation about y",    "rotation about z"};
  const int node = dof >= 0 ? dof / 3 : -1;
  if (node >= 0)
    nh_diag_add(buf, size, " at node %d, %c, rest position (%.4g, %.4g, %.4g) m", node,
                "xyz"[dof % 3], m -> X[3 * node], m -> X[3 * node + 1], m -> X[3 * node + 2]);
  /* the leaves with that corner (at most 8), smallest tissue fraction first */
  int around[8], n_around = 0, inverted = 0, small_cell = -1, small_near = 0;
  double small = INFINITY;
  for (int l = 0; l < m->n_leaves; l++) {
    const int c = m->leaves[l];
    const double f = nh_diag_fraction(s, c);
    if (f < small) small = f, small_cell = c;
    int has = 0;
    for (int a = 0; a < 8 && node >= 0; a++) has |= m->cells[8 * c + a] == node;
    if (!has || n_around == 8) continue;
    inverted |= nh_tissue_cell_inverted(s->tissue, c, u);
    small_near |= f <= NH_DIAG_SMALL_FILL;
    int k = n_around++;
    for (; k > 0 && nh_diag_fraction(s, around[k - 1]) > f; k--) around[k] = around[k - 1];
    around[k] = c;
  }
  if (n_around > 0) {
    nh_diag_add(buf, size, "; cells around it (tissue fraction):");
    for (int k = 0; k < n_around && k < NH_DIAG_CELLS; k++) {
      const int c = around[k], region = nh_diag_tied(s, c);
      char tied[64] = "";
      if (region >= 0) snprintf(tied, sizeof tied, ", tied by tissue.fixed[%d]", region);
      nh_diag_add(buf, size, " %d (%.3g%s%s)", c, nh_diag_fraction(s, c), tied,
                  nh_tissue_cell_inverted(s->tissue, c, u) ? ", inverted" : "");
    }
  }
  if (node >= 0) nh_diag_rows(rows, node, buf, size);
  if (small_cell >= 0 && small < 1.0)
    nh_diag_add(buf, size, "; the smallest tissue fraction is %.3g (cell %d)", small, small_cell);
  const nh_rigid rg = rigid ? *rigid : nh_system_rigid(s, u, NULL);
  if (rg.mode >= 0)
    nh_diag_add(buf, size, "; the softest rigid mode, %s, has %.2g of the mean stiffness%s",
                mode_name[rg.mode], rg.rho, rigid ? " at the step's start" : "");
  /* the likely cause */
  if (rg.loose) {
    nh_diag_add(buf, size, ". Likely cause: the body is not held: its rigid");
    for (int k = 0, first = 1; k < 6; k++)
      if (rg.loose >> k & 1)
        nh_diag_add(buf, size, "%s %s", first ? "" : ",", mode_name[k]), first = 0;
    nh_diag_add(buf, size,
                " meet no stiffness (no fixed region or tie holds them; add one to "
                "tissue.fixed)");
    return NH_CAUSE_NOT_HELD;
  }
  if (rg.mode >= 0 && rg.rho <= NH_DIAG_WEAK) {
    nh_diag_add(buf, size,
                ". Likely cause: the body is only weakly held: its rigid %s is held by a "
                "support far softer than the tissue (a fixed region small for its load: make "
                "it larger, or add one)",
                mode_name[rg.mode]);
    nh_diag_ties(s, buf, size);
    return NH_CAUSE_WEAK;
  }
  if (rg.turn_mode >= 0 && rg.turn > NH_DIAG_TURN) {
    nh_diag_add(buf, size,
                ". Likely cause: the body is only weakly held for its load: the load's moment "
                "over the supports' stiffness in the %s is %.3g rad, so the first linearised "
                "step turns the body by that angle (a fixed region small for its load: make it "
                "larger, or add one)",
                mode_name[rg.turn_mode], rg.turn);
    nh_diag_ties(s, buf, size);
    return NH_CAUSE_WEAK;
  }
  if (inverted) {
    nh_diag_add(buf, size,
                ". Likely cause: an inverted cell at that node (the load or the step is too "
                "large for the mesh there)");
    return NH_CAUSE_INVERTED;
  }
  if (small_near) {
    nh_diag_add(
        buf, size,
        ". Likely cause: a cut cell with a tiny tissue fraction at that node (a sliver "
        "of the domain: a finer or shifted grid; with tissue.cut_cells: scaled, integrated)");
    return NH_CAUSE_SLIVER;
  }
  nh_diag_add(buf, size,
              ". No likely cause found among the rigid modes, inverted cells and cut cells");
  return NH_CAUSE_NONE;
}

nh_cause nh_system_where_field(nh_system *s, const double *u, const double *f, const nh_rows *rows,
                               const nh_rigid *rigid, char *msg, size_t size) {
  const int n = 3 * s->tissue->mesh->n_nodes;
  int worst = -1;
  for (int i = 0; i < n; i++)
    if (worst < 0 || fabs(f[i]) > fabs(f[worst])) worst = i;
  nh_diag_add(msg, size, "; its largest entry, %.3g, is", worst >= 0 ? fabs(f[worst]) : 0.0);
  return nh_system_diagnose(s, u, worst, rigid, rows, msg, size);
}

void nh_system_where(nh_system *s, const double *u, const double *f, const nh_rows *rows, char *msg,
                     size_t size) {
  nh_system_where_field(s, u, f, rows, NULL, msg, size);
}

void nh_system_where_dof(nh_system *s, const double *u, int dof, const nh_rows *rows, char *msg,
                         size_t size) {
  nh_system_diagnose(s, u, dof, NULL, rows, msg, size);
}
