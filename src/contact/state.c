/* state.c — the tools' and constraints' state as bytes, for checkpoints
 * (docs/outputs.md, "Checkpoints and restart").
 *
 * Everything a step reads from the previous one: per tool its beam (current
 * positions, directors, velocities), nesting (released, offset), state and
 * last forces; per group the puncture (entry point, outward normal, rows),
 * the channel (every point with its material position, cell, natural
 * coordinates, length, projection, tie and multipliers: the constraint warm
 * start, and whether its friction slid: the static or the kinetic bound
 * next), the front and the tip tool; the last step's statistics; the
 * quasi-static step's prediction (the tissue's increment over the last
 * step, contact.c: without it a continued static run starts its Newton
 * elsewhere and agrees only to the tolerance); and the skull's warm starts
 * (contact/skull.c). The prescribed motion
 * is a function of time, and the rows, blocks, rest shapes and skull points
 * are rebuilt from the scene and the mesh, so none of them is saved. Cells and
 * natural coordinates are saved as they are: the checkpoint restores the
 * same mesh. Native byte order, like the rest of the checkpoint. */
#include "contact/contact_impl.h"

#include <stdlib.h>
#include <string.h>

static void put(nh_bytes *b, const void *p, size_t n) {
  nh_bytes_put(b, p, n);
}

static void put_int(nh_bytes *b, int x) {
  put(b, &x, sizeof x);
}

int nh_contact_state_save(const nh_contact *c, unsigned char **out, size_t *size) {
  nh_bytes b = {0};
  put_int(&b, c->n);
  put_int(&b, c->n_groups);
  for (int k = 0; k < c->n; k++) {
    const nh_tool *t = &c->tools[k];
    nh_beam *beam = t->beam;
    int nodes = nh_beam_nodes(beam);
    put_int(&b, nodes);
    put(&b, nh_beam_positions(beam), sizeof(double) * 3 * (size_t)nodes);
    put(&b, nh_beam_directors(beam), sizeof(double) * 9 * (size_t)nodes);
    put(&b, nh_beam_velocities(beam), sizeof(double) * 6 * (size_t)nodes);
    put_int(&b, t->released);
    put(&b, &t->offset, sizeof t->offset);
    put_int(&b, (int)t->state);
    put(&b, t->F, sizeof t->F);
    put(&b, t->f_node, sizeof(double) * 3 * (size_t)nodes);
  }
  for (int g = 0; g < c->n_groups; g++) {
    const nh_group *G = &c->groups[g];
    put_int(&b, G->has_entry);
    put(&b, G->n_out, sizeof G->n_out);
    put(&b, &G->entry, sizeof G->entry);
    put_int(&b, G->entry_row);
    put_int(&b, G->punctured);
    put_int(&b, G->n_chan);
    put(&b, G->chan, sizeof *G->chan * (size_t)G->n_chan);
    put(&b, &G->front, sizeof G->front);
    put_int(&b, G->tip_tool);
    put(&b, G->entry_x, sizeof G->entry_x);
  }
  put_int(&b, c->cut);
  put(&b, &c->solve, sizeof c->solve);
  put_int(&b, c->n_du);
  put(&b, c->du_last, sizeof(double) * (size_t)c->n_du);
  if (c->skull) nh_skull_state_save(c->skull, &b);
  if (b.failed) {
    free(b.data);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory saving the tools' state");
  }
  *out = b.data;
  *size = b.len;
  return NH_OK;
}

static void get(nh_byte_reader *r, void *out, size_t n) {
  nh_bytes_get(r, out, n);
}

static int get_int(nh_byte_reader *c) {
  int x;
  get(c, &x, sizeof x);
  return x;
}

int nh_contact_state_load(nh_contact *c, const unsigned char *data, size_t size) {
  nh_byte_reader r = {data, data + size, 0};
  if (get_int(&r) != c->n || get_int(&r) != c->n_groups)
    return NH_ERROR(NH_ERR_INPUT, "the checkpoint's tools are not the scene's");
  for (int k = 0; k < c->n && !r.short_read; k++) {
    nh_tool *t = &c->tools[k];
    nh_beam *beam = t->beam;
    int nodes = nh_beam_nodes(beam);
    if (get_int(&r) != nodes)
      return NH_ERROR(NH_ERR_INPUT, "the checkpoint's tool %d has another number of nodes", k);
    get(&r, nh_beam_positions(beam), sizeof(double) * 3 * (size_t)nodes);
    get(&r, nh_beam_directors(beam), sizeof(double) * 9 * (size_t)nodes);
    get(&r, nh_beam_velocities(beam), sizeof(double) * 6 * (size_t)nodes);
    t->released = get_int(&r);
    get(&r, &t->offset, sizeof t->offset);
    t->state = (nh_tool_state)get_int(&r);
    get(&r, t->F, sizeof t->F);
    get(&r, t->f_node, sizeof(double) * 3 * (size_t)nodes);
  }
  for (int g = 0; g < c->n_groups && !r.short_read; g++) {
    nh_group *G = &c->groups[g];
    G->has_entry = get_int(&r);
    get(&r, G->n_out, sizeof G->n_out);
    get(&r, &G->entry, sizeof G->entry);
    G->entry_row = get_int(&r);
    G->punctured = get_int(&r);
    int n_chan = get_int(&r);
    if (r.short_read || n_chan < 0 || (size_t)n_chan > size / sizeof *G->chan)
      return NH_ERROR(NH_ERR_INPUT, "the checkpoint's channel of group %d is malformed", g);
    if (n_chan > G->cap_chan) {
      NH_TRY(nh_realloc((void **)&G->chan, (size_t)n_chan, sizeof *G->chan));
      G->cap_chan = n_chan;
    }
    G->n_chan = n_chan;
    get(&r, G->chan, sizeof *G->chan * (size_t)n_chan);
    get(&r, &G->front, sizeof G->front);
    G->tip_tool = get_int(&r);
    get(&r, G->entry_x, sizeof G->entry_x);
  }
  c->cut = get_int(&r);
  get(&r, &c->solve, sizeof c->solve);
  int n_du = get_int(&r);
  if (r.short_read || n_du < 0 || (size_t)n_du > size / sizeof(double))
    return NH_ERROR(NH_ERR_INPUT, "the checkpoint's quasi-static prediction is malformed");
  if (n_du != c->n_du) {
    NH_TRY(nh_realloc((void **)&c->du_last, (size_t)n_du, sizeof(double)));
    c->n_du = n_du;
  }
  get(&r, c->du_last, sizeof(double) * (size_t)n_du);
  if (c->skull) NH_TRY(nh_skull_state_load(c->skull, &r));
  if (r.short_read || r.p != r.end)
    return NH_ERROR(NH_ERR_INPUT, "the checkpoint's tool state is malformed");
  return NH_OK;
}
