/*
 * contact_soft.c — a deformable object's response to contact impulses (contact_soft.h).
 */
#include "contact_soft.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "elastic.h"
#include "mat3.h"
#include "mg.h"
#include "solver.h"

static int grow_f64(double **p, size_t *cap, size_t n)
{
    if (n <= *cap)
        return 0;
    double *g = realloc(*p, n * sizeof *g);
    if (!g)
        return -1;
    *p = g;
    *cap = n;
    return 0;
}

/*
 * The coarse part: centre of mass, inverse mass per free axis and inverse inertia over the
 * free rotations, of the mass A gives the nodes (mass[i]). Held or pinned nodes: no coarse
 * part. Nodes on the ground (constrained by it in D's last step): x, y translation and the
 * rotation about z only (the ground takes the rest). Held: the ground's friction holds the
 * object, the net force of its next step along the ground, P_xy (res summed: gravity, loads;
 * the elastic forces cancel), within ground_mu times the net force into it, −P_z. Then u0 has
 * no coarse drift (U = 0: the object does not slide), and the rigid bodies' contacts (not iso)
 * see no coarse part at all, the object as held. Before, on a slope of 3°, where μ = 0.5
 * holds, the solve saw a block's top heading down the slope with the whole block's
 * acceleration while the ground held it, and a rigid box resting on the block slid off it
 * (1.2 cm/s, then faster). The deformable–deformable pass keeps the coarse response to its
 * impulses: without it a soft block overhanging another on the ground gained energy (0.11 J
 * over 3 s against 0.04 J). Returns whether the object is held.
 */
static bool coarse_modes(cs_soft_resp *r, const cs_object *D, const double *mass,
                         const double P[3], double ground_mu)
{
    memset(r->minv, 0, sizeof r->minv);
    memset(r->iinv, 0, sizeof r->iinv);
    memset(r->c, 0, sizeof r->c);
    bool pinned = D->n_fixed_nodes > 0, ground = false;
    double M = 0;
    for (int i = 0; i < D->n; i++) {
        pinned = pinned || D->pin[i];
        ground = ground || (D->contact && cs_ground_contact(D->contact[i]));
        M += mass[i];
        for (int a = 0; a < 3; a++)
            r->c[a] += mass[i] * D->x[3 * (size_t)i + a];
    }
    if (pinned || !(M > 0))
        return false;
    for (int a = 0; a < 3; a++)
        r->c[a] /= M;
    const bool held = ground && hypot(P[0], P[1]) <= ground_mu * -P[2];
    if (held && !r->iso)
        return true;
    r->coarse = true;
    double I[9] = {0};
    for (int i = 0; i < D->n; i++) {
        double d[3];
        for (int a = 0; a < 3; a++)
            d[a] = D->x[3 * (size_t)i + a] - r->c[a];
        const double d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++)
                I[3 * a + b] += mass[i] * ((a == b ? d2 : 0.0) - d[a] * d[b]);
    }
    r->minv[0] = r->minv[1] = 1 / M;
    if (ground) {
        if (I[8] > 0)
            r->iinv[8] = 1 / I[8];
        return held;
    }
    r->minv[2] = 1 / M;
    double adj[9];
    const double det = cs_mat3_adjugate(I, adj);
    if (det > 0) /* (a body of one row of nodes has a singular inertia: no rotations then) */
        for (int k = 0; k < 9; k++)
            r->iinv[k] = adj[k] / det;
    return false;
}

/* y = A p, A = (1 + dt α) M + (dt² + dt β) K (the damping fields' terms, the pins' penalty, the
 * drags' springs)
 * the operator of D's next implicit step, zero at held dofs (a cs_matvec_fn; ctx is the
 * response). The damping fields' product goes to the scratch's last third (free after the
 * blocks are set up). */
static void apply_step_operator(void *ctx, const double *p, double *y)
{
    const cs_soft_resp *r = ctx;
    cs_object *D = r->D;
    const double dt = r->dt, al = D->mat.damping[0], be = D->mat.damping[1];
    const bool fld = D->fld.has_damping;
    const double mc = fld ? 1 : 1 + dt * al, kc = dt * dt + (fld ? 0 : dt * be);
    double *kd = r->scratch + 6 * (size_t)D->n;
    cs_elastic_apply_K(D, p, y);
    if (fld)
        cs_elastic_apply_Kd(D, p, kd);
    for (int i = 0; i < D->n; i++)
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * (size_t)i + a;
            double v = kc * y[d] + mc * D->m[i] * p[d];
            if (fld)
                v += dt * be * kd[d] + dt * al * D->fld.md[i] * p[d];
            if (D->pin[i])
                v += dt * dt * D->penalty * p[d];
            y[d] = D->mask[d] ? 0.0 : v;
        }
    if (D->n_inputs == 0)
        return;
    /* (the springs' corners may be held: zero them again) */
    cs_object_add_spring_operator(D, dt * dt, p, y);
    for (size_t d = 0; d < 3 * (size_t)D->n; d++)
        if (D->mask[d])
            y[d] = 0.0;
}

/*
 * The blocks A_ii⁻¹, the coarse modes, and u0 = v + Φ U + A_ii⁻¹ (res − A Φ U) with
 * res = M v + dt f − A v the residual of D's next step at v and U = (Φᵀ M Φ)⁻¹ Φᵀ res its
 * coarse correction (K Φ = 0 for rigid modes). f holds the clients' inputs the step will apply
 * (point forces, drags, pressure; a drag's spring is in A too).
 */
static void prepare_stiff(cs_soft_resp *r, cs_object *D, double dt, double ground_mu)
{
    const size_t n = (size_t)D->n;
    const double al = D->mat.damping[0], be = D->mat.damping[1];
    const bool fld = D->fld.has_damping;
    const double mc = fld ? 1 : 1 + dt * al, kc = dt * dt + (fld ? 0 : dt * be);
    double *f = r->scratch, *av = r->scratch + 3 * n;
    const double *v = D->v;
    cs_elastic_update(D, D->x);
    D->elastic_energy_valid = false;
    if (fld) /* the damping field's blocks, in the scratch until folded in */
        cs_elastic_diag_blocks_d(D, r->scratch);
    cs_elastic_diag_blocks(D, r->ainv);
    for (size_t i = 0; i < 9 * n; i++)
        r->ainv[i] *= kc;
    cs_object_add_spring_blocks(D, dt * dt, r->ainv);
    for (size_t i = 0; i < n; i++) {
        double *B = r->ainv + 9 * i;
        for (int k = 0; k < 9 && fld; k++)
            B[k] += dt * be * r->scratch[9 * i + k];
        for (int a = 0; a < 3; a++)
            B[4 * a] += mc * D->m[i] + (fld ? dt * al * D->fld.md[i] : 0.0) +
                        (D->pin[i] ? dt * dt * D->penalty : 0.0);
        if (r->iso) {
            const double a = 3.0 / (B[0] + B[4] + B[8]);
            for (int k = 0; k < 9; k++)
                B[k] = k % 4 == 0 ? a : 0.0;
        } else {
            cs_invert_block(B);
        }
    }
    /* the residual res (into f), then the mass A gives each node */
    cs_elastic_force(D, D->x, f, NULL);
    cs_object_add_input_forces(D, f);
    apply_step_operator(r, v, av);
    for (size_t i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * i + a;
            double F = f[d] + D->f_const[d];
            if (D->pin[i])
                F += D->penalty * (D->cm.node_rest[d] - D->x[d]);
            f[d] = D->mask[d] ? 0.0 : D->m[i] * v[d] + dt * F - av[d];
        }
    }
    double *mass = r->mass;
    for (size_t i = 0; i < n; i++)
        mass[i] = mc * D->m[i] + (fld ? dt * al * D->fld.md[i] : 0.0);
    double P[3] = {0, 0, 0}, L[3] = {0, 0, 0}, U[3], Wc[3];
    for (size_t i = 0; i < 3 * n; i++)
        P[i % 3] += f[i];
    const bool held = coarse_modes(r, D, mass, P, ground_mu);
    r->has_res0 = false;
    if (!r->coarse && !grow_f64(&r->res0, &r->cap_res0, 3 * n)) {
        memcpy(r->res0, f, 3 * n * sizeof *f);
        r->has_res0 = true;
    }
    /* U = (Φᵀ A Φ)⁻¹ Φᵀ res. The torque is that of the loads and the mass damping alone,
     * dt f_const − (mass − m) v: the elastic forces are internal and leave it out.
     * - Their stiffness term dt² (K v)ᵢ: for a rigid rotation of an unstrained body K Φ = 0,
     *   but after contact impulses on a few nodes of a stiff, strained, turning body v has
     *   spikes there whose dt² K v has a torque the exact step does not see (its v1 is smooth:
     *   Φᵀ A v1 = Φᵀ b takes dt² (KΦ)ᵀ v1, not v). Three steel blocks (E 2e11 Pa) dropped on
     *   each other were predicted to turn at tens of rad/s, and the solve's impulses threw
     *   them kilometres.
     * - The elastic force at x, dt f_el (session 33): a corotated cell's force has a net torque
     *   of second order in its non-affine strain (its rotation is the polar one at its centre),
     *   which the step does not turn the body by (a free body's step keeps its angular
     *   momentum, world.c "turning bodies"). A cube broken off the fracture demo's beam with
     *   14 % of such strain has 0.03 N·m: predicted to spin at 900 rad/s, its nodes heading
     *   apart at 20 m/s, against which its contacts pushed, and the cube was thrown apart
     *   (230× its volume in one step).
     * (The linear part of both sums to zero.) */
    for (size_t i = 0; i < n; i++) {
        double d[3], t[3], q[3];
        for (int a = 0; a < 3; a++) {
            const size_t k = 3 * i + a;
            d[a] = D->x[k] - r->c[a];
            q[a] = D->mask[k] ? 0.0 : dt * D->f_const[k] - (mass[i] - D->m[i]) * v[k];
        }
        cs_vec3_cross(d, q, t);
        for (int a = 0; a < 3; a++)
            L[a] += t[a];
    }
    for (int a = 0; a < 3; a++)
        U[a] = held ? 0.0 : r->minv[a] * P[a];
    cs_mat3_vec(r->iinv, L, Wc);
    if (held)
        Wc[0] = Wc[1] = Wc[2] = 0;
    memcpy(r->U0, U, sizeof U);
    memcpy(r->W0, Wc, sizeof Wc);
    for (size_t i = 0; i < n; i++) {
        double d[3], wd[3], res[3], du[3];
        for (int a = 0; a < 3; a++)
            d[a] = D->x[3 * i + a] - r->c[a];
        cs_vec3_cross(Wc, d, wd);
        for (int a = 0; a < 3; a++)
            res[a] = f[3 * i + a] - mass[i] * (U[a] + wd[a]);
        cs_mat3_vec(r->ainv + 9 * i, res, du);
        for (int a = 0; a < 3; a++)
            if (!D->mask[3 * i + a])
                r->u[3 * i + a] += U[a] + wd[a] + du[a];
        /* a node on the ground does not go down through it */
        if (D->contact && cs_ground_contact(D->contact[i]) && r->u[3 * i + 2] < 0)
            r->u[3 * i + 2] = 0;
    }
}

int cs_soft_prepare(cs_soft_resp *r, cs_object *D, double dt, uint64_t step, bool iso,
                    double ground_mu)
{
    if (r->D == D && r->id == D->id && r->step == step && r->n == D->n)
        return 0;
    const size_t n = (size_t)D->n;
    /* a Newmark object pushed by a contact takes its next step by implicit Euler (world.c) */
    const bool stiff = (D->integrator == CS_INTEGRATOR_IMPLICIT_EULER ||
                        D->integrator == CS_INTEGRATOR_NEWMARK) &&
                       D->n_fixed_nodes < D->n;
    if (grow_f64(&r->u, &r->cap_u, 3 * n) ||
        (stiff && (grow_f64(&r->ainv, &r->cap_a, 9 * n) ||
                   grow_f64(&r->scratch, &r->cap_s, 9 * n) ||
                   grow_f64(&r->mass, &r->cap_m, n))))
        return -1;
    r->D = D;
    r->id = D->id;
    r->step = step;
    r->n = D->n;
    r->stiff = stiff;
    r->coarse = false;
    r->two_level = iso;
    r->iso = iso;
    r->nm = 0;
    r->modes_open = r->exact = r->exact_open = false;
    r->dt = dt;
    memset(r->V, 0, sizeof r->V);
    memset(r->W, 0, sizeof r->W);
    memset(r->U0, 0, sizeof r->U0);
    memset(r->W0, 0, sizeof r->W0);
    memset(r->minv, 0, sizeof r->minv);
    memset(r->iinv, 0, sizeof r->iinv);
    memset(r->c, 0, sizeof r->c);
    memcpy(r->u, D->v, 3 * n * sizeof *r->u);
    if (stiff)
        prepare_stiff(r, D, dt, ground_mu);
    return 0;
}

void cs_soft_free(cs_soft_resp *r)
{
    free(r->res0);
    free(r->modes);
    free(r->raw);
    free(r->S);
    free(r->cn);
    free(r->slot);
    free(r->dense);
    cs_cg_work_free(&r->cg);
    free(r->u);
    free(r->ainv);
    free(r->scratch);
    free(r->mass);
    memset(r, 0, sizeof *r);
}

/* A node the contacts move: not held, with mass. */
static bool movable(const cs_object *D, size_t i)
{
    return !D->mask[3 * i] && D->m[i] > 0;
}

/*
 * The coarse velocity V + W × (x_i − c) as node i sees it. In the two-level response
 * (r->two_level) the block-Jacobi pass after the coarse correction takes back A_ii⁻¹ mass_i
 * of it: the same iteration as u0, on the impulses, so the response is consistent with u0 (a
 * block resting on another: the impulse that holds it is seen as doing so), a free object
 * pushed in proportion to its masses moves as a whole and a very soft one tends to free point
 * masses; adding the local and the full coarse response counts that mass twice. Zero without
 * coarse modes.
 */
static void coarse_at(const cs_soft_resp *r, size_t i, const double V[3], const double W[3],
                      double out[3])
{
    out[0] = out[1] = out[2] = 0;
    if (!r->coarse)
        return;
    double d[3], wd[3], t[3];
    for (int a = 0; a < 3; a++)
        d[a] = r->D->x[3 * i + a] - r->c[a];
    cs_vec3_cross(W, d, wd);
    for (int a = 0; a < 3; a++)
        out[a] = V[a] + wd[a];
    if (!r->two_level || !r->stiff || !movable(r->D, i))
        return;
    cs_mat3_vec(r->ainv + 9 * i, out, t);
    for (int a = 0; a < 3; a++)
        out[a] -= r->mass[i] * t[a];
}

/* e_m at the point, along d: Σ_j w_j e_m,j · d (a held object's mode m). */
static double mode_at(const cs_soft_resp *r, int m, const int32_t *nodes, const double *w, int k,
                      const double d[3])
{
    const double *e = r->modes + (size_t)m * 3 * (size_t)r->n;
    double s = 0;
    for (int j = 0; j < k; j++) {
        const double *x = e + 3 * (size_t)nodes[j];
        s += w[j] * (x[0] * d[0] + x[1] * d[1] + x[2] * d[2]);
    }
    return s;
}

/* The velocity along d at the point of a unit coordinate of mode m: e_m there, less what the
 * block-Jacobi pass after the coarse one takes back, A_jj⁻¹ (A e_m)_j (the two-level response,
 * as u0 = v + ψ is: ψ = A⁻¹ res is a mode, so the pass after it has nothing left to do). */
static double mode_velocity(const cs_soft_resp *r, int m, const int32_t *nodes, const double *w,
                            int k, const double d[3])
{
    const size_t n3 = 3 * (size_t)r->n;
    const double *e = r->modes + (size_t)m * n3, *ae = r->modes + (size_t)(2 + m) * n3;
    double s = 0;
    for (int j = 0; j < k; j++) {
        const size_t i = (size_t)nodes[j];
        if (!movable(r->D, i))
            continue;
        double t[3];
        cs_mat3_vec(r->ainv + 9 * i, ae + 3 * i, t);
        for (int a = 0; a < 3; a++)
            s += w[j] * d[a] * (e[3 * i + a] - t[a]);
    }
    return s;
}

void cs_soft_arm(const cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                 double arm[3])
{
    arm[0] = arm[1] = arm[2] = 0;
    for (int j = 0; j < k; j++)
        for (int a = 0; a < 3; a++)
            arm[a] += w[j] * r->D->x[3 * (size_t)nodes[j] + a];
    for (int a = 0; a < 3; a++)
        arm[a] -= r->c[a];
}

void cs_soft_velocity(const cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                      const double arm[3], double v[3])
{
    (void)arm;
    v[0] = v[1] = v[2] = 0;
    for (int j = 0; j < k; j++) {
        const size_t i = (size_t)nodes[j];
        double c[3];
        coarse_at(r, i, r->V, r->W, c);
        for (int a = 0; a < 3; a++)
            v[a] += w[j] * (r->u[3 * i + a] + c[a]);
    }
    for (int m = 0; m < r->nm; m++) {
        for (int a = 0; a < 3; a++) {
            const double e[3] = {a == 0, a == 1, a == 2};
            v[a] += r->cm[m] * mode_velocity(r, m, nodes, w, k, e);
        }
    }
}

/* The local part of the point's compliance along d, scaled by `local`: Σ w_j² dᵀ A_jj⁻¹ d
 * (free point masses 1/m_j when not stiff) over its movable nodes, or over every node with
 * mass (all: as if none were held; ainv holds every node's block, held or not). */
static double block_compliance(const cs_soft_resp *r, const int32_t *nodes, const double *w,
                               int k, const double d[3], double local, bool all)
{
    double s = 0;
    for (int j = 0; j < k; j++) {
        const size_t i = (size_t)nodes[j];
        if (all ? !(r->D->m[i] > 0) : !movable(r->D, i))
            continue;
        if (r->stiff) {
            double t[3];
            cs_mat3_vec(r->ainv + 9 * i, d, t);
            s += local * w[j] * w[j] * (d[0] * t[0] + d[1] * t[1] + d[2] * t[2]);
        } else {
            s += local * w[j] * w[j] * (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) / r->D->m[i];
        }
    }
    return s;
}

double cs_soft_compliance(const cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                          const double arm[3], const double d[3], double local)
{
    double s = 0;
    if (r->exact) { /* dᵀ (Σ_ij w_i w_j (A⁻¹)_ij) d over the point's free nodes */
        for (int j = 0; j < k; j++) {
            const int32_t sj = r->slot[nodes[j]];
            for (int q = 0; q < k && sj >= 0; q++) {
                const int32_t sq = r->slot[nodes[q]];
                if (sq < 0)
                    continue;
                double t[3];
                cs_mat3_vec(r->S + 9 * ((size_t)sq * r->n_cn + sj), d, t);
                s += local * w[j] * w[q] * (d[0] * t[0] + d[1] * t[1] + d[2] * t[2]);
            }
        }
        return s;
    }
    s += block_compliance(r, nodes, w, k, d, local, false);
    if (r->nm > 0) /* a held object's modes: Δc_m = e_m,pᵀ d, seen along d at the point */
        for (int m = 0; m < r->nm; m++) {
            const double dc = mode_at(r, m, nodes, w, k, d);
            s += dc * mode_velocity(r, m, nodes, w, k, d);
        }
    if (r->coarse) {
        /* the coarse velocity the impulse d gives, seen at the point's nodes */
        double rd[3], dV[3], dW[3];
        cs_vec3_cross(arm, d, rd);
        cs_mat3_vec(r->iinv, rd, dW);
        for (int a = 0; a < 3; a++)
            dV[a] = r->minv[a] * d[a];
        for (int j = 0; j < k; j++) {
            double c[3];
            coarse_at(r, (size_t)nodes[j], dV, dW, c);
            s += w[j] * (d[0] * c[0] + d[1] * c[1] + d[2] * c[2]);
        }
    }
    return s;
}

double cs_soft_unheld_compliance(const cs_soft_resp *r, const int32_t *nodes, const double *w,
                                 int k, const double d[3])
{
    return block_compliance(r, nodes, w, k, d, 1.0, true);
}

void cs_soft_impulse(cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                     const double arm[3], const double J[3], double local)
{
    cs_object *D = r->D;
    bool any = false;
    if (r->exact) { /* every contact node answers: u_q += Σ_j w_j (A⁻¹)_qj J */
        for (int j = 0; j < k; j++) {
            const size_t i = (size_t)nodes[j];
            const int32_t sj = r->slot[i];
            if (!movable(D, i) || sj < 0)
                continue;
            for (int a = 0; a < 3; a++)
                D->v[3 * i + a] += w[j] * J[a] / D->m[i]; /* the momentum, now */
            for (int q = 0; q < r->n_cn; q++) {
                double du[3];
                cs_mat3_vec(r->S + 9 * ((size_t)q * r->n_cn + sj), J, du);
                for (int a = 0; a < 3; a++)
                    r->u[3 * (size_t)r->cn[q] + a] += local * w[j] * du[a];
            }
        }
        return; /* (a held object: no coarse part) */
    }
    for (int j = 0; j < k; j++) {
        const size_t i = (size_t)nodes[j];
        if (!movable(D, i))
            continue;
        any = true;
        double du[3];
        if (r->stiff)
            cs_mat3_vec(r->ainv + 9 * i, J, du);
        else
            for (int a = 0; a < 3; a++)
                du[a] = J[a] / D->m[i];
        for (int a = 0; a < 3; a++) {
            D->v[3 * i + a] += w[j] * J[a] / D->m[i]; /* the momentum, now */
            r->u[3 * i + a] += local * w[j] * du[a];  /* the solve's view of the response */
        }
    }
    for (int m = 0; any && m < r->nm; m++)
        r->cm[m] += mode_at(r, m, nodes, w, k, J);
    if (!any || !r->coarse)
        return;
    double rj[3], dw[3];
    cs_vec3_cross(arm, J, rj);
    cs_mat3_vec(r->iinv, rj, dw);
    for (int a = 0; a < 3; a++) {
        r->V[a] += r->minv[a] * J[a];
        r->W[a] += dw[a];
    }
}

double cs_soft_coarse_compliance(const cs_soft_resp *r, const double arm[3], const double d[3])
{
    if (!r->coarse)
        return 0;
    double rd[3], t[3];
    cs_vec3_cross(arm, d, rd);
    cs_mat3_vec(r->iinv, rd, t);
    double s = rd[0] * t[0] + rd[1] * t[1] + rd[2] * t[2];
    for (int a = 0; a < 3; a++)
        s += r->minv[a] * d[a] * d[a];
    return s;
}

void cs_soft_coarse_velocity(const cs_soft_resp *r, const double arm[3], double v[3])
{
    v[0] = v[1] = v[2] = 0;
    if (!r->coarse) /* (coarse modes are set only when stiff: r->mass exists) */
        return;
    const cs_object *D = r->D;
    double P[3] = {0, 0, 0}, L[3] = {0, 0, 0}, W[3], wa[3];
    for (int i = 0; i < D->n; i++) {
        const double *x = D->x + 3 * (size_t)i, *u = D->v + 3 * (size_t)i;
        double d[3], t[3];
        for (int a = 0; a < 3; a++)
            d[a] = x[a] - r->c[a];
        cs_vec3_cross(d, u, t);
        for (int a = 0; a < 3; a++) {
            P[a] += r->mass[i] * u[a];
            L[a] += r->mass[i] * t[a];
        }
    }
    cs_mat3_vec(r->iinv, L, W);
    for (int a = 0; a < 3; a++)
        W[a] += r->W0[a];
    cs_vec3_cross(W, arm, wa);
    for (int a = 0; a < 3; a++)
        v[a] = r->minv[a] * P[a] + r->U0[a] + wa[a];
}

/* ---------------------------------------------------------------- a held object's modes */

bool cs_soft_is_held(const cs_soft_resp *r)
{
    return r->stiff && !r->coarse;
}

int cs_soft_modes_begin(cs_soft_resp *r)
{
    if (r->modes_open || r->nm > 0)
        return 1;
    if (!cs_soft_is_held(r) || !r->has_res0)
        return 0;
    const size_t n3 = 3 * (size_t)r->n;
    if (grow_f64(&r->modes, &r->cap_modes, 5 * n3))
        return -1;
    memset(r->modes + 4 * n3, 0, n3 * sizeof *r->modes);
    r->modes_open = true;
    return 1;
}

void cs_soft_modes_add(cs_soft_resp *r, const int32_t *nodes, const double *w, int k,
                       const double d[3])
{
    double *g = r->modes + 4 * 3 * (size_t)r->n;
    for (int j = 0; j < k; j++) {
        const size_t i = (size_t)nodes[j];
        if (movable(r->D, i))
            for (int a = 0; a < 3; a++)
                g[3 * i + a] += w[j] * d[a];
    }
}

/*
 * x ≈ A⁻¹ b by conjugate gradients on A (apply_step_operator) from x = 0, to ‖res‖ ≤ tol ‖b‖
 * or max_it iterations, preconditioned by D's multigrid hierarchy where its step has one for
 * its current cells (lagged: a preconditioner only), else by the blocks. False if it took no
 * step or left x not finite. (Any x is a valid mode: the model stays consistent, and the
 * closer x is to A⁻¹ b, the closer it is to the step.)
 */
static bool step_solve(cs_soft_resp *r, const double *b, double *x, double tol, int max_it,
                       int which)
{
    cs_object *D = r->D;
    const size_t n3 = 3 * (size_t)r->n;
    /* the warm start: this solve's answer in D's last step with contacts, if D is the same */
    const bool warm = r->raw_id == D->id && r->raw_version == D->topology_version &&
                      r->raw_n == r->n && r->raw_valid[which];
    if (r->cg.n != (int)n3 && (cs_cg_work_free(&r->cg), cs_cg_work_init(&r->cg, (int)n3)))
        return false;
    if (warm)
        memcpy(x, r->raw + (size_t)which * n3, n3 * sizeof *x);
    else
        memset(x, 0, n3 * sizeof *x);
    const bool mg = D->mg && cs_mg_matches(D->mg, &D->cm, &D->fem, D->topology_version);
    const cs_cg_result res =
        mg ? cs_pcg_ex(&r->cg, apply_step_operator, r, cs_mg_vcycle, D->mg, D->mask, b, x, tol,
                       max_it, cs_elastic_threads(D))
           : cs_pcg(&r->cg, apply_step_operator, r, r->ainv, D->mask, b, x, tol, max_it,
                    cs_elastic_threads(D));
    bool ok = res.iterations > 0 || (warm && res.converged);
    for (size_t d = 0; d < n3 && ok; d++)
        ok = isfinite(x[d]);
    if (ok && !grow_f64(&r->raw, &r->cap_raw, 2 * n3)) {
        if (r->raw_id != D->id || r->raw_version != D->topology_version || r->raw_n != r->n)
            r->raw_valid[0] = r->raw_valid[1] = false;
        r->raw_id = D->id;
        r->raw_version = D->topology_version;
        r->raw_n = r->n;
        memcpy(r->raw + (size_t)which * n3, x, n3 * sizeof *x);
        r->raw_valid[which] = true;
    }
    return ok;
}

#define MODE_ITERATIONS 200 /* conjugate gradients on A x = b: at most */
#define MODE_TOLERANCE 1e-2 /* relative residual. Any vector is a consistent mode and each
                             * solve starts from the last step's answer, so the modes sharpen
                             * over the steps; from zero and to 1e-6 the fracture demo's star
                             * took 180 iterations a solve and its steps cost 2x */

/* Append x (3n, in the modes' room at slot r->nm) to the A-orthonormal modes: made
 * A-orthogonal to those before it (twice: Gram–Schmidt loses it otherwise), normalized, A x
 * stored beside it; dropped if little is left of it. ax: 3n scratch. */
static void add_mode(cs_soft_resp *r, double *ax)
{
    const size_t n3 = 3 * (size_t)r->n;
    double *x = r->modes + (size_t)r->nm * n3;
    apply_step_operator(r, x, ax);
    double xax0 = 0;
    for (size_t d = 0; d < n3; d++)
        xax0 += x[d] * ax[d];
    if (!(xax0 > 0) || !isfinite(xax0))
        return;
    for (int pass = 0; pass < 2; pass++)
        for (int m = 0; m < r->nm; m++) {
            const double *e = r->modes + (size_t)m * n3;
            double c = 0;
            for (size_t d = 0; d < n3; d++)
                c += e[d] * ax[d];
            for (size_t d = 0; d < n3; d++)
                x[d] -= c * e[d];
            apply_step_operator(r, x, ax);
        }
    double xax = 0;
    for (size_t d = 0; d < n3; d++)
        xax += x[d] * ax[d];
    if (!(xax > 1e-12 * xax0))
        return;
    const double s = 1 / sqrt(xax);
    double *ae = r->modes + (size_t)(2 + r->nm) * n3, c = 0;
    for (size_t d = 0; d < n3; d++) {
        x[d] *= s;
        ae[d] = ax[d] * s;
        c += x[d] * r->res0[d];
    }
    /* u0 through the modes: u holds v + B res, the modes add P res − B A P res, their
     * coordinates start at e_mᵀ res (so with ψ = A⁻¹ res exact, u0 = v + ψ) */
    r->cm[r->nm++] = c;
}

int cs_soft_modes_solve(cs_soft_resp *r)
{
    if (!r->modes_open)
        return 0;
    r->modes_open = false;
    const size_t n3 = 3 * (size_t)r->n;
    double *g = r->modes + 4 * n3, *ax = malloc(n3 * sizeof *ax);
    if (!ax)
        return -1;
    /* mode 0: ψ ≈ A⁻¹ res, the step from v without contacts */
    if (step_solve(r, r->res0, r->modes, MODE_TOLERANCE, MODE_ITERATIONS, 0))
        add_mode(r, ax);
    /* the next: φ = A⁻¹ g, the object's answer to its contacts pushing together */
    if (step_solve(r, g, r->modes + (size_t)r->nm * n3, MODE_TOLERANCE, MODE_ITERATIONS, 1))
        add_mode(r, ax);
    free(ax);
    return 0;
}

/* ---------------------------------------------------------------- a small held object's exact response */

#define EXACT_DOFS 240 /* free dofs up to which a held object's A is factored (dense) */

int cs_soft_exact_begin(cs_soft_resp *r)
{
    if (r->exact_open || r->exact)
        return 1;
    if (!cs_soft_is_held(r) || !r->has_res0)
        return 0;
    int nf = 0;
    for (size_t d = 0; d < 3 * (size_t)r->n; d++)
        nf += !r->D->mask[d] && r->D->m[d / 3] > 0;
    if (nf == 0 || nf > EXACT_DOFS)
        return 0;
    int32_t *g = realloc(r->slot, (size_t)r->n * sizeof *g);
    if (!g)
        return -1;
    r->slot = g;
    for (int i = 0; i < r->n; i++)
        r->slot[i] = -1;
    r->n_cn = 0;
    r->exact_open = true;
    return 1;
}

int cs_soft_exact_add(cs_soft_resp *r, const int32_t *nodes, const double *w, int k)
{
    for (int j = 0; j < k; j++) {
        const int32_t i = nodes[j];
        if (w[j] == 0 || !movable(r->D, (size_t)i) || r->slot[i] >= 0)
            continue;
        if (r->n_cn == r->cap_cn) {
            const int c = r->cap_cn ? 2 * r->cap_cn : 16;
            int32_t *g = realloc(r->cn, (size_t)c * sizeof *g);
            if (!g)
                return -1;
            r->cn = g;
            r->cap_cn = c;
        }
        r->slot[i] = r->n_cn;
        r->cn[r->n_cn++] = i;
    }
    return 0;
}

int cs_soft_exact_solve(cs_soft_resp *r)
{
    if (!r->exact_open)
        return 0;
    r->exact_open = false;
    const cs_object *D = r->D;
    const size_t n3 = 3 * (size_t)r->n;
    const int m = r->n_cn;
    /* the free dofs, A on them column by column (its products with unit vectors) */
    int nf = 0;
    for (size_t d = 0; d < n3; d++)
        nf += !D->mask[d] && D->m[d / 3] > 0;
    int32_t *fd = malloc((size_t)nf * sizeof *fd);
    double *e = calloc(n3, sizeof *e), *ae = malloc(n3 * sizeof *ae), *x = malloc((size_t)nf * sizeof *x);
    int rc = -1;
    if (!fd || !e || !ae || !x || grow_f64(&r->dense, &r->cap_dense, (size_t)nf * nf) ||
        grow_f64(&r->S, &r->cap_S, 9 * (size_t)m * m))
        goto out;
    rc = 0;
    nf = 0;
    for (size_t d = 0; d < n3; d++)
        if (!D->mask[d] && D->m[d / 3] > 0)
            fd[nf++] = (int32_t)d;
    double *A = r->dense;
    for (int j = 0; j < nf; j++) {
        e[fd[j]] = 1;
        apply_step_operator(r, e, ae);
        e[fd[j]] = 0;
        for (int i = 0; i < nf; i++)
            A[(size_t)i * nf + j] = ae[fd[i]];
    }
    for (int i = 0; i < nf; i++) /* (symmetric to round-off) */
        for (int j = i + 1; j < nf; j++)
            A[(size_t)i * nf + j] = A[(size_t)j * nf + i] =
                0.5 * (A[(size_t)i * nf + j] + A[(size_t)j * nf + i]);
    if (cs_cholesky(A, nf) != 0)
        goto out; /* (the block model answers) */
    /* S: A⁻¹ on the contact nodes, one column per contact node and axis */
    int32_t *dof_of = calloc(n3, sizeof *dof_of); /* free dof index + 1, or 0 */
    if (!dof_of) {
        rc = -1;
        goto out;
    }
    for (int i = 0; i < nf; i++)
        dof_of[fd[i]] = i + 1;
    /* (A⁻¹)_pq = y_p·y_q with y_q = L⁻¹ e_q, zero before row q: forward solves only, one
     * per contact dof, and dot products from the later of the two rows on */
    double *Y = malloc(((size_t)3 * m * nf + 1) * sizeof *Y); /* (+1: m may be 0) */
    int32_t *qs = malloc(((size_t)3 * m + 1) * sizeof *qs);
    if (!Y || !qs) {
        free(Y);
        free(qs);
        free(dof_of);
        rc = -1;
        goto out;
    }
    for (int c = 0; c < 3 * m; c++) {
        double *y = Y + (size_t)c * nf;
        qs[c] = dof_of[3 * (size_t)r->cn[c / 3] + c % 3] - 1; /* -1: not free */
        memset(y, 0, (size_t)nf * sizeof *y);
        if (qs[c] >= 0) {
            y[qs[c]] = 1;
            cs_cholesky_forward(A, nf, qs[c], y);
        }
    }
    for (int c1 = 0; c1 < 3 * m; c1++)
        for (int c2 = c1; c2 < 3 * m; c2++) {
            const double s = qs[c1] >= 0 && qs[c2] >= 0
                                 ? cs_dot_short(Y + (size_t)c1 * nf, Y + (size_t)c2 * nf,
                                                qs[c1] > qs[c2] ? qs[c1] : qs[c2], nf)
                                 : 0.0;
            /* S's block (k, j) holds row = the axis of k's dof, a = the axis of j's */
            const int k1 = c1 / 3, a1 = c1 % 3, k2 = c2 / 3, a2 = c2 % 3;
            r->S[9 * ((size_t)k1 * m + k2) + 3 * a1 + a2] = s;
            r->S[9 * ((size_t)k2 * m + k1) + 3 * a2 + a1] = s;
        }
    free(Y);
    free(qs);
    /* u0 = v + A⁻¹ res in place of v + A_ii⁻¹ res (responses u holds already stay) */
    for (int i = 0; i < nf; i++)
        x[i] = r->res0[fd[i]];
    cs_cholesky_solve(A, nf, x);
    for (int i = 0; i < r->n; i++) {
        double jac[3];
        cs_mat3_vec(r->ainv + 9 * (size_t)i, r->res0 + 3 * (size_t)i, jac);
        for (int a = 0; a < 3; a++) {
            const size_t d = 3 * (size_t)i + a;
            if (dof_of[d])
                r->u[d] += x[dof_of[d] - 1] - jac[a];
        }
        if (D->contact && cs_ground_contact(D->contact[i]) && r->u[3 * (size_t)i + 2] < 0)
            r->u[3 * (size_t)i + 2] = 0;
    }
    free(dof_of);
    r->exact = true;
out:
    free(fd);
    free(e);
    free(ae);
    free(x);
    return rc;
}
