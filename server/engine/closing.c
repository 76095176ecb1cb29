/* closing.c — placeholder until the §3.2 implementation lands: no closing triangles (the
 * fracture repair closes every loop). */
#include "closing.h"

int cs_close_face_triangles(const cs_close_face *f, const double *rest, const int32_t *tris,
                            const int32_t *cand, int n_cand, const uint8_t *c1_side,
                            int32_t *out, int cap, char *err, size_t errlen)
{
    return 0;
}

int cs_earcut(const double *xy, int n, int32_t *out)
{
    return -1;
}
