/*
 * contact_probe.h — how deep a node of one object lies inside another's deformed cells: the
 * penetration measure of the contact tests (test_contact.c, test_contact_born.c); and an
 * object's mass-weighted means (its centre and centre velocity; test_rigid.c too).
 */
#ifndef CS_TEST_CONTACT_PROBE_H
#define CS_TEST_CONTACT_PROBE_H

#include <math.h>
#include <stdbool.h>
#include <string.h>

#include "lattice.h"
#include "world_internal.h"

/* The mass-weighted mean of a per-node vector u (positions: the centre of mass; velocities:
 * its velocity). */
static inline void mass_mean(const cs_object *o, const double *u, double c[3])
{
    c[0] = c[1] = c[2] = 0;
    for (int i = 0; i < o->n; i++)
        for (int k = 0; k < 3; k++)
            c[k] += o->m[i] * u[3 * i + k] / o->mass;
}

/* Local coordinates u of p in the hexahedron X (CS_CORNER order) by Newton on the trilinear
 * map; false if it does not converge. */
static inline bool hex_coords(const double X[8][3], const double p[3], double u[3])
{
    u[0] = u[1] = u[2] = 0.5;
    for (int it = 0; it < 20; it++) {
        double r[3] = {-p[0], -p[1], -p[2]}, J[3][3] = {{0}};
        for (int k = 0; k < 8; k++) {
            double f[3], df[3];
            for (int a = 0; a < 3; a++) {
                f[a] = CS_CORNER[k][a] ? u[a] : 1 - u[a];
                df[a] = CS_CORNER[k][a] ? 1 : -1;
            }
            const double dN[3] = {df[0] * f[1] * f[2], f[0] * df[1] * f[2], f[0] * f[1] * df[2]};
            for (int a = 0; a < 3; a++) {
                r[a] += f[0] * f[1] * f[2] * X[k][a];
                for (int b = 0; b < 3; b++)
                    J[a][b] += X[k][a] * dN[b];
            }
        }
        const double det = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) -
                           J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
                           J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
        if (!(fabs(det) > 0))
            return false;
        double du[3];
        for (int a = 0; a < 3; a++) { /* Cramer */
            double M[3][3];
            memcpy(M, J, sizeof M);
            for (int b = 0; b < 3; b++)
                M[b][a] = r[b];
            du[a] = (M[0][0] * (M[1][1] * M[2][2] - M[1][2] * M[2][1]) -
                     M[0][1] * (M[1][0] * M[2][2] - M[1][2] * M[2][0]) +
                     M[0][2] * (M[1][0] * M[2][1] - M[1][1] * M[2][0])) / det;
        }
        double m = 0;
        for (int a = 0; a < 3; a++) {
            u[a] -= du[a];
            m = fmax(m, fabs(du[a]));
        }
        if (m < 1e-12)
            return true;
    }
    return false;
}

/* How deep any node of P lies inside Q: the largest over P's nodes inside a deformed cell of
 * Q of h · min over the cell's faces of the node's distance to it in the cell's coordinates
 * (a lower bound of its depth in Q); 0 if none is inside. */
static inline double deepest_inside(const cs_object *P, const cs_object *Q)
{
    double deep = 0;
    for (int i = 0; i < P->n; i++)
        for (int32_t c = 0; c < Q->cm.n_cells; c++) {
            double X[8][3], u[3];
            for (int k = 0; k < 8; k++)
                for (int a = 0; a < 3; a++)
                    X[k][a] = Q->x[3 * (size_t)Q->cm.cell_nodes[8 * c + k] + a];
            if (!hex_coords(X, P->x + 3 * i, u))
                continue;
            double d = INFINITY;
            for (int a = 0; a < 3; a++)
                d = fmin(d, fmin(u[a], 1 - u[a]));
            deep = fmax(deep, d * Q->cm.h);
        }
    return deep;
}

#endif
