/* integrate.c — backward Euler with one linearisation per step and the
 * quasi-static Newton solve (docs/theory.md §3, the seed's Eqs. 12-14).
 *
 * Dynamic: with h the step, M lumped, C = αM + βK and K = K(x_t) the
 * corotational tangent,
 *   (M + hC + h²K) dv = h (f_ext − f_int(u_t) − C v_t) − h² K v_t,
 *   v_{t+h} = v_t + dv,   u_{t+h} = u_t + h v_{t+h}
 * (the seed's Eq. 14 in displacements u = x − X, see fem/hex.c).
 * For a linear system this is the exact implicit Euler step, whose
 * amplification for an undamped oscillator of frequency ω is 1/(1 ± iωh): it
 * never adds energy, and stretches the period by ωh / atan(ωh).
 *
 * Static: Newton on K du = f_ext − f_int(u) with the same tangent. The
 * dropped variation of R makes the iteration converge linearly (not
 * quadratically) under large rotation; it converges to the exact corotational
 * equilibrium because the residual is exact. Its floor is round-off in R:
 * R is accurate to eps, so the corotated displacement carries an error near
 * eps h against a signal of strain × h, and the relative residual cannot go
 * below about 40 eps / peak strain (measured over six decades of strain,
 * docs/theory.md §3; 4e-12 at strain 1e-4): tolerances below
 * that fail to converge, and say so.
 *
 * nh_step_dynamic is the coupled step (coupled.c) without rows, then
 * Newton corrections; nh_solve_static runs the tissue's phases of a step
 * (step.c) and the factorisation (reuse.c) per Newton iteration. */
#include "solve/system_impl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static double nh_norm(const double *a, int n) {
  double s = 0.0;
  for (int i = 0; i < n; i++) s += a[i] * a[i];
  return sqrt(s);
}

int nh_step_dynamic(nh_system *s, const nh_integrator *in, const double *f_ext, double *u,
                    double *v, nh_step_stats *stats) {
  nh_coupled_stats st;
  int rc = nh_step_coupled(s, in, f_ext, u, v, 0, NULL, NULL, 1.0, 1.0, 0, &st);
  if (stats) *stats = st.step;
  return rc;
}

/* No progress (docs/reliability.md, "Failures diagnosed"): after
 * NH_NEWTON_STALL_ITERATIONS iterations no relative residual has fallen
 * below NH_NEWTON_STALL times the step's first, and the diagnosis names a
 * cause: a rigid mode not held, or held only by a support far softer than
 * the tissue (at the step's start) — final, since more iterations or
 * smaller load steps cannot remove it — or an inverted cell at the largest
 * residual — a load step too large, solved again in smaller load steps
 * (sim.c). Without a cause the iteration goes on: a large load's Newton
 * can stall that long and converge (the cantilever of
 * cases/cantilever.yaml at 0.2 N: 1, 1, 0.998, 0.553, then 0.072 and 1e-13
 * at the 9th iteration), until the long rule (NH_NEWTON_STALL_LONG,
 * nh_newton_stalled) ends it. NH_NEWTON_STALL_ITERATIONS and NH_NEWTON_STALL
 * are in solve.h. */

/* Append to msg where the largest entry of the residual b (over the
 * unknowns) sits and the likely cause (diagnose.c), which it returns. */
static nh_cause nh_static_where(nh_system *s, const double *u, const double *b,
                                const nh_rigid *start, char *msg, size_t size) {
  int worst = 0;
  for (int i = 1; i < s->n_free; i++)
    if (fabs(b[i]) > fabs(b[worst])) worst = i;
  size_t len = strlen(msg);
  snprintf(msg + len, size - len, "; the largest residual, %.3g N, is",
           s->n_free > 0 ? fabs(b[worst]) : 0.0);
  return nh_system_diagnose(s, u, s->n_free > 0 ? s->dof_of[worst] : -1, start, NULL, msg, size);
}

int nh_newton_stalled(nh_newton_watch *w, int it, double rel) {
  if (it == 0 || rel < w->best) {
    w->best = rel, w->best_it = it;
    return 0;
  }
  return it - w->best_it >= NH_NEWTON_STALL_LONG;
}

/* The no-progress test at iteration `it` (rel[0..it]: the residuals so
 * far): 1 when none of rel[1..it] is below NH_NEWTON_STALL times rel[0],
 * the message's start, naming `what`, then in msg. */
static int nh_no_progress(const char *what, const double *rel, int it, char *msg, size_t size) {
  double best = rel[1];
  for (int k = 2; k <= it; k++) best = fmin(best, rel[k]);
  if (best < NH_NEWTON_STALL * rel[0]) return 0;
  snprintf(msg, size, "%s makes no progress: relative residual", what);
  for (int k = 0; k <= it; k++)
    snprintf(msg + strlen(msg), size - strlen(msg), "%s %.3g", k ? "," : "", rel[k]);
  snprintf(msg + strlen(msg), size - strlen(msg), " in %d iterations (none below %g of the first)",
           it, NH_NEWTON_STALL);
  return 1;
}

/* The rule's decision on the cause the diagnosis named: NH_OK to go on,
 * else the failure with its message. */
static int nh_no_progress_stop(nh_cause cause, const char *msg, nh_step_stats *stats) {
  if (cause != NH_CAUSE_NOT_HELD && cause != NH_CAUSE_WEAK && cause != NH_CAUSE_INVERTED)
    return NH_OK;
  /* a support missing or too soft is final; an iterate that inverted a cell
   * is a load step too large, which smaller load steps can cure (sim.c) */
  if (stats) stats->diagnosed = cause != NH_CAUSE_INVERTED;
  return NH_ERROR(NH_ERR_NUMERIC, "%s", msg);
}

/* The static Newton's rule: where is the largest entry of the residual b. */
static int nh_static_progress(nh_system *s, const double *u, const double *b, const double *rel,
                              int it, const nh_rigid *start, nh_step_stats *stats) {
  char msg[1536];
  if (!nh_no_progress("static Newton", rel, it, msg, sizeof msg)) return NH_OK;
  return nh_no_progress_stop(nh_static_where(s, u, b, start, msg, sizeof msg), msg, stats);
}

int nh_newton_progress(nh_system *s, const char *what, const double *u, const double *du,
                       const nh_rigid *start, const double *rel, int it, nh_step_stats *stats) {
  char msg[1536];
  if (!nh_no_progress(what, rel, it, msg, sizeof msg)) return NH_OK;
  snprintf(msg + strlen(msg), sizeof msg - strlen(msg), "; the last increment");
  return nh_no_progress_stop(nh_system_where_field(s, u, du, NULL, start, msg, sizeof msg), msg,
                             stats);
}

int nh_system_factor_symmetric(nh_system *s, const nh_integrator *in, const double *u,
                               nh_factor_rule mode, nh_step_stats *st) {
  int rc = nh_system_factor_or_reuse(s, in, mode, st);
  if (rc == NH_ERR_NUMERIC && s->consistent) {
    nh_error_clear();
    double t0 = nh_time_now();
    nh_system_set_tangent(s, NH_TANGENT_COROTATIONAL); /* with A's coefficients (dynamic too) */
    nh_system_assemble(s, u, NULL, s->a_cM, s->a_cK, s->work[0], NULL, in->threads);
    nh_system_set_tangent(s, NH_TANGENT_CONSISTENT);
    st->t_assemble += nh_time_now() - t0;
    rc = nh_system_factor_or_reuse(s, in, mode, st);
  }
  return rc;
}

/* One Newton step du = K⁻¹ b with the consistent tangent K = S + N:
 * UMFPACK's LU of K without multiplier rows; with them (hanging nodes), the
 * Cholesky factor of S and the rows' multipliers, falling back to the
 * corotational tangent (positive semi-definite) where S is indefinite
 * (docs/theory.md §3, "Quasi-static Newton"). */
static int nh_static_newton_step(nh_system *s, const nh_integrator *in, const double *u,
                                 const double *b, double *du, nh_step_stats *st) {
  if (s->consistent && s->skew) {
    double tf = 0.0;
    int rc = nh_system_solve_lu(s, b, du, &tf);
    st->t_factor += tf;
    st->factorised++;
    return rc;
  }
  int rc = nh_system_factor_symmetric(s, in, u, NH_FACTOR_NEWTON, st);
  return rc ? rc : nh_step_free_solve(s, in, b, du, st);
}

int nh_system_tangent_restore(nh_system *s, const nh_integrator *in, const double *f_ext,
                              const double *u, int refactor, nh_step_stats *st) {
  nh_system_set_tangent(s, NH_TANGENT_COROTATIONAL);
  free(s->skew);
  s->skew = NULL;
  if (!refactor) return NH_OK;
  double t0 = nh_time_now(), f_scale;
  nh_step_assemble(s, in, 1, f_ext, u, NULL, s->fwork[1], &f_scale);
  double t1 = nh_time_now();
  int rc = nh_system_factor(s);
  st->factorised += !rc;
  st->t_assemble += t1 - t0;
  st->t_factor += nh_time_now() - t1;
  return rc;
}

int nh_solve_static(nh_system *s, const nh_integrator *in, const double *f_ext, double *u,
                    nh_step_stats *stats) {
  double *b = s->fwork[0], *du = s->fwork[1];
  double t_sol = 0.0, rel = INFINITY, history[NH_NEWTON_STALL_ITERATIONS + 1];
  nh_step_stats st = {0};
  nh_rigid start = {.mode = -1};
  nh_newton_watch watch = {0};
  if (stats) stats->diagnosed = 0;
  int it, rc = NH_OK, lu_steps = 0;
  nh_step_begin(s, in);
  for (it = 0; !rc && it <= in->max_iterations; it++) {
    double t0 = nh_time_now(), f_scale;
    /* the consistent tangent once the residual is below NH_NEWTON_CONSISTENT
     * (the iterations before take the corotational one, which does not
     * diverge from far-off starts) */
    const int consistent = rel <= NH_NEWTON_CONSISTENT;
    nh_system_set_tangent(s, consistent ? NH_TANGENT_CONSISTENT : NH_TANGENT_COROTATIONAL);
    if (consistent && s->n_rows == 0 && (rc = nh_system_keep_skew(s))) break;
    nh_step_assemble(s, in, 1, f_ext, u, NULL, b, &f_scale);
    if ((rc = nh_stop_check())) break; /* SIGINT/SIGTERM: between iterations or in the assembly */
    nh_system_add_reactions(s, b);
    rel = nh_norm(b, s->n_free) / fmax(f_scale, 1e-300);
    st.t_assemble += nh_time_now() - t0;
    if (!isfinite(rel)) {
      rc = NH_ERROR(NH_ERR_NUMERIC, "the static residual is not finite");
      break;
    }
    if (rel <= in->tolerance || nh_norm(b, s->n_free) == 0.0) break;
    if (it == 0) start = nh_system_rigid(s, u, b); /* the supports, at the step's start */
    if (it <= NH_NEWTON_STALL_ITERATIONS) history[it] = rel;
    if (it == NH_NEWTON_STALL_ITERATIONS &&
        (rc = nh_static_progress(s, u, b, history, it, &start, stats)))
      break;
    if (nh_newton_stalled(&watch, it, rel)) {
      char msg[1536];
      snprintf(msg, sizeof msg,
               "static Newton makes no progress: relative residual %.3g at iteration %d, none of "
               "the last %d below %.3g (iteration %d)",
               rel, it, NH_NEWTON_STALL_LONG, watch.best, watch.best_it);
      nh_static_where(s, u, b, &start, msg, sizeof msg);
      rc = NH_ERROR(NH_ERR_NUMERIC, "%s", msg);
      break;
    }
    if (it == in->max_iterations) break;
    double t2 = nh_time_now(), tf0 = st.t_factor;
    lu_steps += s->consistent && s->skew;
    if ((rc = nh_static_newton_step(s, in, u, b, du, &st))) {
      /* a pivot <= 0 of the corotational tangent (positive semi-definite):
       * A is singular, which no load step changes (cholesky.c named where) */
      if (rc == NH_ERR_NUMERIC && s->not_posdef && !(s->consistent && s->skew) && stats)
        stats->diagnosed = 1;
      break;
    }
    nh_step_update(s, 1, 1.0, du, u, NULL);
    t_sol += nh_time_now() - t2 - (st.t_factor - tf0);
  }
  /* Back to the corotational tangent, the other steps'; after the LU path
   * the system is left with the Cholesky factor of the corotational tangent
   * at the solution, which the goal-oriented estimate's dual solves and the
   * next step's reuse use (adapt/dwr.c, reuse.c). */
  if (!rc)
    rc = nh_system_tangent_restore(s, in, f_ext, u, lu_steps > 0, &st);
  else
    nh_system_tangent_restore(s, in, f_ext, u, 0, &st);
  NH_TRY(rc);
  if (stats) {
    stats->t_assemble = st.t_assemble;
    stats->t_factor = st.t_factor;
    stats->t_solve = t_sol - s->t_constraints;
    stats->t_constraints = s->t_constraints;
    stats->iterations = it;
    stats->residual = rel;
    stats->factorised = st.factorised; /* one per Newton iteration unless A was kept */
    stats->pcg_iterations = stats->corrections = 0;
    stats->tangent_updates = nh_system_lazy_updates(s);
    stats->t_factor_reference = st.factorised > 0 ? st.t_factor / st.factorised : 0.0;
    stats->t_aside = 0.0;
  }
  if (!(rel <= in->tolerance) && rel != 0.0) {
    char msg[1536];
    snprintf(msg, sizeof msg,
             "static Newton did not converge in %d iterations (relative residual %.3g > %.3g)",
             in->max_iterations, rel, in->tolerance);
    nh_static_where(s, u, b, &start, msg, sizeof msg);
    return NH_ERROR(NH_ERR_NUMERIC, "%s", msg);
  }
  return NH_OK;
}
