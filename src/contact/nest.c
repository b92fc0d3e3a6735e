/* nest.c — a released nested tool held by its host's bore
 * (docs/interaction.md, "Nested tools and the outermost-tool rule").
 *
 * Until its release a nested tool follows its host kinematically
 * (tools.c). Released, it is a beam of its own in the coupled step, and
 * while it is inside its host the host's wall holds it. Let a_end be the
 * arc length on the tool where the host's tip passes it (the host's tip
 * projected onto the tool), or the tool's length L if its tip is inside
 * the host: its part [0, a_end] is in the bore. Its nodes k ≥ 1 (node 0 is
 * its base, prescribed) with k l₀ < a_end − l₀/2 whose closest point on
 * the host's deformed axis lies at s ∈ [0, L_host], and its point at
 * a_end (the rim, or the tool's tip) held at its closest host point (s
 * clamped to L_host), each get two bilateral rows across the host's axis,
 *
 *   g_q = n_q · (x(a) − x_host(s)),   q = 1, 2,
 *
 * n1 the host's second director at its node nearest s made orthogonal to
 * the tangent t(s), n2 = t × n1: the frame of the channel's shaft rows
 * (channel.c). They are rows between two tools (nh_rows.tool2: the inner
 * tool's point in place of a tissue point, the host's point as the tool
 * part), so W = J A⁻¹ Jᵀ gets both beams' columns. Along t nothing: the
 * inner tool slides axially without friction (no scene key gives the bore
 * one). Nodes are the points where the inner beam's position is its own
 * DOFs; the end point follows the rim continuously as either tool moves,
 * so no row depends on which side of the host's tip a node lies by
 * rounding or by the tools' axial strain (a tool released with its tip at
 * its host's, as dbs-skull.yaml's electrode, has its tip there to 1e-9 m),
 * and the half element between the last node and the end keeps their rows
 * apart (independent).
 *
 * What is neglected: the bore's clearance. The rows hold the node on the
 * axis (lateral equality), where the physical constraint is unilateral,
 * |offset| ≤ inner_radius(host) − radius(inner); a tool at rest under its
 * weight would lie on the wall, that clearance off the axis. The scenes'
 * cannulas give no inner radius (solid sections), so there is no
 * clearance to keep; a real DBS cannula's is 0.05–0.2 mm.
 *
 * As the host retracts (or the tool advances past its tip) a_end moves
 * back along the tool: a node whose k l₀ passes a_end − l₀/2 loses its
 * rows, the end point half an element ahead of it still held, so the
 * position does not jump and its load moves to the neighbouring rows. A
 * node that enters (a host moved over a released tool, or a tool drawn back
 * into its host) is pulled onto the axis within the step, without the
 * hand-over's allowance (channel.c): no scene does that yet.
 * The rows start from λ = 0 every step (bilateral, solved exactly as one
 * block by nh_mcp_solve), so they carry no state between steps and a
 * checkpoint needs nothing of them. */
#include "contact/contact_impl.h"

#include <string.h>

/* The two rows holding the released tool tl's point at arc length a on its
 * host's axis at arc length s; NH_ERR_MEMORY. */
static int nh_nest_point_rows(nh_contact *c, nh_tool *tl, const nh_tool *host, double a, double s) {
  nh_rows *rows = &c->rows;
  double xh[3], t[3], Jh[36], xih, xa[3], Ja[36], n1[3], n2[3];
  int eh, ea;
  nh_beam_point(host->beam, s, xh, t, &eh, &xih, Jh);
  nh_beam_point(tl->beam, a, xa, NULL, &ea, NULL, Ja);
  nh_frame_normal(nh_beam_directors(host->beam) + 9 * (xih < 0.5 ? eh : eh + 1), t, n1);
  nh_vec3_cross(t, n1, n2);
  const double *dirs[2] = {n1, n2}, g[3] = {xa[0] - xh[0], xa[1] - xh[1], xa[2] - xh[2]};
  if (tl->nest_row < 0) tl->nest_row = rows->m;
  for (int q = 0; q < 2; q++) {
    int r = nh_rows_add(rows);
    if (r < 0) return NH_ERROR(NH_ERR_MEMORY, "out of memory: the rows of a nested tool");
    memcpy(rows->dir + 3 * r, dirs[q], 3 * sizeof(double));
    rows->tool[r] = host->dyn, rows->elem[r] = eh;
    memcpy(rows->J + 36 * r, Jh, sizeof Jh);
    rows->tool2[r] = tl->dyn, rows->elem2[r] = ea;
    memcpy(rows->J2 + 36 * r, Ja, sizeof Ja);
    rows->gap[r] = nh_vec3_dot(dirs[q], g);
  }
  tl->nest_n += 2;
  return NH_OK;
}

/* Closest point of beam b to x from the guess of its base's tangent line. */
static double nh_nest_project(const nh_beam *b, const double x[3]) {
  double x0[3], t0[3];
  nh_beam_point(b, 0.0, x0, t0, NULL, NULL, NULL);
  const double d[3] = {x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]};
  return nh_tool_project(b, x, nh_vec3_dot(d, t0));
}

int nh_nest_rows(nh_contact *c) {
  for (int i = 0; i < c->n; i++) {
    nh_tool *tl = &c->tools[i];
    tl->nest_row = -1, tl->nest_n = 0;
    if (tl->host < 0 || tl->dyn < 0) continue; /* an outer tool, or following its host */
    const nh_tool *host = &c->tools[tl->host];
    if (host->dyn < 0) continue;
    const double Lh = nh_beam_length(host->beam), L = nh_beam_length(tl->beam),
                 l0 = L / nh_beam_elements(tl->beam), *x = nh_beam_positions(tl->beam);
    /* the end of the part inside: where the host's tip passes the tool, or
     * the tool's tip if that is inside the host */
    double tip[3];
    nh_beam_point(host->beam, Lh, tip, NULL, NULL, NULL, NULL);
    const double a_end = fmin(nh_nest_project(tl->beam, tip), L);
    if (!(a_end > 0.0)) continue; /* the host's tip is behind the tool's base */
    for (int k = 1; k * l0 < a_end - 0.5 * l0; k++) {
      const double s = nh_nest_project(host->beam, x + 3 * k);
      if (s >= 0.0 && s <= Lh) NH_TRY(nh_nest_point_rows(c, tl, host, k * l0, s));
    }
    double xe[3];
    nh_beam_point(tl->beam, a_end, xe, NULL, NULL, NULL, NULL);
    const double s = nh_nest_project(host->beam, xe);
    if (s >= 0.0) NH_TRY(nh_nest_point_rows(c, tl, host, a_end, fmin(s, Lh)));
  }
  return NH_OK;
}

void nh_contact_nest_force(const nh_contact *c, int k, double tau, double f[3]) {
  const nh_tool *tl = &c->tools[k];
  const nh_rows *rows = &c->rows;
  f[0] = f[1] = f[2] = 0.0;
  for (int r = tl->nest_row; r >= 0 && r < tl->nest_row + tl->nest_n && r < rows->m; r++)
    for (int i = 0; i < 3; i++) f[i] += rows->dir[3 * r + i] * rows->lambda[r] / tau;
}
