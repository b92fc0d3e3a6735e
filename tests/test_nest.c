/* test_nest — a released nested tool hangs in its host's bore
 * (contact/nest.c; docs/interaction.md, "Nested tools").
 *
 * tests/data/nest_weight.yaml, quasi-static: an electrode (L = 0.1 m,
 * r = 0.7 mm, 16 elements, E = 10 GPa, ρ = 7800) inside a massless cannula
 * (0.12 m, r = 3 mm, E = 10 GPa), both clamped at the same base along x,
 * gravity −z, clear of the tissue. The electrode's weight is lumped at its
 * nodes (docs/beam.md): F_j = q l₀ (q l₀/2 at the tip; the base node's
 * goes into the clamp), q = ρ π r² g. A point load P at a on a cantilever
 * of flexural rigidity EI moves x ≥ a by P a² (3x − a) / (6EI).
 *
 *  1. Step 2, released and held: every electrode node k ≥ 1 lies on the
 *     cannula's axis — its distance from the axis below 1e-4 of the free
 *     sag δ_free below (the rows are lateral equalities: the bore's
 *     clearance, 0 here, neglected; a rows-less electrode is off by
 *     δ_free, 10⁴ times the bound). Held along their whole length the two
 *     bend together as one section of rigidity EI_h + EI_e (the electrode's
 *     nodal rotations are its own, so only to the order of its share
 *     EI_e / (EI_h + EI_e) = 0.3 %): the electrode's tip moves by
 *     δ_comp = Σ F_j a_j² (3L − a_j) / (6 (EI_h + EI_e)), and
 *     the cannula carries the weight the electrode's clamp does not: the
 *     rows' total force on the electrode is +z, Σ_{j≥1} F_j EI_h / (EI_h +
 *     EI_e) (= q (L − l₀/2) less the clamp's share, which a rigid host
 *     would take to zero).
 *  2. Steps 3-11, the cannula drawn back over the electrode: the nodes
 *     still in the bore (half an element behind the cannula's tip, rows of
 *     contact/nest.c) stay on its axis (the same bound), and the tip's sag
 *     only grows. Step 12, the cannula 0.15 m back, behind the electrode's base:
 *     the electrode has no rows (zero force) and hangs as a cantilever,
 *     tip sag δ_free = Σ F_j a_j² (3L − a_j) / (6 EI_e) (qL⁴/8EI to
 *     O(1/n²): lumped loads) within 2e-4, the corotational beam's
 *     geometric term being (δ/L)² = 6e-5.
 * Tolerances: 1. the composite section is exact but for the electrode's
 * own nodal rotations, whose effect is a fraction of its 0.3 % share, so
 * 1e-4 on the sag and 3e-5 q L (1 % of the share) on the force; the force
 * is normal to the cannula's axis, which the sag tilts by 3e-5: |f_x| ≤
 * 1e-3 f_z, f_y ≤ 1e-9 q L. Without the rows (contact/nest.c's call left
 * out) the electrode is 7.8e-4 m off the axis and every check of 1 fails.
 * NH_VERBOSE=1 prints the numbers. */
#include "contact/contact_impl.h"
#include "sim/sim_impl.h"
#include "sim_util.h"

#include <stdlib.h>

/* Tip deflection of a cantilever of length L, rigidity EI, n elements,
 * under the lumped nodal loads of q (nodes 1..n; the tip's half). */
static double lumped_sag(double q, double L, int n, double EI) {
  const double l0 = L / n;
  double w = 0.0;
  for (int j = 1; j <= n; j++) {
    const double F = q * l0 * (j == n ? 0.5 : 1.0), a = j * l0;
    w += F * a * a * (3.0 * L - a) / (6.0 * EI);
  }
  return w;
}

/* Largest distance from its host's axis of tool k's nodes 1.. at rest arc
 * lengths below a_max. */
static double off_axis(nh_contact *c, int k, int host, double a_max) {
  nh_beam *b = nh_contact_beam(c, k), *h = nh_contact_beam(c, host);
  const double *x = nh_beam_positions(b), l0 = nh_beam_length(b) / nh_beam_elements(b);
  double worst = 0.0;
  for (int j = 1; j < nh_beam_nodes(b) && j * l0 < a_max; j++) {
    double s = nh_tool_project(h, x + 3 * j, x[3 * j] - nh_beam_positions(h)[0]), p[3];
    CHECK(s >= 0.0 && s <= nh_beam_length(h), "node %d at s = %g, not in the host", j, s);
    nh_beam_point(h, s, p, NULL, NULL, NULL, NULL);
    double d[3] = {x[3 * j] - p[0], x[3 * j + 1] - p[1], x[3 * j + 2] - p[2]};
    worst = fmax(worst, sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]));
  }
  return worst;
}

int main(void) {
  const int verbose = getenv("NH_VERBOSE") != NULL;
  char path[1024];
  const char *src = getenv("NH_SOURCE_DIR");
  snprintf(path, sizeof path, "%s/tests/data/nest_weight.yaml", src ? src : ".");
  nh_scene *scene;
  nh_sim *sim;
  CHECK_OK(nh_scene_load(path, 0, NULL, &scene));
  nh_sim_options opt = {.dry_run = 1, .progress = 0};
  CHECK_OK(nh_sim_create(scene, &opt, &sim));
  nh_contact *c = sim->contact;
  const nh_tool_spec *ch = &scene->tools[0], *el = &scene->tools[1];
  const double g = 9.81, q = el->density * M_PI * el->radius * el->radius * g, L = el->length;
  const double EIe = el->young * M_PI * pow(el->radius, 4) / 4.0,
               EIh = ch->young * M_PI * pow(ch->radius, 4) / 4.0;
  const int n = el->elements;
  const double l0 = L / n, sag_free = lumped_sag(q, L, n, EIe),
               sag_comp = lumped_sag(q, L, n, EIe + EIh),
               rows_force = q * (L - 0.5 * l0) * EIh / (EIh + EIe);
  const double z0 = el->base[2];

  for (int s = 0; s < 2; s++) CHECK_OK(nh_sim_step(sim));
  double f[3], tip[3];
  nh_contact_nest_force(c, 1, 1.0, f);
  nh_beam_point(nh_contact_beam(c, 1), L, tip, NULL, NULL, NULL, NULL);
  const double off = off_axis(c, 1, 0, 2.0 * L);
  if (verbose)
    printf("held: off axis %.3e m (bound %.3e); tip sag %.9e m, composite %.9e; rows' force "
           "[%.3e %.3e %.9e] N, expected z %.9e (q L = %.6e)\n",
           off, 1e-4 * sag_free, z0 - tip[2], sag_comp, f[0], f[1], f[2], rows_force, q * L);
  CHECK(off <= 1e-4 * sag_free, "held electrode %.3e m off the cannula's axis, bound %.3e m", off,
        1e-4 * sag_free);
  CHECK_CLOSE(z0 - tip[2], sag_comp, 1e-4 * sag_comp, "held electrode's tip sag (composite)");
  CHECK_CLOSE(f[2], rows_force, 3e-5 * q * L, "the cannula's force on the electrode, z");
  CHECK(fabs(f[1]) <= 1e-9 * q * L && fabs(f[0]) <= 1e-3 * f[2],
        "the cannula's force [%g, %g, %g] N not across its axis in the x-z plane", f[0], f[1],
        f[2]);

  double sag_last = z0 - tip[2];
  for (int s = 2; s < 12; s++) {
    CHECK_OK(nh_sim_step(sim));
    /* the nodes still in the bore, half an element behind its rim, stay on
     * the axis; the tip's sag grows with the overhang, without a jump back */
    double rim[3], ct[3];
    nh_beam_point(nh_contact_beam(c, 0), nh_beam_length(nh_contact_beam(c, 0)), ct, NULL, NULL,
                  NULL, NULL);
    const double a_end = fmin(nh_tool_project(nh_contact_beam(c, 1), ct, ct[0]), L);
    nh_beam_point(nh_contact_beam(c, 1), L, rim, NULL, NULL, NULL, NULL);
    const double off_s = off_axis(c, 1, 0, a_end - 0.5 * l0), sag = z0 - rim[2];
    if (verbose)
      printf("step %d: rim at %.4f m of the electrode, nodes behind it off axis %.3e m, tip sag "
             "%.6e m\n",
             s + 1, a_end, off_s, sag);
    CHECK(off_s <= 1e-4 * sag_free, "step %d: a node in the bore %.3e m off the axis", s + 1,
          off_s);
    CHECK(sag >= sag_last * (1.0 - 1e-9), "step %d: the tip's sag fell from %.6e to %.6e m", s + 1,
          sag_last, sag);
    sag_last = sag;
  }
  nh_contact_nest_force(c, 1, 1.0, f);
  nh_beam_point(nh_contact_beam(c, 1), L, tip, NULL, NULL, NULL, NULL);
  if (verbose)
    printf("withdrawn: tip sag %.9e m, free cantilever %.9e (qL^4/8EI %.6e); rows' force %g N\n",
           z0 - tip[2], sag_free, q * pow(L, 4) / (8 * EIe), f[2]);
  CHECK(c->tools[1].nest_n == 0 && f[2] == 0.0,
        "withdrawn cannula: the electrode still has %d rows (force %g N)", c->tools[1].nest_n,
        f[2]);
  CHECK_CLOSE(z0 - tip[2], sag_free, 2e-4 * sag_free, "free electrode's tip sag");
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
  return nh_test_failures != 0;
}
