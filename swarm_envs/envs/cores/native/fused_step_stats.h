/* The statistics of one swarm, for fused_step_body.h: included once per floating type
 * (REAL, INDEX, SQRT, FABS and the function name SWARM_STATS), with the agents' flags
 * AG_* of the generated header step_params.h.
 *
 * The group statistics of swarm_envs.envs.task.statistics and swarm_envs.metrics
 * (docs/models.md §2) over the swarm's members: every agent where agents have no
 * statuses (masked = 0), else the mobile ones (masked = 1, Frame.members, metrics'
 * members=). Each is a sum over the members divided by their count n (no member: NaN,
 * and success 0, as the shared definitions give):
 *
 *   polarization       |Σ v̂_i| / n, at most 1        (v̂ = v/|v|, 0 at rest)
 *   angular_momentum   |Σ r̂_ic × v̂_i| / n, at most 1 (r_ic = r_i − r_c, r_c the
 *                      members' centroid; r̂ 0 within the centring tolerance, which
 *                      scales with the largest coordinate of every agent, as
 *                      metrics._unit_relative's)
 *   expanse            Σ |r_ic| / n
 *   nearest_neighbor_distance  Σ ρ_i / n (ρ_i the nearest present other's distance;
 *                      0 where there is none, and for n = 1)
 *   fraction_arrived   #{|r_g − r_i| ≤ arrival_radius} / n
 *   centroid_distance  |r_c − r_g|
 *   mean_goal_distance Σ |r_g − r_i| / n
 *   goal_angular_momentum  |Σ (r_i − r_g) × v_i| / n
 *   mill_speed         |Σ w_i (r_i − r_g) × v_i| / n, w_i = 1/|r_i − r_g| within the
 *                      arrival radius (and off the goal), else 0
 *   success            fraction_arrived ≥ success_threshold (success_count's rule,
 *                      evaluated in double as Python evaluates it)
 *
 * Headings and unit offsets are quotients whose divisor is replaced by 1 where they are
 * 0, so that the loops vectorise; the angular momenta about the goal are summed from the
 * offsets r_g − r_i (the sign goes in the norm). masked is a constant at each call: the
 * masks fold away where agents have no statuses. */
static inline __attribute__((always_inline)) void SWARM_STATS(
    const int masked, const int64_t N, const int64_t d, const int64_t S, const REAL *xs,
    const REAL *vs, const REAL *off, const REAL *gd, const REAL *near_d, const INDEX *alive,
    const REAL *g, const REAL centre_tol, const REAL goal_radius, const double threshold,
    REAL *pk) {
    const REAL *x0 = xs, *x1 = xs + S, *x2 = xs + 2 * S;
    const REAL *v0 = vs, *v1 = vs + S, *v2 = vs + 2 * S;
    REAL members = 0, hs0 = 0, hs1 = 0, hs2 = 0, cs0 = 0, cs1 = 0, cs2 = 0, scale = 0;
#pragma omp simd reduction(+ : members, hs0, hs1, hs2, cs0, cs1, cs2) reduction(max : scale)
    for (int64_t i = 0; i < N; i++) {
        const int member = !masked || (alive[i] & AG_MOBILE);
        const REAL vz = d == 3 ? v2[i] : 0, xz = d == 3 ? x2[i] : 0;
        const REAL speed = SQRT(v0[i] * v0[i] + v1[i] * v1[i] + vz * vz);
        const int moves = speed > 0;
        const REAL den = moves ? speed : 1;
        hs0 += member ? (moves ? v0[i] : 0) / den : 0;
        hs1 += member ? (moves ? v1[i] : 0) / den : 0;
        if (d == 3) hs2 += member ? (moves ? vz : 0) / den : 0; /* else +0 */
        cs0 += member ? x0[i] : 0;
        cs1 += member ? x1[i] : 0;
        cs2 += member ? xz : 0;
        members += member ? 1 : 0;
        REAL ax = FABS(x0[i]) > FABS(x1[i]) ? FABS(x0[i]) : FABS(x1[i]);
        ax = FABS(xz) > ax ? FABS(xz) : ax;
        scale = ax > scale ? ax : scale;
    }
    const REAL n = masked ? members : (REAL)N;
    const REAL centre[3] = {cs0 / n, cs1 / n, cs2 / n};
    REAL polarization = SQRT(hs0 * hs0 + hs1 * hs1 + hs2 * hs2) / n;
    polarization = polarization > 1 ? 1 : polarization;
    const REAL tol = centre_tol * scale;
    REAL cross0 = 0, cross1 = 0, cross2 = 0, radius_sum = 0, gd_sum = 0, near_sum = 0;
    REAL arrived_count = 0, am0 = 0, am1 = 0, am2 = 0, ms0 = 0, ms1 = 0, ms2 = 0;
#pragma omp simd reduction(+ : cross0, cross1, cross2, radius_sum, gd_sum, near_sum,       \
                               arrived_count, am0, am1, am2, ms0, ms1, ms2)
    for (int64_t i = 0; i < N; i++) {
        const int member = !masked || (alive[i] & AG_MOBILE);
        const REAL vz = d == 3 ? v2[i] : 0;
        const REAL r0 = x0[i] - centre[0], r1 = x1[i] - centre[1];
        const REAL r2 = d == 3 ? x2[i] - centre[2] : 0;
        const REAL radius = SQRT(r0 * r0 + r1 * r1 + r2 * r2);
        const REAL speed = SQRT(v0[i] * v0[i] + v1[i] * v1[i] + vz * vz);
        radius_sum += member ? radius : 0;
        const int moves = speed > 0, off_centre = member & (radius > tol);
        const REAL sden = moves ? speed : 1, rden = off_centre ? radius : 1;
        const REAL h0 = (moves ? v0[i] : 0) / sden, h1 = (moves ? v1[i] : 0) / sden;
        const REAL h2 = (moves ? vz : 0) / sden;
        const REAL e0 = (off_centre ? r0 : 0) / rden, e1 = (off_centre ? r1 : 0) / rden;
        const REAL e2 = (off_centre ? r2 : 0) / rden;
        cross2 += e0 * h1 - e1 * h0;
        if (d == 3) {
            cross0 += e1 * h2 - e2 * h1;
            cross1 += e2 * h0 - e0 * h2;
        }
        REAL nearest = N > 1 ? near_d[i] : 0;
        if (masked) nearest = nearest - nearest == 0 ? nearest : 0; /* none present (inf) */
        near_sum += member ? nearest : 0;
        const REAL dist = gd[i];
        const int arrived = member & (dist <= goal_radius), inside = arrived & (dist > 0);
        gd_sum += member ? dist : 0;
        arrived_count += arrived ? 1 : 0;
        const REAL w = (inside ? 1 : 0) / (inside ? dist : 1);
        const REAL o0 = off[i], o1 = off[S + i], o2 = d == 3 ? off[2 * S + i] : 0;
        const REAL z = o0 * v1[i] - o1 * v0[i];
        am2 += member ? z : 0;
        ms2 += member ? w * z : 0;
        if (d == 3) {
            const REAL cx = o1 * vz - o2 * v1[i], cy = o2 * v0[i] - o0 * vz;
            am0 += member ? cx : 0;
            am1 += member ? cy : 0;
            ms0 += member ? w * cx : 0;
            ms1 += member ? w * cy : 0;
        }
    }
    const REAL turn =
        d == 2 ? FABS(cross2) : SQRT(cross0 * cross0 + cross1 * cross1 + cross2 * cross2);
    REAL angular = turn / n;
    angular = angular > 1 ? 1 : angular;
    REAL cd2 = 0;
    for (int64_t c = 0; c < d; c++) cd2 += (centre[c] - g[c]) * (centre[c] - g[c]);
    const REAL goal_turn = d == 2 ? FABS(am2) : SQRT(am0 * am0 + am1 * am1 + am2 * am2);
    const REAL mill_turn = d == 2 ? FABS(ms2) : SQRT(ms0 * ms0 + ms1 * ms1 + ms2 * ms2);
    pk[PK_polarization] = polarization;
    pk[PK_angular_momentum] = angular;
    pk[PK_expanse] = radius_sum / n;
    pk[PK_nearest_neighbor_distance] = near_sum / n;
    pk[PK_fraction_arrived] = arrived_count / n;
    pk[PK_centroid_distance] = SQRT(cd2);
    pk[PK_mean_goal_distance] = gd_sum / n;
    pk[PK_goal_angular_momentum] = goal_turn / n;
    pk[PK_mill_speed] = mill_turn / n;
    /* the counts are exact in REAL: their quotient in double is Python's c / n */
    pk[PK_success] = (double)arrived_count / (double)n >= threshold ? 1 : 0;
}
