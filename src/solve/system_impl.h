/* system_impl.h — the layout of nh_system, private to the solve module. */
#ifndef NH_SYSTEM_IMPL_H
#define NH_SYSTEM_IMPL_H

#include "solve/solve.h"
#include <cholmod.h>

struct nh_system {
  const nh_tissue *tissue; /* borrowed; tissue->mesh is the mesh */
  int n_nodes;
  int n_free;
  int *free_of; /* 3 per node: free index, -1 if fixed */
  int *dof_of;  /* n_free: the nodal DOF of each unknown */

  /* A, upper triangle, CSC over free DOFs; values live in A->x. */
  cholmod_common cm;
  cholmod_sparse *A;
  cholmod_factor *L;
  int *diag; /* n_free: position of the diagonal entry of each column */

  int *scatter; /* 576 per leaf (leaf order): position in A->x of K_e[r][c], -1 if not stored */
  int n_colours;
  int *colour_start; /* n_colours + 1 */
  int *colour_leaf;  /* leaf indices grouped by colour */

  /* Work vectors for cholmod_solve2 and the integrators. */
  cholmod_dense *B, *X, *Y, *E;
  double *work[4];  /* 3 per node each */
  double *fwork[2]; /* n_free each */
};

#endif
