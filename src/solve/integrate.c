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
 * that fail to converge, and say so. */
#include "solve/system_impl.h"

#include <math.h>
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
  /* Newton corrections on the implicit-Euler equations: the residual's
   * evaluation left A(u) assembled and R in fwork[0]; work[3] holds the
   * step's velocity change so far. */
  const int n = 3 * s->n_nodes;
  double *dv = s->work[3], *delta = s->work[0], *b = s->fwork[0], *x = s->fwork[1];
  for (int it = 0; !rc && it < in->newton_iterations && !(st.step.residual <= in->newton_tolerance);
       it++) {
    if (nh_stop_requested()) break; /* the step stands as linearised (u, v consistent) */
    double t0 = nh_time_now();
    if ((rc = nh_system_factor(s))) break;
    double t1 = nh_time_now();
    if ((rc = nh_system_solve_constrained(s, b, x))) break;
    nh_system_scatter(s, x, delta);
    for (int i = 0; i < n; i++) {
      v[i] += delta[i];
      u[i] += in->dt * delta[i];
      dv[i] += delta[i];
    }
    double t2 = nh_time_now();
    st.step.residual = nh_dynamic_residual(s, in, f_ext, u, v, dv, NULL, b);
    st.step.t_factor += t1 - t0;
    st.step.t_solve += t2 - t1;
    st.step.t_assemble += nh_time_now() - t2;
    st.step.iterations++;
  }
  st.step.tangent_updates = nh_system_lazy_updates(s);
  if (stats) *stats = st.step;
  return rc;
}

int nh_solve_static(nh_system *s, const nh_integrator *in, const double *f_ext, double *u,
                    nh_step_stats *stats) {
  const int n = 3 * s->n_nodes;
  double *f_int = s->work[0], *r = s->work[2];
  double *b = s->fwork[0], *du = s->fwork[1];
  double t_asm = 0.0, t_fac = 0.0, t_sol = 0.0, rel = INFINITY;
  int it, n_factor = 0;
  s->t_constraints = 0.0;
  nh_system_reset_multipliers(s);
  nh_system_set_lazy(s, in->lazy_rotation);
  nh_system_lazy_reset(s);
  for (it = 0; it <= in->max_iterations; it++) {
    double t0 = nh_time_now();
    nh_system_assemble(s, u, NULL, 0.0, 1.0, f_int, NULL, in->threads);
    NH_TRY(nh_stop_check()); /* SIGINT/SIGTERM: between iterations or in the assembly */
    for (int i = 0; i < n; i++) r[i] = f_ext[i] - f_int[i];
    nh_system_gather(s, r, b);
    nh_system_add_reactions(s, b);
    double scale = fmax(fmax(nh_norm(f_ext, n), nh_norm(f_int, n)), 1e-300);
    rel = nh_norm(b, s->n_free) / scale;
    double t1 = nh_time_now();
    t_asm += t1 - t0;
    if (!isfinite(rel)) return NH_ERROR(NH_ERR_NUMERIC, "the static residual is not finite");
    if (rel <= in->tolerance || nh_norm(b, s->n_free) == 0.0) break;
    if (it == in->max_iterations) break;
    if (!s->factor_current) { /* lazy tangents may have left A as it was */
      NH_TRY(nh_system_factor(s));
      n_factor++;
    }
    double t2 = nh_time_now();
    NH_TRY(nh_system_solve_constrained(s, b, du));
    nh_system_scatter(s, du, s->work[3]);
    for (int i = 0; i < n; i++) u[i] += s->work[3][i];
    double t3 = nh_time_now();
    t_fac += t2 - t1;
    t_sol += t3 - t2;
  }
  if (stats) {
    stats->t_assemble = t_asm;
    stats->t_factor = t_fac;
    stats->t_solve = t_sol - s->t_constraints;
    stats->t_constraints = s->t_constraints;
    stats->iterations = it;
    stats->residual = rel;
    stats->factorised = n_factor; /* one per Newton iteration unless A was kept */
    stats->pcg_iterations = stats->corrections = 0;
    stats->tangent_updates = nh_system_lazy_updates(s);
    stats->t_factor_reference = n_factor > 0 ? t_fac / n_factor : 0.0;
    stats->t_aside = 0.0;
  }
  if (!(rel <= in->tolerance) && rel != 0.0)
    return NH_ERROR(
        NH_ERR_NUMERIC,
        "static Newton did not converge in %d iterations (relative residual %.3g > %.3g)",
        in->max_iterations, rel, in->tolerance);
  return NH_OK;
}
