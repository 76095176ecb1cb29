/*
 * world_internal.h — the engine's private object and world records, shared by world.c (the
 * step, inputs, reading) and fracture.c (seed 000 §2.3, §3.1–3.2). Not part of the API.
 *
 * Owns (through cs_object): the cube mesh, the bound surface, the FEM data and every
 * per-node array; (through cs_world) every object, and the events and topology changes of
 * the last mutating call.
 */
#ifndef CS_WORLD_INTERNAL_H
#define CS_WORLD_INTERNAL_H

#include "cubesim.h"
#include "cubemesh.h"
#include "fem.h"
#include "solver.h"
#include "surface.h"

#define CS_MAX_INPUTS 1024
#define CS_MAX_NAME 255

typedef enum { CS_INPUT_FORCE = 0, CS_INPUT_DRAG = 1 } cs_input_kind;

typedef struct cs_input {
    cs_input_kind kind;
    int32_t cell;
    double w[8];          /* trilinear weight of each corner of `cell` */
    double force[3];      /* CS_INPUT_FORCE */
    double target[3];     /* CS_INPUT_DRAG */
    double stiffness;
    int steps_left;
} cs_input;

typedef struct cs_object {
    cs_object_id id;
    char *name;
    cs_model model;
    cs_integrator integrator; /* resolved: never CS_INTEGRATOR_DEFAULT */
    cs_material mat;
    bool fracture;
    double fracture_radius;  /* [m], > 0 */
    uint8_t *cell_cut;       /* per cell: bit 2·axis + (side > 0) set where a fracture cut
                                that face; NULL until the first fracture */
    uint8_t *cell_open;      /* per cell, the same bits: faces whose four nodes are separated
                                (their closing surfaces exist); NULL until then */
    uint8_t *tri_kind;       /* per surface triangle: 0 from the mesh, 1 made by fracture */
    int32_t *corner_vertex;  /* per node: the surface vertex made for it as a closing-surface
                                corner (seed 000 §3.2), or -1; NULL until the first fracture */
    cs_cubemesh cm;
    cs_surface surf;
    cs_fem fem;
    int n;                 /* nodes */
    double *x, *v, *m;     /* 3, 3, 1 per node */
    double *f_const;       /* gravity + scene loads, 3 per node */
    double *f, *b, *v1, *blocks;
    uint8_t *mask;         /* per dof: held */
    uint8_t *smask;        /* per dof: held or in ground contact during this step's solve */
    uint8_t *contact;      /* per node: 1 constrained by the ground this step, 2 released */
    int n_fixed_nodes;
    double mass;
    cs_cg_work cg;
    cs_input inputs[CS_MAX_INPUTS];
    int n_inputs;
    int still_steps;
    bool sleeping;
    uint32_t topology_version;
    /* elastic energy of the current positions, valid until they change (status messages
     * ask for it several times a second; recomputing means a rotation per element) */
    double elastic_energy;
    bool elastic_energy_valid;
    /* operator coefficients of the current solve */
    double mcoef, kcoef, dcoef;
    /* CS_MODEL_RIGID: pose, velocities and mass properties (rigid.h); NULL otherwise */
    struct cs_rigid *rb;
} cs_object;

/* The topology changes of one mutating call: their arrays live in one arena. */
typedef struct cs_topo_list {
    cs_topo_change *items;
    int n, cap;
    void **blocks;          /* owned allocations the items point into */
    int n_blocks, cap_blocks;
} cs_topo_list;

struct cs_world {
    cs_world_def def;
    int threads;
    cs_object **objects;
    int n_objects, cap_objects;
    cs_object_id next_id;
    double time;
    int64_t frame;
    cs_step_stats stats;
    cs_event *events;
    int n_events, cap_events;
    cs_topo_list topo;
    struct cs_rigid_world *rigid; /* rigid.c's per-step scratch; NULL until a rigid step */
};

/* Defined in world.c, used by fracture.c. */
/* Write the message to err (if any) and return code: the engine's runtime-error idiom. */
int cs_engine_fail(char *err, size_t errlen, int code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
cs_object *cs_world_find_internal(const cs_world_t *w, cs_object_id id);
int cs_world_append_object(cs_world_t *w, cs_object *o);
void cs_object_free_internal(cs_object *o);
int cs_object_alloc_state(cs_object *o);

/* Defined in fracture.c, used by world.c. */
void cs_fracture_clear_step(cs_world_t *w);
void cs_world_fracture_free(cs_world_t *w);
/* Stress test and fracture of one object after its step (fracture enabled only). */
int cs_fracture_after_step(cs_world_t *w, cs_object *o);

#endif


