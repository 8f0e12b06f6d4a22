/* rbf: the metric of S²₊ × S²₊ (paper Eq. 2-3), the isotropic-reciprocal canonical frame, the kernels and
 * the hemisphere quadrature used by the reconstruction. Pure functions, no allocation. Angles in radians. */
#ifndef RECON_RBF_H
#define RECON_RBF_H

#include <stddef.h>

/* Kernel families (see rbf.c for the positive-definiteness argument of each). */
enum rbf_kernel {
	RBF_K_WENDLAND = 0, /* default: symmetrised product of C2 Wendland functions of chordal distance (PD) */
	RBF_K_EXP = 1,      /* symmetrised product of exp(-d/c), d great-circle distance (PD, Gneiting 2013) */
	RBF_K_GAUSS = 2,    /* symmetrised product of Gaussians of chordal distance (PD, ill-conditioned) */
	RBF_K_PAPER = 3,    /* the paper's literal construction: Gaussian of d_Rec (NOT guaranteed PD) */
	RBF_K__COUNT
};

/* Great-circle distance between (th1,ph1) and (th2,ph2), haversine form (paper Eq. 2), in [0, π]. */
double rbf_gc_dist(double th1, double ph1, double th2, double ph2);
/* Product metric d_Ω (paper Eq. 3) between a = (θi,φi,θo,φo) and b. */
double rbf_prod_dist(const double a[4], const double b[4]);
/* Reciprocal metric d_Rec = min(d_Ω(a,b), d_Ω(a,σb)), σ swapping incidence and observation. */
double rbf_rec_dist(const double a[4], const double b[4]);

/* Canonical isotropic-reciprocal frame of (θi,φi,θo,φo): two unit vectors out[0..2] (incidence) and
 * out[3..5] (observation), invariant under rotation about the normal, the mirror φ → −φ and the swap
 * (reciprocity) of the inputs. See rbf.c for the construction. */
void rbf_canon(double ti, double pi, double to, double po, double out[6]);
/* The involution τ of the canonical frame (swap then mirror): the image of a canonical point under σ. */
void rbf_tau(const double in[6], double out[6]);
/* Squared chordal distance of canonical point a from b or its reciprocal image tb = rbf_tau(b), the nearer one. */
static inline double rbf_canon_dist2(const double a[6], const double b[6], const double tb[6])
{
	double d1 = 0, d2 = 0;
	for (int i = 0; i < 6; i++) {
		d1 += (a[i] - b[i]) * (a[i] - b[i]);
		d2 += (a[i] - tb[i]) * (a[i] - tb[i]);
	}
	return d1 < d2 ? d1 : d2;
}

/* Symmetrised kernel K(a,b) = k(a,b) + k(a,τb) (or the paper's Gaussian of d_Rec) on canonical points;
 * tb must be rbf_tau(b). shape > 0 is the kernel's length scale (chordal units, radians for exp/paper). */
double rbf_kernel(int kernel, double shape, const double a[6], const double b[6], const double tb[6]);
/* Kernel matrix K[q*n + j] = rbf_kernel(q-th query, j-th centre) for m queries and n centres (row-major). */
void rbf_kmatrix(int kernel, double shape, size_t m, const double *q, size_t n, const double *ctr,
		 const double *tctr, double *K);
/* Structure-of-arrays copy of n canonical centres for rbf_krow: soa[c*n + j] = ctr[6*j + c]. */
void rbf_soa(size_t n, const double *ctr, double *soa);
/* One kernel row krow[j] = rbf_kernel(q, centre j, τ centre j) from the SoA centres (same bits as
 * rbf_kernel; the Wendland loop is written to vectorise). */
void rbf_krow(int kernel, double shape, const double q[6], size_t n, const double *soa, double *krow);
/* Kernel matrix K[q*n + j] for m queries from SoA centres (rbf_krow per query). */
void rbf_kmatrix_soa(int kernel, double shape, size_t m, const double *q, size_t n, const double *soa,
		     double *K);
/* Single-precision copy of the centres in structure-of-arrays form (6n floats). */
void rbf_soa_f32(size_t n, const double *ctr, float *soa);
/* The Wendland kernel matrix K[i*n + j] in single precision (m queries q[6m] against soa from rbf_soa_f32). */
void rbf_kmatrix_wendland_f32(double shape, size_t m, const double *q, size_t n, const float *soa, float *K);
/* Name of a kernel ("wendland", "exp", "gauss", "paper"), or NULL. */
const char *rbf_kernel_name(int kernel);
/* Kernel from its name, or -1. */
int rbf_kernel_from_name(const char *name);

/* Gauss-Legendre nodes and weights on [0, 1] (n ≤ 256); returns 0, or -1 if n is out of range. */
int rbf_gauss_legendre01(int n, double *x, double *w);

#endif
