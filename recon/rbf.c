/* rbf: metric, canonical frame, positive-definite kernels and quadrature of the reconstruction. */
#include "recon/rbf.h"

#include <math.h>
#include <string.h>

/* Haversine hav(x) = sin²(x/2). */
static double rbf_hav(double x)
{
	double s = sin(0.5 * x);
	return s * s;
}

double rbf_gc_dist(double th1, double ph1, double th2, double ph2)
{
	double h = rbf_hav(th1 - th2) + sin(th1) * sin(th2) * rbf_hav(ph1 - ph2);
	if (!(h > 0)) /* also catches NaN: distance 0 */
		h = 0;
	if (h > 1)
		h = 1;
	return 2.0 * asin(sqrt(h));
}

double rbf_prod_dist(const double a[4], const double b[4])
{
	double di = rbf_gc_dist(a[0], a[1], b[0], b[1]);
	double dout = rbf_gc_dist(a[2], a[3], b[2], b[3]);
	return sqrt(di * di + dout * dout);
}

double rbf_rec_dist(const double a[4], const double b[4])
{
	double sb[4] = { b[2], b[3], b[0], b[1] };
	double d1 = rbf_prod_dist(a, b), d2 = rbf_prod_dist(a, sb);
	return d1 < d2 ? d1 : d2;
}

/*
 * The canonical frame.
 *
 * An isotropic BRDF depends on (θi, θo, Δ) with Δ = |φo − φi| folded into [0, π] (rotation about the
 * normal, mirror φ → −φ). We pick one representative of each orbit as a point of S²₊ × S²₊:
 *
 *     ωi at azimuth  αi = −Δ · sinθo / (sinθi + sinθo),   ωo at azimuth αo = +Δ · sinθi / (sinθi + sinθo)
 *
 * (αo − αi = Δ, so it is a rotation of the input). Two reasons for this weighting rather than "φi = 0":
 *  1. At normal incidence (θi = 0) ωo lands at azimuth 0 whatever Δ is, so the map is continuous at the
 *     poles, where Δ has no meaning (with φi = 0 the same physical configuration would get many images).
 *  2. Applying the same formula to the reciprocal configuration (θo, θi, Δ) gives τ(c(x)) with
 *     τ = (swap the two vectors, then mirror y → −y), an isometry of the product of great-circle (or
 *     chordal) distances. With "φi = 0" the swap is not an isometry, and symmetrising would not give
 *     reciprocity.
 * Queries are evaluated in the representative with θi ≤ θo, so f(ωi, ωo) and f(ωo, ωi) go through
 * the very same arithmetic: reciprocity holds bit for bit, not only to rounding.
 */
void rbf_canon(double ti, double pi, double to, double po, double out[6])
{
	if (ti > to) {
		double t = ti;
		ti = to;
		to = t;
	}
	/* Δ = |φo − φi| wrapped to [0, π] (mirror fold). remainder() is exact and odd, so swapping the two
	 * azimuths gives the same bits. */
	double d = fabs(remainder(po - pi, 2.0 * M_PI));
	if (d > M_PI)
		d = M_PI;
	double si = sin(ti), so = sin(to), s = si + so;
	double ai = 0, ao = 0;
	if (s > 0) {
		ai = -d * so / s;
		ao = d * si / s;
	}
	out[0] = si * cos(ai);
	out[1] = si * sin(ai);
	out[2] = cos(ti);
	out[3] = so * cos(ao);
	out[4] = so * sin(ao);
	out[5] = cos(to);
}

void rbf_tau(const double in[6], double out[6])
{
	double t[6] = { in[3], -in[4], in[5], in[0], -in[1], in[2] };
	memcpy(out, t, sizeof t);
}

/* Chordal distance |u − v| of two unit vectors, from differences (no cancellation near 0). */
static inline double chord(const double *u, const double *v)
{
	double x = u[0] - v[0], y = u[1] - v[1], z = u[2] - v[2];
	return sqrt(x * x + y * y + z * z);
}

/* Great-circle distance from the chord: d = 2 asin(r/2), the haversine form of Eq. 2. */
static inline double gc_from_chord(double r)
{
	double h = 0.5 * r;
	return 2.0 * asin(h < 1.0 ? h : 1.0);
}

/* Wendland ψ_{3,1}(t) = (1 − t)⁴₊ (4t + 1): C², positive definite on R³ (Wendland 1995). */
static inline double wendland(double t)
{
	if (t >= 1.0)
		return 0.0;
	double u = 1.0 - t, u2 = u * u;
	return u2 * u2 * (4.0 * t + 1.0);
}

/*
 * Positive definiteness of the default kernels (why Cholesky cannot fail on distinct points).
 *
 * 1. A radial function PD on R³ composed with the chordal distance |ω − ω'| is PD on S² ⊂ R³ (restriction
 *    of a PD kernel to a subset). Wendland ψ_{3,1} and the Gaussian are strictly PD on R³; the chordal
 *    distance is 2 sin(d/2), a monotone function of the great-circle distance d, so these are functions of
 *    the great-circle distance. exp(−d/c) of the great-circle distance itself is strictly PD on S² for
 *    every c > 0 (Gneiting 2013, "Strictly and non-strictly positive definite functions on spheres").
 * 2. k(a, b) = k1(ωi, ωi') · k1(ωo, ωo') is PD on S² × S² (Schur/tensor product of PD kernels; strictly PD
 *    on distinct pairs when both factors are).
 * 3. τ is an involution with k(τa, τb) = k(a, b) (τ mirrors both vectors, an isometry of each factor, and
 *    swaps them; the two factors use the same function). Hence
 *        K(a, b) = k(a, b) + k(a, τb) = ½ Σ_{g,h ∈ {e,τ}} k(ga, hb)
 *    is PD (group averaging: it is the Gram kernel of the features φ(a) + φ(τa)), and K(τa, b) = K(a, b):
 *    every interpolant is reciprocal exactly.
 * 4. The canonical map c of the isotropy group is applied before k: K(c(x), c(y)) is a pull-back of a PD
 *    kernel, PD on any set of samples whose orbits {c(x), τc(x)} are distinct. Coincident orbits (repeated or
 *    reciprocal samples) are merged before fitting, and a smoothing term (K + Λ) keeps the rest well-posed.
 * The paper's construction, a Gaussian of d_Rec = min(d_Ω(a,b), d_Ω(a,τb)), has none of these guarantees:
 * the Gaussian of a geodesic distance is not PD on the sphere, nor is a function of a min. It is kept as an
 * option; when its matrix is not PD the fit reports it.
 */
double rbf_kernel(int kernel, double shape, const double a[6], const double b[6], const double tb[6])
{
	double r1 = chord(a, b), r2 = chord(a + 3, b + 3);
	double t1 = chord(a, tb), t2 = chord(a + 3, tb + 3);
	double inv = 1.0 / shape;
	switch (kernel) {
	case RBF_K_WENDLAND:
		return wendland(r1 * inv) * wendland(r2 * inv) + wendland(t1 * inv) * wendland(t2 * inv);
	case RBF_K_EXP:
		return exp(-(gc_from_chord(r1) + gc_from_chord(r2)) * inv) +
		       exp(-(gc_from_chord(t1) + gc_from_chord(t2)) * inv);
	case RBF_K_GAUSS:
		return exp(-(r1 * r1 + r2 * r2) * inv * inv) + exp(-(t1 * t1 + t2 * t2) * inv * inv);
	case RBF_K_PAPER: {
		double d1 = gc_from_chord(r1), d2 = gc_from_chord(r2);
		double e1 = gc_from_chord(t1), e2 = gc_from_chord(t2);
		double da = d1 * d1 + d2 * d2, db = e1 * e1 + e2 * e2;
		double dm = da < db ? da : db; /* d_Rec² */
		return exp(-dm * inv * inv);
	}
	default:
		return 0.0;
	}
}

void rbf_kmatrix(int kernel, double shape, size_t m, const double *q, size_t n, const double *ctr,
		 const double *tctr, double *K)
{
	for (size_t i = 0; i < m; i++)
		for (size_t j = 0; j < n; j++)
			K[i * n + j] = rbf_kernel(kernel, shape, q + 6 * i, ctr + 6 * j, tctr + 6 * j);
}

void rbf_soa(size_t n, const double *ctr, double *soa)
{
	for (size_t j = 0; j < n; j++)
		for (int c = 0; c < 6; c++)
			soa[(size_t)c * n + j] = ctr[6 * j + c];
}

/* Branch-free Wendland for the vector loop: identical values to wendland() (0 beyond the support). */
static inline __attribute__((always_inline)) double wendland_bf(double t)
{
	t = t < 1.0 ? t : 1.0;
	double u = 1.0 - t, u2 = u * u;
	return u2 * u2 * (4.0 * t + 1.0);
}

/*
 * The hot loop of every evaluation (MERL cells, render pixels, quadrature nodes): centres in structure-of-
 * arrays form, the τ image read from the same arrays (τ(ci, co) = (mirror co, mirror ci)), no branches, so
 * the compiler vectorises it (recon/module.mk builds this file with -O3 -fno-math-errno -fno-trapping-math;
 * an AVX2 copy is chosen at run time where the CPU has it). The arithmetic is
 * the same, in the same order, as chord() in rbf_kernel, so both paths give the same bits.
 */
/*
 * One Wendland row for both precisions (written once: T the element type, SQRT its square root, W its
 * branch-free Wendland). In double it is chord()'s arithmetic in chord()'s order (q1 + oy is q1 - (-oy),
 * exactly), so both paths give the same bits; the casts are then no-ops.
 */
#define KROW_WENDLAND_ROW(T, SQRT, W)                                                                        \
	do {                                                                                                 \
		const T *restrict cx = soa, *restrict cy = soa + n, *restrict cz = soa + 2 * n,              \
			*restrict ox = soa + 3 * n, *restrict oy = soa + 4 * n, *restrict oz = soa + 5 * n;  \
		T *restrict krow = krow_;                                                                    \
		const T q0 = (T)q[0], q1 = (T)q[1], q2 = (T)q[2], q3 = (T)q[3], q4 = (T)q[4], q5 = (T)q[5],  \
			inv = (T)(1.0 / shape);                                                              \
		for (size_t j = 0; j < n; j++) {                                                             \
			T a = q0 - cx[j], b = q1 - cy[j], c = q2 - cz[j];                                    \
			T r1 = SQRT(a * a + b * b + c * c);                                                  \
			T d = q3 - ox[j], e = q4 - oy[j], f = q5 - oz[j];                                    \
			T r2 = SQRT(d * d + e * e + f * f);                                                  \
			T g = q0 - ox[j], h = q1 + oy[j], i = q2 - oz[j];                                    \
			T t1 = SQRT(g * g + h * h + i * i);                                                  \
			T k = q3 - cx[j], l = q4 + cy[j], o = q5 - cz[j];                                    \
			T t2 = SQRT(k * k + l * l + o * o);                                                  \
			krow[j] = W(r1 * inv) * W(r2 * inv) + W(t1 * inv) * W(t2 * inv);                     \
		}                                                                                            \
	} while (0)

/* The Wendland row, inlined into a baseline and an AVX2 copy (chosen at run time by rbf_krow). */
static inline __attribute__((always_inline)) void krow_wendland(double shape, const double q[6], size_t n,
								const double *soa, double *krow_)
{
	KROW_WENDLAND_ROW(double, sqrt, wendland_bf);
}

/* A row's baseline and AVX2 copies, and NAME_run choosing one at run time (the CPU's answer is cached). */
#if defined(__x86_64__)
#define KROW_CLONES(NAME, T)                                                                                 \
	__attribute__((target("avx2"))) static void NAME##_avx2(double shape, const double q[6], size_t n,   \
								const T *soa, T *krow)                       \
	{                                                                                                    \
		NAME(shape, q, n, soa, krow);                                                                \
	}                                                                                                    \
	static void NAME##_base(double shape, const double q[6], size_t n, const T *soa, T *krow)            \
	{                                                                                                    \
		NAME(shape, q, n, soa, krow);                                                                \
	}                                                                                                    \
	static void NAME##_run(double shape, const double q[6], size_t n, const T *soa, T *krow)             \
	{                                                                                                    \
		if (__builtin_cpu_supports("avx2"))                                                          \
			NAME##_avx2(shape, q, n, soa, krow);                                                 \
		else                                                                                         \
			NAME##_base(shape, q, n, soa, krow);                                                 \
	}
#else
#define KROW_CLONES(NAME, T)                                                                                 \
	static void NAME##_run(double shape, const double q[6], size_t n, const T *soa, T *krow)             \
	{                                                                                                    \
		NAME(shape, q, n, soa, krow);                                                                \
	}
#endif

KROW_CLONES(krow_wendland, double)

/* The same row in single precision (8 lanes with AVX2): for the MERL table's single-precision GEMM, whose
 * error (this row's included) rgbeval measures against the double path before using it. */
static inline __attribute__((always_inline)) float wendland_bf_f(float t)
{
	t = t < 1.0f ? t : 1.0f;
	float u = 1.0f - t, u2 = u * u;
	return u2 * u2 * (4.0f * t + 1.0f);
}

static inline __attribute__((always_inline)) void krow_wendland_f(double shape, const double q[6], size_t n,
								  const float *soa, float *krow_)
{
	KROW_WENDLAND_ROW(float, sqrtf, wendland_bf_f);
}

KROW_CLONES(krow_wendland_f, float)

void rbf_soa_f32(size_t n, const double *ctr, float *soa)
{
	for (size_t j = 0; j < n; j++)
		for (int c = 0; c < 6; c++)
			soa[(size_t)c * n + j] = (float)ctr[6 * j + c];
}

void rbf_kmatrix_wendland_f32(double shape, size_t m, const double *q, size_t n, const float *soa, float *K)
{
	for (size_t i = 0; i < m; i++)
		krow_wendland_f_run(shape, q + 6 * i, n, soa, K + i * n);
}

void rbf_krow(int kernel, double shape, const double q[6], size_t n, const double *soa, double *krow)
{
	if (kernel == RBF_K_WENDLAND) {
		krow_wendland_run(shape, q, n, soa, krow);
		return;
	}
	const double *cx = soa, *cy = soa + n, *cz = soa + 2 * n, *ox = soa + 3 * n, *oy = soa + 4 * n,
		     *oz = soa + 5 * n;
	for (size_t j = 0; j < n; j++) {
		double b[6] = { cx[j], cy[j], cz[j], ox[j], oy[j], oz[j] }, tb[6];
		rbf_tau(b, tb);
		krow[j] = rbf_kernel(kernel, shape, q, b, tb);
	}
}

void rbf_kmatrix_soa(int kernel, double shape, size_t m, const double *q, size_t n, const double *soa, double *K)
{
	for (size_t i = 0; i < m; i++)
		rbf_krow(kernel, shape, q + 6 * i, n, soa, K + i * n);
}

static const char *const kernel_names[RBF_K__COUNT] = { "wendland", "exp", "gauss", "paper" };

const char *rbf_kernel_name(int kernel)
{
	return kernel >= 0 && kernel < RBF_K__COUNT ? kernel_names[kernel] : NULL;
}

int rbf_kernel_from_name(const char *name)
{
	for (int k = 0; k < RBF_K__COUNT; k++)
		if (name && !strcmp(name, kernel_names[k]))
			return k;
	return -1;
}

/* P_n(z) by the three-term recurrence; returns P_n and sets *dp to P_n'(z). */
static double legendre_p(int n, double z, double *dp)
{
	double p1 = 1.0, p2 = 0.0;
	for (int j = 1; j <= n; j++) {
		double p3 = p2;
		p2 = p1;
		p1 = ((2.0 * j - 1.0) * z * p2 - (j - 1.0) * p3) / j;
	}
	*dp = n * (z * p1 - p2) / (z * z - 1.0);
	return p1;
}

/* Gauss-Legendre on [−1, 1] by Newton on P_n (Golub-Welsch not needed at n ≤ 256), mapped to [0, 1]. */
int rbf_gauss_legendre01(int n, double *x, double *w)
{
	if (n < 1 || n > 256)
		return -1;
	for (int i = 0; i < (n + 1) / 2; i++) {
		double z = cos(M_PI * (i + 0.75) / (n + 0.5)), pp = 1.0;
		for (int it = 0; it < 100; it++) {
			double p1 = legendre_p(n, z, &pp);
			double z1 = z;
			z = z1 - p1 / pp;
			if (fabs(z - z1) < 1e-15)
				break;
		}
		/* recompute the derivative at the converged root */
		legendre_p(n, z, &pp);
		double wi = 2.0 / ((1.0 - z * z) * pp * pp);
		x[i] = 0.5 * (1.0 - z);
		x[n - 1 - i] = 0.5 * (1.0 + z);
		w[i] = w[n - 1 - i] = 0.5 * wi;
	}
	return 0;
}
