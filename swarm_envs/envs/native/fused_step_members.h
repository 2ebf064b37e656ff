/* The statistics of a swarm whose agents have statuses, for fused_step_body.h: included
 * once per floating type (REAL, INDEX, SQRT, FABS and the function name MEMBER_STATS),
 * with the agents' flags AG_* of fused_step.c. */

/* The group statistics of the swarm's members, the mobile agents, where agents have
 * statuses (swarm_envs.envs.task.statistics with Frame.members, swarm_envs.metrics with
 * members=): headings, centroid, expanse, nearest-neighbour distance, goal distances,
 * arrivals and angular momenta about the goal (off: the offsets r_g − r_i) summed over
 * the members and divided by their count (no member: NaN, and success 0, as the shared
 * definitions give). The centring tolerance scales with the largest coordinate of every
 * agent, as metrics._unit_relative's; an agent's nearest distance is 0 where it has no
 * present other (inf). */
static inline void MEMBER_STATS(const int64_t N, const int64_t d, const int64_t S,
                                const REAL *xs, const REAL *vs, const REAL *off,
                                const REAL *gd, const REAL *near_d, const INDEX *alive,
                                const REAL *g, const REAL centre_tol, const REAL goal_radius,
                                const REAL threshold, REAL *pk) {
    const REAL *x0 = xs, *x1 = xs + S, *x2 = xs + 2 * S;
    const REAL *v0 = vs, *v1 = vs + S, *v2 = vs + 2 * S;
    REAL count = 0, hs0 = 0, hs1 = 0, hs2 = 0, cs0 = 0, cs1 = 0, cs2 = 0, scale = 0;
#pragma omp simd reduction(+ : count, hs0, hs1, hs2, cs0, cs1, cs2) reduction(max : scale)
    for (int64_t i = 0; i < N; i++) {
        const REAL w = alive[i] & AG_MOBILE ? 1 : 0;
        const REAL vz = d == 3 ? v2[i] : 0, xz = d == 3 ? x2[i] : 0;
        const REAL speed = SQRT(v0[i] * v0[i] + v1[i] * v1[i] + vz * vz);
        const int moves = speed > 0;
        const REAL den = moves ? speed : 1;
        hs0 += (moves ? v0[i] : 0) / den * w;
        hs1 += (moves ? v1[i] : 0) / den * w;
        hs2 += (moves ? vz : 0) / den * w;
        cs0 += x0[i] * w;
        cs1 += x1[i] * w;
        cs2 += xz * w;
        count += w;
        REAL ax = FABS(x0[i]) > FABS(x1[i]) ? FABS(x0[i]) : FABS(x1[i]);
        ax = FABS(xz) > ax ? FABS(xz) : ax;
        scale = ax > scale ? ax : scale;
    }
    const REAL centre[3] = {cs0 / count, cs1 / count, cs2 / count};
    const REAL m0 = hs0 / count, m1 = hs1 / count, m2 = hs2 / count;
    REAL polarization = SQRT(m0 * m0 + m1 * m1 + m2 * m2);
    polarization = polarization > 1 ? 1 : polarization;
    const REAL tol = centre_tol * scale;
    REAL cross0 = 0, cross1 = 0, cross2 = 0, radius_sum = 0, gd_sum = 0, near_sum = 0;
    REAL arrived_count = 0, am0 = 0, am1 = 0, am2 = 0, ms0 = 0, ms1 = 0, ms2 = 0;
#pragma omp simd reduction(+ : cross0, cross1, cross2, radius_sum, gd_sum, near_sum,       \
                               arrived_count, am0, am1, am2, ms0, ms1, ms2)
    for (int64_t i = 0; i < N; i++) {
        const int member = (alive[i] & AG_MOBILE) != 0;
        const REAL w = member ? 1 : 0;
        const REAL vz = d == 3 ? v2[i] : 0;
        const REAL r0 = x0[i] - centre[0], r1 = x1[i] - centre[1];
        const REAL r2 = d == 3 ? x2[i] - centre[2] : 0;
        const REAL radius = SQRT(r0 * r0 + r1 * r1 + r2 * r2);
        const REAL speed = SQRT(v0[i] * v0[i] + v1[i] * v1[i] + vz * vz);
        radius_sum += member ? radius : 0;
        const int moves = speed > 0, off_centre = radius > tol;
        const REAL sden = moves ? speed : 1, rden = off_centre ? radius : 1;
        const REAL h0 = (moves ? v0[i] : 0) / sden, h1 = (moves ? v1[i] : 0) / sden;
        const REAL h2 = (moves ? vz : 0) / sden;
        const REAL e0 = (off_centre ? r0 : 0) / rden * w, e1 = (off_centre ? r1 : 0) / rden * w;
        const REAL e2 = (off_centre ? r2 : 0) / rden * w;
        cross2 += e0 * h1 - e1 * h0;
        if (d == 3) {
            cross0 += e1 * h2 - e2 * h1;
            cross1 += e2 * h0 - e0 * h2;
        }
        REAL nearest = N > 1 ? near_d[i] : 0;
        nearest = nearest - nearest == 0 ? nearest : 0; /* none present (inf): 0 */
        near_sum += member ? nearest : 0;
        const REAL dist = gd[i];
        const int arrived = member & (dist <= goal_radius), inside = arrived & (dist > 0);
        gd_sum += member ? dist : 0;
        arrived_count += arrived ? 1 : 0;
        /* the angular momenta about the goal (fused_step_body.h), of the members */
        const REAL wm = (inside ? 1 : 0) / (inside ? dist : 1);
        const REAL o0 = off[i], o1 = off[S + i], o2 = d == 3 ? off[2 * S + i] : 0;
        const REAL z = o0 * v1[i] - o1 * v0[i];
        am2 += member ? z : 0;
        ms2 += inside ? wm * z : 0;
        if (d == 3) {
            const REAL cx = o1 * vz - o2 * v1[i], cy = o2 * v0[i] - o0 * vz;
            am0 += member ? cx : 0;
            am1 += member ? cy : 0;
            ms0 += inside ? wm * cx : 0;
            ms1 += inside ? wm * cy : 0;
        }
    }
    const REAL turn =
        d == 2 ? FABS(cross2) : SQRT(cross0 * cross0 + cross1 * cross1 + cross2 * cross2);
    REAL angular = turn / count;
    angular = angular > 1 ? 1 : angular;
    REAL cd2 = 0;
    for (int64_t c = 0; c < d; c++) cd2 += (centre[c] - g[c]) * (centre[c] - g[c]);
    const REAL arrived = arrived_count / count;
    pk[PK_polarization] = polarization;
    pk[PK_angular_momentum] = angular;
    pk[PK_expanse] = radius_sum / count;
    pk[PK_nearest_neighbor_distance] = near_sum / count;
    pk[PK_fraction_arrived] = arrived;
    pk[PK_centroid_distance] = SQRT(cd2);
    pk[PK_mean_goal_distance] = gd_sum / count;
    pk[PK_goal_angular_momentum] =
        (d == 2 ? FABS(am2) : SQRT(am0 * am0 + am1 * am1 + am2 * am2)) / count;
    pk[PK_mill_speed] = (d == 2 ? FABS(ms2) : SQRT(ms0 * ms0 + ms1 * ms1 + ms2 * ms2)) / count;
    pk[PK_success] = arrived >= threshold ? 1 : 0;
}
