/*
 * band.c — band Cholesky (band.h): row by row, L_ij = (a_ij − Σ_k L_ik L_jk) / L_jj over the
 * columns both rows hold, n·b² multiply-adds.
 */
#include "band.h"

#include <math.h>
#include <stdlib.h>

int cs_band_init(cs_band *m, int n, int b)
{
    m->n = n;
    m->b = b;
    m->a = calloc((size_t)n * (size_t)(b + 1), sizeof *m->a);
    return m->a ? 0 : -1;
}

void cs_band_free(cs_band *m)
{
    free(m->a);
    m->a = NULL;
}

int cs_band_cholesky(cs_band *m)
{
    const int n = m->n, b = m->b, w = b + 1;
    double dmax = 0;
    for (int i = 0; i < n; i++)
        dmax = fmax(dmax, m->a[(size_t)w * i + b]);
    if (!(dmax > 0) || !isfinite(dmax))
        return -1;
    for (int i = 0; i < n; i++) {
        double *ri = m->a + (size_t)w * i; /* ri[b - (i - j)] = L_ij */
        const int j0 = i - b > 0 ? i - b : 0;
        for (int j = j0; j <= i; j++) {
            const double *rj = m->a + (size_t)w * j;
            const int k0 = j0 > j - b ? j0 : j - b; /* columns both rows hold, below j */
            double s = ri[b - (i - j)];
            for (int k = k0; k < j; k++)
                s -= ri[b - (i - k)] * rj[b - (j - k)];
            if (j < i) {
                ri[b - (i - j)] = s / rj[b];
            } else {
                if (!(s > 1e-14 * dmax) || !isfinite(s))
                    return -1;
                ri[b] = sqrt(s);
            }
        }
    }
    return 0;
}

void cs_band_solve3(const cs_band *L, double *x)
{
    const int n = L->n, b = L->b, w = b + 1;
    for (int i = 0; i < n; i++) { /* L y = x */
        const double *ri = L->a + (size_t)w * i;
        const int j0 = i - b > 0 ? i - b : 0;
        double s0 = x[3 * (size_t)i], s1 = x[3 * (size_t)i + 1], s2 = x[3 * (size_t)i + 2];
        for (int j = j0; j < i; j++) {
            const double l = ri[b - (i - j)], *xj = x + 3 * (size_t)j;
            s0 -= l * xj[0];
            s1 -= l * xj[1];
            s2 -= l * xj[2];
        }
        x[3 * (size_t)i] = s0 / ri[b];
        x[3 * (size_t)i + 1] = s1 / ri[b];
        x[3 * (size_t)i + 2] = s2 / ri[b];
    }
    for (int i = n - 1; i >= 0; i--) { /* Lᵀ x = y: column i of Lᵀ is row i of L */
        const double *ri = L->a + (size_t)w * i;
        double *xi = x + 3 * (size_t)i;
        xi[0] /= ri[b];
        xi[1] /= ri[b];
        xi[2] /= ri[b];
        const int j0 = i - b > 0 ? i - b : 0;
        for (int j = j0; j < i; j++) {
            const double l = ri[b - (i - j)];
            double *xj = x + 3 * (size_t)j;
            xj[0] -= l * xi[0];
            xj[1] -= l * xi[1];
            xj[2] -= l * xi[2];
        }
    }
}
