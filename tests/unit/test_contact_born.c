/*
 * test_contact_born.c — contacts between pieces of one broken deformable object that rest on
 * each other from the moment they break (rigid.c born_contacts: born pairs and their reference
 * depths).
 *
 * The column: 2×2×6 cubes of 0.1 m (corotational, implicit Euler, ν 0.3, 1000 kg/m³, mass
 * damping 1/s), its bottom nodes held, under gravity, no ground. A bar under its own weight
 * held at its foot goes down u(z) = ρ g (H z − z²/2) / E at height z (uniaxial, H = 0.6 m):
 * its top ρ g H² / (2E) = 17.66 mm at E = 1e5 Pa, its third layer's top (z = 0.3 m) 13.24 mm.
 * Cut across between its third and fourth layers before the first step (and its upper part cut
 * again between its fourth and fifth), its upper part must rest on its lower part as the uncut
 * column does: on main it fell through (z ≈ −3.2 m after 50 steps at E = 1e6 Pa).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "demo_beam.h"
#include "contact_probe.h"
#include "cubesim.h"
#include "lattice.h"
#include "world_internal.h"

#define COL_H 0.1
#define COL_LAYERS 6
#define COL_STEPS 300
#define COL_LAST 60 /* the last second */

static cs_object_id add_column(cs_world_t *w, double young)
{
    int32_t *ijk = cs_box_cells(2, 2, COL_LAYERS);
    if (!ijk)
        return CS_NULL_OBJECT;
    cs_object_def d = cs_object_def_default();
    d.name = "column";
    d.material.young = young;
    d.material.damping[0] = 1;
    d.cube_size = COL_H;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = 2 * 2 * COL_LAYERS;
    const cs_aabb foot = {{-0.01, -0.01, -0.01}, {0.21, 0.21, 0.01}};
    d.fixed = &foot;
    d.n_fixed = 1;
    cs_object_id id = CS_NULL_OBJECT;
    char err[256];
    if (cs_world_add_object(w, &d, &id, err, sizeof err) != CS_OK) {
        fprintf(stderr, "add_column: %s\n", err);
        id = CS_NULL_OBJECT;
    }
    free(ijk);
    return id;
}

/* The piece holding a cell of layer round(z/h) (of the layer below z when `below`). */
static cs_object *piece_at(cs_world_t *w, double z, bool below)
{
    cs_object_id ids[16];
    const int n = cs_world_object_ids(w, ids, 16);
    const int k = (int)lround(z / COL_H) - (below ? 1 : 0);
    for (int i = 0; i < n && i < 16; i++) {
        cs_object *o = cs_world_find_internal(w, ids[i]);
        for (int32_t c = 0; c < o->cm.n_cells; c++)
            if (o->cm.cell_ijk[3 * (size_t)c + 2] == k)
                return o;
    }
    return NULL;
}

/* Mean lowering of o's nodes at rest height z: z − their mean current z. */
static double lowering(const cs_object *o, double z)
{
    double s = 0;
    int n = 0;
    for (int i = 0; i < o->n; i++)
        if (fabs(o->cm.node_rest[3 * (size_t)i + 2] - z) < 1e-9) {
            s += o->x[3 * (size_t)i + 2];
            n++;
        }
    return n ? z - s / n : NAN;
}

static int cmp_double(const void *a, const void *b)
{
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Over every crack (a pair of pieces with twins, nodes at the same rest position, the upper
 * piece's cells above them): the median depth of the upper piece's crack nodes below their
 * twins (*median, the largest over the cracks) and the deepest one (*node). */
static void crack_depth(cs_world_t *w, double *median, double *node)
{
    cs_object_id ids[16];
    const int n = cs_world_object_ids(w, ids, 16);
    *median = *node = 0;
    for (int a = 0; a < n && a < 16; a++) {
        const cs_object *P = cs_world_find_internal(w, ids[a]);
        for (int b = 0; b < n && b < 16; b++) {
            const cs_object *Q = cs_world_find_internal(w, ids[b]);
            double d[64];
            int cnt = 0;
            for (int i = 0; i < P->n && Q != P; i++)
                for (int j = 0; j < Q->n && cnt < 64; j++) {
                    const double *rp = P->cm.node_rest + 3 * (size_t)i,
                                 *rq = Q->cm.node_rest + 3 * (size_t)j;
                    if (fabs(rp[0] - rq[0]) + fabs(rp[1] - rq[1]) + fabs(rp[2] - rq[2]) > 1e-9)
                        continue;
                    const int k = (int)lround((rp[2] - P->cm.origin[2]) / P->cm.h);
                    bool above = false;
                    for (int32_t c = 0; c < P->cm.n_cells && !above; c++)
                        above = P->cm.cell_ijk[3 * (size_t)c + 2] == k;
                    if (!above)
                        continue;
                    d[cnt] = Q->x[3 * (size_t)j + 2] - P->x[3 * (size_t)i + 2];
                    *node = fmax(*node, d[cnt]);
                    cnt++;
                }
            if (!cnt)
                continue;
            qsort(d, (size_t)cnt, sizeof *d, cmp_double);
            *median = fmax(*median, d[cnt / 2]);
        }
    }
}

typedef struct column_result {
    int pieces;
    double mid;     /* lowering of the third layer's top (the base's, when cut), mean over the
                     * last second [m] */
    double top;     /* lowering of the column's top, mean over the last second [m] */
    double crack;   /* largest median depth of a crack's upper nodes below their twins, any step */
    double node;    /* the deepest single node below its twin, any step (corners droop) */
    double inside;  /* deepest node of a piece inside a cell of another, any step */
    double speed;   /* fastest centre of a piece over the last second, mean [m/s] */
    double rattle;  /* largest range of a piece's centre height over the last second [m] */
} column_result;

/* The column at Young's modulus E with n_cuts cuts (rest heights cuts[k]) across the piece
 * holding the layer above each, cut k before step at[k]; COL_STEPS steps. 0 or -1. */
static int column(double E, const double *cuts, const int *at, int n_cuts, column_result *r)
{
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    cs_world_t *w = NULL;
    char err[256];
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK)
        return -1;
    memset(r, 0, sizeof *r);
    int rc = add_column(w, E) == CS_NULL_OBJECT ? -1 : 0;
    double cz[COL_LAST][4];
    for (int s = 0, k = 0; s < COL_STEPS && rc == 0; s++) {
        for (; k < n_cuts && at[k] == s && rc == 0; k++) {
            /* the plane goes through the centre of the cell nearest the point: a cell of the
             * layer above the cut, so the cells below it are on the other side */
            cs_object *o = piece_at(w, cuts[k], false);
            rc = o && cs_world_fracture(w, o->id,
                                        (double[3]){0.05, 0.05, cuts[k] + 0.5 * COL_H},
                                        (double[3]){0, 0, 1}, 1.0, err, sizeof err) == CS_OK
                     ? 0
                     : -1;
        }
        if (rc != 0)
            break;
        if (cs_world_step(w) != CS_OK) {
            rc = -1;
            break;
        }
        double median, node;
        crack_depth(w, &median, &node);
        r->crack = fmax(r->crack, median);
        r->node = fmax(r->node, node);
        cs_object_id ids[16];
        const int n = cs_world_object_ids(w, ids, 16);
        if (s >= COL_STEPS - COL_LAST) {
            r->mid += lowering(piece_at(w, 0.3, true), 0.3) / COL_LAST;
            r->top += lowering(piece_at(w, 0.6, true), 0.6) / COL_LAST;
        }
        for (int i = 0; i < n && i < 4; i++) {
            const cs_object *P = cs_world_find_internal(w, ids[i]);
            for (int j = 0; j < n && j < 4; j++)
                if (j != i)
                    r->inside = fmax(r->inside,
                                     deepest_inside(P, cs_world_find_internal(w, ids[j])));
            if (s < COL_STEPS - COL_LAST)
                continue;
            double c = 0;
            for (int q = 0; q < P->n; q++)
                c += P->m[q] * P->x[3 * (size_t)q + 2] / P->mass;
            cz[s - (COL_STEPS - COL_LAST)][i] = c;
        }
    }
    if (rc == 0) {
        cs_object_id ids[16];
        r->pieces = cs_world_object_ids(w, ids, 16);
        for (int i = 0; i < r->pieces && i < 4; i++) {
            double lo = INFINITY, hi = -INFINITY;
            for (int s = 0; s < COL_LAST; s++) {
                lo = fmin(lo, cz[s][i]);
                hi = fmax(hi, cz[s][i]);
            }
            r->rattle = fmax(r->rattle, hi - lo);
            r->speed = fmax(r->speed, fabs(cz[COL_LAST - 1][i] - cz[0][i]) /
                                          ((COL_LAST - 1) * wd.dt));
        }
    } else {
        fprintf(stderr, "column: %s\n", err);
    }
    cs_world_destroy(w);
    return rc;
}

/*
 * The column uncut, cut once and cut twice (its upper part broken again: a piece made by the
 * first cut split into pieces with no record of each other), at E = 1e5 and 1e6 Pa, 300
 * steps. Uncut it must settle within 10 % of the uniaxial answer (its foot is held sideways
 * too: 5 % stiffer). Cut: the third layer's top within 10 % of where the uncut column's is;
 * the column's top within 10 % of the uncut one's plus 0.02 h per crack (the contact's slop,
 * 0.01 h, and the crack's nodes rattling); the upper side of every crack (its median node) no
 * more than 0.1 h below the lower side at any step (on main the upper part fell through);
 * no node ever more than 0.1 h inside a cell of another piece; over the last second no
 * piece's centre moving faster than 5 mm/s on average nor rattling over more than 0.05 h.
 * The lowerings are means over the last second (the last step's until session 25: a stack
 * that still rattles made them a matter of phase). These bounds are loose because at
 * E = 1e6 Pa the crack does not come to rest: the stiff upper piece rocks on it (centres over
 * 1.3–2.1 mm; README, Known limitations). Until session 25 the crack's corner nodes, in the
 * other piece's side planes, also left its faces sideways, took no contact there and drooped
 * 10–20 mm, at both moduli (two separate objects stacked lattice on lattice did the same,
 * so that was the deformable contact's, not the born pairs').
 */
TEST(contact_born_cut_column_rests_on_its_base)
{
    const double rho = 1000, g = 9.81, H = COL_LAYERS * COL_H, zc = 0.3;
    const double Es[2] = {1e5, 1e6}, cuts[2] = {0.3, 0.4};
    /* uncut; cut once; cut twice at once */
    const int n_cuts[3] = {0, 1, 2}, second[3] = {0, 0, 0};
    for (int e = 0; e < 2; e++) {
        const double E = Es[e];
        const double u_top = rho * g * H * H / (2 * E);
        const double u_mid = rho * g * (H * zc - zc * zc / 2) / E;
        column_result r0 = {0};
        for (int cs = 0; cs < 3; cs++) {
            const int nc = n_cuts[cs], at[2] = {0, second[cs]};
            column_result r;
            ENSURE(column(E, cuts, at, nc, &r) == 0);
            if (nc == 0)
                r0 = r;
            printf("    [E %.0e Pa, %d cut%s] %d piece%s: z = 0.3 m down %.2f mm (uniaxial %.2f), "
                   "top down %.2f mm (uniaxial %.2f); cracks' upper sides at most %.2f mm below "
                   "their lower sides (median node) (a single node %.2f mm); deepest node inside "
                   "another piece %.2f mm; last second: centres moved %.1e m/s on average, "
                   "rattled %.2f mm\n",
                   E, nc, nc == 1 ? "" : "s", r.pieces, r.pieces == 1 ? "" : "s", 1e3 * r.mid,
                   1e3 * u_mid, 1e3 * r.top, 1e3 * u_top, 1e3 * r.crack, 1e3 * r.node,
                   1e3 * r.inside, r.speed, 1e3 * r.rattle);
            ENSURE_MSG(r.pieces == nc + 1, "%d pieces after %d cuts", r.pieces, nc);
            if (nc == 0) {
                ENSURE_MSG(fabs(r.mid / u_mid - 1) < 0.1 && fabs(r.top / u_top - 1) < 0.1,
                           "uncut: down %.3f and %.3f mm, uniaxial %.3f and %.3f", 1e3 * r.mid,
                           1e3 * r.top, 1e3 * u_mid, 1e3 * u_top);
                continue;
            }
            ENSURE_MSG(fabs(r.mid / r0.mid - 1) < 0.1, "z = 0.3 m down %.3f mm, uncut %.3f",
                       1e3 * r.mid, 1e3 * r0.mid);
            const double tol = 0.1 * r0.top + nc * 0.02 * COL_H;
            ENSURE_MSG(fabs(r.top - r0.top) < tol, "top down %.3f mm, uncut %.3f, within %.3f",
                       1e3 * r.top, 1e3 * r0.top, 1e3 * tol);
            ENSURE_MSG(r.crack < 0.1 * COL_H, "a crack's upper side went %.2f mm below its "
                       "lower side", 1e3 * r.crack);
            ENSURE_MSG(r.inside < 0.1 * COL_H, "a node went %.2f mm inside another piece",
                       1e3 * r.inside);
            ENSURE_MSG(r.speed < 5e-3 && r.rattle < 0.05 * COL_H, "a centre still moves at "
                       "%.2e m/s, rattling over %.2f mm", r.speed, 1e3 * r.rattle);
        }
    }
}

/*
 * A fracture between steps and the contact impulses not yet shared out. A soft block T (2×2×2
 * cubes of 0.1 m, E 1e5 Pa, mass damping 1/s) rests on a soft block L of its size on the
 * ground for 90 steps; the contact pass of each step leaves on T's bottom nodes the impulse that
 * holds T up during the next step (T's weight times dt). T is then cut between its layers: a
 * fracture moves no node and must give no piece momentum T did not have. At rest, each half's
 * centre must move slower than 0.02 m/s right after the cut (the impulse taken back: the next
 * pass makes the halves' own contacts); left on the nodes, the whole of it went to the lower
 * half, 0.33 m/s upwards (twice g dt: it holds twice its own weight). Then, 120 steps on, the
 * upper half rests on the lower one: its median crack node less than 0.1 h below its twin
 * (measured 6.8 mm: with the impulse taken back the halves meet at 2 g dt, an approach the
 * born pairs leave to the ordinary pass, and sink into each other before they slow down).
 */
TEST(contact_born_cut_between_steps_takes_back_pending_impulses)
{
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    wd.has_ground = true;
    wd.sleep_steps = 0; /* asleep, the pair takes no contacts */
    cs_world_t *w = NULL;
    char err[256];
    ENSURE(cs_world_create(&wd, &w, err, sizeof err) == CS_OK);
    int32_t *ijk = cs_box_cells(2, 2, 2);
    ENSURE(ijk);
    cs_object_def d = cs_object_def_default();
    d.material.young = 1e5;
    d.material.damping[0] = 1;
    d.cube_size = COL_H;
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = 8;
    cs_object_id low = CS_NULL_OBJECT, top = CS_NULL_OBJECT;
    d.name = "low";
    ENSURE(cs_world_add_object(w, &d, &low, err, sizeof err) == CS_OK);
    d.name = "top";
    d.cells_origin[2] = 0.2;
    ENSURE(cs_world_add_object(w, &d, &top, err, sizeof err) == CS_OK);
    free(ijk);
    for (int s = 0; s < 90; s++)
        ENSURE(cs_world_step(w) == CS_OK);
    /* the four faces between its layers: the layers part at the fourth */
    for (int i = 0; i < 4; i++)
        ENSURE_MSG(cs_world_cut_face(w, top, (int32_t[3]){i % 2, i / 2, 0}, 2, err, sizeof err) ==
                       CS_OK,
                   "%s", err);
    cs_object_id ids[8];
    const int n = cs_world_object_ids(w, ids, 8);
    ENSURE_MSG(n == 3, "%d objects after the cut", n);
    double vmax = 0;
    for (int i = 0; i < n; i++) {
        const cs_object *P = cs_world_find_internal(w, ids[i]);
        double v[3] = {0, 0, 0};
        for (int j = 0; j < P->n; j++)
            for (int a = 0; a < 3; a++)
                v[a] += P->m[j] * P->v[3 * (size_t)j + a] / P->mass;
        const double sp = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        printf("    after the cut: %s, %d cells, centre at %+.4f m/s vertically\n", P->name,
               P->cm.n_cells, v[2]);
        if (P->id != low)
            vmax = fmax(vmax, sp);
    }
    ENSURE_MSG(vmax < 0.02, "a half of the block set moving at %.3f m/s by the cut", vmax);
    double crack = 0, node = 0;
    for (int s = 0; s < 120; s++) {
        ENSURE(cs_world_step(w) == CS_OK);
        double m, nd;
        crack_depth(w, &m, &nd);
        crack = fmax(crack, m);
        node = fmax(node, nd);
    }
    printf("    120 steps on: the upper half at most %.2f mm below the lower one's top (median "
           "crack node; a single node %.2f mm)\n", 1e3 * crack, 1e3 * node);
    ENSURE_MSG(crack < 0.1 * COL_H, "the upper half went %.2f mm into the lower one",
               1e3 * crack);
    cs_world_destroy(w);
}

/*
 * Pieces held at their crack. The fracture demo's beam (E 2 MPa, 100 kg/m³, damping 0.5/s and
 * 0.002 s, dt 1/60 s) as a 4×2×2 cantilever of 25 mm cubes held at x = 0, cut lengthwise along
 * y = 25 mm before its first step: both halves keep held nodes on the crack at x = 0, each at
 * the same place as its twin, which is a corner of the other half's cells. Such a contact is
 * between two points nothing moves (the node held, the face point on the other's held corner
 * up to round-off weights of 1e-15 on its free ones): its effective mass came out 1e28–1e64 kg
 * and the impulse the round-off asked for, given to the free corners by their round-off
 * weights, threw them at hundreds of m/s, and in the fracture demo tore the beam apart. Each
 * half sags under its weight as the uncut beam does (both halves alike, so the crack carries
 * no load): over 120 steps every node must stay within 0.1 mm of where the uncut beam has it
 * (its tip sags 0.03 mm) and no node move faster than 0.01 m/s between steps; the pieces'
 * velocities after a step (which hold contact impulses still to be shared out) stay below 1 m/s.
 */
static cs_world_t *held_beam(int nx, bool cut, cs_object_id *id)
{
    cs_world_def wd = cs_world_def_default();
    wd.threads = 1;
    wd.dt = 1.0 / 60;
    cs_world_t *w = NULL;
    char err[256];
    if (cs_world_create(&wd, &w, err, sizeof err) != CS_OK)
        return NULL;
    int32_t *ijk = cs_box_cells(nx, 2, 2);
    cs_object_def d = cs_object_def_default();
    d.name = "beam";
    demo_beam_material(&d);
    d.geometry = CS_GEOMETRY_CELLS;
    d.cells_ijk = ijk;
    d.n_cells = 4 * nx;
    const cs_aabb clamp = {{-0.001, -1, -1}, {0.001, 1, 1}};
    d.fixed = &clamp;
    d.n_fixed = 1;
    int rc = ijk ? cs_world_add_object(w, &d, id, err, sizeof err) : CS_ERR_NOMEM;
    free(ijk);
    if (rc == CS_OK && cut)
        rc = cs_world_fracture(w, *id, (double[3]){0.0125 * nx, 0.0375, 0.025}, (double[3]){0, 1, 0},
                               1.0, err, sizeof err);
    if (rc != CS_OK) {
        fprintf(stderr, "held_beam: %s\n", err);
        cs_world_destroy(w);
        return NULL;
    }
    return w;
}

/* The fastest a coordinate of P's nodes moved since the last call with *prev (per second at
 * dt 1/60 s; 0 on the first, which allocates *prev), or NAN when out of memory. */
static double node_speed(const cs_object *P, double **prev)
{
    double sp = 0;
    if (!*prev) {
        if (!(*prev = malloc(3 * (size_t)P->n * sizeof(double))))
            return NAN;
    } else {
        for (int k = 0; k < 3 * P->n; k++)
            sp = fmax(sp, fabs(P->x[k] - (*prev)[k]) / (1.0 / 60));
    }
    memcpy(*prev, P->x, 3 * (size_t)P->n * sizeof(double));
    return sp;
}

TEST(contact_born_pieces_held_at_their_crack_stay_still)
{
    cs_object_id whole, half;
    cs_world_t *u = held_beam(4, false, &whole), *w = held_beam(4, true, &half);
    ENSURE(u && w);
    cs_object_id ids[4];
    ENSURE_MSG(cs_world_object_ids(w, ids, 4) == 2, "the cut made %d pieces",
               cs_world_object_ids(w, ids, 4));
    const cs_object *U = cs_world_find_internal(u, whole);
    double *prev[2] = {NULL, NULL};
    double off = 0, step_speed = 0, vmax = 0;
    for (int s = 0; s < 120; s++) {
        ENSURE(cs_world_step(u) == CS_OK && cs_world_step(w) == CS_OK);
        for (int p = 0; p < 2; p++) {
            const cs_object *P = cs_world_find_internal(w, ids[p]);
            const double sp = node_speed(P, &prev[p]);
            ENSURE(isfinite(sp));
            step_speed = fmax(step_speed, sp);
            for (int i = 0; i < P->n; i++) {
                vmax = fmax(vmax, sqrt(P->v[3 * i] * P->v[3 * i] + P->v[3 * i + 1] *
                                       P->v[3 * i + 1] + P->v[3 * i + 2] * P->v[3 * i + 2]));
                for (int j = 0; j < U->n; j++) { /* its twin in the uncut beam */
                    const double *a = P->cm.node_rest + 3 * i, *b = U->cm.node_rest + 3 * j;
                    if (fabs(a[0] - b[0]) + fabs(a[1] - b[1]) + fabs(a[2] - b[2]) > 1e-9)
                        continue;
                    for (int k = 0; k < 3; k++)
                        off = fmax(off, fabs(P->x[3 * i + k] - U->x[3 * j + k]));
                }
            }
        }
    }
    printf("    halves against the uncut beam: nodes at most %.3g mm apart; fastest node "
           "between steps %.3g m/s, after a step %.3g m/s\n", 1e3 * off, step_speed, vmax);
    ENSURE_MSG(off < 1e-4, "a node of the halves %.3g mm from the uncut beam's", 1e3 * off);
    ENSURE_MSG(step_speed < 0.01, "a node moved at %.3g m/s between steps", step_speed);
    ENSURE_MSG(vmax < 1, "a node left at %.3g m/s after a step", vmax);
    free(prev[0]);
    free(prev[1]);
    cs_world_destroy(u);
    cs_world_destroy(w);
}

/*
 * The same two held halves, one pushed against the other at its free end (1 N up and
 * sideways for 0.5 s), then left alone: they must come to rest (damping 0.5/s and 0.002 s).
 * Before session 33 the contacts between them, answered by each half's blocks and predicting
 * its next step by one block-Jacobi iteration, gave energy at every exchange: the halves
 * rattled on for as long as they were watched (4 cubes long: 2–5 m/s of node motion; 16
 * cubes long: 3–18 m/s; after the collective factor alone still 0.24 m/s). Now a half of 72
 * free dofs answers exactly (dense factor), one of 16 cubes (288) through its two modes
 * (contact_soft.h): over the last of 8 s (7.5 s after the push) no node may move faster than
 * 1 mm/s between steps.
 */
TEST(contact_born_held_halves_pushed_come_to_rest)
{
    const int lengths[2] = {4, 16};
    for (int t = 0; t < 2; t++) {
        const int nx = lengths[t];
        cs_object_id half;
        cs_world_t *w = held_beam(nx, true, &half);
        ENSURE(w);
        cs_object_id ids[4];
        ENSURE(cs_world_object_ids(w, ids, 4) == 2);
        char err[256];
        ENSURE_MSG(cs_world_apply_force(w, ids[0], (double[3]){0.025 * nx, 0.0, 0.05},
                                        (double[3]){0, 1, 1}, 0.5, err, sizeof err) == CS_OK,
                   "%s", err);
        double *prev[2] = {NULL, NULL}, late = 0, early = 0;
        const int steps = 480;
        for (int s = 0; s < steps; s++) {
            ENSURE(cs_world_step(w) == CS_OK);
            for (int p = 0; p < 2; p++) {
                const cs_object *P = cs_world_find_internal(w, ids[p]);
                const double sp = node_speed(P, &prev[p]);
                ENSURE(isfinite(sp));
                if (s >= steps - 60)
                    late = fmax(late, sp);
                else if (s >= 30 && s < 90)
                    early = fmax(early, sp);
            }
        }
        printf("    held halves %d cubes long pushed for 0.5 s: fastest node %.3g m/s in the "
               "second after the push, %.3g m/s in the last second (of 8)\n", nx, early, late);
        ENSURE_MSG(late < 1e-3, "%d cubes long: a node still moves at %.3g m/s 7.5 s after the "
                   "push", nx, late);
        free(prev[0]);
        free(prev[1]);
        cs_world_destroy(w);
    }
}

/* The mean lowering of the nodes at the free end x = 0.1 of the held piece of w with nodes at
 * rest y = 0, from their rest heights [m]. */
static double tip_lowering(cs_world_t *w)
{
    cs_object_id ids[8];
    const int n = cs_world_object_ids(w, ids, 8);
    double s = 0;
    int cnt = 0;
    for (int i = 0; i < n; i++) {
        const cs_object *P = cs_world_find_internal(w, ids[i]);
        bool mine = false;
        if (P->n_fixed_nodes == 0)
            continue; /* (the block) */
        for (int q = 0; q < P->n && !mine; q++)
            mine = fabs(P->cm.node_rest[3 * (size_t)q] - 0.1) < 1e-9 &&
                   fabs(P->cm.node_rest[3 * (size_t)q + 1]) < 1e-9;
        for (int q = 0; q < P->n && mine; q++)
            if (fabs(P->cm.node_rest[3 * (size_t)q] - 0.1) < 1e-9) {
                s += P->cm.node_rest[3 * (size_t)q + 2] - P->x[3 * (size_t)q + 2];
                cnt++;
            }
    }
    return cnt ? s / cnt : NAN;
}

/*
 * A free block resting on one of two small held pieces: the pieces answer their contacts with
 * each other exactly (dense factor), and so they must answer the block's. Until session 36 a
 * piece made exact by a held neighbour registered only the nodes of its held–held contacts:
 * the block's impulses on its other nodes were dropped on its side (no momentum, no
 * compliance), so the block rested on a rigid piece and the piece never felt its weight. The
 * held beam of 4 cubes cut lengthwise; a cube of 10 000 kg/m³ (1.53 N) placed on the free end
 * of the half at y < 0.025. Its weight must bend that half about as a steady force of the same
 * size at the centre of the same cell's top does: the end's extra lowering (mean over the last
 * second, against the beam under its own weight alone) within 0.7–1.35 times the force's
 * (Euler–Bernoulli puts a load anywhere on that cell's top at 0.78–1.23 times the centre's;
 * shear and the coarse mesh widen it; measured 1.27), and still to 1 % over that second.
 * With the impulses dropped the block sank the end by 0.30 mm against the force's 0.63, and
 * the end wandered over 0.32–0.45 mm, never settling.
 */
TEST(contact_born_exact_piece_feels_a_block_on_it)
{
    double extra[2], swing = 0;
    for (int t = 0; t < 3; t++) {
        cs_object_id half;
        cs_world_t *w = held_beam(4, true, &half);
        ENSURE(w);
        char err[256];
        const double W = 10000 * 0.025 * 0.025 * 0.025 * 9.81;
        if (t == 1) {
            int32_t one[3] = {0, 0, 0};
            cs_object_def d = cs_object_def_default();
            d.name = "block";
            demo_beam_material(&d);
            d.material.density = 10000;
            d.geometry = CS_GEOMETRY_CELLS;
            d.cells_ijk = one;
            d.n_cells = 1;
            memcpy(d.cells_origin, (double[3]){0.075, 0, 0.05}, sizeof d.cells_origin);
            ENSURE_MSG(cs_world_add_object(w, &d, NULL, err, sizeof err) == CS_OK, "%s", err);
        }
        const int steps = 300, last = 60;
        double sag = 0, lo = INFINITY, hi = -INFINITY;
        for (int s = 0; s < steps; s++) {
            if (t == 2 && s == 0) {
                cs_object_id ids[4];
                const int n = cs_world_object_ids(w, ids, 4);
                cs_object_id mine = CS_NULL_OBJECT;
                for (int i = 0; i < n; i++) {
                    const cs_object *P = cs_world_find_internal(w, ids[i]);
                    for (int q = 0; q < P->n; q++)
                        if (fabs(P->cm.node_rest[3 * (size_t)q + 1]) < 1e-9)
                            mine = ids[i];
                }
                ENSURE(mine != CS_NULL_OBJECT);
                ENSURE_MSG(cs_world_apply_force(w, mine, (double[3]){0.0875, 0.0125, 0.05},
                                                (double[3]){0, 0, -W}, 1e3, err,
                                                sizeof err) == CS_OK,
                           "%s", err);
            }
            ENSURE(cs_world_step(w) == CS_OK);
            if (s >= steps - last) {
                const double z = tip_lowering(w);
                sag += z / last;
                lo = fmin(lo, z);
                hi = fmax(hi, z);
            }
        }
        ENSURE(isfinite(sag));
        if (t == 1)
            swing = hi - lo;
        if (t == 0)
            extra[0] = extra[1] = -sag;
        else
            extra[t - 1] += sag;
        cs_world_destroy(w);
    }
    printf("    held half under a %.2f N block at its free end: the end lowered %.3f mm more "
           "than under its own weight (over %.4f mm in the last second); under the same force "
           "applied %.3f mm\n",
           10000 * 0.025 * 0.025 * 0.025 * 9.81, 1e3 * extra[0], 1e3 * swing, 1e3 * extra[1]);
    ENSURE_MSG(extra[1] > 1e-4, "the applied force bent the half by only %.4f mm",
               1e3 * extra[1]);
    ENSURE_MSG(extra[0] > 0.7 * extra[1] && extra[0] < 1.35 * extra[1], "the block bent the "
               "half %.3f mm, the force %.3f mm", 1e3 * extra[0], 1e3 * extra[1]);
    ENSURE_MSG(swing < 0.01 * extra[0], "the end under the block still moves over %.4f mm",
               1e3 * swing);
}
