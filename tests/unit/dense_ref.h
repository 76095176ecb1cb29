/*
 * dense_ref.h — the reference stiffness product the kernel tests compare with (test_fem.c,
 * test_products.c): y = Σ_c R_c K_c R_cᵀ p over the active cells (all if act is NULL) with
 * the dense 24×24 matrices, K_c = Σ_g kf_g K_g (graded) or K without kf, R_c = fem->R.
 */
#ifndef CS_TEST_DENSE_REF_H
#define CS_TEST_DENSE_REF_H

#include <stdint.h>
#include <string.h>

#include "fem.h"

static inline void dense_apply(const cs_fem *fem, const double *kf, const uint8_t *act,
                               const double *p, double *y)
{
    memset(y, 0, sizeof(double) * 3 * fem->n_nodes);
    for (int c = 0; c < fem->n_cells; c++) {
        if (act && !act[c])
            continue;
        const int32_t *nd = fem->cell_nodes + 8 * c;
        const double *R = fem->R + 9 * c;
        double Ke[576], u[24], ku[24];
        for (int i = 0; i < 576; i++) {
            Ke[i] = kf ? 0.0 : fem->K[i];
            for (int g = 0; kf && g < 8; g++)
                Ke[i] += kf[8 * c + g] * fem->Kg[576 * g + i];
        }
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++) {
                const double *d = p + 3 * nd[k];
                u[3 * k + i] = R[i] * d[0] + R[3 + i] * d[1] + R[6 + i] * d[2];
            }
        for (int i = 0; i < 24; i++) {
            ku[i] = 0;
            for (int j = 0; j < 24; j++)
                ku[i] += Ke[24 * i + j] * u[j];
        }
        for (int k = 0; k < 8; k++)
            for (int i = 0; i < 3; i++)
                y[3 * nd[k] + i] += R[3 * i] * ku[3 * k] + R[3 * i + 1] * ku[3 * k + 1] +
                                    R[3 * i + 2] * ku[3 * k + 2];
    }
}

#endif
