/*
 * closing.h — the closing surface of one exposed cube face (seed 000 §3.2).
 *
 * When fracture separates cells c1 and c2 along their common face f, the region of f that
 * lies inside the (rest-space) surface is bounded by oriented polygons: directed segments
 * where surface triangles cross f (orientation by Eq. 1: n1→n2 if [n_t × (n2 − n1)]·n_f > 0,
 * n_f the outward normal of f with respect to c1), the pairs of nodes made by one triangle
 * edge joined from the node without an outgoing edge, and f's four corner nodes and boundary
 * nodes walked in the positive sense about n_f, each joined to the next if it has no outgoing
 * edge yet. Every node is assigned a surface vertex (§3.2 rules), node pairs of a triangle are
 * moved towards each other by a third of their distance, consecutive nodes with the same
 * vertex are merged, and the polygons (with holes) are ear-cut in the plane of f; each 2-d
 * triangle (n1,n2,n3) becomes the surface triangle (v1,v2,v3), oriented so that its normal
 * points along n_f. The caller makes t (for c1) and its reverse t' (for c2).
 *
 * Degenerate positions are resolved by symbolic perturbation: a vertex whose coordinate along
 * f's axis equals the plane's counts as lying on the c2 side (just outside c1); a point on one
 * of the lattice lines through f's edges counts as lying just above that line (on the side of
 * larger coordinate), so f's square is [lo, hi) in both axes — inside for a point on a lower
 * edge line, outside on an upper one. The same holds for every triangle and every face of the
 * lattice, so neighbouring triangles agree and the squares of neighbouring faces tile the
 * plane without gaps (a rule that put edge lines outside every square would lose what lies
 * on them). A corner of f is taken just below both of its lines: corner_inside should say
 * whether that point is inside the surface.
 *
 * Pure geometry: no allocation survives a call, nothing is global. Owns nothing.
 */
#ifndef CS_CLOSING_H
#define CS_CLOSING_H

#include <stddef.h>
#include <stdint.h>

typedef struct cs_close_face {
    int axis;          /* f is perpendicular to this lattice axis (0 x, 1 y, 2 z) */
    int c1_below;      /* 1 if c1 lies on the lower side of the plane along axis (so
                          n_f = +e_axis), 0 if above (n_f = -e_axis) */
    double plane;      /* coordinate of f along axis [m] (rest space) */
    double lo[3], hi[3]; /* f's square: extent in the two other axes; the axis entry ignored */
    /* Corner k of f, k = 0..3, in the positive sense about n_f starting at the corner with the
     * smallest coordinates in the other two axes. The caller names a surface vertex for each
     * corner node (its own vertex, at the corner position plus a random offset) or -1 if it
     * has none; a corner that lies outside the surface is never used. */
    int32_t corner_vertex[4];
    /* 1 if the corner lies inside the surface (used only when no triangle crosses f: then f
     * is closed whole if its centre is inside, i.e. if all four corners are, else not at all) */
    int corner_inside[4];
    /* How a node where a triangle t crosses an edge of f gets its vertex (0 by default):
     * CS_CLOSE_BOUNDARY_PAPER: §3.2 as written: if t's other node is made by t's edge
     *   (v1,v2), the third vertex v3; if that node is on f's boundary too, t's vertex
     *   nearest to the node. The two faces sharing that edge of f pick different vertices,
     *   so closings of adjacent exposed faces do not meet.
     * CS_CLOSE_BOUNDARY_SHARED: the vertex the edge rule gives t's crossing edge whose
     *   crossing point lies on the upper side of f's edge line (the side of larger
     *   coordinate), decided by t and the line alone; both faces agree and the closings of
     *   adjacent exposed faces meet along their common edge. */
    int boundary_rule;
} cs_close_face;

enum { CS_CLOSE_BOUNDARY_PAPER = 0, CS_CLOSE_BOUNDARY_SHARED = 1 };

/*
 * Compute the closing triangles of face f.
 *   rest:       rest positions of the surface vertices (3 per vertex)
 *   tris:       the surface triangles (3 per triangle, counter-clockwise seen from outside)
 *   cand:       indices of the triangles that intersect c1 (seed 000 Table 1), n_cand of them
 *   c1_side:    per candidate (same order as cand): 1 if the triangle is assigned to c1's side
 *               of the fracture (to c1 or a cell that stays with it), 0 if to the other side
 *   out, cap:   room for cap triangles (3 int32 each) of surface vertex indices
 * Returns the number of triangles written (0 if f is not inside the surface), or -1 if cap is
 * too small or the polygons cannot be built (inconsistent crossings); err then says why. The
 * caller checks the result against the surface (closed, consistently oriented) and may fall
 * back to another closure.
 */
int cs_close_face_triangles(const cs_close_face *f, const double *rest, const int32_t *tris,
                            const int32_t *cand, int n_cand, const uint8_t *c1_side,
                            int32_t *out, int cap, char *err, size_t errlen);

/*
 * Ear-cut triangulation of one simple polygon given by 2-d points (x,y pairs, n >= 3) in
 * counter-clockwise order; writes n-2 triangles of point indices (3 each) to out. Ears of
 * zero area are taken last. Returns the number of triangles, or -1 (n < 3 or out of memory).
 */
int cs_earcut(const double *xy, int n, int32_t *out);

#endif
