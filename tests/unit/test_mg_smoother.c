/*
 * test_mg_smoother.c — the V-cycle's smoothing polynomials (mg.h cs_mg_smoother_poly/_steps):
 * Lottes' optimised fourth-kind Chebyshev polynomials, applied as a product of root factors.
 * Checked against what they must be: the product form is the paper's three-term recurrence,
 * degree 1 is the damped-Jacobi step of weight 1.5 (β₁ · 4/3), the error stays below 1 in
 * modulus on (0, λ] (so the V-cycle is positive definite) and somewhat beyond it (λ is an
 * estimate), and it damps the upper part of the spectrum, which the coarse levels do not reach.
 */
#include <math.h>
#include <stdio.h>

#include "check.h"
#include "mg.h"

static double poly_at(const double *e, int deg, double t)
{
    double v = 0;
    for (int j = deg; j >= 0; j--)
        v = v * t + e[j];
    return v;
}

static double product_at(const double *c, int deg, double t)
{
    double v = 1;
    for (int i = 0; i < deg; i++)
        v *= 1 - c[i] * t;
    return v;
}

TEST(mg_smoother_product_form_equals_recurrence)
{
    for (int deg = 1; deg <= CS_MG_CHEB_MAX; deg++) {
        double e[CS_MG_CHEB_MAX + 1], c[CS_MG_CHEB_MAX];
        cs_mg_smoother_poly(deg, e);
        ENSURE(cs_mg_smoother_steps(deg, c) == 0);
        ENSURE_NEAR(e[0], 1.0, 1e-15);
        double worst = 0;
        for (int g = 0; g <= 150; g++) {
            const double t = g / 100.0, p = poly_at(e, deg, t);
            const double d = fabs(product_at(c, deg, t) - p) / (1 + fabs(p));
            worst = d > worst ? d : worst;
        }
        printf("    degree %d: weights", deg);
        for (int i = 0; i < deg; i++)
            printf(" %.6f", c[i]);
        printf("; product against recurrence %.1e\n", worst);
        ENSURE(worst < 1e-12);
        for (int i = 0; i < deg; i++) /* real roots in (0, 1]: weights ≥ 1, mildest first */
            ENSURE(c[i] >= 1.0 && (i == 0 || c[i] > c[i - 1]));
    }
    /* degree 1: one Jacobi step of weight β₁ · 4/3 = 1.5 */
    double c1[1];
    ENSURE(cs_mg_smoother_steps(1, c1) == 0);
    ENSURE_NEAR(c1[0], 1.5, 1e-12);
    /* degree 2's roots have a closed form: 2/√5 and (5 − √5)/10 */
    double c2[2];
    ENSURE(cs_mg_smoother_steps(2, c2) == 0);
    ENSURE_NEAR(1.0 / c2[0], 2.0 / sqrt(5.0), 1e-9);
    ENSURE_NEAR(1.0 / c2[1], (5.0 - sqrt(5.0)) / 10.0, 1e-9);
    double bad[CS_MG_CHEB_MAX];
    ENSURE(cs_mg_smoother_steps(0, bad) == -1 && cs_mg_smoother_steps(CS_MG_CHEB_MAX + 1, bad) == -1);
}

TEST(mg_smoother_contracts_and_damps_the_upper_spectrum)
{
    for (int deg = 1; deg <= CS_MG_CHEB_MAX; deg++) {
        double e[CS_MG_CHEB_MAX + 1];
        cs_mg_smoother_poly(deg, e);
        /* |e| < 1 on (0, 1]: every smoothing step contracts the error in the A-norm, and the
         * symmetric V-cycle stays positive definite while λmax(D⁻¹A) ≤ λ */
        double emax = 0, upper = 0, margin = 1;
        for (int g = 1; g <= 100000; g++) {
            const double t = g / 100000.0, v = fabs(poly_at(e, deg, t));
            emax = v > emax ? v : emax;
            if (t >= 0.25)
                upper = v > upper ? v : upper;
        }
        /* how far past λ it still holds: λ is 1.1 × a power estimate of λmax */
        while (fabs(poly_at(e, deg, margin + 1e-4)) < 1 && margin < 3)
            margin += 1e-4;
        printf("    degree %d: max |e| on (0, 1] %.4f, on [1/4, 1] %.4f; |e| < 1 up to %.3f λ\n",
               deg, emax, upper, margin);
        ENSURE(emax < 1.0);
        /* at least 60 % of the error in the upper three quarters of the spectrum goes per
         * smoothing from degree 2 on (degree 1, Jacobi: 37.5 %) */
        ENSURE(upper < (deg == 1 ? 0.63 : 0.40));
        /* the degrees the V-cycle uses (2, 3) stay below 1 to 1.1 λ, 1.21 × the estimate:
         * the power iteration's underestimate has that much room (degree 4 would have 1.08) */
        if (deg <= 3)
            ENSURE(margin > 1.1);
    }
}
