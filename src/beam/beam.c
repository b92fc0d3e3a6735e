/* beam.c — a tool as a chain of corotational beam elements: creation,
 * state, assembly of internal forces, lumped mass, gravity, and points on
 * the deformed axis by cubic Hermite interpolation (docs/beam.md §4-6).
 *
 * Section: hollow circular tube, A = π (r² − rᵢ²), I = π (r⁴ − rᵢ⁴)/4 about
 * both bending axes, torsion constant J = 2I, G = E / (2 (1 + ν)).
 *
 * Assembly: element e couples nodes e and e+1, whose 12 DOFs are the
 * contiguous global DOFs 6e … 6e+11, so the assembled tangent is banded
 * (half bandwidth 11) and the global vector layout is node-major.
 *
 * Mass: lumped. Translations ρAl₀/2 per node and element (the seed's lumped
 * mass). Rotations: the physical rotary inertia of a slender section is
 * ρI l₀/2 about the bending axes and ρJ l₀/2 = ρ I l₀ about the axis. We
 * use the isotropic ρ J l₀/2 about all three axes: an isotropic inertia
 * makes the rotational mass frame independent (no gyroscopic term ω × Iω,
 * no dependence on T), and doubling the tiny bending inertia changes the
 * translational dynamics by O((r/l₀)²). Gravity as lumped loads is M g; the
 * consistent load of the cubic element adds end moments ± q l₀²/12.
 *
 * Points: a point at rest arc length s lies in element e = ⌊s/l₀⌋ at
 * ξ = s/l₀ − e; it is interpolated with the cubic Hermite functions through
 * the end positions and the end tangents l₀ d1 (d1 = the nodal axis
 * director). For a beam whose exact deflection is cubic per element (EB
 * with end loads only) this reproduces the exact deflection curve between
 * nodes (to first order in the rotations); the straight chord does not, and
 * a chord-wise axis would give force spikes at nodes for sliding contacts.
 * Its linearisation δx = Σ Hₐ δxₐ − l₀ (H2 S(t1) δw1 + H4 S(t2) δw2) is the
 * 3x12 block J, and forces go back to the nodes by Jᵀ. J uses the rest
 * length l₀, not the current chord, so J depends on the state only through
 * the tangents (needed for exact transposes: δl would add a non-local term). */
#include "beam/beam_impl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

int nh_beam_section_constants(const nh_beam_section *s, nh_beam_constants *out) {
  NH_CHECK(s->young > 0 && isfinite(s->young), NH_ERR_INPUT,
           "beam section: young = %g must be positive", s->young);
  NH_CHECK(s->poisson > -1.0 && s->poisson < 0.5, NH_ERR_INPUT,
           "beam section: poisson = %g must lie in (-1, 0.5)", s->poisson);
  NH_CHECK(s->radius > 0 && isfinite(s->radius), NH_ERR_INPUT,
           "beam section: radius = %g must be positive", s->radius);
  NH_CHECK(s->inner_radius >= 0 && s->inner_radius < s->radius, NH_ERR_INPUT,
           "beam section: inner_radius = %g must lie in [0, radius = %g)", s->inner_radius,
           s->radius);
  NH_CHECK(s->density >= 0 && isfinite(s->density), NH_ERR_INPUT,
           "beam section: density = %g must be >= 0", s->density);
  const double pi = NH_PI, r = s->radius, ri = s->inner_radius;
  out->area = pi * (r * r - ri * ri);
  out->inertia = 0.25 * pi * (r * r * r * r - ri * ri * ri * ri);
  out->polar = 2.0 * out->inertia;
  out->shear = s->young / (2.0 * (1.0 + s->poisson));
  return NH_OK;
}

int nh_beam_create(const nh_beam_spec *spec, nh_beam **out) {
  *out = NULL;
  nh_beam_constants c;
  NH_TRY(nh_beam_section_constants(&spec->section, &c));
  NH_CHECK(spec->elements >= 1, NH_ERR_INPUT, "beam: elements = %d must be >= 1", spec->elements);
  NH_CHECK(spec->length > 0 && isfinite(spec->length), NH_ERR_INPUT,
           "beam: length = %g must be positive", spec->length);
  const double *d = spec->direction;
  double dn = nh_vec3_norm(d);
  NH_CHECK(dn > 0 && isfinite(dn), NH_ERR_INPUT, "beam: direction must be a non-zero vector");
  double d1[3] = {d[0] / dn, d[1] / dn, d[2] / dn}, d2[3], d3[3];
  /* d2: the given normal made orthogonal to d1, else the coordinate axis
   * least aligned with d1, made orthogonal. */
  const double *nv = spec->normal;
  double pn = nh_vec3_dot(nv, d1), n2 = 0.0;
  for (int i = 0; i < 3; i++) d2[i] = nv[i] - pn * d1[i], n2 += d2[i] * d2[i];
  double nn = nh_vec3_norm(nv);
  if (!(sqrt(n2) > 1e-6 * nn) || nn == 0.0) {
    int k = 0;
    for (int i = 1; i < 3; i++)
      if (fabs(d1[i]) < fabs(d1[k])) k = i;
    n2 = 0.0;
    for (int i = 0; i < 3; i++) d2[i] = (i == k) - d1[k] * d1[i], n2 += d2[i] * d2[i];
  }
  n2 = sqrt(n2);
  for (int i = 0; i < 3; i++) d2[i] /= n2;
  d3[0] = d1[1] * d2[2] - d1[2] * d2[1];
  d3[1] = d1[2] * d2[0] - d1[0] * d2[2];
  d3[2] = d1[0] * d2[1] - d1[1] * d2[0];

  nh_beam *b = nh_calloc(1, sizeof *b);
  if (!b) return NH_ERR_MEMORY;
  const int nn_ = spec->elements + 1;
  b->n = spec->elements;
  b->length = spec->length;
  b->l0 = spec->length / spec->elements;
  b->section = spec->section;
  b->c = c;
  b->x = nh_calloc((size_t)nn_ * 3, sizeof(double));
  b->T = nh_calloc((size_t)nn_ * 9, sizeof(double));
  b->v = nh_calloc((size_t)nn_ * 6, sizeof(double));
  b->X = nh_calloc((size_t)nn_ * 3, sizeof(double));
  b->T0 = nh_calloc((size_t)nn_ * 9, sizeof(double));
  if (!b->x || !b->T || !b->v || !b->X || !b->T0) {
    nh_beam_destroy(&b);
    return NH_ERR_MEMORY;
  }
  for (int a = 0; a < nn_; a++)
    for (int i = 0; i < 3; i++) {
      b->X[3 * a + i] = spec->base[i] + a * b->l0 * d1[i];
      b->T0[9 * a + 3 * i] = d1[i], b->T0[9 * a + 3 * i + 1] = d2[i];
      b->T0[9 * a + 3 * i + 2] = d3[i];
    }
  nh_beam_reset(b);
  *out = b;
  return NH_OK;
}

void nh_beam_destroy(nh_beam **beam) {
  if (!beam || !*beam) return;
  nh_beam *b = *beam;
  free(b->x), free(b->T), free(b->v), free(b->X), free(b->T0);
  nh_beam_system_destroy(&b->system);
  free(b);
  *beam = NULL;
}

int nh_beam_elements(const nh_beam *b) {
  return b->n;
}
int nh_beam_nodes(const nh_beam *b) {
  return b->n + 1;
}
int nh_beam_dofs(const nh_beam *b) {
  return 6 * (b->n + 1);
}
double nh_beam_length(const nh_beam *b) {
  return b->length;
}
const nh_beam_constants *nh_beam_get_constants(const nh_beam *b) {
  return &b->c;
}
double *nh_beam_positions(nh_beam *b) {
  return b->x;
}
double *nh_beam_directors(nh_beam *b) {
  return b->T;
}
double *nh_beam_velocities(nh_beam *b) {
  return b->v;
}
const double *nh_beam_rest_positions(const nh_beam *b) {
  return b->X;
}
const double *nh_beam_rest_directors(const nh_beam *b) {
  return b->T0;
}

void nh_beam_reset(nh_beam *b) {
  const size_t nn = (size_t)b->n + 1;
  memcpy(b->x, b->X, nn * 3 * sizeof(double));
  memcpy(b->T, b->T0, nn * 9 * sizeof(double));
  memset(b->v, 0, nn * 6 * sizeof(double));
}

void nh_beam_set_base(nh_beam *b, const double x[3], const double T[9]) {
  if (x) memcpy(b->x, x, 3 * sizeof(double));
  if (T) memcpy(b->T, T, 9 * sizeof(double));
}

void nh_beam_move_rigid(nh_beam *b, const double Q[9], const double c[3], const double t[3]) {
  const double zero[3] = {0, 0, 0};
  if (!c) c = zero;
  if (!t) t = zero;
  for (int a = 0; a <= b->n; a++) {
    double r[3], y[3];
    for (int i = 0; i < 3; i++) r[i] = b->x[3 * a + i] - c[i];
    nh_mat3_vec(Q, r, y);
    for (int i = 0; i < 3; i++) b->x[3 * a + i] = y[i] + c[i] + t[i];
    nh_mat3_mul(Q, b->T + 9 * a, b->T + 9 * a);
  }
}

void nh_beam_increment(nh_beam *b, const double *d) {
  for (int a = 0; a <= b->n; a++) {
    double R[9];
    for (int i = 0; i < 3; i++) b->x[3 * a + i] += d[6 * a + i];
    nh_mat3_rotation(d + 6 * a + 3, R);
    nh_mat3_mul(R, b->T + 9 * a, b->T + 9 * a);
  }
}

double nh_beam_element_force(const nh_beam *b, int e, double f[12], double K[144]) {
  return nh_beam_corot(b->x + 3 * e, b->x + 3 * e + 3, b->T + 9 * e, b->T + 9 * e + 9, b->l0, &b->c,
                       b->section.young, NULL, NULL, f, K);
}

void nh_beam_element_local(const nh_beam *b, int e, double d[7], double E[9]) {
  nh_beam_corot(b->x + 3 * e, b->x + 3 * e + 3, b->T + 9 * e, b->T + 9 * e + 9, b->l0, &b->c,
                b->section.young, d, E, NULL, NULL);
}

double nh_beam_twist(const nh_beam *b, double *twist) {
  double sum = 0.0, d[7];
  if (twist) twist[0] = 0.0;
  for (int e = 0; e < b->n; e++) {
    nh_beam_element_local(b, e, d, NULL);
    sum += d[4] - d[1]; /* θ̄₂ₓ − θ̄₁ₓ: the element's torsion */
    if (twist) twist[e + 1] = sum;
  }
  return sum;
}

double nh_beam_internal_force(const nh_beam *b, double *f_int, double *K, int symmetric) {
  const int N = 6 * (b->n + 1);
  double U = 0.0, fe[12], Ke[144];
  memset(f_int, 0, (size_t)N * sizeof(double));
  if (K) memset(K, 0, (size_t)N * N * sizeof(double));
  for (int e = 0; e < b->n; e++) {
    U += nh_beam_element_force(b, e, fe, K ? Ke : NULL);
    for (int i = 0; i < 12; i++) f_int[6 * e + i] += fe[i];
    if (K)
      for (int i = 0; i < 12; i++)
        for (int j = 0; j < 12; j++) {
          double k = symmetric ? 0.5 * (Ke[12 * i + j] + Ke[12 * j + i]) : Ke[12 * i + j];
          K[(size_t)(6 * e + i) * N + 6 * e + j] += k;
        }
  }
  return U;
}

void nh_beam_mass(const nh_beam *b, double *m) {
  const double rho = b->section.density;
  const double mt = 0.5 * rho * b->c.area * b->l0, mr = 0.5 * rho * b->c.polar * b->l0;
  for (int a = 0; a <= b->n; a++) {
    double w = (a == 0 || a == b->n) ? 1.0 : 2.0; /* elements sharing the node */
    for (int i = 0; i < 3; i++) m[6 * a + i] = w * mt, m[6 * a + 3 + i] = w * mr;
  }
}

void nh_beam_add_gravity(const nh_beam *b, const double g[3], int consistent, double *f) {
  const double q = b->section.density * b->c.area; /* mass per length */
  for (int e = 0; e < b->n; e++) {
    double m[3] = {0, 0, 0};
    if (consistent) {
      double t[3], l = 0.0;
      for (int i = 0; i < 3; i++) t[i] = b->x[3 * e + 3 + i] - b->x[3 * e + i], l += t[i] * t[i];
      l = sqrt(l);
      const double k = q * b->l0 * b->l0 / 12.0 / l;
      m[0] = k * (t[1] * g[2] - t[2] * g[1]);
      m[1] = k * (t[2] * g[0] - t[0] * g[2]);
      m[2] = k * (t[0] * g[1] - t[1] * g[0]);
    }
    for (int i = 0; i < 3; i++) {
      f[6 * e + i] += 0.5 * q * b->l0 * g[i];
      f[6 * e + 6 + i] += 0.5 * q * b->l0 * g[i];
      f[6 * e + 3 + i] += m[i];
      f[6 * e + 9 + i] -= m[i];
    }
  }
}

/* Element and local coordinate of rest arc length s (clamped to [0, L]). */
static void nh_beam_locate(const nh_beam *b, double s, int *e, double *xi) {
  double r = s / b->l0;
  if (!(r > 0)) r = 0; /* also NaN */
  if (r > b->n) r = b->n;
  int k = (int)floor(r);
  if (k > b->n - 1) k = b->n - 1;
  *e = k;
  *xi = r - k;
}

void nh_beam_point(const nh_beam *b, double s, double x[3], double t[3], int *e_out, double *xi_out,
                   double J[36]) {
  int e;
  double xi;
  nh_beam_locate(b, s, &e, &xi);
  const double x2 = xi * xi, x3 = x2 * xi, l0 = b->l0;
  const double H[4] = {1 - 3 * x2 + 2 * x3, xi - 2 * x2 + x3, 3 * x2 - 2 * x3, x3 - x2};
  const double D[4] = {-6 * xi + 6 * x2, 1 - 4 * xi + 3 * x2, 6 * xi - 6 * x2, 3 * x2 - 2 * xi};
  const double *p1 = b->x + 3 * e, *p2 = p1 + 3, *T1 = b->T + 9 * e, *T2 = T1 + 9;
  double t1[3] = {T1[0], T1[3], T1[6]}, t2[3] = {T2[0], T2[3], T2[6]};
  if (x)
    for (int i = 0; i < 3; i++)
      x[i] = H[0] * p1[i] + H[1] * l0 * t1[i] + H[2] * p2[i] + H[3] * l0 * t2[i];
  if (t) {
    double n = 0.0;
    for (int i = 0; i < 3; i++) {
      t[i] = D[0] * p1[i] + D[1] * l0 * t1[i] + D[2] * p2[i] + D[3] * l0 * t2[i];
      n += t[i] * t[i];
    }
    n = sqrt(n);
    for (int i = 0; i < 3; i++) t[i] /= n;
  }
  if (e_out) *e_out = e;
  if (xi_out) *xi_out = xi;
  if (J) {
    double S1[9], S2[9];
    nh_beam_skew(t1, S1);
    nh_beam_skew(t2, S2);
    memset(J, 0, 36 * sizeof(double));
    for (int i = 0; i < 3; i++) {
      J[12 * i + i] = H[0];
      J[12 * i + 6 + i] = H[2];
      for (int j = 0; j < 3; j++) {
        J[12 * i + 3 + j] = -H[1] * l0 * S1[3 * i + j];
        J[12 * i + 9 + j] = -H[3] * l0 * S2[3 * i + j];
      }
    }
  }
}

void nh_beam_add_point_force(const nh_beam *b, double s, const double F[3], double *f) {
  int e;
  double J[36];
  nh_beam_point(b, s, NULL, NULL, &e, NULL, J);
  for (int j = 0; j < 12; j++)
    for (int i = 0; i < 3; i++) f[6 * e + j] += J[12 * i + j] * F[i];
}
