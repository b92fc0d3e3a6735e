/* test_anchor_points — the contact module's bookkeeping of the shaft
 * points' axial data errors (contact/anchor.c; adapt/dwr_front.c, "Shaft
 * points"; docs/theory.md §6.6, "Anchoring"), on a channel built by hand:
 * three shaft points of one group (rows 0–2, 3–5, 6–8: n1, n2 and the axial
 * friction row t), the first sticking with no estimate, the second
 * sliding, the third sticking with its estimate already kept.
 *  1. nh_contact_stuck_points lists the first point only: a sliding point
 *     is not estimated (its row is a force), a point already estimated
 *     since it last slid is not estimated again;
 *  2. nh_contact_set_point_error(row, e) keeps δc = −e on the point, which
 *     then is no longer listed;
 *  3. nh_contact_data_change puts each kept δc on its point's axial row and
 *     nothing on the lateral rows or on the sliding point (the points have
 *     no anchoring error δX, so no other row changes);
 *  4. a checkpoint of the tools' state (nh_contact_state_save / _load)
 *     keeps both fields.
 * Not exercised here: the reset when a point slides (nh_shaft_update,
 * which needs the tools' beams); the DBS goal study measures the whole
 * (docs/dbs.md, "The shaft points' axial error"). */
#include "check.h"
#include "contact/contact_impl.h"
#include "mesh/mesh.h"

#include <string.h>

#define POINTS 3

/* A contact with one group of POINTS shaft points (channel points 1..3)
 * and their rows; sliding[p] the axial row's state of point p. */
static void make_contact(nh_contact *c, nh_group *G, const int sliding[POINTS]) {
  memset(c, 0, sizeof *c);
  memset(G, 0, sizeof *G);
  c->n_groups = 1, c->groups = G;
  G->tip_tool = -1, G->entry_row = -1;
  G->n_chan = G->cap_chan = POINTS + 1;
  G->chan = calloc((size_t)G->cap_chan, sizeof *G->chan);
  CHECK(G->chan != NULL, "out of memory");
  G->chan[0].row = -1; /* the entry point: channel point 0, never estimated */
  for (int p = 0; p < POINTS; p++) {
    nh_cpoint *q = &G->chan[p + 1];
    q->row = 3 * p, q->tool = -1;
    for (int k = 0; k < 3; k++) {
      int r = nh_rows_add(&c->rows);
      CHECK(r == 3 * p + k, "row %d added as %d", 3 * p + k, r);
      c->rows.law[r].kind = k == 2 ? NH_ROW_FRICTION : NH_ROW_BILATERAL;
      c->rows.law[r].sliding = k == 2 && sliding[p];
    }
  }
}

int main(void) {
  static const double lo[3] = {0, 0, 0}, hi[3] = {0.01, 0.01, 0.01};
  static const int grid[3] = {2, 2, 2};
  nh_mesh *m = NULL;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  double *u = calloc(3 * (size_t)m->n_nodes, sizeof(double));

  nh_contact c;
  nh_group G;
  const int sliding[POINTS] = {0, 1, 0};
  make_contact(&c, &G, sliding);
  G.chan[3].dc_axial = 5e-7, G.chan[3].dc_axial_set = 1; /* estimated before */

  /* part 1: only the first point is listed */
  int row[POINTS] = {-1, -1, -1};
  CHECK(nh_contact_stuck_points(&c, NULL, 0) == 1, "%d points listed, not 1",
        nh_contact_stuck_points(&c, NULL, 0));
  const int listed = nh_contact_stuck_points(&c, row, POINTS);
  CHECK(listed == 1 && row[0] == 0, "%d points listed, the first at row %d, not 1 at row 0", listed,
        row[0]);

  /* part 2: its error kept, it is listed no more */
  nh_contact_set_point_error(&c, 0, 2e-6);
  CHECK(G.chan[1].dc_axial == -2e-6 && G.chan[1].dc_axial_set == 1,
        "point 1 keeps dc %g (set %d), not -2e-6", G.chan[1].dc_axial, G.chan[1].dc_axial_set);
  CHECK(nh_contact_stuck_points(&c, NULL, 0) == 0, "a point estimated once is listed again");

  /* part 3: the data change on the axial rows only */
  double dc[3 * POINTS];
  CHECK_OK(nh_contact_data_change(&c, m, u, 0, NULL, dc, NULL));
  const double want[3 * POINTS] = {0, 0, -2e-6, 0, 0, 0, 0, 0, 5e-7};
  for (int i = 0; i < 3 * POINTS; i++)
    CHECK(dc[i] == want[i], "row %d: data change %g, not %g", i, dc[i], want[i]);

  /* part 4: the tools' state keeps both fields */
  unsigned char *state = NULL;
  size_t size = 0;
  CHECK_OK(nh_contact_state_save(&c, &state, &size));
  nh_contact c2;
  nh_group G2;
  make_contact(&c2, &G2, sliding);
  CHECK_OK(nh_contact_state_load(&c2, state, size));
  for (int p = 1; p <= POINTS; p++)
    CHECK(G2.chan[p].dc_axial == G.chan[p].dc_axial &&
              G2.chan[p].dc_axial_set == G.chan[p].dc_axial_set,
          "point %d after a checkpoint: dc %g (set %d), not %g (set %d)", p, G2.chan[p].dc_axial,
          G2.chan[p].dc_axial_set, G.chan[p].dc_axial, G.chan[p].dc_axial_set);

  free(state);
  nh_rows_free(&c.rows), nh_rows_free(&c2.rows);
  free(G.chan), free(G2.chan), free(c.du_last), free(c2.du_last);
  free(u);
  nh_mesh_destroy(&m);
  return nh_test_failures ? 1 : 0;
}
