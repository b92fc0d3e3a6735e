/* beam_impl.h — the tool's data, private to src/beam. */
#ifndef NH_BEAM_IMPL_H
#define NH_BEAM_IMPL_H

#include "beam/beam.h"

struct nh_beam {
  int n;         /* elements */
  double length; /* L */
  double l0;     /* element rest length L / n */
  nh_beam_section section;
  nh_beam_constants c;
  double *x, *T, *v;      /* current state: 3, 9, 6 per node */
  double *X, *T0;         /* rest state: 3, 9 per node */
  nh_beam_system *system; /* nh_beam_step_system's, created on first use */
};

/* Skew matrix S(a): S(a) b = a × b. */
void nh_beam_skew(const double a[3], double S[9]);

/* Element kernel on explicit end states (element.c): strain energy returned;
 * d[7], E[9], f[12], K[144] may each be NULL. */
double nh_beam_corot(const double x1[3], const double x2[3], const double T1[9], const double T2[9],
                     double l0, const nh_beam_constants *c, double young, double d[7], double E[9],
                     double f[12], double K[144]);

#endif
