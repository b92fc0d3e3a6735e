/* setup.c — everything that depends on the mesh, built at creation and
 * after every refinement (nh_sim_setup_mesh), in named parts: the per-node
 * arrays, the fixed nodes and the ties of fixed regions (docs/theory.md §5,
 * "Fixed regions"), the hanging nodes (docs/theory.md §6.4), the tissue's
 * element data (fem), the drained mass under buoyancy, the load vectors,
 * the embedded points (probes.c), the tools' embedded points and the
 * linear system (solve). At creation, errors only the mesh reveals are the
 * scene's (NH_ERR_INPUT, naming the key); after a refinement, ours. */
#include "sim/sim_impl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Resize a per-node array of `comps` doubles to the mesh's node count. */
static int nh_resize(double **a, int n_nodes, int comps) {
  return nh_realloc((void **)a, (size_t)comps * (size_t)n_nodes, sizeof(double));
}

/* A fixed region's tie stiffness is NH_TIE_STIFFNESS E / ℓ², ℓ its smallest
 * size (nh_region_size): the tissue inside moves by about 1/NH_TIE_STIFFNESS
 * of what an elastic body of size ℓ would (docs/theory.md §5). */
#define NH_TIE_STIFFNESS 1.0e3

/* tissue.fixed[r] on an immersed domain is a volumetric tie (all components
 * clamped, no prescribed motion, a geometric region), not a node set. */
static int nh_sim_fixed_is_tie(const nh_scene *sc, int immersed, int r) {
  const nh_fix *fx = &sc->tissue.fix[r];
  return immersed && sc->tissue.fixed[r].kind != NH_REGION_LABEL && fx->axes == 7 &&
         fx->displacement[0] == 0.0 && fx->displacement[1] == 0.0 && fx->displacement[2] == 0.0;
}

int nh_sim_refine_fixed(nh_sim *s) {
  const nh_scene *sc = s->scene;
  nh_mesh *m = s->mesh;
  int any = 0, passes = 0, n_before = m->n_leaves;
  for (int r = 0; r < sc->tissue.n_fixed; r++) any |= sc->tissue.fix[r].refine > 0.0;
  if (!any) return NH_OK;
  nh_template *tmpl = NULL;
  int *marked = NULL, rc = nh_template_load(sc->adapt.template_path, &tmpl);
  while (!rc) {
    free(marked);
    if (!(marked = nh_calloc((size_t)m->n_leaves, sizeof(int)))) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: refining at the fixed regions");
      break;
    }
    int n = 0, at = -1;
    for (int l = 0; l < m->n_leaves; l++)
      for (int r = 0; r < sc->tissue.n_fixed; r++) {
        double h = sc->tissue.fix[r].refine;
        if (h > 0.0 && nh_mesh_cell_coarser_at(m, m->leaves[l], &sc->tissue.fixed[r], h)) {
          marked[n++] = m->leaves[l], at = r;
          break;
        }
      }
    if (n == 0) break;
    if (sc->limits.max_cells > 0 && m->n_leaves + 7 * n > sc->limits.max_cells) {
      rc = NH_ERROR(NH_ERR_INPUT,
                    "%s.refine: refining the region to %g m needs more than limits.max_cells = %d "
                    "cells",
                    sc->tissue.fixed[at].where, sc->tissue.fix[at].refine, sc->limits.max_cells);
      break;
    }
    if (!(rc = nh_mesh_grade_marks(m, marked, &n))) rc = nh_mesh_refine(m, tmpl, marked, n, NULL);
    passes++;
  }
  if (!rc)
    nh_log_info("fixed regions refined: %d passes, %d -> %d leaves", passes, n_before, m->n_leaves);
  free(marked);
  nh_template_destroy(&tmpl);
  return rc;
}

/* The per-node arrays at the mesh's node count: none fixed, none moved. */
static int nh_sim_resize_nodes(nh_sim *s) {
  const nh_scene *sc = s->scene;
  const int nn = s->mesh->n_nodes;
  NH_TRY(nh_realloc((void **)&s->fixed, (size_t)nn, 1));
  memset(s->fixed, 0, (size_t)nn);
  NH_TRY(nh_resize(&s->x, nn, 3));
  NH_TRY(nh_resize(&s->u_start, nn, 3));
  NH_TRY(nh_resize(&s->v_start, nn, 3));
  NH_TRY(nh_resize(&s->f_ext, nn, 3));
  NH_TRY(nh_resize(&s->drained, nn, 1));
  const int n_unit = sc->tissue.n_loads + sc->tissue.n_tractions;
  NH_TRY(nh_resize(&s->load_unit, nn, 3 * (n_unit ? n_unit : 1)));
  NH_TRY(nh_realloc((void **)&s->moved, (size_t)nn, sizeof(int)));
  for (int i = 0; i < nn; i++) s->moved[i] = -1;
  return NH_OK;
}

/* Fixed regions (docs/theory.md §5, "Fixed regions"): on a box domain the
 * nodes inside; on an immersed one a clamp of all components is a stiff
 * volumetric tie over the region's tissue (nh_sim_ties), which converges
 * to the region under refinement (per-axis and prescribed regions stay node
 * sets). A region without a node is the scene's fault at creation. */
static int nh_sim_fixed_nodes(nh_sim *s, int first) {
  const nh_scene *sc = s->scene;
  const nh_mesh *m = s->mesh;
  const int nn = m->n_nodes, immersed = m->domain.kind != NH_DOMAIN_BOX;
  unsigned char *in = nh_calloc((size_t)(nn ? nn : 1), 1);
  if (!in) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %d nodes", nn);
  for (int r = 0; r < sc->tissue.n_fixed; r++) {
    const nh_region *reg = &sc->tissue.fixed[r];
    const nh_fix *fx = &sc->tissue.fix[r];
    if (nh_sim_fixed_is_tie(sc, immersed, r)) continue; /* tied: nh_sim_ties */
    memset(in, 0, (size_t)nn);
    int count = nh_mesh_nodes_in_region(m, reg, in);
    const int prescribed =
        fx->displacement[0] != 0.0 || fx->displacement[1] != 0.0 || fx->displacement[2] != 0.0;
    for (int i = 0; i < nn; i++) {
      if (!in[i]) continue;
      /* merge with the components fixed so far; all three: 1 */
      int mask = (s->fixed[i] == 0              ? 0
                  : (s->fixed[i] & NH_FIX_AXES) ? s->fixed[i] & 7
                                                : 7) |
                 fx->axes;
      s->fixed[i] = mask == 7 ? 1 : (unsigned char)(NH_FIX_AXES | mask);
      if (prescribed) s->moved[i] = r;
    }
    char what[256];
    nh_region_describe(reg, what, sizeof what);
    if (!(count > 0 || !first)) free(in);
    NH_CHECK(count > 0 || !first, NH_ERR_INPUT, "%s: the %s contains no node of the mesh",
             reg->where, what);
  }
  free(in);
  return NH_OK;
}

/* Hanging nodes: every node not fixed in all three components (a node
 * fixed in some axes keeps the hanging constraint on all three: its
 * masters lie on the same fixed face); the Lagrange variant's rows take
 * whole nodes: there every fixed node is left out. With integrated cut
 * cells also the aggregated nodes (docs/theory.md §5c): the ill-posed nodes
 * without a fixed component, by the tissue's support measures. A mesh
 * refined without an adapt section (tissue.fixed.N.refine) has hanging
 * nodes too: left free, the refined zone would be joined to its coarse
 * neighbours at their corners only (scaled cut cells: static Newton stalled
 * at relative residual 0.83 on tests/data/brain.yaml refined to 5 mm). */
static int nh_sim_hanging_nodes(nh_sim *s) {
  const nh_scene *sc = s->scene;
  const nh_mesh *m = s->mesh;
  const int nn = m->n_nodes, lagrange = sc->adapt.hanging == NH_HANGING_LAGRANGE;
  const int aggregate = nh_domain_integrates_cuts(&m->domain);
  nh_hanging_destroy(&s->hanging);
  int refined = 0;
  for (int l = 0; l < m->n_leaves && !refined; l++) refined = m->level[m->leaves[l]] > 0;
  if (!sc->adapt.enabled && !aggregate && !refined) return NH_OK;
  const size_t n1 = (size_t)(nn ? nn : 1);
  unsigned char *in = nh_calloc(2 * n1, 1), *keep = in + n1;
  double *support = nh_calloc(n1 + (size_t)m->n_cells, sizeof(double)), *fraction = support + n1;
  int rc = in && support ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: %d nodes", nn);
  for (int i = 0; i < nn && !rc; i++) {
    in[i] = s->fixed[i] == 1 || (lagrange && s->fixed[i]);
    keep[i] = s->fixed[i] != 0;
  }
  if (!rc && aggregate) {
    rc = nh_tissue_node_support(s->tissue, support);
    for (int l = 0; l < m->n_leaves; l++)
      fraction[m->leaves[l]] = nh_tissue_fraction(s->tissue, m->leaves[l]);
  }
  const nh_aggregation agg = {support, fraction, NH_AGGREGATE_MIN, keep};
  int orphans = 0;
  if (!rc) rc = nh_hanging_detect_aggregated(m, in, aggregate ? &agg : NULL, &s->hanging, &orphans);
  if (!rc && aggregate && nh_log_get_level() >= NH_LOG_DEBUG)
    nh_log_info("aggregated nodes: %d tied to a root leaf, %d ill posed without one",
                s->hanging->n_aggregated, orphans);
  free(in), free(support);
  return rc;
}

/* The tissue's element data: created at the first build (with the label
 * images' materials), updated after a refinement. */
static int nh_sim_tissue_build(nh_sim *s, int first) {
  const nh_scene *sc = s->scene;
  if (!first) return nh_tissue_update(s->tissue);
  nh_material mat = {sc->tissue.young, sc->tissue.poisson, sc->tissue.density,
                     sc->tissue.formulation};
  NH_TRY(nh_tissue_create(s->mesh, &mat, &s->tissue));
  /* the goal estimate's geometry term: the cut cells one lattice finer,
   * computed once per leaf (adapt/dwr.c, "Geometry"), with their materials */
  const int cache = sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL &&
                    nh_domain_integrates_cuts(&s->mesh->domain);
  if (!sc->tissue.n_materials) return cache ? nh_tissue_set_geometry_cache(s->tissue, 1) : NH_OK;
  int n = sc->tissue.n_materials, *labels = nh_calloc((size_t)n, sizeof(int));
  nh_material *mats = nh_calloc((size_t)n, sizeof(nh_material));
  int rc = labels && mats ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: materials");
  for (int i = 0; i < n && !rc; i++) {
    const nh_label_material *lm = &sc->tissue.materials[i];
    labels[i] = lm->label;
    mats[i] = (nh_material){lm->young, lm->poisson, lm->density, sc->tissue.formulation};
  }
  if (!rc) rc = nh_tissue_set_label_materials(s->tissue, n, labels, mats);
  free(labels), free(mats);
  if (!rc && cache) rc = nh_tissue_set_geometry_cache(s->tissue, 1);
  return rc;
}

/* The ties of the fixed regions on an immersed domain: stiffness
 * NH_TIE_STIFFNESS E / ℓ² over the tissue inside each; a tie without
 * tissue is the scene's fault at creation. */
static int nh_sim_ties(nh_sim *s, int first) {
  const nh_scene *sc = s->scene;
  const int immersed = s->mesh->domain.kind != NH_DOMAIN_BOX, nr = sc->tissue.n_fixed;
  if (!immersed || nr == 0) return NH_OK;
  double *k = nh_calloc(2 * (size_t)nr, sizeof(double));
  if (!k) return NH_ERROR(NH_ERR_MEMORY, "out of memory: ties");
  double *vol = k + nr;
  for (int r = 0; r < nr; r++) {
    double l = nh_region_size(&sc->tissue.fixed[r]);
    k[r] = nh_sim_fixed_is_tie(sc, immersed, r) && l > 0.0 && isfinite(l)
               ? NH_TIE_STIFFNESS * sc->tissue.young / (l * l)
               : 0.0;
  }
  int rc = nh_tissue_set_ties(s->tissue, nr, sc->tissue.fixed, k, vol);
  for (int r = 0; r < nr && !rc; r++) {
    if (!nh_sim_fixed_is_tie(sc, immersed, r)) continue;
    char what[256];
    nh_region_describe(&sc->tissue.fixed[r], what, sizeof what);
    if (first && s->options.progress) /* Σ ∫ χ dV of the quadrature: region ∩ tissue */
      nh_log_info("tie %d (%s): tissue volume %.6g m^3, stiffness %.4g N/m^4", r, what, vol[r],
                  k[r]);
    if (!(vol[r] > 0.0))
      rc = NH_ERROR(first ? NH_ERR_INPUT : NH_ERR_INTERNAL,
                    "%s: the %s holds no tissue (on an immersed domain a fixed region ties the "
                    "tissue inside it, so it needs a volume inside the shape)",
                    sc->tissue.fixed[r].where, what);
  }
  free(k);
  return rc;
}

int nh_sim_drainage_plane(const nh_scene *sc, double plane[6]) {
  if (!sc->tissue.buoyant || !sc->tissue.buoyancy_has_level) return 0;
  const double *g = sc->gravity;
  double gn = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  for (int k = 0; k < 3; k++) plane[k] = sc->tissue.buoyancy_level[k], plane[3 + k] = -g[k] / gn;
  return 1;
}

/* The drained mass: all of it, or the part above the fluid level. */
static int nh_sim_drained_mass(nh_sim *s) {
  const nh_mesh *m = s->mesh;
  double plane[6];
  memcpy(s->drained, s->tissue->mass, sizeof(double) * (size_t)m->n_nodes);
  if (!nh_sim_drainage_plane(s->scene, plane)) return NH_OK;
  NH_TRY(nh_tissue_set_drainage(s->tissue, plane)); /* the cut entries keep their part above */
  memset(s->drained, 0, sizeof(double) * (size_t)m->n_nodes);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double mc[8];
    NH_TRY(nh_tissue_corner_masses(s->tissue, c, plane, mc));
    for (int a = 0; a < 8; a++) s->drained[m->cells[8 * c + a]] += mc[a];
  }
  return NH_OK;
}

/* The nodal forces of each load, then each traction, at factor 1. */
static int nh_sim_load_vectors(nh_sim *s) {
  const nh_scene *sc = s->scene;
  const nh_mesh *m = s->mesh;
  const int n = 3 * m->n_nodes, n_unit = sc->tissue.n_loads + sc->tissue.n_tractions;
  memset(s->load_unit, 0, sizeof(double) * (size_t)n * (size_t)n_unit);
  for (int l = 0; l < sc->tissue.n_loads; l++)
    NH_TRY(nh_mesh_region_load(m, &sc->tissue.loads[l].region, sc->tissue.loads[l].force,
                               s->load_unit + (size_t)l * n));
  for (int l = 0; l < sc->tissue.n_tractions; l++)
    NH_TRY(nh_traction_load(m, &sc->tissue.tractions[l],
                            s->load_unit + (size_t)(sc->tissue.n_loads + l) * n, NULL));
  return NH_OK;
}

/* The tissue's linear system (fixed DOFs and, under adapt.hanging:
 * eliminate, hanging nodes eliminated; under lagrange, their rows). After a
 * mesh change (transfer: how adapt carried the fields) with factor reuse,
 * the new system preconditions with the old one's factor until it
 * factorises its own (solve/inherit.c). */
static int nh_sim_system_build(nh_sim *s, const nh_node_transfer *transfer) {
  const nh_scene *sc = s->scene;
  const int lagrange = sc->adapt.hanging == NH_HANGING_LAGRANGE;
  nh_system *old = s->system;
  s->system = NULL;
  int rc = nh_system_create(s->tissue, s->fixed, lagrange ? NULL : s->hanging, &s->system);
  if (rc == NH_ERR_INPUT)
    rc = NH_ERROR(NH_ERR_INPUT, "%s: every node of the tissue is fixed: nothing to simulate",
                  sc->tissue.where_fixed);
  if (!rc && lagrange) rc = nh_system_set_hanging_rows(s->system, s->hanging);
  if (!rc && transfer && s->integrator.reuse) rc = nh_system_inherit(s->system, old, transfer);
  nh_system_destroy(&old);
  return rc;
}

/* Cut leaves whose tissue falls apart inside them (the brain's fissure in
 * a cell column straddling the midline): one trilinear element joins the
 * parts through its nodes. Reported, not split: on dbs-skull.yaml the joint
 * alone moves the STN by < 1 % (docs/dbs.md, "Isolating the odd grids'
 * offset"). */
static int nh_sim_report_split_cells(const nh_sim *s) {
  if (!nh_domain_integrates_cuts(&s->mesh->domain)) return NH_OK;
  int n_split, most;
  NH_TRY(nh_mesh_split_cells(s->mesh, &n_split, &most));
  if (n_split)
    nh_log_info("cut cells: %d of %d leaves hold tissue in 2..%d disconnected parts, joined "
                "by their one element",
                n_split, s->mesh->n_leaves, most);
  return NH_OK;
}

int nh_sim_setup_mesh(nh_sim *s, int first) {
  NH_TRY(nh_sim_resize_nodes(s));
  NH_TRY(nh_sim_fixed_nodes(s, first));
  NH_TRY(nh_sim_tissue_build(s, first));
  if (first) NH_TRY(nh_sim_report_split_cells(s));
  NH_TRY(nh_sim_hanging_nodes(s));
  NH_TRY(nh_sim_ties(s, first));
  NH_TRY(nh_sim_drained_mass(s));
  NH_TRY(nh_sim_load_vectors(s));
  NH_TRY(nh_sim_locate_points(s, first));
  if (!first && s->contact) NH_TRY(nh_contact_relocate(s->contact, s->mesh));
  return nh_sim_system_build(s, first ? NULL : nh_adapt_last_transfer(s->adapt));
}
