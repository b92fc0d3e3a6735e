/* nest.c — a released nested tool held by its host's bore
 * (docs/interaction.md, "Nested tools and the outermost-tool rule").
 *
 * Until its release a nested tool follows its host kinematically
 * (tools.c). Released, it is a beam of its own in the coupled step, and
 * while it is inside its host the host's wall holds it: each node k ≥ 1 of
 * the inner tool (node 0 is its base, prescribed) whose closest point on
 * the host's deformed axis lies at an arc length s ∈ [0, L_host] — the
 * host's covered length (up to NH_NEST_TIP beyond the tip) — gets two
 * bilateral rows across the host's axis,
 *
 *   g_q = n_q · (x_k − x_host(s)),   q = 1, 2,
 *
 * n1 the host's second director at its node nearest s made orthogonal to
 * the tangent t(s), n2 = t × n1: the frame of the channel's shaft rows
 * (channel.c). They are rows between two tools (nh_rows.tool2: the inner
 * tool's node in place of a tissue point, the host's point as the tool
 * part), so W = J A⁻¹ Jᵀ gets both beams' columns. Along t nothing: the
 * inner tool slides axially without friction (no scene key gives the bore
 * one). The rows are written at nodes, the points where the inner beam's
 * position is its own DOFs, as the channel's rows are written at its
 * points, one tie per point; between nodes the Hermite beam stays within
 * its bending of one element of the axis.
 *
 * What is neglected: the bore's clearance. The rows hold the node on the
 * axis (lateral equality), where the physical constraint is unilateral,
 * |offset| ≤ inner_radius(host) − radius(inner); a tool at rest under its
 * weight would lie on the wall, that clearance off the axis. The scenes'
 * cannulas give no inner radius (solid sections), so there is no
 * clearance to keep; a real DBS cannula's is 0.05–0.2 mm.
 *
 * A node that leaves the covered length (the host retracts past it, or
 * the inner tool advances beyond the host's tip) loses its rows: the force
 * it carried goes to the neighbouring rows, its position does not jump. A
 * node that enters it (a host moving over a released tool, or a tool
 * drawn back into its host) is pulled onto the axis within the step,
 * without the hand-over's allowance (channel.c): no scene does that yet.
 * The rows start from λ = 0 every step (bilateral, solved exactly as one
 * block by nh_mcp_solve), so they carry no state between steps and a
 * checkpoint needs nothing of them. */
#include "contact/contact_impl.h"

#include <string.h>

/* A node this close to the host's tip, relative to the host's length, is
 * covered: a tool released with its tip at its host's (dbs-skull.yaml's
 * electrode) keeps its tip's rows whatever the rounding of the projection
 * (1e-13 L) and the two tips' axial strain (1e-10 L) do. */
#define NH_NEST_TIP 1e-9

/* The two rows holding node k of the released tool tl on its host's axis
 * at arc length s; NH_ERR_MEMORY. */
static int nh_nest_node_rows(nh_contact *c, const nh_tool *tl, const nh_tool *host, int k,
                             double s) {
  nh_rows *rows = &c->rows;
  const double l0 = nh_beam_length(tl->beam) / nh_beam_elements(tl->beam);
  double xh[3], t[3], Jh[36], xih, xk[3], Jk[36], xik, n1[3], n2[3];
  int eh, ek;
  nh_beam_point(host->beam, s, xh, t, &eh, &xih, Jh);
  nh_beam_point(tl->beam, k * l0, xk, NULL, &ek, &xik, Jk);
  nh_frame_normal(nh_beam_directors(host->beam) + 9 * (xih < 0.5 ? eh : eh + 1), t, n1);
  nh_vec3_cross(t, n1, n2);
  const double *dirs[2] = {n1, n2}, g[3] = {xk[0] - xh[0], xk[1] - xh[1], xk[2] - xh[2]};
  for (int q = 0; q < 2; q++) {
    int r = nh_rows_add(rows);
    if (r < 0) return NH_ERROR(NH_ERR_MEMORY, "out of memory: the rows of a nested tool");
    memcpy(rows->dir + 3 * r, dirs[q], 3 * sizeof(double));
    rows->tool[r] = host->dyn, rows->elem[r] = eh;
    memcpy(rows->J + 36 * r, Jh, sizeof Jh);
    rows->tool2[r] = tl->dyn, rows->elem2[r] = ek;
    memcpy(rows->J2 + 36 * r, Jk, sizeof Jk);
    rows->gap[r] = nh_vec3_dot(dirs[q], g);
  }
  return NH_OK;
}

int nh_nest_rows(nh_contact *c) {
  for (int i = 0; i < c->n; i++) {
    nh_tool *tl = &c->tools[i];
    tl->nest_row = -1, tl->nest_n = 0;
    if (tl->host < 0 || tl->dyn < 0) continue; /* an outer tool, or following its host */
    const nh_tool *host = &c->tools[tl->host];
    if (host->dyn < 0) continue;
    const int nn = nh_beam_nodes(tl->beam);
    const double L = nh_beam_length(host->beam), *x = nh_beam_positions(tl->beam);
    double x0[3], t0[3];
    nh_beam_point(host->beam, 0.0, x0, t0, NULL, NULL, NULL);
    for (int k = 1; k < nn; k++) {
      const double *xk = x + 3 * k, d[3] = {xk[0] - x0[0], xk[1] - x0[1], xk[2] - x0[2]};
      double s = nh_tool_project(host->beam, xk, nh_vec3_dot(d, t0));
      if (s < 0.0 || s > (1.0 + NH_NEST_TIP) * L) continue; /* outside the host's covered length */
      s = fmin(s, L);
      if (tl->nest_row < 0) tl->nest_row = c->rows.m;
      NH_TRY(nh_nest_node_rows(c, tl, host, k, s));
      tl->nest_n += 2;
    }
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
