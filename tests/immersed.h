/* immersed.h — the immersed ball of the cut-cell tests (test_fcm,
 * test_dwr_skull, test_geometry_term): a sphere domain with integrated cut
 * cells on g³ cells over its bounding box, and its tissue (ν 0.45,
 * ρ 1000 kg/m³, B-bar) when t is not NULL. */
#ifndef NH_TEST_IMMERSED_H
#define NH_TEST_IMMERSED_H

#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"

__attribute__((unused)) static void immersed_ball(const double centre[3], double radius, int g,
                                                  double young, nh_domain *d, nh_mesh **m,
                                                  nh_tissue **t) {
  nh_domain_sphere(centre, radius, d);
  d->cut_cells = NH_CUT_CELLS_INTEGRATED;
  const int grid[3] = {g, g, g};
  CHECK_OK(nh_mesh_create(d, grid, m));
  nh_material mat = {young, 0.45, 1000.0, NH_FORMULATION_BBAR};
  if (t) CHECK_OK(nh_tissue_create(*m, &mat, t));
}

#endif
