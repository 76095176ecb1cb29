/*
 * mesh.h — triangle surface meshes: import and export through assimp.
 *
 * A cs_mesh is a plain indexed triangle list in double precision. It is what the daemon loads
 * from scene files, what --export writes, and what clients rebuild from the bus.
 * Owns: v and t (malloc'd). cs_mesh_free releases them and zeroes the struct.
 */
#ifndef CS_MESH_H
#define CS_MESH_H

#include <stddef.h>
#include <stdint.h>

typedef struct cs_mesh {
    double *v;   /* 3 per vertex */
    int nv;
    int32_t *t;  /* 3 per triangle */
    int nt;
} cs_mesh;

void cs_mesh_free(cs_mesh *m);

/* The longest file path (bytes) a one-line message shows whole; a longer one shows its end. */
#define CS_MSG_PATH 160
/* ... and the scene file's own path, which messages put in front of a mesh's (scene.c) */
#define CS_MSG_SCENE_PATH 120

/*
 * A file path as one-line messages show it, in buf (n bytes): whole if it fits, else its end —
 * the file name and the folders nearest it — behind a "…" that marks the cut
 * ("…/deep/dir/mesh.obj": from a '/' when one is near the cut, never inside a UTF-8
 * character). Control bytes become '?'; NULL reads "(null)". Returns buf. The messages of
 * cs_mesh_load and cs_mesh_export name their file this way, at most CS_MSG_PATH bytes.
 */
const char *cs_msg_path(const char *s, char *buf, size_t n);
/* The same for any text from a file: with `path`, as cs_msg_path; without, a name or word
 * keeps its start, the "…" after it. */
const char *cs_msg_text(const char *s, char *buf, size_t n, int path);

/*
 * Load every mesh of a file assimp reads (OBJ, STL, PLY, glTF, ...; OFF is read here, see
 * mesh_io.c), merged into one,
 * node transforms applied, triangulated, identical vertices welded (by exact position after
 * import), degenerate triangles dropped. Returns 0, or -1 with a one-line message naming the
 * file and the problem (missing, unreadable, rejected by assimp, no triangles, non-finite).
 * The import runs in a forked child under a memory cap (the caller's mapped size plus half
 * the machine's RAM) and a 120 s limit: a file that makes assimp allocate without bound,
 * crash or hang is refused like any other bad file, and the caller's state is untouched.
 */
int cs_mesh_load(const char *path, cs_mesh *out, char *err, size_t errlen);

/* Scale, then rotate by Euler angles in degrees (about x, then y, then z), then translate. */
void cs_mesh_transform(cs_mesh *m, double scale, const double rotation_deg[3],
                       const double position[3]);

/*
 * Write pieces through assimp; the format follows the file extension (obj, stl, ply, off, glb,
 * gltf, ...). Each piece becomes one mesh/node named names[i] (OBJ: one `g` group per piece).
 * Returns 0, or -1 with a message.
 */
/* 0 if assimp has an exporter for the extension of path (what cs_mesh_export would use), else
 * -1: checked before a run, so a bad --export fails at once rather than at its end. */
int cs_mesh_export_format(const char *path);
int cs_mesh_export(const char *path, const cs_mesh *pieces, const char *const *names, int n,
                   char *err, size_t errlen);

#endif
