/*
 * topo.h — a change of one object's surface topology (fracture, seed 000 §3.1–3.2), as the
 * engine makes it, the daemon sends it (CUBESIM_TOPOLOGY) and every client applies it.
 *
 * One change takes an object's surface from topology_version `from_version` to `to_version`.
 * It is applied to the vertex array and the triangle array in exactly this order:
 *   1. vremove: for each index r, in the order given (strictly descending), the last vertex
 *      moves into slot r and the array shrinks by one ("swap-remove").
 *   2. vnew: new vertices are appended (positions given).
 *   3. tremove: the same swap-remove on the triangle array, strictly descending.
 *   4. tset: triangle slot tset_index[i] (an index into the array after step 3) is rewritten
 *      to tset_tri[3i..3i+2] (rewired triangles).
 *   5. tnew: new triangles are appended (closing triangles and the like).
 * Afterwards the object has n_vertices_total vertices and n_triangles_total triangles, and
 * every triangle index lies in [0, n_vertices_total). Triangles that step 1 would leave
 * pointing at a moved or removed vertex are always among those rewritten in step 4 or
 * removed in step 3, so a client never has to scan its triangles.
 *
 * A new object (a piece broken off `parent_id`) is a change with from_version 0 applied to
 * empty arrays: only vnew and tnew are non-empty. Pieces carry their name and model.
 *
 * The struct only borrows its arrays; whoever fills it owns them (the engine until its next
 * mutating call; a decoder until its cleanup).
 */
#ifndef CS_TOPO_H
#define CS_TOPO_H

#include <stddef.h>
#include <stdint.h>

typedef struct cs_topo_change {
    int32_t object_id;
    int32_t parent_id;        /* a new piece: the object it broke off; else 0 */
    const char *name;         /* a new piece: its name; else NULL */
    const char *model;        /* a new piece: its model name; else NULL */
    uint32_t from_version;    /* 0 for a new object */
    uint32_t to_version;      /* > from_version */
    int32_t n_vertices_total; /* after the change */
    int32_t n_triangles_total;
    int32_t n_vremove;
    const int32_t *vremove;   /* strictly descending */
    int32_t n_vnew;
    const double *vnew_xyz;   /* 3 per new vertex: current (deformed) positions [m] */
    int32_t n_tremove;
    const int32_t *tremove;   /* strictly descending */
    int32_t n_tset;
    const int32_t *tset_index;
    const int32_t *tset_tri;  /* 3 per rewired triangle */
    int32_t n_tnew;
    const int32_t *tnew;      /* 3 per new triangle */
    /* Per new vertex (n_vnew of them), the vertex it is a copy of, or -1 for a new point
     * (NULL: every one is a new point). In a split, a copy starts exactly where its source is
     * at the time of the change, unless the engine placed it where its own cell puts it, more
     * than h/10 away (a crack that had opened before: README "Fracture"). A new piece's vertex
     * that was bound to a cell now in another piece starts where the piece's own cell puts it
     * (near its source, by rounding or the crack's opening; 4e-6 m in the tests' pushed
     * icosphere). The index is into the
     * object's vertex array before this change (before step 1); for a new piece, into its
     * parent's vertex array as it is when the piece's change is applied. So a client can
     * compare the volume before and after a change at the same positions (every copy at its
     * source's): the closing surfaces of a crack come in mirror pairs over copies and new
     * points at the same positions, whose volumes cancel exactly. */
    const int32_t *vnew_src;
} cs_topo_change;

/*
 * Check a change against arrays of nv vertices and nt triangles without applying it: removal
 * indices descending and in range at the time they apply, rewired slots in range, final
 * counts equal to the totals, every final index in range, no triangle with a repeated index,
 * finite positions, sources in [-1, nv) (a new piece's: >= -1; its parent is not at hand). Returns 0, or -1 with one line in err naming the first problem.
 */
int cs_topo_check(const cs_topo_change *c, int nv, int nt, char *err, size_t errlen);

/*
 * Step 1 on any per-vertex array of `elem` bytes per vertex holding nv entries (positions,
 * skinning data, ...). The caller makes room for and fills the appended vertices (step 2).
 * Returns the vertex count after step 1.
 */
int cs_topo_remove_vertices(const cs_topo_change *c, void *arr, size_t elem, int nv);
/* Step 3 on any per-triangle array of `elem` bytes (the triangles themselves, or data kept
 * per triangle). Returns the triangle count after step 3. */
int cs_topo_remove_triangles(const cs_topo_change *c, void *arr, size_t elem, int nt);
/*
 * Steps 3–5 on the triangle index array itself: tris must have room for n_triangles_total
 * triangles (and for nt before the change). Returns n_triangles_total.
 */
int cs_topo_apply_triangles(const cs_topo_change *c, int32_t *tris, int nt);

#endif
