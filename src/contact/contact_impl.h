/* contact_impl.h — private to the contact module: the tools, their groups,
 * the embedded tissue points, and the functions the files share.
 *
 *   contact.c   the step: begin (rows of every constraint), the coupled
 *               solve, end (forces, the state machine); creation, relocation
 *   tools.c     tool kinematics: prescribed motion, nesting (a tool following
 *               its host), release, forces per tool and the per-tool report
 *   points.c    tissue material points tied to the tools: where they are now,
 *               the material point at a current position, a row's tissue part
 *   puncture.c  the puncture constraint: entry point on the current surface,
 *               its rows, its force against the puncture force
 *   channel.c   the tip constraint (stick or cut and advance) and the shaft
 *               constraint (channel points, stick/slide ties, retraction)
 *   nest.c      a released nested tool held on its host's axis (rows
 *               between two tools)
 *
 * Each constraint has a rows/update pair: nh_X_rows writes its rows for the
 * step (nothing in a state where it does not act), nh_X_update reads their
 * forces after the solve into the group's events. */
#ifndef NH_CONTACT_IMPL_H
#define NH_CONTACT_IMPL_H

#include "contact/contact.h"

#include <math.h>

/* A tissue material point tied to a tool. */
typedef struct {
  double X[3];        /* material position */
  int cell;           /* leaf containing X */
  double xi[3];       /* natural coordinates in it */
  double len;         /* channel length it stands for (spacing), m */
  double s;           /* arc length of its tool point (last projection) */
  double s0;          /* quasi-static: s at the step's first iteration (the slip is s − s0) */
  int tool;           /* the tool it was tied to in the last step (−1: none) */
  int row;            /* its first row in the last step (−1: none) */
  double lam[4];      /* its rows' multipliers: n1, n2, t, and the torsion row (shaft points) */
  int slid;           /* its friction slid in the last step (static or kinetic bound next) */
  double handover[3]; /* the lateral offset to its tool's axis still allowed after it passed
                         from one tool of the group to another (channel.c: the hand-over) */
  double dX[3];       /* its anchoring error: the exact solution's anchor − X (anchor.c) */
  double dc_axial;    /* a shaft point's axial data error, −t · e (anchor.c), while it sticks */
  int dc_axial_set;   /* dc_axial estimated since the point last slid */
} nh_cpoint;

/* One tool: a beam, its motion and the forces of the last step. */
typedef struct {
  const nh_tool_spec *spec;
  nh_beam *beam;
  int group;     /* its group */
  int host;      /* nested: the host tool (its group's outer tool); −1 for an outer tool */
  int released;  /* nested: no longer follows its host */
  double offset; /* nested: arc length of its base along the host */
  int dyn;       /* its block in this step's coupled solve (−1: kinematic) */
  double base_v[6];
  double F[3];          /* the tissue's force on the tool in the last step, N */
  double *f_node;       /* 3 per node: F distributed to the nearest nodes */
  nh_tool_state state;  /* an outer tool's: its group's */
  int nest_row, nest_n; /* released nested: its rows with its host in the last step (nest.c):
                           the first (−1: none) and how many */
} nh_tool;

/* The tissue part of a tip or puncture row: the mean over the tool's
 * cross-section, a disc of material points (points.c, nh_disc_build), as
 * node weights w (Σ w = 1). */
typedef struct {
  int n, cap;
  int *node;
  double *w;
  double X[3], nrm[3], ref[3], rho; /* the disc's rule (nh_disc_points); rho 0: the point */
} nh_disc;

/* A tool group: an outer tool and the tools nested in it, one hole in the
 * tissue. The constraints live here: the entry point (puncture), the
 * channel's front (tip) and the channel points (shaft). */
typedef struct {
  int outer; /* the outer tool */
  int has_entry;
  double n_out[3];
  nh_cpoint entry; /* the puncture point; channel point 0 once punctured */
  int entry_row;   /* first puncture row in the last step (−1) */
  int punctured;
  nh_cpoint *chan; /* channel points laid behind the tip (entry first) */
  int n_chan, cap_chan;
  nh_cpoint front;   /* the channel's front: the tip's anchor */
  int tip_tool;      /* the tool with the tip rows in the last step (−1) */
  double entry_x[3]; /* current position of the entry point (after the last step) */
  int fine_warned;   /* the warning that an explicit spacing is finer than a cell was given */
  int cut;           /* its tip cut in the last step (the front moved) */
} nh_group;

/* What a group's constraints saw in the step just solved: the input of the
 * state machine (contact.c). */
typedef struct {
  int puncture_rows; /* the puncture rows were active */
  int touching;      /* their normal force was positive */
  int yielded;       /* it reached the puncture force: the tool punctures */
  int covered;       /* a tip or shaft row was active */
  int cut;           /* the tip cut forward */
} nh_group_events;

struct nh_contact {
  const nh_scene *scene;
  int n, n_groups;
  nh_tool *tools;
  nh_group *groups;
  /* the step's constraint rows and dynamic tools (the coupled solve's blocks) */
  nh_rows rows;
  nh_coupled_tool *blocks;
  int n_blocks;
  nh_coupled_stats solve; /* the last step's */
  int cut;                /* groups whose tip cut in the last step */
  nh_skull *skull;        /* tissue.skull (NULL without): its rows follow the tools' */
  int statics;            /* this step is quasi-static (nh_contact_solve_static) */
  int iteration;          /* its Newton iteration (0: the first; always 0 dynamic) */
  double *du_last;        /* quasi-static: the tissue's increment over the last step (3 per
                             node, n_du of them), which predicts the skull rows' approach */
  int n_du;
  nh_disc disc; /* scratch: the disc of the tip or puncture rows being written */
};

/* ---- tools.c ---- */
/* Speed of the prescribed insertion over the step t → t + h (m/s, < 0 retracting). */
double nh_tool_speed(const nh_tool_spec *spec, double t, double h);
/* Set up tool k of the scene (its group already set): its beam at rest,
 * an outer tool checked to reach the tissue, a nested tool placed on its
 * host (created before it). NH_ERR_INPUT (the scene's tools.k: the beam's
 * reason, the tool starts inside the tissue or its tip never comes within
 * one cell of it over its motion), NH_ERR_MEMORY. */
int nh_tool_init(nh_contact *c, int k, const nh_mesh *mesh);
/* Place a nested tool on its host's deformed axis (velocities over h; h = 0: at rest). */
void nh_tool_follow(nh_tool *in, const nh_tool *host, double h);
/* Nested tools not yet released follow their host and are released at
 * their release time t_new. */
void nh_tools_follow(nh_contact *c, double t_new, double h);
/* The coupled solve's block of every tool that moves by its own dynamics
 * (not a nested tool following its host) over t → t + h, under gravity g,
 * with the rows' time scale τ (docs/interaction.md): dynamic (τ = h) the
 * base velocity of the motion; quasi-static (τ = 1) a Newton iteration
 * whose base moves by the motion's travel over the step if `moving`, by 0
 * otherwise (the later iterations of the step). */
void nh_tools_blocks(nh_contact *c, double t, double h, double tau, int moving, const double g[3]);
/* Zero the forces of the last step; NH_ERR_NUMERIC on a tool position that
 * is not finite. */
int nh_tools_clear_forces(nh_contact *c);
/* Add row r's force on the tool (−n λ / τ) at arc length s to its totals. */
void nh_tool_add_force(nh_tool *tool, const nh_rows *rows, int r, double tau, double s);
/* Closest point of a tool to x: arc length by Newton from s0 (unclamped:
 * the caller decides what lies beyond the ends). */
double nh_tool_project(const nh_beam *beam, const double x[3], double s0);

/* ---- points.c ---- */
/* Current position of an embedded tissue point. */
void nh_point_position(const nh_mesh *mesh, const double *u, const nh_cpoint *p, double x[3]);
/* Set a point's material position and locate it (nonzero: outside the mesh). */
int nh_point_set(const nh_mesh *mesh, nh_cpoint *p, const double X[3]);
/* The tool's cross-section at p as the tissue sees it (docs/interaction.md,
 * "Tip disc"): the disc of radius rho about p's material position normal to
 * nrm, by a ring rule fine enough for p's cell (sample points at most half
 * its edge apart, at most 8 rings), as the weights of the mesh nodes in
 * the disc's mean; samples outside the tissue are left out. rho = 0: the
 * point itself (its cell's shape values). The rings' first samples lie
 * along ref's part across nrm (a tool's disc: the tool's frame, so the rule
 * turns with the tool, continuously), or with ref NULL along the axis least
 * aligned with nrm (a fixed normal). NH_ERR_MEMORY. */
int nh_disc_build(nh_disc *d, const nh_mesh *mesh, const nh_cpoint *p, const double nrm[3],
                  const double ref[3], double rho);
void nh_disc_free(nh_disc *d);
/* The disc's mean current position. */
void nh_disc_position(const nh_disc *d, const nh_mesh *mesh, const double *u, double x[3]);
/* The disc as the tissue part of row r (the last row). NH_ERR_MEMORY. */
int nh_disc_row(nh_rows *rows, int r, const nh_disc *d);
/* The material point p whose disc (nrm, ref, rho, in d) has its mean at the
 * current position x (Newton on x̄(X) = x with F = I + ∂u/∂X of the cell at
 * X, starting from X0; rho = 0: X + u(X) = x). NH_ERR_INPUT if it leaves
 * the tissue, NH_ERR_MEMORY. */
int nh_material_point(const nh_mesh *mesh, const double *u, const double x[3], const double X0[3],
                      const double nrm[3], const double ref[3], double rho, nh_disc *d,
                      nh_cpoint *p);
/* Channel point spacing at p: nh_channel_spacing with the edge of p's cell. */
double nh_point_spacing(const nh_tool_spec *spec, const nh_mesh *mesh, const nh_cpoint *p);
/* The tissue part of row r: p's cell nodes and shape values. */
void nh_row_tissue(nh_rows *rows, int r, const nh_mesh *mesh, const nh_cpoint *p);
/* The radius of a tool's cross-section as its tip and puncture rows act on
 * the tissue (docs/interaction.md, "Tip disc"). */
double nh_tip_radius(const nh_tool_spec *spec);

/* ---- anchor.c ---- */
/* Add the change of the rows of every anchor with an anchoring error (the
 * fronts with tip rows, the channel points tied) to dc (rows.m, may be
 * NULL) and dw (rows.m per field of the n fields w, may be NULL), as
 * nh_contact_data_change describes. NH_ERR_MEMORY. */
int nh_anchor_data_change(const nh_contact *c, const nh_mesh *mesh, const double *u, int n,
                          const double *w, double *dc, double *dw);

/* ---- puncture.c ---- */
/* The entry point of an outer tool on the rest surface (has_entry = 0: its
 * axis misses the tissue). */
void nh_puncture_init(nh_group *G, const nh_tool_spec *spec, const nh_mesh *mesh);
int nh_puncture_rows(nh_contact *c, nh_group *G, const nh_mesh *mesh, const double *u, double tau);
void nh_puncture_update(nh_contact *c, nh_group *G, double tau, nh_group_events *ev);

/* ---- channel.c ---- */
/* Open the channel at the entry point (the transition to punctured). */
int nh_channel_open(nh_group *G, const nh_tool_spec *spec, const nh_mesh *mesh);
int nh_tip_rows(nh_contact *c, nh_group *G, const nh_mesh *mesh, const double *u, double t,
                double h, double tau);
int nh_tip_update(nh_contact *c, nh_group *G, const nh_mesh *mesh, const double *u, double tau,
                  nh_group_events *ev);
/* The shaft rows over t → t + h (the step's travel of the tools: the axial
 * bounds of a dynamic step are those at its end, channel.c). */
int nh_shaft_rows(nh_contact *c, nh_group *G, const nh_mesh *mesh, const double *u, double t,
                  double h, double tau);
void nh_shaft_update(nh_contact *c, nh_group *G, double tau, nh_group_events *ev);
/* n1 of a tie's frame: the second director of the node T made orthogonal
 * to the tangent t and normalised. */
void nh_frame_normal(const double *T, const double t[3], double n1[3]);

/* ---- nest.c ---- */
/* The rows holding every released nested tool's nodes on its host's axis
 * where the host covers them (after the blocks: both tools dynamic).
 * NH_ERR_MEMORY. */
int nh_nest_rows(nh_contact *c);

#endif
