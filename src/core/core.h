/* core — status codes, error messages with file/line, logging, timers,
 * small dense 3x3 algebra and a polar decomposition robust to det F <= 0.
 *
 * Every function that can fail returns int: NH_OK (0) or one of nh_status.
 * The failing site records a message with nh_error_set(); callers propagate
 * the code with NH_TRY and the front end prints nh_error_message() once.
 * Matrices are 3x3, row-major, double[9]: A[3*i + j] = A_ij. */
#ifndef NH_CORE_H
#define NH_CORE_H

#include <stddef.h>
#include <stdio.h>

#ifndef NH_VERSION
#define NH_VERSION "0.0.0"
#endif

/* π, the one home of the constant (C11 has no M_PI). */
#define NH_PI 3.14159265358979323846

typedef enum {
  NH_OK = 0,
  NH_ERR_INPUT,      /* bad scene, argument or template: the user can fix it (exit 2) */
  NH_ERR_NUMERIC,    /* not positive definite, NaN, no convergence (exit 1) */
  NH_ERR_IO,         /* a file could not be written or read (exit 1) */
  NH_ERR_MEMORY,     /* allocation failed (exit 1) */
  NH_ERR_INTERNAL,   /* a broken invariant: a bug (exit 1) */
  NH_ERR_INTERRUPTED /* stopped by a signal after a checkpoint (exit 1) */
} nh_status;

/* Record a message for status code `code` (printf format) and return `code`.
 * The message replaces any earlier one. `src_file`/`src_line` are the C
 * source location, kept for debugging (NH_DEBUG_ERRORS=1 prints them). */
int nh_error_set(int code, const char *src_file, int src_line, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* Copy `text` to `out` (`size` bytes, NUL-terminated) with every control
 * byte (below 0x20, and 0x7f) written as \n, \t, \r or \xNN: what every
 * message and warning goes through, so input bytes echoed in it can neither
 * break the line nor drive the terminal. Truncates, never mid-escape. */
void nh_escape_control(char *out, size_t size, const char *text);
/* The last recorded message ("" if none; one line, no control byte). */
const char *nh_error_message(void);
/* Forget the last message. */
void nh_error_clear(void);
/* Exit status for a status code: 0 ok, 2 input, 1 otherwise. */
int nh_error_exit_status(int code);

#define NH_ERROR(code, ...) nh_error_set((code), __FILE__, __LINE__, __VA_ARGS__)
#define NH_TRY(expr)                                                                               \
  do {                                                                                             \
    int nh_rc_ = (expr);                                                                           \
    if (nh_rc_) return nh_rc_;                                                                     \
  } while (0)
#define NH_CHECK(cond, code, ...)                                                                  \
  do {                                                                                             \
    if (!(cond)) return NH_ERROR((code), __VA_ARGS__);                                             \
  } while (0)

/* Allocation that records NH_ERR_MEMORY on failure. calloc semantics. */
void *nh_calloc(size_t n, size_t size);
/* Grow *ptr to hold at least `need` items of `size` bytes (capacity doubles).
 * Returns NH_OK or NH_ERR_MEMORY (the old block is kept on failure). */
int nh_grow(void **ptr, int *capacity, int need, size_t size);
/* Resize *ptr to exactly `n` items of `size` bytes (at least one item), the
 * realloc of this code base. Returns NH_OK, or NH_ERR_MEMORY with a message
 * if n * size overflows or the allocation fails (the old block is kept). */
int nh_realloc(void **ptr, size_t n, size_t size);

/* ---- stop requests (SIGINT, SIGTERM) ----
 * A signal handler records the request (async-signal-safe); the long loops
 * (assembly colours, compliance columns, constraint sweeps, Newton
 * iterations) poll it and return NH_ERR_INTERRUPTED ("interrupted"), so a
 * step stops within a fraction of a second instead of at its end. */
void nh_stop_request(int signal_number);
/* The signal that asked to stop (0: none). */
int nh_stop_requested(void);
/* NH_ERR_INTERRUPTED with a message if a stop was requested, else NH_OK. */
int nh_stop_check(void);

/* ---- bytes (bytes.c): a growable buffer and a bounded reader ---- */
typedef struct {
  unsigned char *data; /* malloc'd; the owner frees it */
  size_t len, cap;
  int failed; /* an allocation failed: later puts do nothing */
} nh_bytes;
/* Append n bytes (nothing once failed). */
void nh_bytes_put(nh_bytes *b, const void *p, size_t n);
typedef struct {
  const unsigned char *p, *end;
  int short_read; /* a read went past the end: it and later ones give zeros */
} nh_byte_reader;
/* Read n bytes into out. */
void nh_bytes_get(nh_byte_reader *r, void *out, size_t n);

/* ---- the fields of a comma-separated line (csv_fields.c) ---- */
/* Split `line` in place (a trailing newline dropped) into at most `max`
 * fields; a field in double quotes may hold commas and "" (a quote), and
 * loses its quotes. Returns the count, or -1 for an unclosed quote or text
 * after a closing one. */
int nh_csv_split(char *line, char **field, int max);
/* The index of `name` among names[0..n), or -1. */
int nh_csv_column(char *const *names, int n, const char *name);

/* ---- limits on the files a scene names (limits.c) ----
 * Every reader of a user's file (NIfTI images, STL surfaces, refinement
 * templates, checkpoints) checks what a file's header implies against these
 * before it allocates or decompresses anything, and reads with a bound, so a
 * malformed or hostile file is refused in milliseconds instead of filling
 * the memory. Counts are doubles (whole numbers; 4e9 exceeds an int). */
typedef struct nh_read_limits {
  double max_voxels;     /* voxels of a label image, nx ny nz (default 2e8) */
  double max_triangles;  /* triangles of a surface (default 2e7) */
  double max_file_bytes; /* bytes of a file, and the bytes a compressed one expands to (4e9) */
} nh_read_limits;
/* The defaults: they admit a 0.5 mm whole-head image (512³ = 1.3e8 voxels,
 * 1.07 GB as float64) and a 0.5 mm marching-cubes cortex (~2e6 triangles)
 * with margin (docs/reliability.md). */
extern const nh_read_limits nh_read_limits_default;
/* `limits`, or the defaults when it is NULL. */
const nh_read_limits *nh_read_limits_or_default(const nh_read_limits *limits);
/* Open `path` for binary reading: *f, and *size its size in bytes when it is
 * a regular file (-1 for a stream: a FIFO or a device, whose reader must
 * bound what it reads itself). Fails with NH_ERR_INPUT, "PATH: reason":
 * cannot open (the system's reason), a folder, more bytes than
 * max_file_bytes. `what` names the file's kind in messages ("image"). */
int nh_file_open_limited(const char *path, const char *what, const nh_read_limits *limits, FILE **f,
                         double *size);

/* ---- logging ---- */
typedef enum { NH_LOG_QUIET = 0, NH_LOG_INFO = 1, NH_LOG_DEBUG = 2 } nh_log_level;
void nh_log_set_level(nh_log_level level);
nh_log_level nh_log_get_level(void);
/* Informational line on stderr (suppressed by --quiet). */
void nh_log_info(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
/* Warning line on stderr (always shown). */
void nh_log_warn(const char *fmt, ...) __attribute__((format(printf, 1, 2)));

/* ---- paths (core/paths.c) ---- */
/* The folder of the running program (/proc/self/exe without its last
 * component) into out[size]. Returns 0, or -1 if it cannot be read or does
 * not fit. */
int nh_exe_dir(char *out, size_t size);
/* `path` as an absolute path: itself if it starts with '/', else the
 * current folder, '/', path (not normalised: "a/../b" stays). Returns out,
 * or path itself if the current folder cannot be read or out[size] is too
 * small. */
const char *nh_path_absolute(const char *path, char *out, size_t size);
/* The refinement templates folder: $NH_TEMPLATES_DIR if set and not empty,
 * else EXE/../share/needlehex/templates or EXE/share/needlehex/templates (the
 * first that exists; EXE from nh_exe_dir), else "templates". The result is
 * the environment's string, `buf` (size bytes) or a literal. */
const char *nh_templates_dir(char *buf, size_t size);

/* ---- timers ---- */
/* Monotonic wall time in seconds. */
double nh_time_now(void);

/* ---- 3-vectors (mat3.c) ---- */
double nh_vec3_dot(const double a[3], const double b[3]); /* a · b */
double nh_vec3_norm(const double a[3]);                   /* |a| = (a · a)^½ */
/* c = a × b (c may alias a or b). */
void nh_vec3_cross(const double a[3], const double b[3], double c[3]);
/* a /= |a| unless |a| = 0 (then a is left as is); returns |a| before. */
double nh_vec3_normalize(double a[3]);

/* ---- 3x3 algebra ---- */
void nh_mat3_identity(double A[9]);
void nh_mat3_mul(const double A[9], const double B[9], double C[9]);    /* C = A B   */
void nh_mat3_mul_tn(const double A[9], const double B[9], double C[9]); /* C = Aᵀ B  */
void nh_mat3_mul_nt(const double A[9], const double B[9], double C[9]); /* C = A Bᵀ  */
void nh_mat3_transpose(const double A[9], double At[9]);
/* y = A x and y = Aᵀ x (y may alias x), inline: the element kernels call
 * them per corner (a call cost more than the product; the same bits). */
static inline void nh_mat3_vec(const double A[9], const double x[3], double y[3]) {
  const double t0 = A[0] * x[0] + A[1] * x[1] + A[2] * x[2],
               t1 = A[3] * x[0] + A[4] * x[1] + A[5] * x[2],
               t2 = A[6] * x[0] + A[7] * x[1] + A[8] * x[2];
  y[0] = t0, y[1] = t1, y[2] = t2;
}
static inline void nh_mat3_tvec(const double A[9], const double x[3], double y[3]) {
  const double t0 = A[0] * x[0] + A[3] * x[1] + A[6] * x[2],
               t1 = A[1] * x[0] + A[4] * x[1] + A[7] * x[2],
               t2 = A[2] * x[0] + A[5] * x[1] + A[8] * x[2];
  y[0] = t0, y[1] = t1, y[2] = t2;
}
double nh_mat3_det(const double A[9]);
/* Inverse; returns NH_ERR_NUMERIC if |det| <= tiny (no message recorded). */
int nh_mat3_inverse(const double A[9], double Ainv[9]);
/* 1 when A, of determinant det, is too close to singular for nh_mat3_inverse
 * (|det| <= 1e-14 max|Aᵢⱼ|³ or <= 1e-300), else 0. */
int nh_mat3_singular(const double A[9], double det);
/* Rotation matrix from a rotation vector (axis * angle), Rodrigues' formula. */
void nh_mat3_rotation(const double rotvec[3], double R[9]);

/* Symmetric eigen-decomposition by cyclic Jacobi: S = V diag(w) Vᵀ, w sorted
 * descending, V's columns orthonormal with det V = +1. */
void nh_mat3_sym_eigen(const double S[9], double w[3], double V[9]);

/* Polar decomposition F = R U with R a proper rotation (det R = +1) for every
 * F, including det F <= 0 and rank-deficient F: from the SVD F = P Σ Qᵀ with
 * the sign of the smallest singular value flipped when det F < 0, R = P Qᵀ
 * (the "rotation-variant" SVD of invertible FEM). F = 0 gives R = I.
 * Never produces NaN for finite F. */
void nh_polar_rotation(const double F[9], double R[9]);

#endif
