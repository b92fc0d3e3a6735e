/* check.h — assertions of the stand-alone tests: silent on success, loud on
 * failure with expected and actual values and the tolerance. */
#ifndef NH_TEST_CHECK_H
#define NH_TEST_CHECK_H

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "core/core.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static int nh_test_failures = 0;

/* |actual - expected| <= tol (absolute). */
#define CHECK_CLOSE(actual, expected, tol, what)                                                   \
  do {                                                                                             \
    double a_ = (actual), e_ = (expected), t_ = (tol);                                             \
    if (!(fabs(a_ - e_) <= t_)) {                                                                  \
      fprintf(stderr, "%s:%d: %s: expected %.17g, got %.17g (|diff| %.3g > tol %.3g)\n", __FILE__, \
              __LINE__, (what), e_, a_, fabs(a_ - e_), t_);                                        \
      nh_test_failures++;                                                                          \
    }                                                                                              \
  } while (0)

#define CHECK(cond, ...)                                                                           \
  do {                                                                                             \
    if (!(cond)) {                                                                                 \
      fprintf(stderr, "%s:%d: check failed: %s: ", __FILE__, __LINE__, #cond);                     \
      fprintf(stderr, __VA_ARGS__);                                                                \
      fputc('\n', stderr);                                                                         \
      nh_test_failures++;                                                                          \
    }                                                                                              \
  } while (0)

/* A call returning a status that must be 0. */
#define CHECK_OK(expr)                                                                             \
  do {                                                                                             \
    int rc_ = (expr);                                                                              \
    if (rc_) {                                                                                     \
      fprintf(stderr, "%s:%d: %s returned %d: %s\n", __FILE__, __LINE__, #expr, rc_,               \
              nh_error_message());                                                                 \
      exit(1);                                                                                     \
    }                                                                                              \
  } while (0)

/* A soft check that also prints the library's last error message (for
 * tests of functions that report through nh_error_message). */
#define EXPECT(cond, ...)                                                                          \
  do {                                                                                             \
    if (!(cond)) {                                                                                 \
      fprintf(stderr, "%s:%d: FAILED %s: ", __FILE__, __LINE__, #cond);                            \
      fprintf(stderr, __VA_ARGS__);                                                                \
      fprintf(stderr, " [last error: %s]\n", nh_error_message());                                  \
      nh_test_failures++;                                                                          \
    }                                                                                              \
  } while (0)

/* A call returning a status that should be 0 (soft: counted, not fatal). */
#define EXPECT_OK(expr)                                                                            \
  do {                                                                                             \
    int rc_ = (expr);                                                                              \
    EXPECT(rc_ == NH_OK, "%s returned %d, expected 0", #expr, rc_);                                \
  } while (0)

#define TEST_END() return nh_test_failures ? 1 : 0

/* Deterministic uniform numbers in [-1, 1] (xorshift), so failures reproduce. */
static unsigned long long nh_test_rng = 88172645463325252ull;
__attribute__((unused)) static double nh_rand(void) {
  nh_test_rng ^= nh_test_rng << 13;
  nh_test_rng ^= nh_test_rng >> 7;
  nh_test_rng ^= nh_test_rng << 17;
  return 2.0 * (double)(nh_test_rng >> 11) / 9007199254740992.0 - 1.0;
}

/* The observed order of convergence: the least-squares slope of log |e|
 * against log h over n grids. */
__attribute__((unused)) static double nh_test_order(const double *h, const double *e, int n) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (int i = 0; i < n; i++) {
    const double x = log(h[i]), y = log(fabs(e[i]));
    sx += x, sy += y, sxx += x * x, sxy += x * y;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

#endif
