/* step.c — the tissue's phases of one step (docs/design.md, "One step"),
 * shared by the coupled step (coupled.c: dynamic, and each iteration of the
 * quasi-static coupled Newton), the dynamic step's Newton corrections and
 * the static Newton (integrate.c): begin (nh_step_begin), assemble A and b
 * (nh_step_assemble: the seed's Eq. 13, or K and f_ext − f_int), the free
 * solve (nh_step_free_solve), the update (nh_step_update) and the residual
 * of the implicit-Euler equations (nh_dynamic_residual, docs/theory.md §3).
 * Between assembly and free solve the step factorises or reuses a factor:
 * reuse.c (nh_system_factor_or_reuse). */
#include "solve/system_impl.h"

#include <float.h>
#include <math.h>

void nh_step_begin(nh_system *s, const nh_integrator *in) {
  s->t_constraints = 0.0;
  nh_system_reset_multipliers(s); /* this step's hanging-node reactions only */
  nh_system_set_lazy(s, in->lazy_rotation);
  nh_system_lazy_reset(s);
}

void nh_step_assemble(nh_system *s, const nh_integrator *in, int statics, const double *f_ext,
                      const double *u, const double *v, double *b, double *f_scale) {
  const nh_tissue *t = s->tissue;
  const int n = 3 * s->n_nodes;
  const double h = in->dt;
  double *f_int = s->work[0], *Kv = s->work[1], *rhs = s->work[2];
  if (statics) { /* a Newton iteration: A = K(u), b = f_ext − f_int(u) */
    nh_system_assemble(s, u, NULL, 0.0, 1.0, f_int, NULL, in->threads);
    for (int i = 0; i < n; i++) rhs[i] = f_ext[i] - f_int[i];
  } else {
    nh_system_assemble(s, u, v, 1.0 + h * in->alpha, h * in->beta + h * h, f_int, Kv, in->threads);
    for (int i = 0; i < n; i++) {
      double Mv = t->mass[i / 3] * v[i];
      rhs[i] = h * (f_ext[i] - f_int[i] - in->alpha * Mv - in->beta * Kv[i]) - h * h * Kv[i];
    }
  }
  nh_system_gather(s, rhs, b);
  if (statics) {
    double fe = 0.0, fi = 0.0;
    for (int i = 0; i < n; i++) fe += f_ext[i] * f_ext[i], fi += f_int[i] * f_int[i];
    *f_scale = fmax(sqrt(fe), sqrt(fi));
  }
}

int nh_step_free_solve(nh_system *s, const nh_integrator *in, const double *b, double *x,
                       nh_step_stats *st) {
  if (s->n_rows > 0) /* hanging-node rows: the factor is current (reuse.c) */
    return nh_system_solve_constrained(s, b, x);
  int its = 0, rc = nh_system_solve_reuse(s, b, x, in->tolerance, &its, &st->t_factor);
  st->pcg_iterations += its;
  return rc;
}

void nh_step_update(nh_system *s, int statics, double h, const double *x, double *u, double *v) {
  const int n = 3 * s->n_nodes;
  double *full = s->work[3];
  nh_system_scatter(s, x, full);
  if (statics) {
    for (int i = 0; i < n; i++) u[i] += full[i];
  } else {
    for (int i = 0; i < n; i++) {
      v[i] += full[i];
      u[i] += h * v[i];
    }
  }
}

double nh_system_residual_floor(const nh_system *s) {
  return s->residual_floor;
}

/* The round-off of the internal forces h f_int(u) in the residual's units
 * (N s), an estimate: each element forms R K (Rᵀ x − X), whose difference
 * carries an error of about eps |x| per coordinate, so f_int carries about
 * eps |x| K_ii per unknown; |x| ≤ |x|_max, K_ii from the assembled
 * A = cM M + cK K (upper triangle). A stiff body at rest (a rigid-like block
 * after the tool leaves) has forces at this level, a relative residual of
 * round-off over round-off, which is no sign of an unsolved step. Measured on
 * a block of E = 1e12 Pa at rest (tests/unsolved.py): residuals 0.04 of it. */
static double nh_force_roundoff(const nh_system *s, const double *u, double h) {
  const nh_tissue *t = s->tissue;
  const double *X = t->mesh->X, cM = s->c_assembled[0], cK = s->c_assembled[1];
  if (!s->a_valid || !(cK > 0.0)) return 0.0;
  double xmax = 0.0, k2 = 0.0;
  for (int i = 0; i < 3 * s->n_nodes; i++) xmax = fmax(xmax, fabs(X[i] + u[i]));
  /* A's columns hold sorted rows of the upper triangle (system.c), the
   * diagonal always among them: a column's last entry is its diagonal */
  const int *p = s->A->p;
  const double *Ax = s->A->x;
  for (int j = 0; j < s->n_free; j++) {
    double kjj = (Ax[p[j + 1] - 1] - cM * t->mass[s->dof_of[j] / 3]) / cK;
    if (kjj > 0.0) k2 += kjj * kjj;
  }
  return h * DBL_EPSILON * xmax * sqrt(k2);
}

double nh_dynamic_residual(nh_system *s, const nh_integrator *in, const double *f_ext,
                           const double *u, const double *v, const double *dv,
                           const double *reaction, double *b) {
  const nh_tissue *t = s->tissue;
  const int n = 3 * s->n_nodes, nf = s->n_free;
  const double h = in->dt;
  double *f_int = s->work[0], *Kv = s->work[1], *R = s->work[2];
  nh_system_assemble(s, u, v, 1.0 + h * in->alpha, h * in->beta + h * h, f_int, Kv, in->threads);
  double fe = 0.0, fi = 0.0, md = 0.0;
  for (int i = 0; i < n; i++) {
    double Mdv = t->mass[i / 3] * dv[i];
    R[i] = h * (f_ext[i] - f_int[i] - in->alpha * t->mass[i / 3] * v[i] - in->beta * Kv[i]) - Mdv;
    fe += f_ext[i] * f_ext[i], fi += f_int[i] * f_int[i], md += Mdv * Mdv;
  }
  if (nh_stop_requested()) return NAN; /* the assembly was cut short: unknown */
  nh_system_gather(s, R, b);
  nh_system_add_reactions(s, b);
  if (reaction)
    for (int i = 0; i < nf; i++) b[i] += reaction[i];
  double r = 0.0;
  int worst = -1;
  for (int i = 0; i < nf; i++) {
    r += b[i] * b[i];
    if (worst < 0 || fabs(b[i]) > fabs(b[worst])) worst = i;
  }
  s->residual_dof = worst >= 0 ? s->dof_of[worst] : -1;
  double scale = fmax(fmax(h * sqrt(fe), h * sqrt(fi)), fmax(sqrt(md), 1e-300));
  s->residual_floor = nh_force_roundoff(s, u, h) / scale;
  return sqrt(r) / scale;
}
