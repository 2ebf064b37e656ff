/* One SwarmNav step for swarms [b0, b1): the body of fused_step.c, included once per
 * floating type (REAL, with EXP, SQRT, FLOOR and the function name FUSED_STEP).
 *
 * The same arithmetic as swarm_envs.envs.torch_core.build_advance (see its docstring and
 * MODELS.md §1-2): the semi-implicit Euler step with the carried passive force, one pass
 * over the pairs of the new state (forces eqs. 10-12, pair energy eq. 9, distances), the
 * goal sink (eqs. 19-20), the k nearest neighbours, the observations, the statistics and
 * the reward. Everything for one swarm stays in a few kilobytes of scratch memory.
 */

static inline __attribute__((always_inline)) void FUSED_SWARM(
    const int64_t *ip, const double *dp, const int64_t d, int64_t b, REAL *scratch,
                        const REAL *x, const REAL *v, const REAL *f, const REAL *goal,
                        const REAL *a, const uint8_t *move, const REAL *prev_distance,
                        const REAL *prev_arrived, const REAL *start_distance, REAL *x_out,
                        REAL *v_out, REAL *f_out, float *obs, REAL *packed, REAL *mean_dist_out,
                        REAL *arrived_out) {
    const int64_t B = ip[IP_B], N = ip[IP_N], k = ip[IP_K];
    const int64_t k_real = ip[IP_K_REAL], k_sort = ip[IP_K_SORT], need = ip[IP_NEED];
    const int64_t obs_dim = ip[IP_OBS_DIM], physics_goal = ip[IP_PHYSICS_GOAL];
    const int64_t NP = (N + LANES - 1) / LANES * LANES;
    const REAL dt = (REAL)dp[DP_DT], m = (REAL)dp[DP_M], u_max = (REAL)dp[DP_U_MAX];
    const REAL C_a = (REAL)dp[DP_C_A], C_r = (REAL)dp[DP_C_R];
    const REAL l_a = (REAL)dp[DP_L_A], l_r = (REAL)dp[DP_L_R];
    const REAL C_o = (REAL)dp[DP_C_O];
    const REAL beta = (REAL)dp[DP_BETA], C_g = (REAL)dp[DP_C_G], l_g = (REAL)dp[DP_L_G];
    const REAL goal_radius = (REAL)dp[DP_GOAL_RADIUS];
    const REAL collision_radius = (REAL)dp[DP_COLLISION_RADIUS];
    const REAL goal_scale = (REAL)dp[DP_GOAL_SCALE], vel_scale = (REAL)dp[DP_VEL_SCALE];
    const REAL inv_nbr_scale = (REAL)dp[DP_INV_NBR_SCALE];
    const REAL inv_vel_scale = (REAL)dp[DP_INV_VEL_SCALE];
    const REAL obs_bound = (REAL)dp[DP_OBS_BOUND], centre_tol = (REAL)dp[DP_CENTRE_TOL];
    const REAL rho_floor = (REAL)dp[DP_RHO_FLOOR];
    const REAL inf = (REAL)INFINITY;
    const REAL dec_a = (REAL)(-1.0 / dp[DP_L_A]), dec_r = (REAL)(-1.0 / dp[DP_L_R]);
    const REAL dec_o = (REAL)(-1.0 / dp[DP_L_O]);
    const REAL ca_la = (REAL)(dp[DP_C_A] / dp[DP_L_A]), cr_lr = (REAL)(dp[DP_C_R] / dp[DP_L_R]);
    const REAL cg_lg = (REAL)(dp[DP_C_G] / dp[DP_L_G]);
    const int same_decay = l_a == l_r, alignment = C_o > 0;
    const REAL Nr = (REAL)N;
    const int64_t S = NP; /* component stride of the scratch state (padded to LANES) */

    /* Scratch: xs, vs, fs, offset (d × NP each), gd (N), rho (N × NP), near (k_sort × N). */
    REAL *xs = scratch, *vs = xs + d * S, *fs = vs + d * S, *off = fs + d * S;
    REAL *gd = off + d * S, *rho = gd + N, *near_d = rho + N * NP;
    int32_t *near_i = (int32_t *)(near_d + k_sort * N);

    /* 1. Semi-implicit Euler with the carried passive force. */
    for (int64_t c = 0; c < d; c++) {
        const REAL *xc = x + (c * B + b) * N, *vc = v + (c * B + b) * N, *fc = f + (c * B + b) * N;
        const REAL *ab = a + b * N * d;
        for (int64_t i = 0; i < N; i++) {
            if (move[b]) {
                REAL accel = fc[i] + u_max * ab[i * d + c];
                if (m != (REAL)1) accel = accel / m;
                REAL vn = vc[i] + dt * accel;
                vs[c * S + i] = vn;
                xs[c * S + i] = xc[i] + dt * vn;
            } else {
                vs[c * S + i] = vc[i];
                xs[c * S + i] = xc[i];
            }
        }
        for (int64_t i = N; i < NP; i++) xs[c * S + i] = vs[c * S + i] = 0; /* padding lanes */
    }

    /* 2. One pass over the ordered pairs of the new state: F(x', v'), pair energy, ρ.
     * Agents i in blocks of LANES (the vector lanes), candidates j one at a time: every
     * sum stays in its lane (no horizontal reductions), and ρ_ji = ρ_ij is stored as row
     * j, the layout the k-NN below reads. Lanes past N are padding (position 0; their
     * results are never read, their distances are set to inf). */
    REAL E_lane[LANES], F_lane[3][LANES];
    int32_t close_lane[LANES];
    REAL energy_rows = 0;
    int64_t close_pairs = 0;
    const REAL *x0 = xs, *x1 = xs + S, *x2 = xs + 2 * S;
    const REAL *v0 = vs, *v1 = vs + S, *v2 = vs + 2 * S;
    for (int64_t i0 = 0; i0 < N; i0 += LANES) {
        for (int l = 0; l < LANES; l++) {
            F_lane[0][l] = F_lane[1][l] = F_lane[2][l] = E_lane[l] = 0;
            close_lane[l] = 0;
        }
        for (int64_t j = 0; j < N; j++) {
            const REAL xj0 = x0[j], xj1 = x1[j], xj2 = d == 3 ? x2[j] : 0;
            const REAL vj0 = v0[j], vj1 = v1[j], vj2 = d == 3 ? v2[j] : 0;
            REAL *row = rho + j * NP + i0;
#define PAIR_BODY(ALIGN, SAME)                                                             \
    _Pragma("omp simd") for (int l = 0; l < LANES; l++) {                                  \
        const int64_t i = i0 + l;                                                          \
        REAL dx0 = xj0 - x0[i], dx1 = xj1 - x1[i], dx2 = d == 3 ? xj2 - x2[i] : 0;         \
        REAL r2 = dx0 * dx0 + dx1 * dx1;                                                   \
        if (d == 3) r2 = r2 + dx2 * dx2;                                                   \
        REAL r = SQRT(r2);                                                                 \
        REAL inv = (REAL)1 / (r > rho_floor ? r : rho_floor);                              \
        REAL ea = EXP(r * dec_a);                                                          \
        REAL er = SAME ? ea : EXP(r * dec_r);                                              \
        REAL s = ea * ca_la - cr_lr * er;                                                  \
        if (ALIGN) {                                                                       \
            REAL proj = (v0[i] - vj0) * dx0 + (v1[i] - vj1) * dx1;                         \
            if (d == 3) proj = proj + (v2[i] - vj2) * dx2;                                 \
            s = s - proj * inv * EXP(r * dec_o) * C_o;                                     \
        }                                                                                  \
        s = s * inv;                                                                       \
        F_lane[0][l] += s * dx0;                                                           \
        F_lane[1][l] += s * dx1;                                                           \
        if (d == 3) F_lane[2][l] += s * dx2;                                               \
        E_lane[l] += C_r * er - C_a * ea;                                                  \
        int self = j == i;                                                                 \
        close_lane[l] += (!self) & (r < collision_radius);                                 \
        row[l] = self ? inf : r;                                                           \
    }
            if (alignment) {
                if (same_decay) { PAIR_BODY(1, 1) } else { PAIR_BODY(1, 0) }
            } else {
                if (same_decay) { PAIR_BODY(0, 1) } else { PAIR_BODY(0, 0) }
            }
#undef PAIR_BODY
        }
        for (int64_t c = 0; c < d; c++)
            for (int l = 0; l < LANES; l++) fs[c * S + i0 + l] = F_lane[c][l];
        const int64_t n_lanes = N - i0 < LANES ? N - i0 : LANES; /* the rest is padding */
        for (int64_t l = 0; l < n_lanes; l++) {
            energy_rows += E_lane[l];
            close_pairs += close_lane[l];
        }
        for (int64_t j = 0; j < N; j++)
            for (int64_t i = i0 + n_lanes; i < i0 + LANES; i++) rho[j * NP + i] = inf;
    }

    /* Dissipation, then the goal sink (eqs. 19-20), in the torch core's order. */
    const REAL *g = goal + b * d;
    for (int64_t c = 0; c < d; c++)
        for (int64_t i = 0; i < N; i++) {
            if (beta > 0) fs[c * S + i] = fs[c * S + i] - beta * vs[c * S + i];
            off[c * S + i] = g[c] - xs[c * S + i];
        }
    REAL sink = 0;
    for (int64_t i = 0; i < N; i++) {
        REAL s2 = 0;
        for (int64_t c = 0; c < d; c++) s2 += off[c * S + i] * off[c * S + i];
        gd[i] = SQRT(s2);
    }
    if (physics_goal) {
        for (int64_t i = 0; i < N; i++) {
            REAL scale = cg_lg * EXP(-gd[i] / l_g);
            scale = scale / (gd[i] > rho_floor ? gd[i] : rho_floor);
            for (int64_t c = 0; c < d; c++) fs[c * S + i] = fs[c * S + i] + off[c * S + i] * scale;
        }
    }
    if (C_g > 0)
        for (int64_t i = 0; i < N; i++) sink += -C_g * EXP(-gd[i] / l_g);
    REAL kinetic = 0;
    for (int64_t c = 0; c < d; c++)
        for (int64_t i = 0; i < N; i++) kinetic += vs[c * S + i] * vs[c * S + i];
    const REAL phi = (REAL)0.5 * m * kinetic + (REAL)0.5 * (energy_rows - Nr * (C_r - C_a)) + sink;
    const REAL collisions = FLOOR((REAL)close_pairs * (REAL)0.5);

    /* 3. The k_sort nearest neighbours of every agent, ordered by (ρ, j): agents in blocks
     * of LANES, each candidate j inserted into the sorted lists (strict <, so an equal
     * distance keeps the lower index first). ρ is symmetric: row j holds ρ_ij for all i. */
    REAL nnd = 0;
    if (N > 1) {
        VREAL bd[KMAX_SORT];
        VINDEX bi[KMAX_SORT];
        const VINDEX zero_i = {0};
        for (int64_t i0 = 0; i0 < N; i0 += LANES) {
            for (int64_t s = 0; s < k_sort; s++) {
                bd[s] = (VREAL){0} + inf;
                bi[s] = zero_i;
            }
            for (int64_t j = 0; j < N; j++) {
                VREAL cd;
                memcpy(&cd, rho + j * NP + i0, sizeof cd);
                VINDEX ci = zero_i + (INDEX)j;
                for (int64_t s = 0; s < k_sort; s++) {
                    /* lt: all ones where the candidate goes before slot s. */
                    VINDEX lt = (VINDEX)(cd < bd[s]);
                    VINDEX cbits = (VINDEX)cd, bbits = (VINDEX)bd[s];
                    VINDEX old_i = bi[s];
                    bd[s] = (VREAL)((cbits & lt) | (bbits & ~lt));
                    bi[s] = (ci & lt) | (old_i & ~lt);
                    cd = (VREAL)((bbits & lt) | (cbits & ~lt));
                    ci = (old_i & lt) | (ci & ~lt);
                }
            }
            int64_t n_lanes = N - i0 < LANES ? N - i0 : LANES;
            for (int64_t s = 0; s < k_sort; s++)
                for (int64_t l = 0; l < n_lanes; l++) {
                    near_d[s * N + i0 + l] = bd[s][l];
                    near_i[s * N + i0 + l] = (int32_t)bi[s][l];
                }
        }
        for (int64_t i = 0; i < N; i++) nnd += near_d[i];
        nnd = nnd / Nr;
    }

    /* 4. Observations (B, N, obs_dim), float32, clipped to ±obs_bound. */
    for (int64_t i = 0; i < N; i++) {
        float *o = obs + (b * N + i) * obs_dim;
        int64_t p = 0;
#define PUT(value)                                                                 \
    do {                                                                           \
        REAL val_ = (value);                                                       \
        val_ = val_ < -obs_bound ? -obs_bound : (val_ > obs_bound ? obs_bound : val_); \
        o[p++] = (float)val_;                                                      \
    } while (0)
        for (int64_t c = 0; c < d; c++) PUT(off[c * S + i] / goal_scale);
        for (int64_t c = 0; c < d; c++) PUT(vs[c * S + i] / vel_scale);
        for (int64_t s = 0; s < k; s++) {
            if (s < k_real) {
                int64_t j = near_i[s * N + i];
                for (int64_t c = 0; c < d; c++) PUT((xs[c * S + j] - xs[c * S + i]) * inv_nbr_scale);
                for (int64_t c = 0; c < d; c++) PUT((vs[c * S + j] - vs[c * S + i]) * inv_vel_scale);
                o[p++] = 1.0f;
            } else {
                for (int64_t c = 0; c < 2 * d + 1; c++) o[p++] = 0.0f;
            }
        }
#undef PUT
    }

    /* 5. Statistics (swarm_envs.metrics, MODELS.md §2). */
    REAL hsum[3] = {0, 0, 0}, centre[3] = {0, 0, 0}, scale = 0;
    for (int64_t i = 0; i < N; i++) {
        REAL s2 = 0;
        for (int64_t c = 0; c < d; c++) s2 += vs[c * S + i] * vs[c * S + i];
        REAL speed = SQRT(s2);
        for (int64_t c = 0; c < d; c++) {
            hsum[c] += speed > 0 ? vs[c * S + i] / speed : 0;
            centre[c] += xs[c * S + i];
            REAL ax = FABS(xs[c * S + i]);
            scale = ax > scale ? ax : scale;
        }
    }
    REAL pol2 = 0;
    for (int64_t c = 0; c < d; c++) {
        pol2 += hsum[c] * hsum[c];
        centre[c] = centre[c] / Nr;
    }
    REAL polarization = SQRT(pol2) / Nr;
    polarization = polarization > 1 ? 1 : polarization;
    const REAL tol = centre_tol * scale;
    REAL cross[3] = {0, 0, 0}, radius_sum = 0;
    for (int64_t i = 0; i < N; i++) {
        REAL rel[3] = {0, 0, 0}, h[3] = {0, 0, 0}, r2 = 0, s2 = 0;
        for (int64_t c = 0; c < d; c++) {
            rel[c] = xs[c * S + i] - centre[c];
            r2 += rel[c] * rel[c];
            s2 += vs[c * S + i] * vs[c * S + i];
        }
        REAL radius = SQRT(r2), speed = SQRT(s2);
        radius_sum += radius;
        for (int64_t c = 0; c < d; c++) {
            h[c] = speed > 0 ? vs[c * S + i] / speed : 0;
            rel[c] = radius > tol ? rel[c] / radius : 0;
        }
        if (d == 2) {
            cross[2] += rel[0] * h[1] - rel[1] * h[0];
        } else {
            cross[0] += rel[1] * h[2] - rel[2] * h[1];
            cross[1] += rel[2] * h[0] - rel[0] * h[2];
            cross[2] += rel[0] * h[1] - rel[1] * h[0];
        }
    }
    REAL turn = d == 2 ? FABS(cross[2])
                       : SQRT(cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]);
    REAL angular = turn / Nr;
    angular = angular > 1 ? 1 : angular;
    REAL cd2 = 0;
    for (int64_t c = 0; c < d; c++) cd2 += (centre[c] - g[c]) * (centre[c] - g[c]);
    int64_t arrived_count = 0;
    REAL gd_sum = 0;
    for (int64_t i = 0; i < N; i++) {
        arrived_count += gd[i] <= goal_radius;
        gd_sum += gd[i];
    }
    const REAL arrived = (REAL)arrived_count / Nr;
    const REAL success = arrived_count >= need ? 1 : 0;
    const REAL mean_goal_distance = gd_sum / Nr;
    REAL effort = 0;
    for (int64_t t = 0; t < N * d; t++) effort += a[b * N * d + t] * a[b * N * d + t];
    const REAL reward = (REAL)dp[DP_W_PROGRESS] * (prev_distance[b] - mean_goal_distance) /
                            start_distance[b] +
                        (REAL)dp[DP_W_ARRIVAL] * (arrived - prev_arrived[b]) +
                        (REAL)dp[DP_W_SUCCESS] * success -
                        (REAL)dp[DP_W_COLLISION] * collisions / Nr -
                        (REAL)dp[DP_W_EFFORT] * effort / Nr - (REAL)dp[DP_W_TIME];

    REAL *pk = packed + b * N_PACKED;
    pk[0] = polarization;
    pk[1] = angular;
    pk[2] = radius_sum / Nr;
    pk[3] = nnd;
    pk[4] = phi;
    pk[5] = arrived;
    pk[6] = collisions;
    pk[7] = SQRT(cd2);
    pk[8] = mean_goal_distance;
    pk[9] = success;
    pk[10] = reward;
    mean_dist_out[b] = mean_goal_distance;
    arrived_out[b] = arrived;
    for (int64_t c = 0; c < d; c++)
        for (int64_t i = 0; i < N; i++) {
            x_out[(c * B + b) * N + i] = xs[c * S + i];
            v_out[(c * B + b) * N + i] = vs[c * S + i];
            f_out[(c * B + b) * N + i] = fs[c * S + i];
        }
}

/* Swarms [b0, b1), spread over the OpenMP threads (torch's own pool when torch is
 * loaded: its libgomp.so.1 is the one this library links to). Every swarm is stepped by
 * one thread in the same way, so the results do not depend on the thread count.
 * Returns 0, 1 if scratch memory could not be allocated, 2 if k_sort > KMAX_SORT. */
int FUSED_STEP(const int64_t *ip, const double *dp, int64_t b0, int64_t b1, const REAL *x,
               const REAL *v, const REAL *f, const REAL *goal, const REAL *a,
               const uint8_t *move, const REAL *prev_distance, const REAL *prev_arrived,
               const REAL *start_distance, REAL *x_out, REAL *v_out, REAL *f_out, float *obs,
               REAL *packed, REAL *mean_dist, REAL *arrived) {
    const int64_t N = ip[IP_N], d = ip[IP_D], k_sort = ip[IP_K_SORT];
    const int64_t NP = (N + LANES - 1) / LANES * LANES;
    if (k_sort > KMAX_SORT) return 2;
    const size_t n_real = (size_t)(4 * d * NP + N + N * NP + 2 * k_sort * N);
    int status = 0;
#pragma omp parallel if (b1 - b0 > 1) reduction(| : status)
    {
        REAL *scratch = (REAL *)malloc(n_real * sizeof(REAL) + 64);
        /* d as a constant in each copy: the loops over components unroll. Every thread
         * reaches the loop (it ends in a barrier), with or without its scratch. */
        if (d == 2) {
#pragma omp for schedule(static)
            for (int64_t b = b0; b < b1; b++) {
                if (!scratch) { status |= 1; continue; }
                FUSED_SWARM(ip, dp, 2, b, scratch, x, v, f, goal, a, move, prev_distance,
                            prev_arrived, start_distance, x_out, v_out, f_out, obs, packed,
                            mean_dist, arrived);
            }
        } else {
#pragma omp for schedule(static)
            for (int64_t b = b0; b < b1; b++) {
                if (!scratch) { status |= 1; continue; }
                FUSED_SWARM(ip, dp, 3, b, scratch, x, v, f, goal, a, move, prev_distance,
                            prev_arrived, start_distance, x_out, v_out, f_out, obs, packed,
                            mean_dist, arrived);
            }
        }
        free(scratch);
    }
    return status;
}
