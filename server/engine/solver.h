/*
 * solver.h — matrix-free preconditioned conjugate gradient (seed 000 §2.2: "the Conjugate
 * Gradient solver only needs to multiply the global stiffness matrix with a vector").
 *
 * The operator is a callback; the preconditioner is 3×3 block Jacobi (the inverse of each
 * node's diagonal block). Constrained degrees of freedom (mask[i] != 0) are held at their
 * initial value: residual and search directions are projected to zero there (filtered CG).
 * Reductions are summed in fixed blocks, so results do not depend on the thread count.
 *
 * Owns: the scratch vectors in cs_cg_work.
 */
#ifndef CS_SOLVER_H
#define CS_SOLVER_H

#include <stdbool.h>
#include <stdint.h>

typedef void (*cs_matvec_fn)(void *ctx, const double *x, double *y);

/*
 * What a solve's tolerance is relative to (cs_cg_work.stop, read by every cs_pcg / cs_pcg_ex):
 * RHS    ‖r‖ ≤ tol·‖b‖ (the default of a zeroed work);
 * START  ‖r‖ ≤ tol·min(‖b − A x0‖, ‖b‖), x0 the initial guess as passed (before the warm
 *        start). For implicit Euler, x0 = v makes this the right-hand side of the Δv form of
 *        the step (Baraff–Witkin): the solve removes the same fraction of what the step
 *        changes at any dt, where ‖b‖ = ‖M v + dt f‖ is mostly momentum at small dt. Never
 *        looser than RHS: after contact impulses on a few nodes of a stiff object, ‖b − A v‖
 *        is dt² K v at those nodes, many times ‖b‖, and a fraction of it left the momentum
 *        wrong by more than gravity's impulse (two 2×2×2 blocks of E = 1e9 Pa resting on
 *        each other: the upper one bounced and was thrown off within 30 steps; 1e11 Pa, both);
 * GIVEN  ‖r‖ ≤ tol·stop_ref (a re-solve of the same step keeps its first reference).
 * RHS and START references are at most stop_cap where it is > 0: an implicit step with ground
 * contacts sets it to the norm of b's momentum and external impulse, ‖M v + dt f‖, because
 * the ground's reactions are read off the residual (world.c, contact_cap).
 * START, GIVEN and a capped reference never ask for less than 1e-12·‖b‖ (round-off: a free
 * body's uniform velocity leaves b − A v = 0).
 */
typedef enum cs_cg_stop { CS_CG_STOP_RHS = 0, CS_CG_STOP_START, CS_CG_STOP_GIVEN } cs_cg_stop;

/* Directions of the warm start's subspace (cs_cg_guess), besides the guess itself; 1 searches
 * the plane of the guess and the last change. */
#ifndef CS_CG_DIRS
#define CS_CG_DIRS 4
#endif

typedef struct cs_cg_work {
    int n;        /* degrees of freedom (3 per node) */
    cs_cg_stop stop; /* what tol is relative to (above); RHS after cs_cg_work_init */
    double stop_ref; /* GIVEN: the norm */
    double stop_cap; /* > 0: RHS and START references at most this (above); 0 after init */
    double *r, *z, *p, *q, *zo, *partial;
    /* warm-start history of a sequence of solves (cs_cg_guess); allocated on first use */
    double *hist_prev, *hist_end;
    double *dirs[CS_CG_DIRS];  /* the last steps' velocity changes, newest first (a ring) */
    double *adirs[CS_CG_DIRS]; /* their products in the solve that uses them (scratch) */
    double *gpartial;          /* per block partial sums of the Galerkin system */
    int ndirs;                 /* how many consecutive directions dirs holds */
    int max_dirs;              /* how many to use (1..CS_CG_DIRS; 0 = CS_CG_DIRS) */
    bool hist_valid, dir_ready;
    int threads;               /* threads of cs_cg_guess's and cs_cg_record's passes (0: one;
                                  the solves take theirs as an argument) */
    /* Asked before every iteration where set (NULL after init): true ends the solve there,
     * not converged (a long static solve stopped by a signal, world.c). */
    bool (*cancel)(void *ctx);
    void *cancel_ctx;
} cs_cg_work;

int cs_cg_work_init(cs_cg_work *w, int n);
void cs_cg_work_free(cs_cg_work *w);

/*
 * Warm start for a sequence of solves whose solutions change smoothly (the velocities of
 * implicit steps). cs_cg_guess sets the initial guess x = v (the state the step starts from)
 * and, when the previous step started from v_prev and ended exactly at v (cs_cg_record), arms
 * the changes of the last steps, d_1 = v − v_prev, d_2 = v_prev − v_prev2, … (up to
 * max_dirs ≤ CS_CG_DIRS, as many as were consecutive), for the next cs_pcg / cs_pcg_ex on this
 * work: that solve first moves x by the combination of them that minimises the A-norm of the
 * error (a Galerkin step on their span: one product per direction and a small dense system;
 * when x is 0 at the held dofs, x itself is one more direction, its product the start
 * residual's, so x may also be scaled at no extra product; never worse than x = v; with one direction a line search along the last change, which is
 * better than the plain extrapolation 2v − v_prev). It remembers v as the next v_prev and
 * forgets the history until cs_cg_record(v_end) is called after the step: a state changed
 * between steps (reset, sleep, a set velocity) no longer matches and starts afresh, and a
 * re-initialised work (fracture changes the node count) has no history. The directions are
 * masked inside the solve, so held and contact dofs keep their initial value. Returns 1 if
 * armed, 0 if not, -1 if out of memory (then x = v).
 */
int cs_cg_guess(cs_cg_work *w, const double *v, double *x);
void cs_cg_record(cs_cg_work *w, const double *v_end);
void cs_cg_forget(cs_cg_work *w);
/* Apply map(ctx, u) in place to the history's velocity vectors (the last start, v_prev, and
 * the changes it holds): for a state that was transformed between steps by the same linear
 * map (a free body's turn, world.c), so that the next guess's changes are the solves' own. */
void cs_cg_map_history(cs_cg_work *w, void (*map)(void *ctx, double *u), void *ctx);
/* The warm start's sums over dofs [lo, hi) (one of its fixed blocks) for nv ≤ CS_CG_DIRS + 1
 * directions D and products Q: out[a·nv + c] = Σ_i D_a[i] Q_c[i], out[nv·nv + a] = Σ_i D_a[i]
 * r[i], each summed in i order from 0 (nv = 5 by vectors across the sums, the same bits). */
void cs_cg_gram_block(const double *const *D, const double *const *Q, const double *r, int nv,
                      int lo, int hi, double *out);

/* Invert each 3×3 block in place (9 per node); a singular block becomes its diagonal inverse. */
void cs_invert_blocks(double *blocks, int n_nodes);
/* One such block (what cs_invert_blocks does to each): for callers that fill and invert blocks
 * in one pass. */
void cs_invert_block(double m[9]);

/* In-place dense Cholesky M = L Lᵀ of the symmetric n×n row-major M (L in the lower
 * triangle); returns -1 if M is not positive definite. cs_cholesky_solve: x = (L Lᵀ)⁻¹ x.
 * cs_cholesky_forward: x = L⁻¹ x for an x that is 0 before row `from` (so is L⁻¹ x):
 * (A⁻¹)_pq = (L⁻¹e_p)·(L⁻¹e_q) takes forward solves only. */
int cs_cholesky(double *M, int n);
void cs_cholesky_solve(const double *L, int n, double *x);
void cs_cholesky_forward(const double *L, int n, int from, double *x);

/* Σ a_i b_i over lo ≤ i < hi, in four interleaved sums (a fixed order: the same bits on
 * every call), for the dense kernels' dot products. */
double cs_dot_short(const double *a, const double *b, int lo, int hi);

typedef struct cs_cg_result {
    int iterations;
    double relres;   /* ‖r‖/ref at exit: the relative residual the solve stopped on */
    double ref;      /* the norm tol was relative to (‖b‖ projected, ‖b − A x0‖, or given) */
    int converged;
    int indefinite;  /* stopped on a direction p with pᵀA p ≤ 0: A is not positive definite */
} cs_cg_result;

/*
 * Solve A x = b for the unconstrained dofs, x holding the initial guess (warm start).
 * Stops when ‖r‖ <= tol·‖b‖ (or the reference w->stop asks for) or after max_iter. A must be symmetric positive definite on
 * the free dofs. Returns the result; x is finite on exit unless A or b were not.
 */
cs_cg_result cs_pcg(cs_cg_work *w, cs_matvec_fn A, void *ctx, const double *inv_blocks,
                    const uint8_t *mask, const double *b, double *x, double tol, int max_iter,
                    int threads);

/*
 * The same with any symmetric positive definite preconditioner: z = B r (z overwritten; B must
 * leave z = 0 at masked dofs and be a linear map, e.g. a multigrid V-cycle, mg.h). β is
 * Polak–Ribière's (flexible CG: equal to the usual one for an exactly symmetric B, and robust
 * when B is symmetric only up to rounding, as the single-precision V-cycle is).
 */
typedef void (*cs_precond_fn)(void *ctx, const double *r, double *z);
cs_cg_result cs_pcg_ex(cs_cg_work *w, cs_matvec_fn A, void *ctx, cs_precond_fn B, void *bctx,
                       const uint8_t *mask, const double *b, double *x, double tol, int max_iter,
                       int threads);

/* Deterministic dot product (fixed blocks, then a serial sum). */
double cs_dot(cs_cg_work *w, const double *a, const double *b, int n, int threads);

#endif
