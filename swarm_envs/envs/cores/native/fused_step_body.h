/* One SwarmNav step for swarms [b0, b1): the body of fused_step.c, included once per
 * floating type (REAL, with EXP, SQRT, FLOOR and the function name FUSED_STEP).
 *
 * The arithmetic of swarm_envs.envs.dynamics.SocialPotentialDynamics (docs/models.md
 * §1-2, §6-7): the semi-implicit Euler step with the carried passive force, split into
 * the substeps that stability needs (substep_plan, with the stable substep h* carried
 * like the force), one pass over the pairs of each new state (pair_law: forces eqs.
 * 10-12; rate_law: the Gershgorin rates of h*; and after the last substep the pair
 * energy eq. 9 and the distances), the goal sink (sink_law, eqs. 19-20), the k nearest
 * neighbours, the observations, the statistics and the actions' effort. Everything for
 * one swarm stays in a few kilobytes of scratch memory.
 */

/* The k_sort = K nearest neighbours of the agents of block I (docs/models.md §2's k-NN order:
 * by (ρ, j)), from the distances that the pair pass stored per tile and offset. Each
 * candidate is inserted into the sorted lists of its lane; the tiles hand candidates over
 * in rotated order, so the comparison is on (ρ, j). Tile (J, I) with J < I holds agent
 * I0 + m's partners rotated the other way: rotated back here. */
static inline __attribute__((always_inline)) void KNN_BLOCK(
    const int64_t K, const int64_t I, const int64_t nb, const int64_t N, const REAL *rho,
    const VINDEX *rot, REAL *near_d, int32_t *near_i) {
    const int64_t I0 = I * LANES;
#ifdef KNN_KEYS
    /* float32: each candidate as one 64-bit key, the bits of ρ (≥ 0, so they order as
     * the numbers do) above its index j: (ρ, j) order is integer order, and the
     * insertion is a min and a max per slot, in two halves of LANES / 2 lanes. */
    vkey lo[KMAX_SORT], hi[KMAX_SORT];
    for (int64_t q = 0; q < K; q++) lo[q] = hi[q] = (vkey){0} + UINT64_MAX;
#else
    /* The empty slots hold (inf, the last lane): a candidate at inf with a lower index
     * (an agent not present) still goes before them, in (ρ, j) order, and a slot left
     * empty (only by NaN distances) names a lane inside the tables. */
    VREAL bd[KMAX_SORT];
    VINDEX bi[KMAX_SORT];
    for (int64_t q = 0; q < K; q++) {
        bd[q] = (VREAL){0} + (REAL)INFINITY;
        bi[q] = (VINDEX){0} + (INDEX)(nb * LANES - 1);
    }
#endif
    for (int64_t J = 0; J < nb; J++) {
        const int64_t J0 = J * LANES;
        const REAL *tile = rho + (J < I ? J * nb + I : I * nb + J) * LANES * LANES;
        const int s_first = J == I ? 1 : 0, s_end = J == I ? LANES / 2 + 1 : LANES;
        for (int s = s_first; s < s_end; s++) {
            VREAL row;
            memcpy(&row, tile + s * LANES, sizeof row);
            const VINDEX back = rot[(LANES - s) & (LANES - 1)];
            for (int side = 0; side < 2; side++) {
                VREAL cd;
                VINDEX ci;
                if (side == 0) {
                    if (J < I) continue;
                    cd = row;
                    ci = (INDEX)J0 + rot[s];
                } else {
                    if (J > I || (J == I && s == LANES / 2)) continue;
                    cd = __builtin_shuffle(row, back);
                    ci = (INDEX)J0 + back;
                }
#ifdef KNN_KEYS
                const VINDEX bits = (VINDEX)cd;
                vkey c_lo = KEY_HALF(bits, ci, 0), c_hi = KEY_HALF(bits, ci, 1);
                for (int64_t q = 0; q < K; q++) {
                    vkey t = key_min(lo[q], c_lo);
                    c_lo = key_max(lo[q], c_lo);
                    lo[q] = t;
                    t = key_min(hi[q], c_hi);
                    c_hi = key_max(hi[q], c_hi);
                    hi[q] = t;
                }
#else
                for (int64_t q = 0; q < K; q++) {
                    /* lt: all ones where the candidate goes before slot q. */
                    VINDEX lt = (VINDEX)(cd < bd[q]) | ((VINDEX)(cd == bd[q]) & (ci < bi[q]));
                    VINDEX cbits = (VINDEX)cd, bbits = (VINDEX)bd[q];
                    VINDEX old_i = bi[q];
                    bd[q] = (VREAL)((cbits & lt) | (bbits & ~lt));
                    bi[q] = (ci & lt) | (old_i & ~lt);
                    cd = (VREAL)((bbits & lt) | (cbits & ~lt));
                    ci = (old_i & lt) | (ci & ~lt);
                }
#endif
            }
        }
    }
    const int64_t n_lanes = N - I0 < LANES ? N - I0 : LANES;
    for (int64_t q = 0; q < K; q++)
        for (int64_t l = 0; l < n_lanes; l++) {
#ifdef KNN_KEYS
            uint64_t key = l < LANES / 2 ? lo[q][l] : hi[q][l - LANES / 2];
            uint32_t rbits = (uint32_t)(key >> 32);
            memcpy(&near_d[q * N + I0 + l], &rbits, sizeof rbits);
            near_i[q * N + I0 + l] = (int32_t)(key & 0xffffffffu);
#else
            near_d[q * N + I0 + l] = bd[q][l];
            near_i[q * N + I0 + l] = (int32_t)bi[q][l];
#endif
        }
}

/* KNN_BLOCK for every block of agents, the usual list lengths instantiated with a
 * constant K so that the lists stay in registers. One function per floating type, not
 * inlined into FUSED_SWARM: the search does not depend on the dimension, and a copy in
 * each dimension's FUSED_SWARM would double its share of the build time for nothing. */
static __attribute__((noinline)) void KNN_ALL(const int64_t k_sort, const int64_t nb,
                                              const int64_t N, const REAL *rho,
                                              const VINDEX *rot, REAL *near_d,
                                              int32_t *near_i) {
    for (int64_t I = 0; I < nb; I++) {
        switch (k_sort) {
        case 1: KNN_BLOCK(1, I, nb, N, rho, rot, near_d, near_i); break;
        case 2: KNN_BLOCK(2, I, nb, N, rho, rot, near_d, near_i); break;
        case 3: KNN_BLOCK(3, I, nb, N, rho, rot, near_d, near_i); break;
        case 4: KNN_BLOCK(4, I, nb, N, rho, rot, near_d, near_i); break;
        case 5: KNN_BLOCK(5, I, nb, N, rho, rot, near_d, near_i); break;
        case 6: KNN_BLOCK(6, I, nb, N, rho, rot, near_d, near_i); break;
        case 7: KNN_BLOCK(7, I, nb, N, rho, rot, near_d, near_i); break;
        case 8: KNN_BLOCK(8, I, nb, N, rho, rot, near_d, near_i); break;
        default: KNN_BLOCK(k_sort, I, nb, N, rho, rot, near_d, near_i); break;
        }
    }
}

/* swarm_envs.physics.integrators.stable_substep in REAL, as numpy computes it in the
 * state's dtype: h* = 4·STEP_SAFETY / (γ + √(γ² + 4ω²)); inf where both rates are 0 or one is NaN
 * (the non-finite state then takes one substep, and the guard sees it), 0 where one is
 * inf. */
static inline double STABLE_SUBSTEP(REAL omega2, REAL gamma) {
    const REAL den = gamma + SQRT(gamma * gamma + (REAL)4 * omega2);
    return den > 0 ? (double)((REAL)STEP_EDGE_NUMERATOR / den) : INFINITY;
}

#include "fused_step_stats.h" /* SWARM_STATS */

static inline __attribute__((always_inline)) int FUSED_SWARM(
    const StepParams *P, const int64_t d, int64_t b, REAL *scratch, const REAL *x,
    const REAL *v, const REAL *f, const double *h_in, const REAL *goal, const REAL *a,
    const uint8_t *move, const int8_t *status, REAL *x_out, REAL *v_out, REAL *f_out,
    double *h_out, float *obs, REAL *packed) {
    const int64_t B = P->batch, N = P->n_agents, k = P->n_neighbors;
    const int64_t k_real = P->k_real, k_sort = P->k_rank;
    const int64_t obs_dim = P->obs_dim, physics_goal = P->physics_goal;
    const int64_t observe_status = P->observe_status;
    const int64_t NP = (N + LANES - 1) / LANES * LANES;
    const REAL m = (REAL)P->physics_m, u_max = (REAL)P->u_max;
    const REAL C_a = (REAL)P->physics_C_a, C_r = (REAL)P->physics_C_r;
    const REAL l_a = (REAL)P->physics_l_a, l_r = (REAL)P->physics_l_r;
    const REAL C_o = (REAL)P->physics_C_o;
    const REAL beta = (REAL)P->physics_beta, C_g = (REAL)P->physics_C_g;
    const REAL l_g = (REAL)P->physics_l_g;
    const REAL goal_radius = (REAL)P->arrival_radius;
    const REAL collision_radius = (REAL)P->collision_radius;
    const REAL goal_scale = (REAL)P->obs_goal_scale, vel_scale = (REAL)P->obs_velocity_scale;
    const REAL inv_nbr_scale = (REAL)(1.0 / P->obs_neighbor_scale);
    const REAL inv_vel_scale = (REAL)(1.0 / P->obs_velocity_scale);
    const REAL obs_bound = (REAL)P->obs_bound, centre_tol = (REAL)P->centre_tol;
    const REAL rho_floor = (REAL)P->rho_floor;
    const REAL inf = (REAL)INFINITY;
    const REAL dec_a = (REAL)(-1.0 / P->physics_l_a), dec_r = (REAL)(-1.0 / P->physics_l_r);
    const REAL dec_o = (REAL)(-1.0 / P->physics_l_o);
    const REAL ca_la = (REAL)(P->physics_C_a / P->physics_l_a);
    const REAL cr_lr = (REAL)(P->physics_C_r / P->physics_l_r);
    const REAL cg_lg = (REAL)(P->physics_C_g / P->physics_l_g);
    /* The step-size rule's constants (social_potential.rate_law and pair_rates). */
    const REAL kappa_r = (REAL)(P->physics_C_r / (P->physics_l_r * P->physics_l_r));
    const REAL kappa_a = (REAL)(P->physics_C_a / (P->physics_l_a * P->physics_l_a));
    const REAL omega2_scale = (REAL)(2.0 / P->physics_m);
    const REAL omega2_sink =
        (REAL)(P->physics_C_g / (P->physics_l_g * P->physics_l_g * P->physics_m));
    const REAL gamma_still = (REAL)(P->physics_beta / P->physics_m);
    /* Self-propulsion (social_potential.dissipation and dissipation_rate): with α > 0
     * the Rayleigh term (α − β|v_i|²) v_i replaces the friction −β v_i, and the damping
     * rate 3β max_i |v_i|² − α (which may be negative) replaces β. */
    const int rayleigh = P->physics_alpha > 0;
    const REAL alpha = (REAL)P->physics_alpha;
    const REAL three_beta = (REAL)(3.0 * P->physics_beta);
    const int friction = !rayleigh && beta > 0;
    /* integrator='implicit_damping_euler' (integrators.implicit_damping_update): each
     * agent's implicit dissipation b_i and alignment row sum w_i (damping_rates) are
     * carried as the rows d and d + 1 of f (ks and ws in the scratch after a pass);
     * Δv_i = h (a_i + w_i s)/(m + h (b_i + w_i)) with the swarm's collective increment
     * s. Its rule is the block bound (stiffness_law, block_bound, stiffness_rate):
     * ω² = max_i [Σ_j k_ij + λ̄(Q_i)] / m, Q_i = Σ_j p_ij u uᵀ, and h* = 0.9 · 2/ω. */
    const int block = P->implicit_damping != 0;
    const int64_t nq = d == 2 ? 3 : 6; /* Q_i: 00, 01, 11 (, 02, 12, 22) */
    const double cap = (double)P->max_substeps;
    const int same_decay = l_a == l_r, alignment = C_o > 0;
    const int64_t S = NP; /* component stride of the scratch state (padded to LANES) */

    /* Scratch: xs, vs, fs, offset (d × NP each), the agents' rate sums ks, ws (NP each),
     * gd (N), rho (NP × NP, per tile and offset), near (k_sort × N each, distances and
     * int32 indices), tab (8 × NP) and own (2d × NP float32) for the observations, and
     * the agents' flags (NP, INDEX). */
    REAL *xs = scratch, *vs = xs + d * S, *fs = vs + d * S, *off = fs + d * S;
    REAL *ks = off + d * S, *ws = ks + S;
    REAL *gd = ws + S, *rho = gd + N, *near_d = rho + NP * NP;
    int32_t *near_i = (int32_t *)(near_d + k_sort * N);
    INDEX *alive = (INDEX *)(near_d + 2 * k_sort * N + 8 * NP + 2 * d * NP);
    REAL *qs = (REAL *)(alive + NP); /* the agents' Q_i of the block bound, nq × NP */

    /* The agents' statuses (swarm_envs.envs.task.agent_status; status NULL: every agent
     * active) as flags (STATUS_FLAGS, generated): AG_PRESENT (in the physics: its pairs
     * interact, it can be a neighbour), AG_MOBILE (its update is integrated, it is a
     * member of the swarm for the statistics), AG_ACTIVE (the observed status); padding
     * lanes are absent. With statuses (masked), every tile takes the masked path: a pair
     * interacts where both agents are present. */
    const int8_t *st = status ? status + b * N : NULL;
    const int masked = st != NULL;
    for (int64_t i = 0; i < NP; i++) {
        const int s_i = i < N ? (st ? st[i] : STATUS_ACTIVE) : STATUS_ABSENT;
        alive[i] = (INDEX)(s_i >= 0 && s_i < STATUS_COUNT ? status_flags[s_i] : 0);
    }

    /* 1. The step in substeps (swarm_envs.envs.dynamics.SocialPotentialDynamics.step).
     * Each plans the time tau left of the step with the stable substep hs of the current
     * state (substep_plan); where the count would pass max_substeps the swarm is marked
     * over the cap (needed: the count it would have taken) and takes the time left in
     * the substeps left. A substep is the semi-implicit Euler update with the carried
     * passive force (the inputs' in the first substep, then the scratch state's),
     * actions clipped to [-1, 1] (FUSED_STEP has checked that they are finite), then
     * one pass over the pairs of the new state (2. below) for its passive force and
     * its hs; after the last substep that pass also sums the energy and stores the
     * distances. A measure without a step (move[b] = 0) is that last pass alone. */
    const REAL *ab = a + b * N * d;
    const REAL *g = goal + b * d;
    const int moving = move[b];
    double tau = moving ? P->dt : 0, hs = h_in[b], used = 0, needed = 0;
    int over = 0;
    const int64_t nb = NP / LANES;
    VINDEX iota, rot[LANES];
    for (int l = 0; l < LANES; l++) iota[l] = l;
    for (int s = 0; s < LANES; s++) rot[s] = (iota + s) & (LANES - 1);
    REAL energy_pairs = 0; /* the sum over ordered pairs i ≠ j of the pair energy */
    int64_t close_pairs = 0; /* ordered pairs closer than the collision radius */
    for (int first = 1;; first = 0) {
        if (moving) {
            double n, h;
            substep_plan(tau, hs, &n, &h);
            needed = used + n > needed ? used + n : needed;
            const double left = cap - used;
            if (n > left) { /* the rest in the substeps left, and marked */
                over = 1;
                n = left > 1 ? left : 1;
                h = tau / n;
            }
            const REAL hr = (REAL)h;
            /* implicit_damping_euler: b_i, w_i of the current state, and s (per
             * component) over the agents that move (an agent held at rest: w_i = 0) */
            const REAL *own_in = first ? f + (d * B + b) * N : ks;
            const REAL *al_in = first ? f + ((d + 1) * B + b) * N : ws;
            REAL sv[3] = {0, 0, 0};
            if (block) {
                REAL num[3] = {0, 0, 0}, z = 0;
                for (int64_t i = 0; i < N; i++) {
                    const int held = masked && !(alive[i] & AG_MOBILE);
                    const REAL al = held ? 0 : al_in[i];
                    const REAL den = m + hr * (own_in[i] + al);
                    z += al * (m + hr * own_in[i]) / den;
                    for (int64_t c = 0; c < d; c++) {
                        const REAL *fc = first ? f + (c * B + b) * N : fs + c * S;
                        REAL accel = fc[i] + u_max * UNIT_CLIP(ab[i * d + c]);
                        if (held) accel = 0;
                        num[c] += al * hr * accel / den;
                    }
                }
                for (int64_t c = 0; c < d; c++) sv[c] = z > 0 ? num[c] / z : 0;
            }
            for (int64_t c = 0; c < d; c++) {
                const int64_t at = (c * B + b) * N;
                const REAL *xc = first ? x + at : xs + c * S, *vc = first ? v + at : vs + c * S;
                const REAL *fc = first ? f + at : fs + c * S;
                REAL *xn = xs + c * S, *vn = vs + c * S;
                if (block) {
                    const REAL sc = sv[c];
#pragma omp simd
                    for (int64_t i = 0; i < N; i++) {
                        REAL accel = fc[i] + u_max * UNIT_CLIP(ab[i * d + c]);
                        const int held = masked && !(alive[i] & AG_MOBILE);
                        if (held) accel = 0;
                        const REAL al = held ? 0 : al_in[i];
                        const REAL den = m + hr * (own_in[i] + al);
                        vn[i] = vc[i] + hr * (accel + al * sc) / den;
                        xn[i] = xc[i] + hr * vn[i];
                    }
                } else {
#pragma omp simd
                    for (int64_t i = 0; i < N; i++) {
                        REAL accel = fc[i] + u_max * UNIT_CLIP(ab[i * d + c]);
                        if (masked) accel = alive[i] & AG_MOBILE ? accel : 0; /* held at rest */
                        if (m != (REAL)1) accel = accel / m;
                        vn[i] = vc[i] + hr * accel;
                        xn[i] = xc[i] + hr * vn[i];
                    }
                }
                for (int64_t i = N; i < NP; i++) xn[i] = vn[i] = 0; /* padding lanes */
            }
            used += 1;
            tau = n <= 1 ? 0 : tau - h;
        } else {
            for (int64_t c = 0; c < d; c++) {
                memcpy(vs + c * S, v + (c * B + b) * N, N * sizeof(REAL));
                memcpy(xs + c * S, x + (c * B + b) * N, N * sizeof(REAL));
                for (int64_t i = N; i < NP; i++) xs[c * S + i] = vs[c * S + i] = 0;
            }
        }
        const int last = tau == 0;

        /* 2. One pass over the unordered pairs of the new state: F(x', v'), the rates
         * κ and w summed per agent, and after the last substep the pair energy and ρ.
         * Agents in tiles of LANES × LANES (I ≤ J blocks). In tile (I, J) the lanes hold
         * agents i = I0 + l and, at offset s, the partners j = J0 + (l + s) mod LANES
         * (block J rotated by s): every pair is evaluated once, its force and rates
         * added to i in its lane and, rotated back by s, to j (the force negated). The
         * diagonal tile (I, I) needs offsets 1 .. LANES/2 only (offset LANES/2 holds
         * every pair twice, so it adds to i only). Lanes past N are padding: masked
         * out, their distances inf; with statuses, so is every pair with an agent not
         * present (no force, rate or energy, not a neighbour), and a close pair is a
         * collision only where one of the two moves (the masks pv, mv per offset, from
         * the agents' flags). ρ is stored per tile and offset, the layout the k-NN
         * below reads. The lane loop (PAIR_BODY) writes each pair's terms; the offset
         * loop (S_LOOP) adds them to the sums of i (FI, KI, ...: vectors, so that they
         * stay in registers) and of j (FJ, KJ, ...). */
        for (int64_t c = 0; c < d; c++)
            for (int64_t i = 0; i < NP; i++) fs[c * S + i] = 0;
        for (int64_t i = 0; i < NP; i++) ks[i] = ws[i] = 0;
        if (block)
            for (int64_t i = 0; i < nq * NP; i++) qs[i] = 0;
        for (int64_t I = 0; I < nb; I++) {
            const int64_t I0 = I * LANES;
            /* Sums per agent i of block I, lane by lane: force, pair energy (× 2 for
             * ordered pairs), κ, w and ordered pairs closer than the collision radius. */
            VREAL FI[3] = {{0}, {0}, {0}}, E_lane = {0}, KI = {0}, WI = {0};
            VREAL QI[6] = {{0}, {0}, {0}, {0}, {0}, {0}};
            VINDEX close_lane = {0};
            const REAL *xi0 = xs + I0, *xi1 = xs + S + I0, *xi2 = xs + 2 * S + I0;
            const REAL *vi0 = vs + I0, *vi1 = vs + S + I0, *vi2 = vs + 2 * S + I0;
            VINDEX aI;
            memcpy(&aI, alive + I0, sizeof aI);
            for (int64_t J = I; J < nb; J++) {
                const int64_t J0 = J * LANES;
                VREAL xJ[3], vJ[3], FJ[3], KJ = {0}, WJ = {0};
                VREAL QJ[6] = {{0}, {0}, {0}, {0}, {0}, {0}};
                VINDEX aJ;
                memcpy(&aJ, alive + J0, sizeof aJ);
                for (int64_t c = 0; c < d; c++) {
                    memcpy(&xJ[c], xs + c * S + J0, sizeof(VREAL));
                    memcpy(&vJ[c], vs + c * S + J0, sizeof(VREAL));
                    FJ[c] = (VREAL){0};
                }
                const int s_first = J == I ? 1 : 0, s_last = J == I ? LANES / 2 : LANES - 1;
                /* no padding lanes, no statuses */
                const int full = !masked && I0 + LANES <= N && J0 + LANES <= N;
#define PAIR_BODY(ALIGN, SAME, FULL, LAST, BLOCK)                                          \
    _Pragma("omp simd") for (int l = 0; l < LANES; l++) {                                  \
        const int valid = FULL || pv[l];                                                    \
        REAL dx0 = xj[0][l] - xi0[l], dx1 = xj[1][l] - xi1[l];                             \
        REAL dx2 = d == 3 ? xj[2][l] - xi2[l] : 0;                                         \
        REAL r2 = dx0 * dx0 + dx1 * dx1;                                                   \
        if (d == 3) r2 = r2 + dx2 * dx2;                                                   \
        REAL r = SQRT(r2);                                                                 \
        INDEX r_bits, floor_bits; /* max(r, ρ_floor) on the bits (both ≥ 0) */            \
        memcpy(&r_bits, &r, sizeof r_bits);                                                \
        memcpy(&floor_bits, &rho_floor, sizeof floor_bits);                                \
        r_bits = r_bits > floor_bits ? r_bits : floor_bits;                                \
        REAL r_safe;                                                                       \
        memcpy(&r_safe, &r_bits, sizeof r_safe);                                           \
        REAL inv = (REAL)1 / r_safe;                                                       \
        REAL ea = EXP(r * dec_a);                                                          \
        REAL er = SAME ? ea : EXP(r * dec_r);                                              \
        REAL sp = ea * ca_la - cr_lr * er;                                                 \
        if (BLOCK) { /* stiffness_law: k = max(a, t) + t, p = a − t; Q: p u uᵀ */       \
            const REAL cur = kappa_r * er - kappa_a * ea, tra = sp * inv;                  \
            const REAL a_ = cur > 0 ? cur : 0, t_ = tra > 0 ? tra : 0;                     \
            kx[l] = valid ? (a_ > t_ ? a_ : t_) + t_ : 0;                                  \
            const REAL pu = valid ? (a_ - t_) * inv * inv : 0;                             \
            qx[0][l] = pu * dx0 * dx0;                                                     \
            qx[1][l] = pu * dx0 * dx1;                                                     \
            qx[2][l] = pu * dx1 * dx1;                                                     \
            if (d == 3) {                                                                  \
                qx[3][l] = pu * dx0 * dx2;                                                 \
                qx[4][l] = pu * dx1 * dx2;                                                 \
                qx[5][l] = pu * dx2 * dx2;                                                 \
            }                                                                              \
        } else {                                                                           \
            kx[l] = valid ? kappa_r * er + kappa_a * ea : 0; /* κ(ρ) */                    \
        }                                                                                  \
        if (ALIGN) {                                                                       \
            REAL proj = (vi0[l] - vj[0][l]) * dx0 + (vi1[l] - vj[1][l]) * dx1;             \
            if (d == 3) proj = proj + (vi2[l] - vj[2][l]) * dx2;                           \
            REAL eo = EXP(r * dec_o);                                                      \
            sp = sp - proj * inv * eo * C_o;                                               \
            wx[l] = valid ? C_o * eo : 0; /* w(ρ) */                                       \
        }                                                                                  \
        sp = valid ? sp * inv : 0;                                                         \
        cx[0][l] = sp * dx0;                                                               \
        cx[1][l] = sp * dx1;                                                               \
        if (d == 3) cx[2][l] = sp * dx2;                                                   \
        if (LAST) {                                                                        \
            ex[l] = valid ? w * (C_r * er - C_a * ea) : 0;                                 \
            cl[l] = (FULL || mv[l]) & (r < collision_radius) ? wc : 0;                     \
            drow[l] = valid ? r : inf;                                                     \
        }                                                                                  \
    }
#define S_LOOP(ALIGN, SAME, FULL, LAST, BLOCK)                                             \
    for (int s = s_first; s <= s_last; s++) {                                              \
        const int both = !(J == I && s == LANES / 2); /* else each pair twice */           \
        const REAL w = both ? 2 : 1;                                                       \
        const INDEX wc = both ? 2 : 1;                                                     \
        REAL xj[3][LANES], vj[3][LANES], cx[3][LANES], kx[LANES], wx[LANES], ex[LANES];    \
        REAL qx[6][LANES];                                                                 \
        INDEX cl[LANES], pv[LANES], mv[LANES];                                             \
        if (!FULL) { /* pairs of present agents; and one of them moves */                 \
            const VINDEX aj = __builtin_shuffle(aJ, rot[s]);                               \
            const VINDEX p = (aI & aj & AG_PRESENT) != 0;                                  \
            const VINDEX mo = p & (((aI | aj) & AG_MOBILE) != 0);                          \
            memcpy(pv, &p, sizeof p);                                                      \
            memcpy(mv, &mo, sizeof mo);                                                    \
        }                                                                                  \
        for (int64_t c = 0; c < d; c++) {                                                  \
            VREAL t = __builtin_shuffle(xJ[c], rot[s]);                                    \
            memcpy(xj[c], &t, sizeof t);                                                   \
            t = __builtin_shuffle(vJ[c], rot[s]);                                          \
            memcpy(vj[c], &t, sizeof t);                                                   \
        }                                                                                  \
        REAL *drow = rho + ((I * nb + J) * LANES + s) * LANES;                             \
        PAIR_BODY(ALIGN, SAME, FULL, LAST, BLOCK)                                          \
        { /* to i, in its lane */                                                          \
            VREAL t;                                                                       \
            for (int64_t c = 0; c < d; c++) {                                              \
                memcpy(&t, cx[c], sizeof t);                                               \
                FI[c] += t;                                                                \
            }                                                                              \
            memcpy(&t, kx, sizeof t);                                                      \
            KI += t;                                                                       \
            if (BLOCK)                                                                     \
                for (int64_t q = 0; q < nq; q++) {                                         \
                    memcpy(&t, qx[q], sizeof t);                                           \
                    QI[q] += t;                                                            \
                }                                                                          \
            if (ALIGN) {                                                                   \
                memcpy(&t, wx, sizeof t);                                                  \
                WI += t;                                                                   \
            }                                                                              \
            if (LAST) {                                                                    \
                memcpy(&t, ex, sizeof t);                                                  \
                E_lane += t;                                                               \
                VINDEX ct;                                                                 \
                memcpy(&ct, cl, sizeof ct);                                                \
                close_lane += ct;                                                          \
            }                                                                              \
        }                                                                                  \
        if (both) { /* to j, rotated back */                                               \
            const VINDEX back = rot[(LANES - s) & (LANES - 1)];                            \
            for (int64_t c = 0; c < d; c++) {                                              \
                VREAL t;                                                                   \
                memcpy(&t, cx[c], sizeof t);                                               \
                FJ[c] -= __builtin_shuffle(t, back);                                       \
            }                                                                              \
            VREAL t;                                                                       \
            memcpy(&t, kx, sizeof t);                                                      \
            KJ += __builtin_shuffle(t, back);                                              \
            if (BLOCK)                                                                     \
                for (int64_t q = 0; q < nq; q++) {                                         \
                    memcpy(&t, qx[q], sizeof t);                                           \
                    QJ[q] += __builtin_shuffle(t, back);                                   \
                }                                                                          \
            if (ALIGN) {                                                                   \
                memcpy(&t, wx, sizeof t);                                                  \
                WJ += __builtin_shuffle(t, back);                                          \
            }                                                                              \
        }                                                                                  \
    }
                /* Constant flags: alignment, equal decay lengths, no padding lane in the
                 * tile (the masks fold away), and the last substep's pass; each copy has
                 * its own offset loop, so that its sums stay in registers. The other
                 * passes do not share the exponential of equal decay lengths (four
                 * copies fewer to compile). */
                if (block) { /* the block bound: in 2-D a tile without padding lanes
                              * (and without statuses) as two copies, the last pass's and
                              * the others'; every other tile as one more copy, its flags
                              * at run time (in 3-D a copy per tile kind would let the
                              * compiler fuse other multiply-adds: other last bits) */
                    if (d == 2 && full && last) { S_LOOP(alignment, 0, 1, 1, 1) }
                    else if (d == 2 && full) { S_LOOP(alignment, 0, 1, 0, 1) }
                    else { S_LOOP(alignment, 0, 0, last, 1) }
                } else {
                    if (last) {
                        if (full) {
                            if (alignment) {
                                if (same_decay) { S_LOOP(1, 1, 1, 1, 0) }
                                else { S_LOOP(1, 0, 1, 1, 0) }
                            } else {
                                if (same_decay) { S_LOOP(0, 1, 1, 1, 0) }
                                else { S_LOOP(0, 0, 1, 1, 0) }
                            }
                        } else if (alignment) {
                            if (same_decay) { S_LOOP(1, 1, 0, 1, 0) } else { S_LOOP(1, 0, 0, 1, 0) }
                        } else {
                            if (same_decay) { S_LOOP(0, 1, 0, 1, 0) } else { S_LOOP(0, 0, 0, 1, 0) }
                        }
                    } else if (full) {
                        if (alignment) { S_LOOP(1, 0, 1, 0, 0) } else { S_LOOP(0, 0, 1, 0, 0) }
                    } else {
                        if (alignment) { S_LOOP(1, 0, 0, 0, 0) } else { S_LOOP(0, 0, 0, 0, 0) }
                    }
                }
#undef S_LOOP
#undef PAIR_BODY
                for (int64_t c = 0; c < d; c++)
                    for (int l = 0; l < LANES; l++) fs[c * S + J0 + l] += FJ[c][l];
                for (int l = 0; l < LANES; l++) {
                    ks[J0 + l] += KJ[l];
                    ws[J0 + l] += WJ[l];
                }
                if (block)
                    for (int64_t q = 0; q < nq; q++)
                        for (int l = 0; l < LANES; l++) qs[q * NP + J0 + l] += QJ[q][l];
            }
            for (int64_t c = 0; c < d; c++)
                for (int l = 0; l < LANES; l++) fs[c * S + I0 + l] += FI[c][l];
            for (int l = 0; l < LANES; l++) {
                ks[I0 + l] += KI[l];
                ws[I0 + l] += WI[l];
            }
            if (last) /* the other passes sum no energy and no close pairs */
                for (int l = 0; l < LANES; l++) {
                    energy_pairs += E_lane[l];
                    close_pairs += close_lane[l];
                }
            if (block)
                for (int64_t q = 0; q < nq; q++)
                    for (int l = 0; l < LANES; l++) qs[q * NP + I0 + l] += QI[q][l];
        }

        /* Dissipation, then the goal sink (eqs. 19-20), in the numpy core's order. The
         * Rayleigh term also takes the largest squared speed for the damping rate (NaN
         * kept, as numpy's max keeps it). */
        REAL speed2_max = 0;
        int speed_nan = 0;
        if (rayleigh) {
#pragma omp simd reduction(max : speed2_max) reduction(| : speed_nan)
            for (int64_t i = 0; i < N; i++) {
                REAL s2 = vs[i] * vs[i];
                for (int64_t c = 1; c < d; c++) s2 = s2 + vs[c * S + i] * vs[c * S + i];
                const REAL gain = alpha - beta * s2;
                for (int64_t c = 0; c < d; c++)
                    fs[c * S + i] = fs[c * S + i] + gain * vs[c * S + i];
                speed2_max = s2 > speed2_max ? s2 : speed2_max;
                speed_nan |= s2 != s2;
            }
        }
        for (int64_t c = 0; c < d; c++)
            for (int64_t i = 0; i < N; i++) {
                if (friction) fs[c * S + i] = fs[c * S + i] - beta * vs[c * S + i];
                off[c * S + i] = g[c] - xs[c * S + i];
            }
#pragma omp simd
        for (int64_t i = 0; i < N; i++) {
            REAL s2 = 0;
            for (int64_t c = 0; c < d; c++) s2 += off[c * S + i] * off[c * S + i];
            gd[i] = SQRT(s2);
        }
        if (physics_goal) {
#pragma omp simd
            for (int64_t i = 0; i < N; i++) {
                REAL scale = cg_lg * EXP(-gd[i] / l_g);
                scale = scale / (gd[i] > rho_floor ? gd[i] : rho_floor);
                for (int64_t c = 0; c < d; c++)
                    fs[c * S + i] = fs[c * S + i] + off[c * S + i] * scale;
            }
        }

        /* The stable substep of the new state (pair_rates, then STABLE_SUBSTEP, in
         * REAL as numpy computes them in the state's dtype): ω² = (2/m) max_i Σ_j κ_ij
         * (+ the sink's C_g/(l_g² m) where it acts passively), γ = (β + 2 max_i Σ_j
         * w_ij)/m, with β replaced by 3β max_i |v_i|² − α under self-propulsion; a NaN
         * sum or speed makes ω² NaN (h* is then inf, as numpy's is for a NaN rate). */
        if (block) {
            /* ω² = max_i [Σ_j k_ij + λ̄(Q_i)] / m (block_bound), h* = 0.9 · 2/ω; the
             * agents' implicit dissipation b_i = D_i⁺ into ks once read (damping_rates;
             * ws keeps their alignment row sums w_i). */
            REAL bmax = 0;
            int bnan = 0;
            for (int64_t i = 0; i < N; i++) {
                const REAL *q = qs + i;
                REAL bound;
                if (d == 2) {
                    const REAL half = (REAL)0.5 * (q[0] - q[2 * NP]);
                    bound = ks[i] + (REAL)0.5 * (q[0] + q[2 * NP]) +
                            SQRT(half * half + q[NP] * q[NP]);
                } else {
                    const REAL q00 = q[0], q01 = q[NP], q11 = q[2 * NP];
                    const REAL q02 = q[3 * NP], q12 = q[4 * NP], q22 = q[5 * NP];
                    const REAL mean = (q00 + q11 + q22) * (REAL)(1.0 / 3.0);
                    const REAL d0 = q00 - mean, d1 = q11 - mean, d2 = q22 - mean;
                    const REAL off2 = q01 * q01 + q02 * q02 + q12 * q12;
                    const REAL dev2 = d0 * d0 + d1 * d1 + d2 * d2 + (REAL)2 * off2;
                    bound = ks[i] + mean + (REAL)0.816496580927726 * SQRT(dev2);
                }
                bmax = bound > bmax ? bound : bmax;
                bnan |= bound != bound;
                REAL own = beta;
                if (rayleigh) {
                    REAL s2 = vs[i] * vs[i];
                    for (int64_t c = 1; c < d; c++) s2 = s2 + vs[c * S + i] * vs[c * S + i];
                    own = three_beta * s2 - alpha;
                    own = own > 0 ? own : 0;
                }
                ks[i] = own;
            }
            REAL omega2 = bnan | speed_nan ? (REAL)NAN : bmax / m;
            if (physics_goal) omega2 = omega2 + omega2_sink;
            const REAL den = (REAL)2 * SQRT(omega2);
            hs = den > 0 ? (double)((REAL)STEP_EDGE_NUMERATOR / den) : INFINITY;
            if (last) break;
            continue;
        }
        REAL kmax = 0, wmax = 0;
        int nan = 0;
#pragma omp simd reduction(max : kmax, wmax) reduction(| : nan)
        for (int64_t i = 0; i < N; i++) {
            kmax = ks[i] > kmax ? ks[i] : kmax;
            wmax = ws[i] > wmax ? ws[i] : wmax;
            nan |= (ks[i] != ks[i]) | (ws[i] != ws[i]);
        }
        REAL omega2 = nan | speed_nan ? (REAL)NAN : omega2_scale * kmax;
        if (physics_goal) omega2 = omega2 + omega2_sink;
        REAL gamma;
        if (rayleigh) {
            const REAL rate = three_beta * speed2_max - alpha;
            gamma = alignment ? (rate + (REAL)2 * wmax) / m : rate / m + (REAL)0 * omega2;
        } else {
            gamma = alignment ? (beta + (REAL)2 * wmax) / m : gamma_still + (REAL)0 * omega2;
        }
        hs = STABLE_SUBSTEP(omega2, gamma);
        if (last) break;
    }

    /* The energy: kinetic, pairs and sink, of the step's last state. The sums below and
     * in 5. are vectorised (omp simd reductions): their order is fixed by the build,
     * not by the thread count. */
    REAL sink = 0, kinetic = 0;
    if (C_g > 0) {
        if (masked) {
#pragma omp simd reduction(+ : sink)
            for (int64_t i = 0; i < N; i++)
                sink += alive[i] & AG_PRESENT ? -C_g * EXP(-gd[i] / l_g) : 0;
        } else {
#pragma omp simd reduction(+ : sink)
            for (int64_t i = 0; i < N; i++) sink += -C_g * EXP(-gd[i] / l_g);
        }
    }
    for (int64_t c = 0; c < d; c++) {
        const REAL *vc = vs + c * S;
#pragma omp simd reduction(+ : kinetic)
        for (int64_t i = 0; i < N; i++) kinetic += vc[i] * vc[i];
    }
    const REAL phi = (REAL)0.5 * m * kinetic + (REAL)0.5 * energy_pairs + sink;
    const REAL collisions = FLOOR((REAL)close_pairs * (REAL)0.5);

    /* 3. The k_sort nearest neighbours of every agent, ordered by (ρ, j): agents in blocks
     * of LANES, each candidate inserted into the sorted lists of its lane (KNN_ALL). */
    if (N > 1) KNN_ALL(k_sort, nb, N, rho, rot, near_d, near_i);

    /* 4. Observations (B, N, obs_dim), float32, clipped to ±obs_bound. Every agent j's
     * position, velocity, a 1 (the slot mask) and, with observe_status, its status flag
     * (1 where active) sit in 8 lanes (tab, one neighbour block of the row: 2d + 1 (+ 1)
     * ≤ 8 values); a neighbour's block is (tab_j − tab_i with its flags kept) × scale.
     * With statuses a slot holds a neighbour only where both agents are present (else
     * padding, zeros: fewer present others than slots, or an observer not present).
     * float32 with AVX-512 handles two blocks per 16-lane vector and compresses their
     * values together (OBS_PAIRS_AVX512); otherwise each block is stored 8 wide in order
     * so that the next block overwrites the spare lanes (the last one at its own
     * width). */
    REAL *tab = near_d + k_sort * N + k_sort * N; /* after near_i (k_sort × N int32) */
    const int64_t blk = 2 * d + 1 + observe_status;
    REAL keep[8], scl[8];
    for (int c = 0; c < 8; c++) {
        keep[c] = c < 2 * d ? 1 : 0;
        scl[c] = c < d ? inv_nbr_scale : (c < 2 * d ? inv_vel_scale : 1);
    }
    for (int64_t j = 0; j < NP; j++) { /* padding rows: zeros */
        REAL *t = tab + j * 8;
        for (int c = 0; c < 8; c++) t[c] = 0;
        if (j >= N) continue;
        for (int64_t c = 0; c < d; c++) {
            t[c] = xs[c * S + j];
            t[d + c] = vs[c * S + j];
        }
        t[2 * d] = 1;
        if (observe_status) t[2 * d + 1] = alive[j] & AG_ACTIVE ? 1 : 0;
    }
    float *own = (float *)(tab + 8 * NP); /* the row's first 2d values, (2d, NP) */
#define CLIP_OBS(val) ((float)((val) < -obs_bound ? -obs_bound : ((val) > obs_bound ? obs_bound : (val))))
    for (int64_t c = 0; c < d; c++) {
#pragma omp simd
        for (int64_t i = 0; i < N; i++) {
            REAL val = off[c * S + i] / goal_scale;
            own[c * NP + i] = CLIP_OBS(val);
            val = vs[c * S + i] / vel_scale;
            own[(d + c) * NP + i] = CLIP_OBS(val);
        }
    }
#ifdef OBS_PAIRS_AVX512
    /* float32 with AVX-512: two neighbour blocks per 16-lane vector, their 2 x blk
     * values compressed together and stored with a mask (no spill past the pair). */
    const __mmask16 blk_lanes = (__mmask16)((1u << blk) - 1);
    const __mmask16 pair_lanes = (__mmask16)(blk_lanes | (blk_lanes << 8));
    const __mmask16 pair_out = (__mmask16)((1u << (2 * blk)) - 1);
    const __m512 scl16 = PAIR8(_mm256_loadu_ps(scl), _mm256_loadu_ps(scl));
    const __m512 lo16 = _mm512_set1_ps(-obs_bound), hi16 = _mm512_set1_ps(obs_bound);
    for (int64_t i = 0; i < N; i++) {
        float *o = obs + (b * N + i) * obs_dim;
        for (int64_t c = 0; c < 2 * d; c++) o[c] = own[c * NP + i];
        const __m256 selfk = _mm256_mul_ps(_mm256_loadu_ps(tab + i * 8), _mm256_loadu_ps(keep));
        const __m512 self16 = PAIR8(selfk, selfk);
        const INDEX here = alive[i] & AG_PRESENT;
        float *on = o + 2 * d;
        int64_t q = 0;
        for (; q + 1 < k_real; q += 2) {
            const int32_t j0 = near_i[q * N + i], j1 = near_i[(q + 1) * N + i];
            const __m256 g0 = _mm256_loadu_ps(tab + j0 * 8);
            const __m256 g1 = _mm256_loadu_ps(tab + j1 * 8);
            __m512 val = _mm512_mul_ps(_mm512_sub_ps(PAIR8(g0, g1), self16), scl16);
            val = _mm512_min_ps(hi16, _mm512_max_ps(lo16, val)); /* NaN stays NaN */
            if (masked) /* slots without a present neighbour: padding */
                val = _mm512_maskz_mov_ps(
                    (__mmask16)((here & alive[j0] ? 0x00ffu : 0u) | (here & alive[j1] ? 0xff00u : 0u)),
                    val);
            _mm512_mask_storeu_ps(on + q * blk, pair_out, _mm512_maskz_compress_ps(pair_lanes, val));
        }
        if (q < k_real) { /* an odd last real block */
            const int32_t j0 = near_i[q * N + i];
            const __m256 g0 = _mm256_loadu_ps(tab + j0 * 8);
            __m512 val = _mm512_mul_ps(_mm512_sub_ps(PAIR8(g0, g0), self16), scl16);
            val = _mm512_min_ps(hi16, _mm512_max_ps(lo16, val));
            if (masked && !(here & alive[j0])) val = _mm512_setzero_ps();
            _mm512_mask_storeu_ps(on + q * blk, blk_lanes, val);
            q++;
        }
        for (int64_t t = q * blk; t < k * blk; t++) on[t] = 0.0f; /* padding blocks */
    }
#else
    for (int64_t i = 0; i < N; i++) {
        float *o = obs + (b * N + i) * obs_dim;
        for (int64_t c = 0; c < 2 * d; c++) o[c] = own[c * NP + i];
        const REAL *self = tab + i * 8;
        const INDEX here = alive[i] & AG_PRESENT;
        float *on = o + 2 * d;
        for (int64_t q = 0; q < k; q++) {
            float out[8];
            const int32_t j = q < k_real ? near_i[q * N + i] : 0;
            if (q < k_real && (!masked || (here & alive[j]))) {
                const REAL *g = tab + j * 8;
#pragma omp simd
                for (int c = 0; c < 8; c++) {
                    REAL val = (g[c] - self[c] * keep[c]) * scl[c];
                    out[c] = CLIP_OBS(val);
                }
            } else {
                for (int c = 0; c < 8; c++) out[c] = 0.0f;
            }
            switch (q + 1 < k ? 8 : blk) { /* constant sizes: the copies are inlined */
            case 5: memcpy(on + q * blk, out, 5 * sizeof(float)); break;
            case 6: memcpy(on + q * blk, out, 6 * sizeof(float)); break;
            case 7: memcpy(on + q * blk, out, 7 * sizeof(float)); break;
            default: memcpy(on + q * blk, out, 8 * sizeof(float)); break;
            }
        }
    }
#endif
#undef CLIP_OBS

    /* 5. Statistics (SWARM_STATS, fused_step_stats.h): over every agent, or over the
     * members where agents have statuses. */
    REAL *pk = packed + b * PK_SIZE;
    if (masked)
        SWARM_STATS(1, N, d, S, xs, vs, off, gd, near_d, alive, g, centre_tol, goal_radius,
                    P->success_threshold, pk);
    else
        SWARM_STATS(0, N, d, S, xs, vs, off, gd, near_d, alive, g, centre_tol, goal_radius,
                    P->success_threshold, pk);
    /* mill_order: mill_speed / v0, at most 1; 0 without self-propulsion (v0 = 0). */
    const REAL cruise = (REAL)P->cruise_speed;
    const REAL mill = pk[PK_mill_speed] / (cruise > 0 ? cruise : 1);
    pk[PK_mill_order] = cruise > 0 ? (mill > 1 ? (REAL)1 : mill) : 0;
    REAL effort = 0;
#pragma omp simd reduction(+ : effort)
    for (int64_t t = 0; t < N * d; t++) {
        const REAL at = UNIT_CLIP(ab[t]);
        effort += at * at;
    }
    pk[PK_energy] = phi;
    pk[PK_collisions] = collisions;
    pk[PK_substeps] = (REAL)used;
    pk[PK_unstable] = 0; /* set by the caller's guard, which undoes an unstable step */
    pk[PK_effort] = effort;
    pk[PK_over_cap] = (REAL)over;
    pk[PK_needed] = (REAL)needed;
#ifdef SWARM_ENVS_PERTURB_COLUMN
    /* A deliberately broken term, for the conformance tests only (built with
     * -DSWARM_ENVS_PERTURB_COLUMN=PK_<name>): they check that the suite catches it. */
    pk[SWARM_ENVS_PERTURB_COLUMN] += (REAL)0.25;
#endif
    /* Over the cap, or a column not finite (x - x is NaN for NaN and inf): the caller's
     * guard decides (swarm_envs.envs.common.unstable_swarms); else it has nothing to do. */
    REAL probe = 0; /* NaN where a column is (or the sum overflows: checked needlessly) */
    for (int c = 0; c < PK_SIZE; c++) probe += pk[c];
    const int unsound = over | !(probe - probe == 0);
    for (int64_t c = 0; c < d; c++)
        for (int64_t i = 0; i < N; i++) {
            x_out[(c * B + b) * N + i] = xs[c * S + i];
            v_out[(c * B + b) * N + i] = vs[c * S + i];
            f_out[(c * B + b) * N + i] = fs[c * S + i];
        }
    if (block)
        for (int64_t i = 0; i < N; i++) {
            f_out[(d * B + b) * N + i] = ks[i];
            f_out[((d + 1) * B + b) * N + i] = ws[i];
        }
    h_out[b] = hs;
    return unsound;
}

/* Swarms [b0, b1) (or rows[b0 .. b1) where rows is not NULL: a reset re-measures the
 * swarms it drew in place, outputs aliasing inputs, which is safe as FUSED_SWARM reads
 * a swarm's inputs before it writes its outputs), spread over the OpenMP
 * threads (torch's own pool when torch is loaded: its libgomp.so.1 is the one this
 * library links to). Every swarm is stepped by one thread in the same way, so the
 * results do not depend on the thread count.
 * State per swarm: x, v and the carried passive force f (component first, d × B × N),
 * and the carried stable substep h (B, double); the agents' statuses (B × N int8,
 * swarm_envs.envs.task.agent_status), or NULL where every agent is active; the step writes the new ones to the
 * *_out arrays, the observations to obs and the columns PK_* to packed (B × PK_SIZE):
 * the statistics, the actions' effort, over_cap (1 where the step needed more than
 * max_substeps) and needed (the substeps it would have taken).
 * Returns a STEP_* code (swarm_envs.envs.cores.native.contract.StepCode): STEP_OK,
 * STEP_NO_SCRATCH where a thread could not allocate its scratch memory,
 * STEP_TOO_MANY_NEIGHBOURS where k_sort > KMAX_SORT or STEP_NON_FINITE_ACTIONS where an
 * action of these swarms is NaN or infinite (both checked first: nothing is written);
 * or'ed with STEP_UNSOUND where a swarm went over the cap or wrote a non-finite column.
 * Finite actions outside [-1, 1] are clipped, as numpy's clip would. */
int FUSED_STEP(const StepParams *P, int64_t b0, int64_t b1, const int64_t *rows,
               const REAL *x, const REAL *v, const REAL *f, const double *h, const REAL *goal,
               const REAL *a, const uint8_t *move, const int8_t *status, REAL *x_out,
               REAL *v_out, REAL *f_out, double *h_out, float *obs, REAL *packed) {
    const int64_t N = P->n_agents, d = P->dim, k_sort = P->k_rank;
    const int64_t NP = (N + LANES - 1) / LANES * LANES;
    if (k_sort > KMAX_SORT) return STEP_TOO_MANY_NEIGHBOURS;
    /* Non-finite actions: exponent bits all ones (an integer OR reduction, vectorised). */
    ABITS nonfinite = 0;
    for (int64_t t = b0; t < b1; t++) {
        const ABITS *abits = (const ABITS *)(a + (rows ? rows[t] : t) * N * d);
        for (int64_t u = 0; u < N * d; u++)
            nonfinite |= (ABITS)((abits[u] & EXP_MASK) == EXP_MASK);
    }
    if (nonfinite) return STEP_NON_FINITE_ACTIONS;
    const size_t n_real =
        (size_t)(4 * d * NP + 2 * NP + N + NP * NP + 2 * k_sort * N + 8 * NP + 2 * d * NP + NP +
                 6 * NP);
    int code = STEP_OK;
#pragma omp parallel if (b1 - b0 > 1) reduction(| : code)
    {
        REAL *scratch = (REAL *)malloc(n_real * sizeof(REAL) + 64);
        /* d as a constant in each copy: the loops over components unroll. Every thread
         * reaches the loop (it ends in a barrier), with or without its scratch. */
        if (d == 2) {
#pragma omp for schedule(static)
            for (int64_t t = b0; t < b1; t++) {
                if (!scratch) { code |= STEP_NO_SCRATCH; continue; }
                if (FUSED_SWARM(P, 2, rows ? rows[t] : t, scratch, x, v, f, h, goal, a, move,
                                status, x_out, v_out, f_out, h_out, obs, packed))
                    code |= STEP_UNSOUND;
            }
        } else {
#pragma omp for schedule(static)
            for (int64_t t = b0; t < b1; t++) {
                if (!scratch) { code |= STEP_NO_SCRATCH; continue; }
                if (FUSED_SWARM(P, 3, rows ? rows[t] : t, scratch, x, v, f, h, goal, a, move,
                                status, x_out, v_out, f_out, h_out, obs, packed))
                    code |= STEP_UNSOUND;
            }
        }
        free(scratch);
    }
    return code;
}
