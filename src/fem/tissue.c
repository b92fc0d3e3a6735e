/* tissue.c — element data of the tissue mesh and its lumped mass.
 *
 * Materials per label (docs/anatomy.md, "Mixed cells"). K₀ is linear in the
 * Lamé parameters, K₀ = λ K_λ + μ K_μ, so with materials per label every
 * shape keeps K_λ and K_μ and a cell's K₀ is formed from its own (λ_c, μ_c)
 * when needed. A cell that holds several labels gets the volume averages
 *     λ_c = Σ_l f_l λ_l,   μ_c = Σ_l f_l μ_l,   ρ_c = Σ_l f_l ρ_l,
 * f_l the fraction of the tissue's sub-cell midpoints (of NH_FILL_SAMPLES³)
 * whose voxel holds label l: the Voigt average, exact for the mass and for
 * strains that are uniform across the cell (layers loaded along them), an
 * upper bound of the stiffness for layers loaded across (series), where the
 * exact value is the harmonic (Reuss) mean of the compliances.
 *
 * K₀ (4.6 kB) depends only on the rest shape of a cell up to translation.
 * A uniform grid has one shape, a refined one a handful per level, so cells
 * share element data through a key: their rest corners relative to corner
 * 0, rounded to a binary quantum of 2⁻⁴⁰ (about 1e-12) of the cell's size,
 * which absorbs the round-off between cells of one shape in different places
 * of the grid. The element data are computed from the key itself (the
 * rounded corners, corner 0 at the origin), not from the first cell that
 * had it: so they are a function of the cell's own corners alone, the same
 * whichever cells were met before, and a run continued from a checkpoint
 * (one pass over the restored mesh) has bit for bit the element data of the
 * run that built them across its refinements. The rounding moves a corner
 * by at most 2⁻⁴¹ of the cell size; two cells that differ by less but round
 * to different keys simply get two entries. Every update looks up every
 * leaf (a hash of 24 numbers), since coarsening renumbers the cells.
 *
 * Place in fem: the top. The per-cell entry points (force, tangent, energy,
 * stresses) look up the cell's data and material here and call the element
 * (hex.c) and the stresses inside it (stress.c), which know no mesh. */
#include "fem/fem.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

void nh_tissue_destroy(nh_tissue **tissue) {
  if (!tissue || !*tissue) return;
  nh_tissue *t = *tissue;
  free(t->K0);
  free(t->G0);
  free(t->Gbar);
  free(t->volume);
  free(t->key);
  free(t->cell_shape);
  free(t->mass);
  free(t->label), free(t->label_material), free(t->Kl), free(t->Km), free(t->cell_material);
  free(t->cell_tie);
  free(t->cell_tie_region);
  free(t->tie);
  free(t->cell_cut);
  free(t->cut);
  free(t->fine);
  free(t);
  *tissue = NULL;
}

/* The cell's shape key: its rest corners relative to corner 0, rounded to
 * the binary quantum q = 2^(e − 40), e the exponent of the largest
 * coordinate (each key[i] an integer multiple of q, exactly representable;
 * + 0.0 turns −0 into +0, so equal shapes have equal bits). */
static void nh_shape_key(const double Xe[24], double key[24]) {
  double big = 0.0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) big = fmax(big, fabs(Xe[3 * a + k] - Xe[k]));
  const double q = big > 0.0 ? ldexp(1.0, ilogb(big) - 40) : 1.0;
  for (int i = 0; i < 24; i++) key[i] = nearbyint((Xe[i] - Xe[i % 3]) / q) * q + 0.0;
}

static uint64_t nh_shape_hash(const double key[24]) {
  uint64_t h = 1469598103934665603ull;
  for (int i = 0; i < 24; i++) {
    uint64_t bits;
    memcpy(&bits, &key[i], sizeof bits);
    h = (h ^ bits) * 1099511628211ull;
  }
  return h;
}

/* Find or compute the element data for the rest corners Xe. */
static int nh_tissue_shape(nh_tissue *t, const double Xe[24], int *table, int table_size,
                           int *shape) {
  double key[24];
  nh_shape_key(Xe, key);
  int slot = (int)(nh_shape_hash(key) % (uint64_t)table_size);
  while (table[slot] >= 0) {
    if (!memcmp(t->key + 24 * table[slot], key, sizeof key)) {
      *shape = table[slot];
      return NH_OK;
    }
    slot = (slot + 1) % table_size;
  }
  int s = t->n_shapes;
  if (s >= t->cap_shapes) {
    int cap = t->cap_shapes ? 2 * t->cap_shapes : 8;
    const size_t n = (size_t)cap;
    NH_TRY(nh_realloc((void **)&t->K0, 576 * n, sizeof(double)));
    NH_TRY(nh_realloc((void **)&t->G0, 24 * n, sizeof(double)));
    NH_TRY(nh_realloc((void **)&t->Gbar, 24 * n, sizeof(double)));
    NH_TRY(nh_realloc((void **)&t->volume, n, sizeof(double)));
    NH_TRY(nh_realloc((void **)&t->key, 24 * n, sizeof(double)));
    if (t->n_labels) {
      NH_TRY(nh_realloc((void **)&t->Kl, 576 * n, sizeof(double)));
      NH_TRY(nh_realloc((void **)&t->Km, 576 * n, sizeof(double)));
    }
    t->cap_shapes = cap;
  }
  if (nh_hex_stiffness(key, t->lambda, t->mu, t->material.formulation == NH_FORMULATION_BBAR,
                       t->K0 + 576 * s, t->G0 + 24 * s, t->Gbar + 24 * s, t->volume + s))
    return NH_ERR_INPUT;
  if (t->n_labels) {
    double G[24], v;
    nh_hex_stiffness(key, 1.0, 0.0, 0, t->Kl + 576 * s, G, NULL, &v);
    nh_hex_stiffness(key, 0.0, 1.0, 0, t->Km + 576 * s, G, NULL, &v);
  }
  memcpy(t->key + 24 * s, key, sizeof key);
  t->n_shapes++;
  table[slot] = s;
  *shape = s;
  return NH_OK;
}

static void nh_tissue_mix(nh_tissue *t, int c);
static int nh_tissue_cuts(nh_tissue *t);

/* Cell c's stored λ, μ, ρ were mixed for the cell that now has its id: the
 * same rest corners 0 and 6 (no two cells of a mesh share both). */
static int nh_tissue_mix_is_own(const nh_tissue *t, int c) {
  const double *cm = t->cell_material + NH_CELL_MATERIAL * c;
  const nh_mesh *m = t->mesh;
  if (isnan(cm[0])) return 0;
  return !memcmp(cm + 3, m->X + 3 * m->cells[8 * c], 3 * sizeof(double)) &&
         !memcmp(cm + 6, m->X + 3 * m->cells[8 * c + 6], 3 * sizeof(double));
}

int nh_tissue_update(nh_tissue *t) {
  const nh_mesh *m = t->mesh;
  if (m->n_cells > t->cap_cells) {
    NH_TRY(nh_realloc((void **)&t->cell_shape, (size_t)m->n_cells, sizeof(int)));
    for (int c = t->cap_cells; c < m->n_cells; c++) t->cell_shape[c] = -1;
    if (t->n_labels) {
      NH_TRY(nh_realloc((void **)&t->cell_material, NH_CELL_MATERIAL * (size_t)m->n_cells,
                        sizeof(double)));
      for (int c = t->cap_cells; c < m->n_cells; c++) t->cell_material[NH_CELL_MATERIAL * c] = NAN;
    }
    t->cap_cells = m->n_cells;
  }
  if (m->n_nodes > t->cap_nodes) {
    NH_TRY(nh_realloc((void **)&t->mass, (size_t)m->n_nodes, sizeof(double)));
    t->cap_nodes = m->n_nodes;
  }
  /* The hash table is rebuilt from the shapes already known, then extended. */
  int table_size = 2 * (t->n_shapes + m->n_leaves) + 1;
  int *table = nh_calloc((size_t)table_size, sizeof(int));
  if (!table) return NH_ERROR(NH_ERR_MEMORY, "out of memory: shape table");
  for (int i = 0; i < table_size; i++) table[i] = -1;
  for (int s = 0; s < t->n_shapes; s++) {
    int slot = (int)(nh_shape_hash(t->key + 24 * s) % (uint64_t)table_size);
    while (table[slot] >= 0) slot = (slot + 1) % table_size;
    table[slot] = s;
  }
  int rc = NH_OK;
  double Xe[24];
  for (int l = 0; l < m->n_leaves && !rc; l++) {
    int c = m->leaves[l]; /* every leaf: coarsening renumbers cells */
    nh_mesh_cell_coords(m, m->X, c, Xe);
    rc = nh_tissue_shape(t, Xe, table, table_size, &t->cell_shape[c]);
    if (rc == NH_ERR_INPUT)
      NH_ERROR(rc, "cell %d (level %d) has a non-positive Jacobian in its rest shape", c,
               m->level[c]);
  }
  free(table);
  if (rc) return rc;
  if (t->n_labels) /* coarsening renumbers cells: a leaf's mix is kept only if it is its own */
    for (int l = 0; l < m->n_leaves; l++)
      if (!nh_tissue_mix_is_own(t, m->leaves[l])) nh_tissue_mix(t, m->leaves[l]);
  NH_TRY(nh_tissue_cuts(t));
  memset(t->mass, 0, sizeof(double) * (size_t)m->n_nodes);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double mc[8];
    NH_TRY(nh_tissue_corner_masses(t, c, NULL, mc));
    for (int a = 0; a < 8; a++) t->mass[m->cells[8 * c + a]] += mc[a];
  }
  return NH_OK;
}

/* λ, μ, ρ of cell c: the volume average over the tissue's sub-cell
 * midpoints of the materials of their voxels' labels. */
static void nh_tissue_mix(nh_tissue *t, int c) {
  const nh_mesh *m = t->mesh;
  const nh_domain *d = &m->domain;
  const int n = NH_FILL_SAMPLES;
  double Xe[24], sum[3] = {0, 0, 0}, total = 0.0;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++)
      for (int k = 0; k < n; k++) {
        double xi[3] = {-1 + (2 * i + 1.0) / n, -1 + (2 * j + 1.0) / n, -1 + (2 * k + 1.0) / n};
        double N[8], x[3] = {0, 0, 0};
        nh_hex_shape(xi, N);
        for (int a = 0; a < 8; a++)
          for (int p = 0; p < 3; p++) x[p] += N[a] * Xe[3 * a + p];
        if (d->kind != NH_DOMAIN_BOX && !nh_domain_inside(d, x)) continue;
        /* Equal weights: the sub-cells of a trilinear cell differ in volume
         * only through det J, which varies little inside one cell. */
        int label = nh_image_label_at(d->labels, x), q = -1;
        for (int s = 0; s < t->n_labels && q < 0; s++)
          if (t->label[s] == label) q = s;
        const nh_material *mat = q >= 0 ? &t->label_material[q] : &t->material;
        double lambda, mu;
        nh_lame(mat->young, mat->poisson, &lambda, &mu);
        sum[0] += lambda, sum[1] += mu, sum[2] += mat->density;
        total += 1.0;
      }
  double *cm = t->cell_material + NH_CELL_MATERIAL * c;
  if (total > 0) {
    for (int k = 0; k < 3; k++) cm[k] = sum[k] / total;
  } else { /* a cell kept at the fill floor with no sample inside: the default */
    cm[0] = t->lambda, cm[1] = t->mu, cm[2] = t->material.density;
  }
  memcpy(cm + 3, m->X + 3 * m->cells[8 * c], 3 * sizeof(double));
  memcpy(cm + 6, m->X + 3 * m->cells[8 * c + 6], 3 * sizeof(double));
}

void nh_tissue_cell_material(const nh_tissue *t, int c, double *lambda, double *mu,
                             double *density) {
  if (t->n_labels) {
    const double *cm = t->cell_material + NH_CELL_MATERIAL * c;
    if (lambda) *lambda = cm[0];
    if (mu) *mu = cm[1];
    if (density) *density = cm[2];
    return;
  }
  if (lambda) *lambda = t->lambda;
  if (mu) *mu = t->mu;
  if (density) *density = t->material.density;
}

/* φ of leaf c for the cells that are not cut: the sampled fill fraction
 * where no quadrature applies, 1 for an immersed box cell all inside. */
static double nh_cell_phi(const nh_tissue *t, int c) {
  int k = c < t->cap_cell_cut ? t->cell_cut[c] : NH_CUT_NONE;
  return k == NH_CUT_WHOLE ? 1.0 : t->mesh->fill[c];
}

double nh_tissue_fraction(const nh_tissue *t, int c) {
  const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
  return cut ? cut->fraction : nh_cell_phi(t, c);
}

int nh_tissue_node_support(const nh_tissue *t, double *support) {
  const nh_mesh *m = t->mesh;
  double *full = nh_calloc((size_t)(m->n_nodes ? m->n_nodes : 1), sizeof(double));
  if (!full) return NH_ERROR(NH_ERR_MEMORY, "out of memory: support measures");
  memset(support, 0, sizeof(double) * (size_t)m->n_nodes);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
    double v = t->volume[t->cell_shape[c]] / 8.0;
    for (int a = 0; a < 8; a++) {
      int i = m->cells[8 * c + a];
      support[i] += cut ? cut->corner[a] : nh_cell_phi(t, c) * v;
      full[i] += v;
    }
  }
  for (int i = 0; i < m->n_nodes; i++) support[i] = full[i] > 0.0 ? support[i] / full[i] : 0.0;
  free(full);
  return NH_OK;
}

const nh_tissue_cut *nh_tissue_cell_cut(const nh_tissue *t, int c) {
  int k = c < t->cap_cell_cut ? t->cell_cut[c] : NH_CUT_NONE;
  return k >= 0 ? t->cut + k : NULL;
}

/* ∫ N_a dV over the tissue of the box leaf [lo, hi] above the plane
 * {p, up} (the half-space as a set of the cut-cell quadrature), on the
 * lattice `depth`. */
static int nh_part_above(const nh_domain *d, const double lo[3], const double hi[3], int depth,
                         const double *plane, double out[8]) {
  const double half[6] = {plane[0], plane[1], plane[2], -plane[3], -plane[4], -plane[5]};
  nh_cut_moments mom;
  double w[27];
  NH_TRY(nh_cut_domain_cell_at(d, depth, lo, hi, NULL, half, &mom, w));
  nh_cut_shape_integrals(w, out, NULL);
  return NH_OK;
}

/* nh_tissue_corner_masses with the cut data `cut` (NULL: not cut) of the
 * lattice `depth`: the geometry term compares depth NH_CUT_DEPTH with + 1. */
static int nh_corner_masses_at(const nh_tissue *t, int c, const nh_tissue_cut *cut, int depth,
                               const double *plane, double mc[8]) {
  const nh_mesh *m = t->mesh;
  double rho;
  nh_tissue_cell_material(t, c, NULL, NULL, &rho);
  if (plane && cut && t->has_drainage && cut->above[0] == cut->above[0] &&
      !memcmp(plane, t->drainage, sizeof t->drainage)) { /* held by the entry */
    for (int a = 0; a < 8; a++) mc[a] = rho * cut->above[a];
    return NH_OK;
  }
  double Xe[24], lo[3], hi[3];
  int above = 8, box = 0;
  if (plane) {
    nh_mesh_cell_coords(m, m->X, c, Xe);
    above = 0;
    for (int a = 0; a < 8; a++)
      above += (Xe[3 * a] - plane[0]) * plane[3] + (Xe[3 * a + 1] - plane[1]) * plane[4] +
                   (Xe[3 * a + 2] - plane[2]) * plane[5] >
               0;
    box = nh_domain_integrates_cuts(&m->domain) && nh_hex_is_box(Xe, lo, hi);
  }
  if (above == 0) {
    for (int a = 0; a < 8; a++) mc[a] = 0.0;
  } else if (above < 8 && box) { /* the level cuts an immersed box cell: tissue ∩ half-space */
    NH_TRY(nh_part_above(&m->domain, lo, hi, depth, plane, mc));
    for (int a = 0; a < 8; a++) mc[a] *= rho;
  } else {
    double f = above < 8 ? nh_mesh_cell_fraction_above(m, c, plane, plane + 3) : 1.0;
    for (int a = 0; a < 8; a++)
      mc[a] = cut ? rho * cut->corner[a] * f
                  : rho * nh_cell_phi(t, c) * t->volume[t->cell_shape[c]] / 8.0 * f;
  }
  return NH_OK;
}

int nh_tissue_corner_masses(const nh_tissue *t, int c, const double *plane, double mc[8]) {
  return nh_corner_masses_at(t, c, nh_tissue_cell_cut(t, c), NH_CUT_DEPTH, plane, mc);
}

/* K₀ of leaf c: the shape's, or λ_c K_λ + μ_c K_μ with materials per label
 * (B-bar: the deviatoric part μ_c (K_μ − ⅔ K_λ), λ → −⅔μ as in hex.c). */
static const double *nh_cell_K0(const nh_tissue *t, int c, double buf[576]) {
  int s = t->cell_shape[c];
  if (!t->n_labels) return t->K0 + 576 * s;
  const double *cm = t->cell_material + NH_CELL_MATERIAL * c, *Kl = t->Kl + 576 * s,
               *Km = t->Km + 576 * s;
  const double lam = t->material.formulation == NH_FORMULATION_BBAR ? -2.0 * cm[1] / 3.0 : cm[0];
  for (int i = 0; i < 576; i++) buf[i] = lam * Kl[i] + cm[1] * Km[i];
  return buf;
}

int nh_tissue_set_label_materials(nh_tissue *t, int n, const int *labels,
                                  const nh_material *materials) {
  const nh_mesh *m = t->mesh;
  free(t->label), free(t->label_material), free(t->Kl), free(t->Km), free(t->cell_material);
  t->label = NULL, t->label_material = NULL, t->Kl = t->Km = t->cell_material = NULL;
  t->n_labels = 0;
  if (n == 0) return nh_tissue_update(t);
  NH_CHECK(m->domain.labels, NH_ERR_INPUT, "materials per label need a label image");
  t->label = nh_calloc((size_t)n, sizeof(int));
  t->label_material = nh_calloc((size_t)n, sizeof(nh_material));
  size_t cap = t->cap_shapes > 0 ? (size_t)t->cap_shapes : 1;
  t->Kl = nh_calloc((size_t)576 * cap, sizeof(double));
  t->Km = nh_calloc((size_t)576 * cap, sizeof(double));
  t->cell_material =
      nh_calloc(NH_CELL_MATERIAL * (size_t)(t->cap_cells > 0 ? t->cap_cells : 1), sizeof(double));
  if (!t->label || !t->label_material || !t->Kl || !t->Km || !t->cell_material)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: materials per label");
  memcpy(t->label, labels, sizeof(int) * (size_t)n);
  memcpy(t->label_material, materials, sizeof(nh_material) * (size_t)n);
  t->n_labels = n;
  for (int s = 0; s < t->n_shapes; s++) { /* the key is the rest shape up to translation */
    double G[24], v;
    nh_hex_stiffness(t->key + 24 * s, 1.0, 0.0, 0, t->Kl + 576 * s, G, NULL, &v);
    nh_hex_stiffness(t->key + 24 * s, 0.0, 1.0, 0, t->Km + 576 * s, G, NULL, &v);
  }
  for (int c = 0; c < t->cap_cells; c++) t->cell_material[NH_CELL_MATERIAL * c] = NAN;
  return nh_tissue_update(t);
}

int nh_tissue_create(const nh_mesh *mesh, const nh_material *material, nh_tissue **out) {
  *out = NULL;
  nh_tissue *t = nh_calloc(1, sizeof *t);
  if (!t) return NH_ERR_MEMORY;
  t->mesh = mesh;
  t->material = *material;
  t->alpha = NH_TISSUE_ALPHA;
  nh_lame(material->young, material->poisson, &t->lambda, &t->mu);
  int rc = nh_tissue_update(t);
  if (rc) {
    nh_tissue_destroy(&t);
    return rc;
  }
  *out = t;
  return NH_OK;
}

/* The cell's tie (8x8 weights T, tangent T ⊗ I), or NULL. */
static const double *nh_cell_tie(const nh_tissue *t, int c) {
  int tie = c < t->cap_cell_tie ? t->cell_tie[c] : -1;
  return tie < 0 ? NULL : t->tie + 64 * tie;
}

/* K₀ and the B-bar data of leaf c (vol filled, or NULL returned in *volp). */
static const double *nh_cell_data(const nh_tissue *t, int c, double Kc[576], nh_hex_volumetric *vol,
                                  const nh_hex_volumetric **volp) {
  int s = t->cell_shape[c];
  double lambda, mu;
  nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
  const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
  *vol = (nh_hex_volumetric){cut ? cut->Gbar : t->Gbar + 24 * s, lambda + 2.0 * mu / 3.0,
                             cut ? cut->volume : t->volume[s]};
  *volp = nh_tissue_gbar(t, c) ? vol : NULL;
  return cut ? cut->K0 : nh_cell_K0(t, c, Kc);
}

const double *nh_tissue_g0(const nh_tissue *t, int c) {
  const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
  return cut ? cut->G0 : t->G0 + 24 * t->cell_shape[c];
}

void nh_tissue_element_force(const nh_tissue *t, int c, const double *u, double f[24],
                             double frame[NH_HEX_FRAME]) {
  const nh_mesh *m = t->mesh;
  double Xe[24], ue[24], Kc[576];
  nh_hex_volumetric vol;
  const nh_hex_volumetric *vp;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  nh_mesh_cell_coords(m, u, c, ue);
  const double *K0 = nh_cell_data(t, c, Kc, &vol, &vp);
  nh_hex_corot_force(Xe, ue, K0, nh_tissue_g0(t, c), vp, frame, f);
  double phi = nh_tissue_cell_cut(t, c) ? 1.0 : nh_cell_phi(t, c);
  if (phi != 1.0)
    for (int i = 0; i < 24; i++) f[i] *= phi;
  const double *T = nh_cell_tie(t, c);
  if (T)
    for (int a = 0; a < 8; a++)
      for (int b = 0; b < 8; b++)
        for (int k = 0; k < 3; k++) f[3 * a + k] += T[8 * a + b] * ue[3 * b + k];
}

void nh_tissue_element_tangent(const nh_tissue *t, int c, const double frame[NH_HEX_FRAME],
                               double Kt[576]) {
  double Kc[576];
  nh_hex_volumetric vol;
  const nh_hex_volumetric *vp;
  const double *K0 = nh_cell_data(t, c, Kc, &vol, &vp);
  nh_hex_corot_tangent(K0, nh_tissue_g0(t, c), vp, frame, Kt);
  double phi = nh_tissue_cell_cut(t, c) ? 1.0 : nh_cell_phi(t, c);
  if (phi != 1.0)
    for (int i = 0; i < 576; i++) Kt[i] *= phi;
  const double *T = nh_cell_tie(t, c);
  if (T)
    for (int a = 0; a < 8; a++)
      for (int b = 0; b < 8; b++)
        for (int k = 0; k < 3; k++) Kt[24 * (3 * a + k) + 3 * b + k] += T[8 * a + b];
}

void nh_tissue_element_rate_tangent(const nh_tissue *t, int c, const double frame[NH_HEX_FRAME],
                                    const double w[24], double D[576]) {
  double Kc[576];
  nh_hex_volumetric vol;
  const nh_hex_volumetric *vp;
  const double *K0 = nh_cell_data(t, c, Kc, &vol, &vp);
  nh_hex_corot_rate_tangent(K0, nh_tissue_g0(t, c), vp, frame, w, D);
  double phi = nh_tissue_cell_cut(t, c) ? 1.0 : nh_cell_phi(t, c);
  if (phi != 1.0)
    for (int i = 0; i < 576; i++) D[i] *= phi;
}

void nh_tissue_element_apply(const nh_tissue *t, int c, const double frame[NH_HEX_FRAME],
                             const double w[24], double y[24]) {
  double Kc[576];
  nh_hex_volumetric vol;
  const nh_hex_volumetric *vp;
  const double *K0 = nh_cell_data(t, c, Kc, &vol, &vp);
  nh_hex_corot_apply(K0, nh_tissue_g0(t, c), vp, frame, w, y);
  double phi = nh_tissue_cell_cut(t, c) ? 1.0 : nh_cell_phi(t, c);
  if (phi != 1.0)
    for (int i = 0; i < 24; i++) y[i] *= phi;
  const double *T = nh_cell_tie(t, c);
  if (T)
    for (int a = 0; a < 8; a++)
      for (int b = 0; b < 8; b++)
        for (int k = 0; k < 3; k++) y[3 * a + k] += T[8 * a + b] * w[3 * b + k];
}

void nh_tissue_element(const nh_tissue *t, int c, const double *u, double f[24], double Kt[576]) {
  double frame[NH_HEX_FRAME];
  nh_tissue_element_force(t, c, u, f, frame);
  nh_hex_frame_corotational(frame);
  if (Kt) nh_tissue_element_tangent(t, c, frame, Kt);
}

int nh_tissue_set_ties(nh_tissue *t, int n_regions, const nh_region *regions, const double *k,
                       double *volume) {
  const nh_mesh *m = t->mesh;
  if (m->n_cells > t->cap_cell_tie) {
    NH_TRY(nh_realloc((void **)&t->cell_tie, (size_t)m->n_cells, sizeof(int)));
    NH_TRY(nh_realloc((void **)&t->cell_tie_region, (size_t)m->n_cells, sizeof(int)));
    t->cap_cell_tie = m->n_cells;
  }
  for (int c = 0; c < m->n_cells; c++) t->cell_tie[c] = t->cell_tie_region[c] = -1;
  t->n_ties = 0;
  if (volume)
    for (int r = 0; r < n_regions; r++) volume[r] = 0.0;
  double T[64];
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l], entry = -1;
    for (int r = 0; r < n_regions; r++) {
      double v;
      NH_TRY(nh_mesh_region_tie(m, c, &regions[r], T, &v));
      if (v == 0.0) continue;
      if (volume) volume[r] += v;
      if (entry < 0) {
        if (t->n_ties >= t->cap_ties &&
            nh_grow((void **)&t->tie, &t->cap_ties, t->n_ties + 1, 64 * sizeof(double)))
          return NH_ERROR(NH_ERR_MEMORY, "out of memory: ties");
        entry = t->n_ties++;
        memset(t->tie + 64 * entry, 0, 64 * sizeof(double));
        t->cell_tie[c] = entry;
        t->cell_tie_region[c] = r;
      }
      for (int i = 0; i < 64; i++) t->tie[64 * entry + i] += k[r] * T[i];
    }
  }
  return NH_OK;
}

double nh_tissue_energy(const nh_tissue *t, const double *u) {
  const nh_mesh *m = t->mesh;
  double energy = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double Xe[24], ue[24], R[9], d[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_mesh_cell_coords(m, u, c, ue);
    /* ½ dᵀ K0 d with d computed as the force is (centroid-relative, no
     * cancellation of the coordinates' magnitude). */
    nh_hex_corotated(Xe, ue, nh_tissue_g0(t, c), R, d);
    double Kc[576];
    nh_hex_volumetric vol;
    const nh_hex_volumetric *vp;
    const double *K0 = nh_cell_data(t, c, Kc, &vol, &vp);
    const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
    double e = 0.0;
    for (int r = 0; r < 24; r++) {
      double kd = 0.0;
      for (int q = 0; q < 24; q++) kd += K0[24 * r + q] * d[q];
      e += d[r] * kd;
    }
    if (vp) {
      double theta = nh_hex_mean_dilatation(ue, vp->Gbar, NULL);
      e += vp->kappa * vp->volume * theta * theta;
    }
    energy += 0.5 * (cut ? 1.0 : nh_cell_phi(t, c)) * e;
    int tie = c < t->cap_cell_tie ? t->cell_tie[c] : -1;
    if (tie >= 0)
      for (int a = 0; a < 8; a++)
        for (int b = 0; b < 8; b++)
          for (int k = 0; k < 3; k++)
            energy += 0.5 * t->tie[64 * tie + 8 * a + b] * ue[3 * a + k] * ue[3 * b + k];
  }
  return energy;
}

void nh_tissue_gauss_stress(const nh_tissue *t, int c, const double *u, const double xi[3],
                            double s[6]) {
  const nh_mesh *m = t->mesh;
  double Xe[24], ue[24];
  nh_mesh_cell_coords(m, m->X, c, Xe);
  nh_mesh_cell_coords(m, u, c, ue);
  double lambda, mu;
  nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
  nh_hex_stress_at(Xe, ue, nh_tissue_g0(t, c), nh_tissue_gbar(t, c), lambda, mu, 1, xi, s, NULL);
}

void nh_tissue_cell_stress(const nh_tissue *t, int c, const double *u, double s[6]) {
  const double centre[3] = {0, 0, 0};
  nh_tissue_gauss_stress(t, c, u, centre, s);
}

const double *nh_tissue_gbar(const nh_tissue *t, int c) {
  if (t->material.formulation != NH_FORMULATION_BBAR) return NULL;
  const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
  return cut ? cut->Gbar : t->Gbar + 24 * t->cell_shape[c];
}

/* ---- cut cells (docs/theory.md §5c) ---- */

/* e->above of the cut entry e (its lo, hi, corner set) on the lattice of
 * `depth`: NaN without a drainage plane. */
static int nh_cut_above(const nh_tissue *t, nh_tissue_cut *e, int depth) {
  const double *p = t->drainage;
  if (!t->has_drainage) {
    for (int a = 0; a < 8; a++) e->above[a] = NAN;
    return NH_OK;
  }
  int above = 0;
  for (int a = 0; a < 8; a++) {
    double s = 0.0;
    for (int k = 0; k < 3; k++)
      s += ((nh_hex_corner[a][k] > 0 ? e->hi[k] : e->lo[k]) - p[k]) * p[3 + k];
    above += s > 0;
  }
  if (above == 0 || above == 8) {
    for (int a = 0; a < 8; a++) e->above[a] = above ? e->corner[a] : 0.0;
    return NH_OK;
  }
  return nh_part_above(&t->mesh->domain, e->lo, e->hi, depth, p, e->above);
}

/* The element data of a cut cell from the fitted weights w of its tissue
 * part (on the lattice `depth`): K0 = (1 − α) Σ_q w_q BᵀDB(ξ_q) + α K_cell,
 * the mean gradients and the centroid's gradients over the tissue part,
 * ∫ N_a, and ∫ N_a above the drainage plane. */
static int nh_cut_data(const nh_tissue *t, int c, const double Xe[24], const nh_cut_moments *mom,
                       const double w[27], int depth, nh_tissue_cut *e) {
  double lambda, mu, xi[81], Kf[576], G[24], Gb[24], v;
  nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
  const int bbar = t->material.formulation == NH_FORMULATION_BBAR;
  const double lam_q = bbar ? -2.0 * mu / 3.0 : lambda, a = t->alpha;
  /* the fictitious part: the whole cell, fully integrated, times α */
  if (nh_hex_stiffness(Xe, lambda, mu, 0, Kf, G, Gb, &v)) return NH_ERR_INPUT;
  e->lambda = lambda, e->mu = mu;
  e->volume = mom->volume, e->fraction = mom->volume / v;
  memcpy(e->w, w, sizeof e->w);
  for (int i = 0; i < 576; i++) e->K0[i] = a * Kf[i];
  memset(e->Gbar, 0, sizeof e->Gbar);
  nh_cut_points(xi);
  for (int q = 0; q < 27; q++) {
    double g[24];
    if (w[q] == 0.0 || !(nh_hex_gradients(Xe, xi + 3 * q, g) > 0.0)) continue;
    const double wq = (1.0 - a) * w[q];
    for (int i = 0; i < 24; i++) e->Gbar[i] += w[q] * g[i];
    nh_hex_point_stiffness(g, wq, lam_q, mu, e->K0);
  }
  double lo[3], hi[3];
  nh_hex_is_box(Xe, lo, hi);
  for (int k = 0; k < 3; k++) {
    e->lo[k] = lo[k], e->hi[k] = hi[k];
    e->xi[k] = mom->volume > 0.0
                   ? (mom->centroid[k] - 0.5 * (lo[k] + hi[k])) / (0.5 * (hi[k] - lo[k]))
                   : 0.0;
  }
  if (mom->volume > 0.0) {
    for (int i = 0; i < 24; i++) e->Gbar[i] /= mom->volume;
  } else {
    memcpy(e->Gbar, Gb, sizeof Gb);
  }
  if (!(nh_hex_gradients(Xe, e->xi, e->G0) > 0.0)) memcpy(e->G0, G, sizeof G);
  nh_cut_shape_integrals(w, e->corner, NULL);
  e->inside = 0;
  for (int q = 0; q < 35; q++) { /* 27 quadrature points, then the 8 corners */
    const double *z = q < 27 ? xi + 3 * q : nh_hex_corner[q - 27];
    double X[3];
    for (int k = 0; k < 3; k++) X[k] = 0.5 * (lo[k] + hi[k]) + 0.5 * (hi[k] - lo[k]) * z[k];
    if (nh_domain_level(&t->mesh->domain, X) <= 0.0) e->inside |= (uint64_t)1 << q;
  }
  return nh_cut_above(t, e, depth);
}

/* Leaf c's cut data one lattice finer (depth NH_CUT_DEPTH + 1), the
 * geometry term's (nh_tissue_geometry_residual). */
static int nh_cut_fine(const nh_tissue *t, int c, nh_tissue_cut *fine) {
  const nh_mesh *m = t->mesh;
  double Xe[24], lo[3], hi[3], w[27];
  nh_cut_moments mom;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  nh_hex_is_box(Xe, lo, hi);
  int rc = nh_cut_domain_cell_at(&m->domain, NH_CUT_DEPTH + 1, lo, hi, NULL, NULL, &mom, w);
  return rc ? rc : nh_cut_data(t, c, Xe, &mom, w, NH_CUT_DEPTH + 1, fine);
}

/* The finer data of every cut entry that has none yet (λ NaN), the leaves
 * in parallel (each writes its own entry). */
static int nh_tissue_fine_fill(nh_tissue *t) {
  const nh_mesh *m = t->mesh;
  int bad = 0, bad_rc = NH_OK;
#pragma omp parallel for schedule(dynamic, 8)
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l], k = c < t->cap_cell_cut ? t->cell_cut[c] : NH_CUT_NONE;
    if (k < 0 || t->fine[k].lambda == t->fine[k].lambda) continue;
    int rc = nh_cut_fine(t, c, t->fine + k);
    if (rc) {
#pragma omp critical(nh_tissue_fine_fill)
      bad = c, bad_rc = rc;
    }
  }
  if (bad_rc) return NH_ERROR(bad_rc, "cut cell %d: its quadrature one lattice finer failed", bad);
  return NH_OK;
}

/* The cut cells of every leaf: kept where the leaf's box and material are
 * those an entry was computed for, else computed. */
static int nh_tissue_cuts(nh_tissue *t) {
  const nh_mesh *m = t->mesh;
  if (m->n_cells > t->cap_cell_cut) {
    int old = t->cap_cell_cut;
    if (nh_grow((void **)&t->cell_cut, &t->cap_cell_cut, m->n_cells, sizeof(int)))
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: cut cells");
    for (int c = old; c < t->cap_cell_cut; c++) t->cell_cut[c] = NH_CUT_NONE;
  }
  if (!nh_domain_integrates_cuts(&m->domain)) { /* a box, or tissue.cut_cells: scaled */
    for (int c = 0; c < t->cap_cell_cut; c++) t->cell_cut[c] = NH_CUT_NONE;
    t->n_cut = 0;
    return NH_OK;
  }
  int *index = nh_calloc((size_t)t->cap_cell_cut, sizeof(int));
  /* the entry each new one was kept from (-1: computed), for the cache */
  int *from = t->fine ? nh_calloc((size_t)m->n_leaves + 1, sizeof(int)) : NULL;
  nh_tissue_cut *cut = NULL;
  int n_cut = 0, cap_cut = 0, rc = NH_OK;
  if (!index || (t->fine && !from)) {
    free(index), free(from);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: cut cells");
  }
  for (int c = 0; c < t->cap_cell_cut; c++) index[c] = NH_CUT_NONE;
  for (int l = 0; l < m->n_leaves && !rc; l++) {
    int c = m->leaves[l];
    double Xe[24], lo[3], hi[3], mid[3], diag = 0.0;
    nh_mesh_cell_coords(m, m->X, c, Xe);
    if (!nh_hex_is_box(Xe, lo, hi)) continue;
    for (int k = 0; k < 3; k++)
      mid[k] = 0.5 * (lo[k] + hi[k]), diag += 0.25 * (hi[k] - lo[k]) * (hi[k] - lo[k]);
    if (nh_domain_level(&m->domain, mid) < -sqrt(diag)) { /* 1-Lipschitz: all inside */
      index[c] = NH_CUT_WHOLE;
      continue;
    }
    if (n_cut >= cap_cut && nh_grow((void **)&cut, &cap_cut, n_cut + 1, sizeof *cut)) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: cut cells");
      break;
    }
    nh_tissue_cut *e = cut + n_cut;
    const nh_tissue_cut *old = nh_tissue_cell_cut(t, c);
    double lambda, mu;
    nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
    if (old && !memcmp(old->lo, lo, sizeof lo) && !memcmp(old->hi, hi, sizeof hi) &&
        old->lambda == lambda && old->mu == mu) {
      *e = *old;
      if (from) from[n_cut] = (int)(old - t->cut);
      index[c] = n_cut++;
      continue;
    }
    nh_cut_moments mom;
    double w[27];
    rc = nh_cut_domain_cell(&m->domain, lo, hi, NULL, NULL, &mom, w);
    if (rc) break;
    if (mom.volume >= (1.0 - 1e-12) * (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2])) {
      index[c] = NH_CUT_WHOLE;
      continue;
    }
    rc = nh_cut_data(t, c, Xe, &mom, w, NH_CUT_DEPTH, e);
    if (rc)
      NH_ERROR(rc, "cut cell %d (level %d) has a non-positive Jacobian", c, m->level[c]);
    else {
      if (from) from[n_cut] = -1;
      index[c] = n_cut++;
    }
  }
  nh_tissue_cut *fine = NULL;
  if (!rc && t->fine) { /* the kept entries keep their finer data */
    fine = nh_calloc((size_t)(cap_cut ? cap_cut : 1), sizeof *fine);
    if (!fine) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: cut cells' finer data");
    for (int k = 0; k < n_cut && fine; k++)
      if (from[k] >= 0)
        fine[k] = t->fine[from[k]];
      else
        fine[k].lambda = NAN;
  }
  free(from);
  if (rc) {
    free(index), free(cut);
    return rc;
  }
  free(t->cell_cut), free(t->cut);
  t->cell_cut = index, t->cut = cut, t->n_cut = n_cut, t->cap_cut = cap_cut;
  if (!fine) return NH_OK;
  free(t->fine);
  t->fine = fine;
  return nh_tissue_fine_fill(t);
}

int nh_tissue_set_geometry_cache(nh_tissue *t, int on) {
  free(t->fine);
  t->fine = NULL;
  if (!on) return NH_OK;
  t->fine = nh_calloc((size_t)(t->cap_cut ? t->cap_cut : 1), sizeof *t->fine);
  if (!t->fine) return NH_ERROR(NH_ERR_MEMORY, "out of memory: cut cells' finer data");
  for (int k = 0; k < t->n_cut; k++) t->fine[k].lambda = NAN;
  return nh_tissue_fine_fill(t);
}

int nh_tissue_set_drainage(nh_tissue *t, const double *plane) {
  const int same = plane && t->has_drainage && !memcmp(plane, t->drainage, sizeof t->drainage);
  t->has_drainage = plane != NULL;
  if (plane) memcpy(t->drainage, plane, sizeof t->drainage);
  for (int k = 0; k < t->n_cut; k++) {
    if (!same || t->cut[k].above[0] != t->cut[k].above[0])
      NH_TRY(nh_cut_above(t, t->cut + k, NH_CUT_DEPTH));
    nh_tissue_cut *f = t->fine ? t->fine + k : NULL;
    if (f && f->lambda == f->lambda && (!same || f->above[0] != f->above[0]))
      NH_TRY(nh_cut_above(t, f, NH_CUT_DEPTH + 1));
  }
  return NH_OK;
}

int nh_tissue_set_stabilisation(nh_tissue *t, double alpha) {
  t->alpha = alpha;
  for (int k = 0; k < t->n_cut; k++) t->cut[k].lambda = NAN; /* recompute every entry */
  return nh_tissue_update(t);
}

int nh_tissue_tissue_points(const nh_tissue *t, int c, double xi[3 * NH_TISSUE_POINTS]) {
  const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
  if (!cut) return -1;
  if (!(cut->volume > 0.0)) return 0;
  double q[81];
  nh_cut_points(q);
  memcpy(xi, cut->xi, 3 * sizeof(double));
  int n = 1;
  for (int p = 0; p < 35; p++)
    if (cut->inside >> p & 1)
      memcpy(xi + 3 * n++, p < 27 ? q + 3 * p : nh_hex_corner[p - 27], 3 * sizeof(double));
  return n;
}

int nh_tissue_cell_inverted(const nh_tissue *t, int c, const double *u) {
  const nh_mesh *m = t->mesh;
  double X[24], x[24], pts[3 * NH_TISSUE_POINTS];
  nh_mesh_cell_coords(m, m->X, c, X);
  nh_mesh_cell_coords(m, u, c, x);
  for (int i = 0; i < 24; i++) x[i] += X[i];
  const int n = nh_tissue_tissue_points(t, c, pts);
  if (n < 0) return nh_hex_inverted(x);
  for (int p = 0; p < n; p++)
    if (!(nh_hex_det(x, pts + 3 * p) > 0.0)) return 1;
  return 0;
}

/* Leaf c's elastic force at u with the cut data e (the corotational
 * element of nh_tissue_element_force, without the tie). */
static void nh_cut_force(const nh_tissue *t, int c, const nh_tissue_cut *e, const double *u,
                         double f[24]) {
  const nh_mesh *m = t->mesh;
  double Xe[24], ue[24], frame[NH_HEX_FRAME];
  nh_mesh_cell_coords(m, m->X, c, Xe);
  nh_mesh_cell_coords(m, u, c, ue);
  nh_hex_volumetric vol = {e->Gbar, e->lambda + 2.0 * e->mu / 3.0, e->volume};
  const int bbar = t->material.formulation == NH_FORMULATION_BBAR;
  nh_hex_corot_force(Xe, ue, e->K0, e->G0, bbar ? &vol : NULL, frame, f);
}

int nh_tissue_geometry_residual(const nh_tissue *t, int c, const double *u,
                                const nh_geometry_loads *loads, double r[24]) {
  const nh_mesh *m = t->mesh;
  const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
  memset(r, 0, 24 * sizeof(double));
  if (!cut) return 0;
  double f0[24], f1[24];
  nh_tissue_cut computed;
  const nh_tissue_cut *fine = t->fine ? t->fine + (cut - t->cut) : NULL;
  if (!fine || fine->lambda != fine->lambda) { /* not cached */
    int rc = nh_cut_fine(t, c, &computed);
    if (rc) return -rc;
    fine = &computed;
  }
  nh_cut_force(t, c, cut, u, f0);
  nh_cut_force(t, c, fine, u, f1);
  for (int i = 0; i < 24; i++) r[i] = f0[i] - f1[i];
  if (!loads) return 1;
  /* the body force acts on the mass (above the drainage plane, if any),
   * each lattice's own: its half-space cut at that depth where the plane
   * crosses the leaf */
  double m0[8], m1[8];
  int rc = nh_corner_masses_at(t, c, cut, NH_CUT_DEPTH, loads->plane, m0);
  if (!rc) rc = nh_corner_masses_at(t, c, fine, NH_CUT_DEPTH + 1, loads->plane, m1);
  if (rc) return -rc;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) r[3 * a + k] += (m1[a] - m0[a]) * loads->body[k];
  for (int q = 0; q < loads->n_tractions; q++) {
    const double factor = loads->traction_factor ? loads->traction_factor[q] : 1.0;
    if (factor == 0.0) continue;
    nh_traction_cell(m, c, loads->tractions + q, NH_CUT_DEPTH, f0);
    nh_traction_cell(m, c, loads->tractions + q, NH_CUT_DEPTH + 1, f1);
    for (int i = 0; i < 24; i++) r[i] += factor * (f1[i] - f0[i]);
  }
  return 1;
}
