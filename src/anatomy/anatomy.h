/* anatomy — the patient's organs as data: NIfTI label images (read through
 * Debian's libnifti2) and closed triangulated surfaces (STL), and what the
 * immersed domain needs of them: an implicit function F (F < 0 inside,
 * 1-Lipschitz, so F > 0 bounds the distance to the organ from below), an
 * inside test, a ray entry and the label at a point (docs/anatomy.md).
 *
 * World coordinates are metres in the image's world frame (NIfTI: RAS+, x to
 * the right, y anterior, z superior), the frame of every scene point.
 *
 * Voxel (i, j, k) of an image covers the box centred at its index:
 *
 *        world x = A (i, j, k)ᵀ + t          (A, t: the sform, else the qform)
 *
 *          k                 voxel centres •, the indicator χ of the
 *          |  j              selected labels is trilinear between centres
 *          | /               and 0 outside the image; the organ is
 *          |/                {χ > 1/2}, its surface the level χ = 1/2.
 *          •───── i
 *
 * Both kinds of object are shared (the scene's domain, the mesh and the
 * tissue hold the same one) and reference counted: *_retain adds an owner,
 * *_release drops one and frees the object with its last owner. */
#ifndef NH_ANATOMY_H
#define NH_ANATOMY_H

#include "core/core.h"

#include <stddef.h>
#include <stdio.h>

#define NH_ANATOMY_PATH_MAX 1024

/* ---- label images (anatomy/image.c) ---- */
typedef struct nh_image {
  char path[NH_ANATOMY_PATH_MAX];
  int n[3];              /* voxels along i, j, k */
  int *label;            /* n[0] n[1] n[2] integer labels, i fastest (NULL: header only) */
  double A[9], t[3];     /* world (m) = A ijk + t, A row-major */
  double Ainv[9];        /* A⁻¹ */
  double spacing[3];     /* |A e_i|: the voxel edges in metres */
  char orientation[4];   /* the direction each of i, j, k increases to: L/R, P/A, I/S ("LAS") */
  const char *xform;     /* which transform gave A, t: "sform", "qform" or "pixdim" */
  double unit;           /* metres per file unit (1e-3 for mm) */
  unsigned char *inside; /* per voxel: its label is selected (nh_image_select), else NULL */
  int lo[3], hi[3];      /* index bounds of the selected voxels (lo > hi if none) */
  double level_scale; /* 1 / (√3 ‖A⁻¹‖_F): makes F = (1/2 − χ) level_scale 1-Lipschitz */
  double box_min[3], box_max[3]; /* nh_image_bounds, set by nh_image_select */
  float *distance; /* per voxel: a lower bound of the world distance from its centre to the
                      nearest selected centre (σ_min(A) times the index-space EDT) */
  double reach;    /* max |A d| over the diagonals d of [-1, 1]³ (world) */
  int *prefix;     /* (n[0]+1)(n[1]+1)(n[2]+1) prefix sums of `inside` (box counts) */
  int refs;
} nh_image;

/* Read the NIfTI-1 or NIfTI-2 file `path` (.nii, .nii.gz, or a .hdr/.img
 * pair): its size, world transform (sform if its code is non-zero, else
 * qform if non-zero, else the pixdim diagonal) in metres (xyz_units mm, m or
 * µm; unknown units are taken as mm, as NIfTI readers do), and if
 * `read_data` its voxels as integer labels (after scl_slope / scl_inter
 * when the slope is finite and non-zero). The header is read and checked
 * first (docs/anatomy.md, "Reading"), its implied size against `limits`
 * (NULL: nh_read_limits_default) before anything is allocated or
 * decompressed, and the voxels are read with that bound. libnifti2 prints
 * nothing. Output *out with one owner.
 * Fails with NH_ERR_INPUT, message "PATH: what is wrong (the value, the
 * field)": missing, unreadable or not a regular file; not NIfTI; a header
 * field out of range (dim, pixdim, quaternion of norm > 1, non-finite or
 * singular sform, codes, vox_offset); voxels reaching farther than
 * NH_IMAGE_MAX_COORDINATE from the origin; not 3D; not a label data type; more
 * voxels or bytes than the limits; a file shorter or longer than its header
 * says (gzip'd: found as it is read); a voxel that is not a whole number
 * (NaN, 2.5), named by its index. NH_ERR_MEMORY. */
int nh_image_read(const char *path, int read_data, const nh_read_limits *limits, nh_image **out);
/* m: an image whose voxels reach farther from the origin is in no patient's
 * or phantom's frame (a wrong unit code or offset); it also keeps the
 * image's box resolvable in doubles (an offset of 1e20 m swallows the
 * extent). */
#define NH_IMAGE_MAX_COORDINATE 1e3
void nh_image_retain(nh_image *image);
void nh_image_release(nh_image **image); /* sets *image = NULL */

/* Voxel index (continuous) of world point x, and back. */
void nh_image_to_voxel(const nh_image *image, const double x[3], double ijk[3]);
void nh_image_to_world(const nh_image *image, const double ijk[3], double x[3]);
/* True if world point x lies within the image's voxels (the boxes centred at
 * the indices, so indices -1/2 .. n - 1/2). */
int nh_image_contains(const nh_image *image, const double x[3]);
/* Label of the voxel containing x (nearest centre); 0 outside the image. */
int nh_image_label_at(const nh_image *image, const double x[3]);

/* The distinct labels of the image in increasing order and their voxel
 * counts: *labels and *counts (malloc'ed, caller frees), *n. Needs data. */
int nh_image_labels(const nh_image *image, int **labels, long **counts, int *n);

/* Print for `check`: file, size, spacing (mm), orientation, the transform
 * used, and each label with its voxel count and volume (count × |det A|). */
int nh_image_print(const nh_image *image, FILE *f);

/* Select the organ: inside[v] = label[v] is one of labels[0..n). Sets lo,
 * hi. Fails with NH_ERR_INPUT if no voxel is selected, NH_ERR_MEMORY. */
int nh_image_select(nh_image *image, const int *labels, int n);
/* Trilinear χ of the selected voxels at x (0 outside the image). */
double nh_image_indicator(const nh_image *image, const double x[3]);
/* |χ − 1/2| at or below this is 1/2 in nh_image_level: far above χ's
 * round-off (a voxel coordinate's, ≤ n · 1e-15 for n voxels along an axis,
 * times |∂χ/∂p| ≤ 1, plus the 8-term sum's), far below any geometry (where
 * |∇_p χ| ≥ g the surface χ = 1/2 moves by at most 1e-9/g of a voxel). */
#define NH_IMAGE_CHI_ROUNDOFF 1e-9
/* F(x) = max((1/2 − χ(x)) level_scale, I(distance)(x) − 2 reach, distance
 * from x to the bounding box of the selected voxels grown by half a voxel),
 * I the trilinear interpolation: negative exactly where χ > 1/2, and where
 * positive a lower bound of the distance from x to {χ > 1/2}
 * (docs/anatomy.md). */
double nh_image_level(const nh_image *image, const double x[3]);
/* 1 if the world box [lo, hi] may meet {χ > 1/2}: some selected voxel
 * centre lies within one voxel (in index space) of the box, χ's support. */
int nh_image_meets_box(const nh_image *image, const double lo[3], const double hi[3]);
/* World bounding box of {χ > 1/2}: the selected voxels' index box grown by
 * half a voxel, mapped by the affine (its 8 corners' extent). */
void nh_image_bounds(const nh_image *image, double min[3], double max[3]);
/* World bounding box of the whole image (every voxel's box). */
void nh_image_extent(const nh_image *image, double min[3], double max[3]);

/* ---- closed triangulated surfaces (anatomy/surface.c) ---- */
typedef struct nh_surface {
  char path[NH_ANATOMY_PATH_MAX];
  int n_tri;
  double *v;             /* 9 per triangle: the three corners, metres */
  double min[3], max[3]; /* bounding box */
  double unit;           /* metres per file unit */
  /* acceleration: triangles listed under each cell of a g[0] x g[1] x g[2]
     grid over the box (distance, box tests) and of a yz_g[0] x yz_g[1] grid
     over the (y, z) extent (inside test) */
  int g[3], yz_g[2];
  double cell[3], yz_cell[2];
  int *xyz_start, *xyz_tri;
  int *yz_start, *yz_tri;
  double *ball; /* 4 per triangle: a ball holding it (centre, radius) */
  int refs;
} nh_surface;

/* Read an ASCII or binary STL file (`solid` … `endsolid` with `facet normal`,
 * `outer loop`, three `vertex` lines, `endloop`, `endfacet`; or the 80-byte
 * header, a triangle count and 50 bytes per triangle, the size matching the
 * count exactly). Coordinates are in `unit` metres per file unit (1e-3 for
 * millimetres). Zero-area triangles are dropped. The file's normals are
 * ignored. The count a binary header announces is checked against `limits`
 * (NULL: defaults) before anything is allocated, and the file is read with a
 * bound (a stream such as a FIFO too: it must end where its header says, an
 * ASCII one within max_file_bytes and max_triangles). The geometry must be
 * what the file says (docs/anatomy.md, "Surface meshes"): closed, largest
 * extent between `min_extent` (m; 0: no lower bound; a scene gives
 * NH_SURFACE_MIN_EXTENT) and 10 m, a non-zero volume, and the volume inside by nh_surface_inside
 * within 1 % of the volume enclosed by the divergence theorem (else
 * overlapping shells, self-intersection or inconsistent orientation).
 * Fails with NH_ERR_INPUT, "PATH:LINE: reason" (ASCII) or "PATH: reason"
 * (binary: triangle number; geometry: both volumes and a hint): missing
 * file, a keyword out of place, a non-number or non-finite coordinate, a
 * binary byte in an ASCII file, a truncated or overlong file, more than the
 * limits, no triangles, an open surface (an edge not shared by an even
 * number of triangles), the geometry. NH_ERR_MEMORY. */
int nh_surface_read(const char *path, double unit, double min_extent, const nh_read_limits *limits,
                    nh_surface **out);
/* The smallest largest extent of a scene's surface, m: the domain's grid is
 * laid over the surface's own bounding box, so no grid cell can bound it
 * from below; a shape under 1 mm is a `unit` that reads metres as
 * millimetres (a 10 cm organ stored in metres becomes 0.1 mm). */
#define NH_SURFACE_MIN_EXTENT 1e-3
void nh_surface_retain(nh_surface *surface);
void nh_surface_release(nh_surface **surface);

/* Inside test: the parity of the crossings of the ray from x along +x with
 * the triangles. Whether the ray passes through a triangle is decided by the
 * signs of its three edge functions in the (y, z) plane, each computed from
 * the edge's endpoints in a canonical order (so two triangles sharing an
 * edge see exactly opposite values), with a zero resolved by simulation of
 * simplicity (the ray moved by (0, ε, ε²)): a ray through an edge or a vertex
 * is counted in exactly one of the triangles that meet there, whatever their
 * size or shape (slivers included). */
int nh_surface_inside(const nh_surface *surface, const double x[3]);
/* Signed distance (negative inside), truncated at `cap` in magnitude (the
 * search stops there; 1-Lipschitz as a clamp of one). cap <= 0: no cap. */
double nh_surface_level(const nh_surface *surface, const double x[3], double cap);
/* Print for `check`: file, triangles, bounding box, enclosed volume. */
void nh_surface_print(const nh_surface *surface, FILE *f);
/* Volume enclosed, by the divergence theorem (orientation-free: |Σ|). */
double nh_surface_volume(const nh_surface *surface);
/* Volume inside by the inside test: the parity rule's inside length along
 * ny x nz rays in +x at the centres of a grid over the (y, z) extent, times
 * the ray's cell area (NaN if out of memory). */
double nh_surface_inside_volume(const nh_surface *surface, int ny, int nz);
/* First crossing of the ray base + τ dir (τ > 0) with a triangle: τ, point
 * and the unit normal of that triangle facing the ray's origin. 1 if hit. */
int nh_surface_ray_entry(const nh_surface *surface, const double base[3], const double dir[3],
                         double *tau, double point[3], double normal[3]);
/* 1 if some triangle's bounding box meets the box [lo, hi]. */
int nh_surface_meets_box(const nh_surface *surface, const double lo[3], const double hi[3]);

/* ---- 3D Slicer markups (anatomy/markups.c) ----
 * Points planned in 3D Slicer: a `.mrk.json` file (Slicer's markups schema
 * v1.0.3: markups[] of type Fiducial, Line, Angle, Curve, ClosedCurve, Plane
 * or ROI, each with its coordinateSystem RAS or LPS, coordinateUnits mm or
 * um, and controlPoints[] with label and position) or a legacy `.fcsv` (one
 * fiducial list; "# CoordinateSystem = RAS | LPS | 0 | 1"; always mm). Every
 * point is converted to the scene frame: RAS (LPS: x and y negated), metres.
 * The markups are in the world frame of the images they were placed on,
 * which for a NIfTI image is its sform/qform frame: the scene's frame. */
#define NH_MARKUPS_MAX_BYTES      (16L << 20) /* larger files are refused unread */
#define NH_MARKUPS_MAX_COORDINATE 10.0        /* m: a farther point is not a coordinate */

typedef enum {
  NH_MARKUP_FIDUCIAL,
  NH_MARKUP_LINE,
  NH_MARKUP_ANGLE,
  NH_MARKUP_CURVE,
  NH_MARKUP_CLOSED_CURVE,
  NH_MARKUP_PLANE,
  NH_MARKUP_ROI
} nh_markup_type;

typedef struct {
  char *label; /* the control point's label ("" if none) */
  double x[3]; /* scene frame: RAS, metres */
  int defined; /* its position is set (positionStatus "defined" or absent) */
  int markup;  /* index of the markup holding it */
} nh_markup_point;

typedef struct {
  char *name; /* the markup's name ("" if none; .fcsv: the file's stem) */
  nh_markup_type type;
  int first, n; /* its control points: point[first .. first + n) */
} nh_markup;

typedef struct nh_markups {
  char path[NH_ANATOMY_PATH_MAX];
  int n_markups, n_points;
  nh_markup *markup;
  nh_markup_point *point;
} nh_markups;

/* Read a markups file: `.fcsv` when its first line is Slicer's fiducial
 * header ("# Markups fiducial file version = ..."), else JSON. Output *out.
 * Fails with NH_ERR_INPUT, message "PATH: reason" (JSON syntax errors
 * "PATH:LINE:COLUMN: ..."; .fcsv rows "PATH:LINE: ..."): a missing or
 * unreadable file, one above NH_MARKUPS_MAX_BYTES (refused before it is
 * read), not JSON and not .fcsv, JSON without a "markups" array, an unknown
 * type, coordinateSystem or coordinateUnits, a position that is not three
 * numbers, a non-finite one or one farther than NH_MARKUPS_MAX_COORDINATE
 * from the origin. NH_ERR_MEMORY. */
int nh_markups_read(const char *path, nh_markups **out);
void nh_markups_destroy(nh_markups **markups); /* sets *markups = NULL */
/* "Fiducial", "Line", ... (the schema's names). */
const char *nh_markup_type_name(nh_markup_type type);

/* The control point labelled `label`, in the scene frame. It must be the
 * only point of that label in the file, of a Fiducial or a Line markup, with
 * a defined position. Fails with NH_ERR_INPUT, "PATH: reason": no such label
 * (the labels there are listed, at most 8), a label on several points of one
 * markup, a label in more than one markup, a point of a Curve, ClosedCurve,
 * Angle, Plane or ROI, an undefined position. */
int nh_markups_point(const nh_markups *markups, const char *label, double x[3]);
/* The two points of the Line markup named `name` (NULL: the file's only Line
 * markup), in file order. Fails with NH_ERR_INPUT, "PATH: reason": no such
 * Line (the Lines there are listed), several of that name, a Line without
 * two defined points. */
int nh_markups_line(const nh_markups *markups, const char *name, double a[3], double b[3]);
/* Read `path` and return the point labelled `label` (nh_markups_read, then
 * nh_markups_point). */
int nh_markups_find_point(const char *path, const char *label, double x[3]);

/* ---- voxel values of any scalar image (read by anatomy/image.c, interpolated by anatomy/volume.c)
 * ---- */
/* Voxel v of raw NIfTI data of type `datatype` (a NIfTI DT_* code) as a
 * double; 0 and *ok = 0 for a type that is not a real number (complex, RGB). */
double nh_image_voxel_value(const void *data, int datatype, size_t v, int *ok);
/* Read the header of `path` as nh_image_read(path, 0, limits, out) and its
 * voxels as doubles, intensities or labels: values[n0 n1 n2], i fastest
 * (the caller frees), scl_slope · stored + scl_inter when the slope is
 * finite and non-zero (NIfTI's rule), else the stored values. The voxels
 * are read as nh_image_read's labels (bounded, the file's length checked)
 * and must be finite. Fails as nh_image_read, and with NH_ERR_INPUT for a
 * voxel that is not finite (named); NH_ERR_MEMORY. */
int nh_image_read_values(const char *path, const nh_read_limits *limits, nh_image **out,
                         double **values);
/* The value at world point x of `values` given at the voxel centres of
 * `image`: trilinear between centres (nearest = 0), or the nearest centre's
 * (nearest = 1, for labels). 0 outside the image's voxels (index outside
 * [-1/2, n - 1/2)); in the outer half voxel the edge centres' values (the
 * rule of ITK's interpolators, so an image resampled here and by ITK agree
 * there too). */
double nh_image_interpolate(const nh_image *image, const double *values, const double x[3],
                            int nearest);

#endif
