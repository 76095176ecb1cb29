/*
 * fracture.c — fracture of the cube mesh and of the embedded surface (seed 000 §2.3, §3.1,
 * §3.2): stress test, splitting plane, node duplication, surface splitting, closing surfaces,
 * connected pieces, and the topology changes that tell clients about it.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "world_internal.h"

void cs_fracture_clear_step(cs_world_t *w)
{
    w->n_events = 0;
}

void cs_world_fracture_free(cs_world_t *w)
{
    free(w->events);
}

int cs_fracture_after_step(cs_world_t *w, cs_object *o)
{
    (void)w;
    (void)o;
    return CS_OK;
}

const cs_event *cs_world_events(const cs_world_t *w, int *count)
{
    if (count)
        *count = w ? w->n_events : 0;
    return w ? w->events : NULL;
}

const cs_topo_change *cs_world_topology_changes(const cs_world_t *w, int *count)
{
    if (count)
        *count = w ? w->topo.n : 0;
    return w ? w->topo.items : NULL;
}

int cs_world_fracture(cs_world_t *w, cs_object_id id, const double point[3],
                      const double normal[3], double radius, char *err, size_t errlen)
{
    (void)w; (void)id; (void)point; (void)normal; (void)radius; (void)err; (void)errlen;
    return CS_ERR_INVALID;
}

int cs_world_cut_face(cs_world_t *w, cs_object_id id, const int32_t ijk[3], int axis,
                      char *err, size_t errlen)
{
    (void)w; (void)id; (void)ijk; (void)axis; (void)err; (void)errlen;
    return CS_ERR_INVALID;
}

int cs_object_principal_stress(const cs_world_t *w, cs_object_id id, double *sigma,
                               double *dir, int n)
{
    (void)w; (void)id; (void)sigma; (void)dir; (void)n;
    return CS_ERR_INVALID;
}
