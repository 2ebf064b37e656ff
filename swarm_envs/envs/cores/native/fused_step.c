/* The fused SwarmNav step of swarm_envs.envs.cores.native, in C (float32 and float64).
 *
 * An execution strategy for the shared definitions of swarm_envs.physics and
 * swarm_envs.envs.task (docs/design.md): the same semi-implicit Euler step with the
 * carried force and stable substep (step-size control, docs/models.md §7), pair law,
 * goal sink, neighbour ranking, observation layout and statistics, laid out for the
 * CPU. The reward is not here: Python combines it from the statistics and the effort
 * this step writes (swarm_envs.envs.task.reward).
 *
 * The parameters arrive in StepParams; the output columns PK_*, the return codes STEP_*,
 * the agents' statuses STATUS_* and their flags AG_* are named in the header
 * step_params.h that swarm_envs/envs/cores/native/contract.py generates from the Python
 * definitions (a copy is committed in include/ for the builds at install). What this
 * kernel implements it declares below (KERNEL_PHYSICS, KERNEL_STATS, KERNEL_OBS_LAYOUTS,
 * KERNEL_STATUSES); Python refuses configs that need more.
 *
 * Compiled with the system C compiler (-O3 -fopenmp ...) at install, in the variants of
 * swarm_envs/envs/cores/native/variants.py (on x86-64: -march=x86-64-v4, x86-64-v3 and
 * none, "portable"), or where none fits at first use by build.py (-march=
 * <SWARM_ENVS_NATIVE_ARCH, default native>, plus $CFLAGS): the loops over pairs are
 * vectorised (float32 with the inlined exp_f32 below; float64 calls glibc's vector exp,
 * libmvec, declared SIMD), and the swarms are spread over OpenMP threads. Called through
 * ctypes. The GCC vector extensions used (vector_size, __builtin_shuffle,
 * __builtin_convertvector) are 64 bytes wide, 32 with AVX2 and without AVX-512 (see
 * LANES), and lower to narrower vectors or scalars where the registers are narrower;
 * AVX-512 gets min/max intrinsics for the k-NN keys and compressed stores for the
 * observations.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef __AVX512F__
#include <immintrin.h>
#endif

#include "step_params.h"

#pragma omp declare simd notinbranch
double exp(double);

/* What this kernel implements (read by swarm_envs.envs.cores.native.contract.KernelInfo). */
#define KERNEL_PHYSICS "C_a C_r l_a l_r C_o l_o beta C_g l_g m alpha"
#define KERNEL_STATS                                                                        \
    "polarization angular_momentum expanse nearest_neighbor_distance energy "              \
    "fraction_arrived collisions centroid_distance mean_goal_distance "                    \
    "goal_angular_momentum mill_speed mill_order success substeps unstable"
/* The observation layouts it writes, one per line: without and with observe_status. */
#define KERNEL_OBS_LAYOUT                                                                   \
    "goal_offset/obs_goal_scale,velocity/obs_velocity_scale;"                              \
    "offset/obs_neighbor_scale,relative_velocity/obs_velocity_scale,mask"
#define KERNEL_OBS_LAYOUTS KERNEL_OBS_LAYOUT "\n" KERNEL_OBS_LAYOUT ",status"
/* The agents' statuses it applies (swarm_envs.envs.task.agent_status.masks): pairs with
 * an agent not present, updates of agents that do not move, statistics over the members
 * (the mobile agents), the observed flag of the active ones. */
#define KERNEL_STATUSES "present mobile members active"

/* The agents' flags of each status (STATUS_FLAGS, AG_*: generated from
 * swarm_envs.envs.task.agent_status.masks), read by fused_step_body.h. */
static const int8_t status_flags[STATUS_COUNT] = STATUS_FLAGS;

/* x86-64 below AVX2 (the portable build) has no fused multiply-add and no vector
 * rounding (SSE4.1): fmaf there is a software routine called value by value, and floorf
 * a call; the step, whose pair loop takes both in exp_f32, was up to 3.4 times slower
 * so. There the product and the sum are rounded apart (the last bits of e^x differ from
 * the other builds'), and floor(t) is the truncation less one where that is above t,
 * exact for |t| < 2^31 (in exp_f32 |t| <= 128). */
#if defined(__x86_64__) && !defined(__FMA__)
#define MUL_ADD_F32(a, b, c) ((a) * (b) + (c))
#else
#define MUL_ADD_F32(a, b, c) fmaf((a), (b), (c))
#endif
#if defined(__x86_64__) && !defined(__SSE4_1__)
static inline float floor_f32(float t) {
    const float n = (float)(int32_t)t;
    return n > t ? n - 1.0f : n;
}
#else
#define floor_f32 floorf
#endif

/* e^x in float32, inlined so that the pair loop vectorises without calls
 * (docs/performance.md, "Inside the C step", says what each choice here saves).
 * Cephes' expf: x = n ln2 + r with |r| <= ln2/2 (ln2 in two parts), e^r by a degree-6
 * polynomial (relative error below 2e-7, about 2 ulp), times 2^n as one exponent field.
 * x is clamped to [-87.28, 88.3] on its bits, by integer mins, and e^x is 0 below
 * -87.28: there it is under 1.3e-38, the subnormal range, which the single factor 2^n
 * (n >= -126) cannot reach. NaN becomes a bound. */
static inline float exp_f32(float x) {
    uint32_t ub; /* the clamp on the bits: an unsigned and a signed integer min */
    memcpy(&ub, &x, sizeof ub);
    const int flush = ub > 0xC2AE8F5Cu;       /* x < -87.28f (a negative float's bits */
    ub = ub < 0xC2AE8F5Cu ? ub : 0xC2AE8F5Cu; /* grow with its magnitude) */
    int32_t sb = (int32_t)ub;
    sb = sb < 0x42B0999A ? sb : 0x42B0999A; /* x <= 88.3f: n <= 127 */
    memcpy(&x, &sb, sizeof x);
    float n = floor_f32(x * 1.44269504088896341f + 0.5f);
    float r = MUL_ADD_F32(n, -0.693359375f, x);
    r = MUL_ADD_F32(n, 2.12194440e-4f, r);
    float p = 1.9875691500e-4f;
    p = MUL_ADD_F32(p, r, 1.3981999507e-3f);
    p = MUL_ADD_F32(p, r, 8.3334519073e-3f);
    p = MUL_ADD_F32(p, r, 4.1665795894e-2f);
    p = MUL_ADD_F32(p, r, 1.6666665459e-1f);
    p = MUL_ADD_F32(p, r, 5.0000001201e-1f);
    float y = MUL_ADD_F32(p, r * r, r) + 1.0f;
    int32_t bits = ((int32_t)n + 127) << 23; /* 2^n, n in [-126, 127] */
    float scale;
    memcpy(&scale, &bits, sizeof scale); /* a bit cast (folded; it vectorises) */
    return flush ? 0.0f : y * scale;
}

/* swarm_envs.physics.integrators.substep_plan for one swarm: the n equal substeps still
 * needed for the time tau >= 0 left of a step whose stable substep is hs (n = 0 where
 * tau = 0, at least 1 where tau > 0, inf where hs = 0), and their length h = tau / n (0
 * where n is 0 or inf). The relative slack of 1e-9 is Python's, so that the counts
 * agree with the numpy core's. */
static inline void substep_plan(double tau, double hs, double *n_out, double *h_out) {
    const double ratio = hs > 0 ? tau / hs : INFINITY;
    double n = tau > 0 ? ceil(ratio * (1.0 - 1e-9)) : 0.0;
    n = tau > 0 ? (n < 1.0 ? 1.0 : n) : 0.0;
    *n_out = n;
    *h_out = n > 0 && n < INFINITY ? tau / n : 0.0;
}

/* An action x clipped to [-1, 1] (x finite). */
#define UNIT_CLIP(x) ((x) < -1 ? (REAL)-1 : (x) > 1 ? (REAL)1 : (x))

#define KMAX_SORT 64

/* exp_f32 over n values, for the tests. */
void fused_exp_f32(const float *x, float *y, int64_t n) {
    for (int64_t t = 0; t < n; t++) y[t] = exp_f32(x[t]);
}

long long fused_step_layout(void) { return STEP_LAYOUT_HASH; }
int fused_step_kmax(void) { return KMAX_SORT; }
const char *fused_step_physics(void) { return KERNEL_PHYSICS; }
const char *fused_step_stats(void) { return KERNEL_STATS; }
const char *fused_step_obs_layouts(void) { return KERNEL_OBS_LAYOUTS; }
const char *fused_step_statuses(void) { return KERNEL_STATUSES; }

#define REAL float
#define ABITS uint32_t /* a REAL's bits, and its exponent's */
#define EXP_MASK 0x7F800000u
#define INDEX int32_t
/* The lanes of a vector: 16 floats (64 bytes), but 8 (one register) with AVX2 and
 * without AVX-512. There the 64-byte vectors would be two registers each: GCC permutes
 * their lanes by run-time indices (the pair pass's rotations) one by one, and their sums
 * do not fit in the registers; the step was up to 3.8 times slower so. The tiles of the pair
 * pass are LANES agents wide, so the order in which a force's terms are summed, and with
 * it the last bits of the results, differs between the x86-64-v3 build and the others. */
#if defined(__AVX512F__) || !defined(__AVX2__)
#define LANES 16
typedef float vreal_f32 __attribute__((vector_size(64)));
typedef int32_t vindex_f32 __attribute__((vector_size(64)));
typedef uint64_t vkey __attribute__((vector_size(64)));
#else
#define LANES 8
typedef float vreal_f32 __attribute__((vector_size(32)));
typedef int32_t vindex_f32 __attribute__((vector_size(32)));
typedef uint64_t vkey __attribute__((vector_size(32)));
#endif
#define VREAL vreal_f32
#define VINDEX vindex_f32
#define EXP exp_f32
#define SQRT sqrtf
#define FLOOR floorf
#define FABS fabsf
#define FUSED_SWARM fused_swarm_f32
#define STABLE_SUBSTEP stable_substep_f32
#define SWARM_STATS swarm_stats_f32
/* The keys of lanes [h LANES/2, (h + 1) LANES/2) of the int32 vectors bits and ci: lane
 * l's bits above its ci, (bits << 32) | ci as 64-bit integers. On a little-endian machine
 * the two words of a key are its lane of ci then its lane of bits: one interleaving
 * shuffle. */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#if LANES == 16
#define KEY_HALF(bits, ci, h)                                                          \
    ((h) ? (vkey)__builtin_shufflevector((ci), (bits), 8, 24, 9, 25, 10, 26, 11, 27, 12, \
                                         28, 13, 29, 14, 30, 15, 31)                    \
         : (vkey)__builtin_shufflevector((ci), (bits), 0, 16, 1, 17, 2, 18, 3, 19, 4,   \
                                         20, 5, 21, 6, 22, 7, 23))
#else
#define KEY_HALF(bits, ci, h)                                                          \
    ((h) ? (vkey)__builtin_shufflevector((ci), (bits), 4, 12, 5, 13, 6, 14, 7, 15)      \
         : (vkey)__builtin_shufflevector((ci), (bits), 0, 8, 1, 9, 2, 10, 3, 11))
#endif
#else
#if LANES == 16
#define KEY_WORDS(v, h)                                                                \
    __builtin_convertvector(                                                           \
        (h) ? __builtin_shufflevector((v), (v), 8, 9, 10, 11, 12, 13, 14, 15)          \
            : __builtin_shufflevector((v), (v), 0, 1, 2, 3, 4, 5, 6, 7),               \
        vkey)
#else
#define KEY_WORDS(v, h)                                                                \
    __builtin_convertvector((h) ? __builtin_shufflevector((v), (v), 4, 5, 6, 7)       \
                                : __builtin_shufflevector((v), (v), 0, 1, 2, 3),       \
                            vkey)
#endif
#define KEY_HALF(bits, ci, h) ((KEY_WORDS(bits, h) << 32) | KEY_WORDS(ci, h))
#endif
#ifdef __AVX512F__
static inline vkey key_min(vkey a, vkey b) { return (vkey)_mm512_min_epu64((__m512i)a, (__m512i)b); }
static inline vkey key_max(vkey a, vkey b) { return (vkey)_mm512_max_epu64((__m512i)a, (__m512i)b); }
#elif defined(__AVX2__)
/* AVX2 compares signed 64-bit integers, not unsigned ones (GCC compares those lane by
 * lane): with their top bits flipped, the keys compare in signed order as they do in
 * unsigned order. */
typedef int64_t vkey_signed __attribute__((vector_size(sizeof(vkey))));
static inline vkey key_lt(vkey a, vkey b) {
    const vkey top = (vkey){0} + ((uint64_t)1 << 63);
    return (vkey)((vkey_signed)(a ^ top) < (vkey_signed)(b ^ top));
}
static inline vkey key_min(vkey a, vkey b) { vkey lt = key_lt(a, b); return (a & lt) | (b & ~lt); }
static inline vkey key_max(vkey a, vkey b) { vkey lt = key_lt(a, b); return (b & lt) | (a & ~lt); }
#else
static inline vkey key_min(vkey a, vkey b) { vkey lt = (vkey)(a < b); return (a & lt) | (b & ~lt); }
static inline vkey key_max(vkey a, vkey b) { vkey lt = (vkey)(a < b); return (b & lt) | (a & ~lt); }
#endif
#define KNN_KEYS 1
#ifdef __AVX512F__
#define OBS_PAIRS_AVX512 1
/* Two 8-float blocks as one 16-lane vector (AVX-512F only). */
#define PAIR8(a, b)                                                                    \
    _mm512_castpd_ps(_mm512_insertf64x4(_mm512_castps_pd(_mm512_castps256_ps512(a)),  \
                                        _mm256_castps_pd(b), 1))
#endif
#define KNN_BLOCK knn_block_f32
#define KNN_ALL knn_all_f32
#define FUSED_STEP fused_step_f32
#include "fused_step_body.h"
#undef REAL
#undef ABITS
#undef EXP_MASK
#undef EXP
#undef SQRT
#undef FLOOR
#undef FABS
#undef FUSED_SWARM
#undef STABLE_SUBSTEP
#undef SWARM_STATS
#undef KNN_BLOCK
#undef KNN_ALL
#undef KNN_KEYS
#undef OBS_PAIRS_AVX512
#undef FUSED_STEP
#undef INDEX
#undef LANES
#undef VREAL
#undef VINDEX

#define REAL double
#define ABITS uint64_t
#define EXP_MASK 0x7FF0000000000000u
#define INDEX int64_t
#if defined(__AVX512F__) || !defined(__AVX2__)
#define LANES 8
typedef double vreal_f64 __attribute__((vector_size(64)));
typedef int64_t vindex_f64 __attribute__((vector_size(64)));
#else
#define LANES 4
typedef double vreal_f64 __attribute__((vector_size(32)));
typedef int64_t vindex_f64 __attribute__((vector_size(32)));
#endif
#define VREAL vreal_f64
#define VINDEX vindex_f64
#define EXP exp
#define SQRT sqrt
#define FLOOR floor
#define FABS fabs
#define FUSED_SWARM fused_swarm_f64
#define STABLE_SUBSTEP stable_substep_f64
#define SWARM_STATS swarm_stats_f64
#define KNN_BLOCK knn_block_f64
#define KNN_ALL knn_all_f64
#define FUSED_STEP fused_step_f64
#include "fused_step_body.h"

/* The step-size rule over arrays, for the tests (against swarm_envs.physics.integrators). */
void fused_stable_substep_f32(const float *omega2, const float *gamma, double *h, int64_t n) {
    for (int64_t t = 0; t < n; t++) h[t] = stable_substep_f32(omega2[t], gamma[t]);
}
void fused_stable_substep_f64(const double *omega2, const double *gamma, double *h, int64_t n) {
    for (int64_t t = 0; t < n; t++) h[t] = stable_substep_f64(omega2[t], gamma[t]);
}
void fused_substep_plan(const double *tau, const double *hs, double *n, double *h, int64_t count) {
    for (int64_t t = 0; t < count; t++) substep_plan(tau[t], hs[t], &n[t], &h[t]);
}
