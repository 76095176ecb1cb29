/*
 * watertight.h — is a triangle surface closed and consistently oriented?
 *
 * The checker every later stage leans on (fracture, replay --verify): each undirected edge is
 * used by exactly two triangles, in opposite directions; no triangle is degenerate (repeated
 * index or zero area); the enclosed signed volume is positive.
 */
#ifndef CS_WATERTIGHT_H
#define CS_WATERTIGHT_H

#include <stddef.h>
#include <stdint.h>

typedef struct cs_watertight_report {
    int boundary_edges;     /* edges used by one triangle */
    int nonmanifold_edges;  /* edges used by three or more */
    int misoriented_edges;  /* edges used twice in the same direction */
    int degenerate_triangles;
    double volume;          /* signed enclosed volume (divergence theorem) */
} cs_watertight_report;

/* Returns 1 if closed, consistently oriented, non-degenerate and of positive volume; else 0
 * with the first problem in err (e.g. "12 boundary edges: the surface is open"). */
int cs_watertight_check(const double *v, int nv, const int32_t *t, int nt,
                        cs_watertight_report *rep, char *err, size_t errlen);

/* One piece of a fractured object: a view of its surface (borrowed). */
typedef struct cs_piece_view {
    const char *name;       /* for messages; may be NULL */
    const double *v;        /* 3 per vertex */
    int nv;
    const int32_t *t;       /* 3 per triangle */
    int nt;
} cs_piece_view;

/*
 * The fracture checker (issue: fracture), used by the tests and `cubesim-replay --verify`:
 * every piece passes cs_watertight_check, and the pieces' volumes add up to
 * `expected_volume` within |sum - expected| <= rel_tol·|expected| (skipped if expected_volume
 * is not finite). Returns 1 if all holds, else 0 with one line in err naming the piece and the
 * problem. *total_volume (if non-NULL) receives the sum.
 */
int cs_check_pieces(const cs_piece_view *pieces, int n, double expected_volume,
                    double rel_tol, double *total_volume, char *err, size_t errlen);

/* Signed volume enclosed by a triangle surface. */
double cs_mesh_volume(const double *v, const int32_t *t, int nt);

/*
 * Turn outward every part of a closed, consistently oriented surface (one that passes
 * cs_watertight_check) that is wound inside out as a whole: a shell (triangles joined through
 * shared edges) of negative volume at even depth (inside no other shell, or inside a cavity)
 * is such a part's outer wall, and it is turned with every shell inside it (its cavities'
 * walls become inward again). A negative shell at odd depth is a cavity's wall and is kept;
 * a positive shell is never turned on its own (an outward shell inside another is a second
 * solid). Inside: bounding box within the other's and a winding number (by solid angles)
 * about a point of it not 0, the point tried at several triangles until every winding number
 * is near a whole one. Bounded work (a file of many shells: those not decided within about
 * a second are left as given). Returns the number of shells turned, -1 if out of memory;
 * *n_shells (may be NULL) receives the number of shells.
 */
int cs_mesh_orient_shells(const double *v, int nv, int32_t *t, int nt, int *n_shells);

#endif
