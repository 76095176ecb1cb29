/*
 * scene.h — scene files (JSON, SI units) parsed with cJSON into engine definitions.
 *
 * Every field is checked: an unknown field, a field of the wrong type, a value out of range or
 * not finite is an error whose one-line message names the field by its JSON path
 * (e.g. "objects[1].material: unknown material 'sof'"). Mesh files are resolved relative to
 * the scene file's folder, loaded through assimp, placed, edge-subdivided (seed 000 §3.3) and
 * checked closed before the engine sees them.
 *
 * Owns: everything reachable from a cs_scene (object defs point into storage it owns).
 */
#ifndef CS_SCENE_H
#define CS_SCENE_H

#include <stddef.h>
#include "../server/engine/cubesim.h"

typedef struct cs_scene_object_store cs_scene_object_store; /* private storage per object */

typedef struct cs_scene {
    cs_world_def world;
    double publish_hz;        /* surface deltas per simulated second; default 60 */
    double keyframe_s;        /* a full snapshot every this many seconds (wall); default 2 */
    double status_hz;         /* status/telemetry messages per second (wall); default 4 */
    double publish_epsilon;   /* a vertex is resent once it moved more than this [m]; 1e-6 */
    int n_objects;
    cs_object_def *objects;   /* ready for cs_world_add_object */
    cs_scene_object_store *store;
} cs_scene;

/* Parse a scene file. On error returns -1, frees what it made, and err names the problem. */
int cs_scene_load(const char *path, cs_scene *out, char *err, size_t errlen);
/* Parse scene text; meshes are resolved relative to base_dir (NULL: current directory). */
int cs_scene_parse(const char *json, const char *base_dir, cs_scene *out, char *err,
                   size_t errlen);
void cs_scene_free(cs_scene *s);

/* Make a world holding every object of the scene. */
int cs_scene_instantiate(const cs_scene *s, cs_world_t **out, char *err, size_t errlen);

/*
 * Whether scene object i (a mesh, instantiated in w under its name) is voxelized coarsely: its
 * cubes hold at least CS_SCENE_COARSE_RATIO times the volume its mesh encloses (a crossed cube
 * is kept whole, so cubes of about a quarter of the mesh's size or larger inflate its mass and
 * stiffness: one 5 m cube for a 0.2 m ball holds 30 000 times its volume). Returns 1 with one
 * line in msg naming the object, the cubes' and the mesh's volumes and extents; 0 if not (or
 * not a mesh, or not in w).
 */
#define CS_SCENE_COARSE_RATIO 2.0
int cs_scene_coarse_object(const cs_scene *s, const cs_world_t *w, int i, char *msg, size_t n);

/*
 * Whether scene object i's mesh had shells wound inside out with no other shell around them,
 * which loading turned outward (cs_mesh_orient_shells). Returns 1 with one line in msg naming
 * the object and the count; 0 if none (or not a mesh).
 */
int cs_scene_turned_shells(const cs_scene *s, int i, char *msg, size_t n);

/*
 * Whether scene object i (instantiated in w under its name) starts with part of it below the
 * ground plane (the scene has a ground, and the lowest of its cube mesh's nodes is more than a
 * thousandth of its cube size below `ground.height`). Such an object is pushed up onto the
 * plane: a deformable one in its first step, compressed by the depth at once and thrown up by
 * it; a rigid one by its contacts, a little each step. Returns 1 with one line in msg naming
 * the object, the depth and the plane; 0 if not (or no ground, or not in w).
 */
int cs_scene_below_ground_object(const cs_scene *s, const cs_world_t *w, int i, char *msg,
                                 size_t n);

#endif
