/*
 * band.h — a symmetric positive definite band matrix and its Cholesky factor: the scalar
 * consistent mass of a localframe object, factored once, as the preconditioner of its
 * central-difference steps (world.c "the mass factor").
 */
#ifndef CS_BAND_H
#define CS_BAND_H

#include <stddef.h>

/* Row i holds entries (i, i − b) .. (i, i) at a + (b + 1)·i (entries before column 0 are 0). */
typedef struct cs_band {
    int n, b;
    double *a;
} cs_band;

/* Zeroed storage for n rows of half-bandwidth b; -1 if out of memory. */
int cs_band_init(cs_band *m, int n, int b);
void cs_band_free(cs_band *m);
/* Entry (i, j), j ≤ i ≤ j + b: where it is stored. */
static inline double *cs_band_at(cs_band *m, int i, int j)
{
    return m->a + (size_t)(m->b + 1) * i + (m->b - (i - j));
}
/* In place: the lower Cholesky factor L (m = L Lᵀ); -1 if m is not positive definite (a pivot
 * ≤ 1e-14 of the largest diagonal entry or not finite; m is then garbage). */
int cs_band_cholesky(cs_band *m);
/* x = (L Lᵀ)⁻¹ x for three right-hand sides side by side (x: 3 per row), one pass over L. */
void cs_band_solve3(const cs_band *L, double *x);

#endif
