/* reuse.c — solves with a recent factorisation instead of a new one per step
 * (solver.refactor: auto; docs/performance.md, docs/theory.md §4).
 *
 * Consecutive dynamic steps change A = (1 + hα) M + (hβ + h²) K(R) only
 * through the element rotations R: the Cholesky factor L₀ of an earlier
 * A₀ = L₀ L₀ᵀ is an excellent preconditioner for the current A. A system
 * solve is then preconditioned conjugate gradients (PCG) on A x = b with
 * M = A₀:
 *   x₀ = M⁻¹ b,  r = b − A x,  z = M⁻¹ r,  p = z, ...
 * stopped when the residual's M⁻¹-norm is a fraction `tolerance` of the
 * right-hand side's, √(rᵀ M⁻¹ r) ≤ tol √(bᵀ M⁻¹ b). Because M⁻¹A ≈ I this
 * norm is close to the energy norm of the error, so the stop bounds the
 * relative error of x, not only of the residual. When the check passes, the
 * last z (already computed for it) is added to x: one step of iterative
 * refinement for free. Each iteration costs one product with A (nh_system_apply)
 * and one pair of triangular solves with L₀ (a fraction of a factorisation:
 * measured in docs/performance.md).
 *
 * When to factorise (nh_system_factor_or_reuse): THE place where a step
 * decides, after its assembly, whether A is factorised. A step of
 * nh_step_coupled (dynamic, or an iteration of the quasi-static coupled
 * Newton) factorises at every call unless solver.refactor is auto
 * (in->reuse); then a factor of this very A is kept as it is (lazy tangents
 * may leave A unchanged), and an earlier one is kept as a preconditioner
 * unless
 *   - there is no factor yet: a new system factorises at its first step,
 *     unless it inherited the factor of the mesh before a refinement or
 *     coarsening (inherit.c: the old factor extended to the new unknowns,
 *     a two-level preconditioner), which serves under the same rules while
 *     it pays, and while W₀ = J B Jᵀ (one application per constraint row)
 *     and as many PCG iterations as the last step with an inherited factor
 *     made (carried across mesh changes) cost less than a factorisation;
 *   - the renewal rule of nh_system_account asks for it, or the factor is
 *     NH_REFACTOR_MAX_AGE steps old (a schedule that bounds drift on long
 *     quiet runs), unless the step's solution is to be factorised after it
 *     (nh_system_expect_factor_later: the goal estimate's duals), the step
 *     is dynamic and the factor is this mesh's own: that factorisation
 *     renews the cycle, so one at the start would be a second in the step;
 *     one more step with the factor costs about the last step's few PCG
 *     iterations instead (and factorises after all if PCG fails);
 *   - hanging-node rows are enforced by multipliers (compliance.c builds
 *     their W from the factor, exactly).
 * An iteration of the static Newton (nh_solve_static, NH_FACTOR_NEWTON)
 * factorises unless the factor is already this A's. Three more places
 * factorise, each because a reused factor did not serve or A just changed:
 * a solve that still misses the tolerance after NH_PCG_MAX iterations
 * (nh_system_solve_reuse), constraint corrections that do not converge with
 * W₀ (coupled.c, nh_coupled_reused), and each Newton correction of a
 * dynamic step (nh_step_dynamic, on the A its residual assembled). So a step
 * never returns a less accurate answer than asked for.
 *
 * The constraint rows of the coupled step (coupled.c) use W₀ = J A₀⁻¹ Jᵀ from
 * the reused factor inside an outer correction: see nh_step_coupled. */
#include "solve/system_impl.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static double nh_dot(const double *a, const double *b, int n) {
  double s = 0.0;
  for (int i = 0; i < n; i++) s += a[i] * b[i];
  return s;
}

/* z = M⁻¹ r with the factor (old or current). */
static int nh_precondition(nh_system *s, const double *r, double *z) {
  return nh_system_solve(s, r, z);
}

/* Time one numeric factorisation of the current A into a copy of the factor
 * (discarded): the reference a reused step is compared with. */
static int nh_time_aside(nh_system *s, nh_step_stats *st) {
  double t0 = nh_time_now();
  if (!s->L_aside &&
      !(s->L_aside = s->L ? cholmod_copy_factor(s->L, &s->cm) : cholmod_analyze(s->A, &s->cm)))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: a factor copy to time");
  double t1 = nh_time_now();
  int ok = nh_cholmod_factorize(s->A, s->L_aside, &s->cm);
  double t2 = nh_time_now();
  if (!ok || s->cm.status < CHOLMOD_OK)
    return NH_ERROR(NH_ERR_NUMERIC, "timing a factorisation failed (status %d)", s->cm.status);
  st->t_factor_reference = t2 - t1;
  st->t_aside += nh_time_now() - t0;
  return NH_OK;
}

int nh_system_factor_or_reuse(nh_system *s, const nh_integrator *in, nh_factor_rule rule,
                              nh_step_stats *st) {
  double t0 = nh_time_now();
  int need;
  if (rule == NH_FACTOR_NEWTON) {
    need = !s->factor_current; /* lazy tangents may have left A as it was */
  } else {
    /* a factorisation at the step's solution renews the cycle anyway: with
     * this mesh's own factor, a dynamic step does not factorise at its start
     * too (an inherited one, weaker, still does; a quasi-static step's
     * Newton iterations each come here, and would defer it many times) */
    const int later = s->factor_follows && s->L && !in->quasi_static;
    const int renew = (s->refactor_due || s->factor_age >= NH_REFACTOR_MAX_AGE) && !later;
    need = !in->reuse || (!s->L && !s->inh) || s->n_rows > 0 || renew;
    /* an inherited factor (inherit.c) costs one application per constraint
     * row (W₀) and its PCG iterations, as many as the last step that solved
     * with one made (inherit_its): when those cost more than a
     * factorisation, factorise */
    if (!need && !s->L &&
        (double)(s->rows_hint + s->inherit_its) * s->flops_iteration *
                nh_solve_flop_cost(s->flops_factor) >
            s->flops_factor)
      need = 1;
    if (!need && !s->L) {
      NH_TRY(nh_inherit_ready(s)); /* the new unknowns' block, once */
      need = !s->inh;
      s->inh_step = !need;
    }
    /* already the factor of this A (lazy tangents may keep A): reuse takes it;
     * `every` factorises at every step, as asked */
    if (s->factor_current && in->reuse) need = 0;
  }
  if (need) {
    NH_TRY(nh_system_factor(s));
    st->t_factor_reference = nh_time_now() - t0;
    st->factorised++;
  } else if (rule == NH_FACTOR_STEP) {
    s->factor_age++;
    if (in->time_factor) NH_TRY(nh_time_aside(s, st));
  }
  st->t_factor += nh_time_now() - t0 - st->t_aside;
  return NH_OK;
}

int nh_system_pcg(nh_system *s, const double *b, double *x, int guess, double tolerance,
                  int max_iterations, int *iterations) {
  const int n = s->n_free;
  double *r = s->pcg[0], *z = s->pcg[1], *p = s->pcg[2], *q = s->pcg[3];
  *iterations = 0;
  if (!guess) NH_TRY(nh_precondition(s, b, x));
  double ref2 = nh_dot(b, x, n);
  if (!(ref2 > 0.0)) { /* b = 0 (M⁻¹ is positive definite) */
    memset(x, 0, sizeof(double) * (size_t)n);
    return NH_OK;
  }
  nh_system_apply(s, x, q);
  for (int i = 0; i < n; i++) r[i] = b[i] - q[i];
  NH_TRY(nh_precondition(s, r, z));
  double rz = nh_dot(r, z, n);
  memcpy(p, z, sizeof(double) * (size_t)n);
  for (int it = 0;; it++) {
    if (!isfinite(rz))
      return NH_ERROR(NH_ERR_NUMERIC, "preconditioned CG: non-finite residual at iteration %d", it);
    if (rz <= tolerance * tolerance * ref2) {
      /* converged: z = M⁻¹ r is one refinement step more */
      for (int i = 0; i < n; i++) x[i] += z[i];
      *iterations = it;
      return NH_OK;
    }
    if (it == max_iterations) break;
    nh_system_apply(s, p, q);
    double pq = nh_dot(p, q, n);
    if (!(pq > 0.0)) break; /* A not positive definite along p: let the caller factorise */
    double alpha = rz / pq;
    for (int i = 0; i < n; i++) x[i] += alpha * p[i], r[i] -= alpha * q[i];
    NH_TRY(nh_precondition(s, r, z));
    double rz_new = nh_dot(r, z, n);
    double beta = rz_new / rz;
    rz = rz_new;
    for (int i = 0; i < n; i++) p[i] = z[i] + beta * p[i];
    *iterations = it + 1;
  }
  return NH_ERROR(NH_ERR_NUMERIC,
                  "preconditioned CG: relative residual %.3g above %.3g after %d iterations",
                  sqrt(rz / ref2), tolerance, *iterations);
}

double nh_solve_flop_cost(double flops_factor) {
  static const double F[3] = {6e6, 1.15e8, 5.3e9}, rho[3] = {1.0, 3.1, 8.0};
  if (!(flops_factor > F[0])) return rho[0];
  for (int k = 1; k < 3; k++)
    if (flops_factor < F[k]) {
      const double a = log(flops_factor / F[k - 1]) / log(F[k] / F[k - 1]);
      return rho[k - 1] + a * (rho[k] - rho[k - 1]);
    }
  return rho[2];
}

/* The renewal rule of a sequence of solves with slowly degrading
 * preconditioner: with F the cost of the factorisation that opened the
 * cycle and e_j the extra cost of the j-th step's solves with the reused
 * factor, the mean cost per step of a cycle of k steps is
 * (F + Σ_{j<=k} e_j) / k; it is least when cut at the first step whose own
 * extra cost exceeds that mean (marginal above average), so the next step
 * factorises then. A per-step cost common to both paths (W, one constraint
 * solve, one pair of triangular solves) cancels from the comparison.
 *
 * A step's extra cost is what it did beyond the exact path (a direct solve,
 * one constraint solve, one solve for the constraint forces' correction):
 *   - its PCG iterations, a solve and a product with A each;
 *   - with constraint rows, each outer correction after the first
 *     (nh_corrected_step): one more PCG start (a solve and a product), one
 *     more solve for the correction, and one more constraint solve, whose
 *     operations nh_mcp_solve counts (streamed over W̃, and in dense
 *     Cholesky factorisations of free rows). With hundreds of skull rows
 *     these are 4–5 per reused step.
 *
 * Costs are operation counts, not measured times, so the moment of renewal,
 * and with it every result, is the same on a loaded and an idle machine:
 * F is CHOLMOD's flop count of the factorisation; streamed operations
 * (triangular solves, products with A, the constraint solver's sweeps) are
 * weighted by ρ = nh_solve_flop_cost(F), the time of such a flop relative to a
 * factorisation's (triangular solves stream L from memory, the supernodal
 * factorisation runs in dense BLAS-3 blocks: docs/performance.md); the
 * constraint solver's dense factorisations (LAPACK) count as factorisation
 * flops. */
void nh_system_account(nh_system *s, const nh_step_stats *st) {
  const double later = st->corrections > 1 ? st->corrections - 1 : 0;
  const double streamed = (double)st->pcg_iterations * s->flops_iteration +
                          later * (s->flops_iteration + s->flops_solve) + st->correction_flops;
  /* an inherited factor's W₀: one application of the preconditioner per row */
  const double rows_w = !s->L && s->inh ? (double)s->rows_hint * s->flops_iteration : 0.0;
  const double extra =
      (streamed + rows_w) * nh_solve_flop_cost(s->flops_factor) + st->correction_flops_dense;
  if (s->inh_step) /* what the inherited preconditioner took (inherit_its) */
    s->inherit_its = st->pcg_iterations, s->inh_step = 0;
  if (s->factor_age == 0) {
    s->cycle_cost = s->flops_factor;
    s->cycle_steps = 1;
    return;
  }
  s->cycle_cost += extra;
  s->cycle_steps++;
  if (extra > s->cycle_cost / s->cycle_steps) s->refactor_due = 1;
}

int nh_system_factor_later(nh_system *s) {
  NH_TRY(nh_system_factor(s));
  s->later_factorised++;
  s->cycle_cost = s->flops_factor; /* a new cycle (nh_system_account) */
  s->cycle_steps = 1;
  s->refactor_due = 0;
  return NH_OK;
}

void nh_system_expect_factor_later(nh_system *s, int yes) {
  s->factor_follows = yes;
}

int nh_system_take_later_factorisations(nh_system *s) {
  int n = s->later_factorised;
  s->later_factorised = 0;
  return n;
}

int nh_system_solve_reuse(nh_system *s, const double *b, double *x, double tolerance,
                          int *iterations, double *t_factor) {
  if (iterations) *iterations = 0;
  if (s->factor_current) return nh_system_solve(s, b, x);
  int its = 0, rc = nh_system_pcg(s, b, x, 0, tolerance, NH_PCG_MAX, &its);
  if (iterations) *iterations = its;
  if (rc == NH_ERR_NUMERIC) { /* the old factor is too far from A: factorise now */
    nh_error_clear();
    double t0 = nh_time_now();
    NH_TRY(nh_system_factor(s));
    if (t_factor) *t_factor += nh_time_now() - t0;
    return nh_system_solve(s, b, x);
  }
  return rc;
}

/* The reuse state of a checkpoint: whether a factor exists, the u and
 * coefficients of the A it factorises, its age and the renewal rule's
 * counters, the last assembly, and the W₀ the factor's corrections keep
 * (coupled.c: m² doubles and its rows' key). The factor itself (megabytes,
 * CHOLMOD's layout) is not saved: it is made again from the same A, which
 * the same assembly and the same CHOLMOD make bit for bit the same. */
void nh_system_reuse_save(const nh_system *s, nh_bytes *b) {
  int32_t head[4] = {s->L != NULL, s->n_nodes, s->factor_age, s->refactor_due};
  nh_bytes_put(b, head, sizeof head);
  int32_t steps = s->cycle_steps;
  nh_bytes_put(b, &steps, sizeof steps);
  nh_bytes_put(b, &s->cycle_cost, sizeof s->cycle_cost);
  if (s->L) {
    nh_bytes_put(b, s->c_factored, sizeof s->c_factored);
    nh_bytes_put(b, s->u_factored, sizeof(double) * 3 * (size_t)s->n_nodes);
  }
  /* the last assembly (its frames decide which tangents the next one keeps) */
  int32_t assembled = s->a_valid;
  nh_bytes_put(b, &assembled, sizeof assembled);
  if (assembled) {
    nh_bytes_put(b, s->c_assembled, sizeof s->c_assembled);
    nh_bytes_put(b, s->u_assembled, sizeof(double) * 3 * (size_t)s->n_nodes);
  }
  /* the W₀ the factor's corrections keep (coupled.c), with its rows' key:
   * a continued run takes it where the uninterrupted one does */
  int32_t w0[2] = {s->L && s->w0 && s->w0_serial == s->factor_serial ? s->w0_m : -1, s->w0_slots};
  nh_bytes_put(b, w0, sizeof w0);
  if (w0[0] >= 0) {
    nh_bytes_put(b, s->w0_key, sizeof(int) * (size_t)s->w0_slots);
    nh_bytes_put(b, s->w0, sizeof(double) * (size_t)s->w0_m * (size_t)s->w0_m);
  }
  /* the inherited factor's last iterations: the next mesh change decides by them */
  int32_t its = s->inherit_its;
  nh_bytes_put(b, &its, sizeof its);
}

/* The kept W₀ of a saved state (nothing in states written before it was
 * kept: the reader is then at the end). */
static int nh_reuse_load_w0(nh_system *s, nh_byte_reader *r) {
  s->w0_serial = 0;
  if (r->p == r->end) return NH_OK;
  int32_t w0[2];
  nh_bytes_get(r, w0, sizeof w0);
  NH_CHECK(!r->short_read && w0[0] < 100000 && w0[1] >= 0, NH_ERR_INPUT,
           "the checkpoint's solver state is malformed");
  if (w0[0] < 0) return NH_OK;
  const size_t mm = (size_t)w0[0] * (size_t)w0[0];
  /* the sizes against the bytes left, before any allocation */
  NH_CHECK((size_t)(r->end - r->p) >= sizeof(int) * (size_t)w0[1] + sizeof(double) * mm,
           NH_ERR_INPUT, "the checkpoint's solver state is malformed");
  free(s->w0), free(s->w0_key);
  s->w0 = nh_calloc(mm ? mm : 1, sizeof(double));
  s->w0_key = nh_calloc(w0[1] ? (size_t)w0[1] : 1, sizeof(int));
  if (!s->w0 || !s->w0_key) return NH_ERROR(NH_ERR_MEMORY, "out of memory restoring W0");
  nh_bytes_get(r, s->w0_key, sizeof(int) * (size_t)w0[1]);
  nh_bytes_get(r, s->w0, sizeof(double) * mm);
  NH_CHECK(!r->short_read && s->L, NH_ERR_INPUT, "the checkpoint's solver state is malformed");
  s->w0_m = w0[0], s->w0_slots = w0[1], s->w0_serial = s->factor_serial;
  return NH_OK;
}

/* Assemble A at a saved u (f_int to scratch): NH_ERR_INPUT if u is not finite. */
static int nh_reuse_assemble(nh_system *s, nh_byte_reader *r, int threads) {
  double c[2], *u = nh_calloc(3 * (size_t)s->n_nodes, sizeof(double));
  if (!u) return NH_ERROR(NH_ERR_MEMORY, "out of memory restoring the solver's factor");
  nh_bytes_get(r, c, sizeof c);
  nh_bytes_get(r, u, sizeof(double) * 3 * (size_t)s->n_nodes);
  int bad = r->short_read;
  for (int i = 0; i < 3 * s->n_nodes && !bad; i++) bad = !isfinite(u[i]);
  int rc = bad ? NH_ERROR(NH_ERR_INPUT, "the checkpoint's solver state is malformed") : NH_OK;
  if (!rc) {
    nh_system_assemble(s, u, NULL, c[0], c[1], s->work[0], NULL, threads);
    rc = nh_stop_check();
  }
  free(u);
  return rc;
}

int nh_system_reuse_load(nh_system *s, const unsigned char *data, size_t size, int threads) {
  nh_byte_reader r = {data, data + size, 0};
  int32_t head[4], steps, assembled = 0;
  double cost;
  nh_bytes_get(&r, head, sizeof head);
  nh_bytes_get(&r, &steps, sizeof steps);
  nh_bytes_get(&r, &cost, sizeof cost);
  NH_CHECK(!r.short_read && head[1] == s->n_nodes && head[2] >= 0, NH_ERR_INPUT,
           "the checkpoint's solver state is malformed");
  /* the factor: A at the u it factorised, factorised again */
  if (head[0]) {
    NH_TRY(nh_reuse_assemble(s, &r, threads));
    NH_TRY(nh_system_factor(s));
  }
  /* then the last assembly, so A, the kept tangents' frames and whether the
   * factor is A's own are those of the run that wrote the checkpoint */
  nh_bytes_get(&r, &assembled, sizeof assembled);
  NH_CHECK(!r.short_read, NH_ERR_INPUT, "the checkpoint's solver state is malformed");
  if (assembled)
    NH_TRY(nh_reuse_assemble(s, &r, threads));
  else
    s->factor_current = 0;
  NH_TRY(nh_reuse_load_w0(s, &r));
  int32_t its = 0; /* not in states written before it was kept */
  if (r.p != r.end) nh_bytes_get(&r, &its, sizeof its);
  NH_CHECK(r.p == r.end && !r.short_read && its >= 0, NH_ERR_INPUT,
           "the checkpoint's solver state is malformed");
  s->inherit_its = its;
  s->factor_age = head[2];
  s->refactor_due = head[3];
  s->cycle_steps = steps;
  s->cycle_cost = cost;
  return NH_OK;
}
