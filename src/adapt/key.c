/* key.c — what a cache of this module was made for: a mesh's identity.
 *
 * The adapt module keeps results that depend on the mesh only across steps
 * (spr.c: SPR's patches and weights; dwr.c: the goals' functionals). Each is
 * valid for one mesh, and a refinement followed by a coarsening can bring
 * back a mesh with the same counts but other cells, so the key holds the
 * mesh's data themselves, compared exactly at every use: the node and leaf
 * counts, the leaves, their corners, the rest positions, one number per leaf
 * chosen by the cache (SPR: φV; the goals' functionals: the fill φ) and the
 * hanging nodes (NULL table: none). The mesh's domain is fixed for its life
 * and is not part of the key. Comparing costs a few memcmp over arrays the
 * size of the mesh: nothing against what the caches keep. */
#include "adapt/adapt_impl.h"

#include <stdlib.h>
#include <string.h>

int nh_mesh_key_matches(const nh_mesh_key *k, const nh_mesh *m, const double *weight,
                        const nh_hanging *h) {
  const int nh = h ? h->n_hanging : 0;
  if (!k->valid || k->n_nodes != m->n_nodes || k->n_leaves != m->n_leaves || k->n_hanging != nh)
    return 0;
  if (memcmp(k->leaves, m->leaves, sizeof(int) * (size_t)m->n_leaves) ||
      memcmp(k->X, m->X, 3 * sizeof(double) * (size_t)m->n_nodes) ||
      (nh && memcmp(k->hanging, h->node, sizeof(int) * (size_t)nh)))
    return 0;
  for (int l = 0; l < m->n_leaves; l++) {
    const int c = m->leaves[l];
    if (memcmp(k->corners + 8 * l, m->cells + 8 * c, 8 * sizeof(int)) ||
        memcmp(k->weight + l, weight + c, sizeof(double)))
      return 0;
  }
  return 1;
}

int nh_mesh_key_set(nh_mesh_key *k, const nh_mesh *m, const double *weight, const nh_hanging *h) {
  const int nn = m->n_nodes, nl = m->n_leaves, nh = h ? h->n_hanging : 0;
  k->valid = 0;
  NH_TRY(nh_realloc((void **)&k->leaves, (size_t)nl + 1, sizeof(int)));
  NH_TRY(nh_realloc((void **)&k->corners, 8 * (size_t)nl + 1, sizeof(int)));
  NH_TRY(nh_realloc((void **)&k->weight, (size_t)nl + 1, sizeof(double)));
  NH_TRY(nh_realloc((void **)&k->hanging, (size_t)nh + 1, sizeof(int)));
  NH_TRY(nh_realloc((void **)&k->X, 3 * (size_t)nn + 1, sizeof(double)));
  k->n_nodes = nn, k->n_leaves = nl, k->n_hanging = nh;
  memcpy(k->leaves, m->leaves, sizeof(int) * (size_t)nl);
  for (int l = 0; l < nl; l++) {
    memcpy(k->corners + 8 * l, m->cells + 8 * m->leaves[l], 8 * sizeof(int));
    k->weight[l] = weight[m->leaves[l]];
  }
  if (nh) memcpy(k->hanging, h->node, sizeof(int) * (size_t)nh);
  memcpy(k->X, m->X, 3 * sizeof(double) * (size_t)nn);
  k->valid = 1;
  return NH_OK;
}

void nh_mesh_key_free(nh_mesh_key *k) {
  free(k->leaves), free(k->corners), free(k->hanging), free(k->X), free(k->weight);
  memset(k, 0, sizeof *k);
}
