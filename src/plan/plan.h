/* plan — target compensation: where to aim so that the electrode ends on its
 * target after the brain has shifted (docs/dbs.md, "Compensated plan").
 *
 * The surgeon plans on the pre-operative images: the trajectory goes from
 * the entry (burr hole) to the target. During the procedure the brain
 * shifts and the cannula drags it, so the electrode's tip ends away from the
 * target. The planner runs the whole procedure again and again, moving the
 * point the trajectory aims at (tools[].trajectory.aim; the entry stays),
 * until the final miss is below a tolerance. */
#ifndef NH_PLAN_H
#define NH_PLAN_H

#include "core/core.h"

typedef struct {
  const char *out_dir; /* the plan's folder (NULL: out/<name>-plan) */
  double tolerance;    /* m: stop when |miss| <= tolerance (> 0) */
  int max_runs;        /* at most this many runs of the procedure (>= 1) */
  int quiet;           /* no line per run on stdout */
  int workers;         /* steering: candidate runs at once, as child processes (<= 1: one after
                          another in this process) */
} nh_plan_options;

/* Compensate the scene `scene_path` (with the `--set` overrides
 * sets[0..n_sets)): every tool with a trajectory must aim at the same
 * target T (targets[T]); its miss is m(a) = tip of T's tool − T's current
 * position at the last step of a run whose trajectories aim at the point a.
 * The aim starts at T's point (or at the aim the scene gives) and moves by
 * Broyden's method on m(a) = 0 from the Jacobian I (exact when the brain is
 * rigid: then m(a) = a − T):
 *     a_{k+1} = a_k − J_k⁻¹ m_k,
 *     J_{k+1} = J_k + (Δm − J_k Δa) Δaᵀ / (Δaᵀ Δa),
 * J reset to I when a run misses by more than the run before it. Run k
 * writes its outputs in OUT/run_NN (NN = k, from 01) and OUT/final links to
 * the last one; OUT/plan.yaml records the target, entry, aim, miss per run,
 * runs and wall time. Prints one line per run unless quiet.
 * Returns NH_OK when the last run's |miss| <= tolerance; NH_ERR_NUMERIC
 * (exit 1) when max_runs runs did not get there (plan.yaml written, with
 * converged: false); NH_ERR_INPUT for a scene with no trajectory or with
 * trajectories aiming at different targets, or bad options; whatever a run
 * fails with (its message prefixed with the run). */
int nh_plan_run(const char *scene_path, int n_sets, const char *const *sets,
                const nh_plan_options *options);

#endif
