/* plan: the sampling planner — plan files, blind zones, collision-safe moves, ordering, time estimates.
 *
 * Conventions. Angles in degrees. A bench configuration is three axis positions (struct plan_pos): the laser
 * zenith θL (incident direction ωi = (θL, laser_phi); a negative θL is the other side, azimuth + 180°), the
 * detector zenith θD and azimuth φD (ωo = (θD, φD)). ψ is the great-circle angle between ωi and ωo.
 * With m = bench_geom.safety_margin_deg, a configuration is blind when
 *   (a) ψ < detector_body + beam + m and detector_radius < laser_radius   (detector arm occludes the beam)
 *   (b) ψ < laser_body + fov + m and laser_radius < detector_radius       (laser arm hides the view)
 *   (c) ψ < laser_body + detector_body + m                                (the arms collide)
 * or when an axis is outside its limits. Motion: every waypoint segment of a planned move stays within the
 * limits and keeps ψ at or above the largest of the applicable half-angles (a), (b), (c) at every instant
 * (usually (c): the arms never cross), with all axes of the segment starting together, each on its own
 * trapezoidal profile (speed, acceleration = deceleration).
 *
 * Times. A move costs the sum of its segments' durations (a segment lasts as long as its slowest axis) plus
 * the largest settling time among the axes that moved; each point then dwells averages × (integration +
 * read-out). The sweep duration is the dwell of every point plus the moves between consecutive points (the
 * sweep starts with the arms at the first point). */
#ifndef PLAN_H
#define PLAN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "config/acq_err.h"
#include "config/bench.h"
#include "config/yconf.h"

enum plan_blind_policy { PLAN_BLIND_DROP, PLAN_BLIND_MOVE };
enum plan_integ_mode { PLAN_INTEG_AUTO, PLAN_INTEG_FIXED };

/* Size limits of a plan (requested points, before blind-zone handling). */
#define PLAN_MAX_POINTS 50000
#define PLAN_MAX_PER_INCIDENCE 5000

/* What an adaptive sweep aims at (plan_adaptive.c): `brdf-recon select --target` and the stop rule. */
enum plan_target_kind {
	PLAN_TARGET_DHR_SIGMA, /* σ of the DHR at the listed incidences ≤ le */
	PLAN_TARGET_LNF_SIGMA, /* largest posterior σ of ln f over the hemisphere pair ≤ le */
	PLAN_TARGET_RGB_SIGMA  /* σ of the MERL table's RGB values (sr⁻¹), RMS under the table's projected measure ≤ le */
};
#define PLAN_MAX_TARGET_INC 8
#define PLAN_MAX_SPEC_RINGS 8   /* rings of candidates around the mirror direction */
#define PLAN_MAX_SEED_SPEC 16   /* in-plane offsets from the mirror direction added to an adaptive seed */

/* The adaptive part of a plan (kind: adaptive): the seed is the plan_spec that holds it; after the seed, batches
 * chosen by `brdf-recon select` among candidate directions until the target or the budget is reached. */
struct plan_adaptive {
	enum plan_target_kind target;
	double target_inc[PLAN_MAX_TARGET_INC]; /* DHR σ: incidences, degrees */
	size_t n_target_inc;
	double le;                  /* the threshold the target's value must reach */
	double le_lnf;              /* > 0: a combined target, the DHR σ ≤ le AND the largest σ of ln f ≤ le_lnf */
	int lnf_weight;             /* lnf_sigma's weight: 0 projected, 1 rad, 2 mix, 3 bright (select's lnf[:rad,:mix,:bright]) */
	double budget_s;            /* bench seconds for the whole sweep, seed included (0: no limit) */
	size_t budget_points;       /* points for the whole sweep, seed included (0: no limit) */
	size_t batch;               /* points per batch */
	double *cand_inc;           /* candidate incidences θL, degrees */
	size_t n_cand_inc;
	size_t cand_count;          /* candidate observation directions per incidence (Fibonacci set) */
	double cand_max_theta_deg;  /* ... over the cap θ ≤ this */
	double cand_lobe_above_deg; /* > 0: candidates of incidence above it only where the model has its lobe (select's
				     * :lobe_above=; the lobe gate); 0: all */
	bool overlap;               /* choose batch k+2 (from the model through batch k) while batch k+1 is measured */
	bool cand_specular;         /* per candidate incidence also the mirror direction and rings around it */
	double spec_rings_deg[PLAN_MAX_SPEC_RINGS]; /* ... the rings' angular radii around it, degrees */
	size_t n_spec_rings;
	size_t spec_per_ring;       /* ... directions per ring */
	double seed_spec_deg[PLAN_MAX_SEED_SPEC];  /* the seed's extra points per incidence: in the specular plane at
						    * these offsets (degrees of θo) from the mirror direction */
	size_t n_seed_spec;
};

/* A parsed plan file (plan_load / plan_parse), or one built by code (arrays malloc'ed; plan_spec_free). */
#define PLAN_SAMPLE_MAX 64
struct plan_spec {
	char name[64];
	char sample[PLAN_SAMPLE_MAX]; /* the sample's name (plan key sample:; "" when not given): identifies the
				       * previous sweep an exposure prior comes from */
	double *incidence;          /* laser zeniths θL, n_incidence of them */
	size_t n_incidence;
	double *obs_theta, *obs_phi; /* grid mode: observation zeniths × azimuths per incidence */
	size_t n_obs_theta, n_obs_phi;
	size_t fib_count;           /* > 0: Fibonacci mode, fib_count near-uniform directions per incidence */
	double fib_max_theta_deg;   /* Fibonacci: the set covers the cap θ ≤ this (default 85) */
	enum plan_integ_mode integ_mode;
	double integ_ms;            /* fixed: the integration time; auto: the estimate used for timing */
	double target_peak;         /* auto: target peak as a fraction of full scale */
	double max_integ_ms;        /* auto: upper bound on the integration time */
	double integ_spread;        /* auto, timing only: longest / shortest time the sample needs at one viewing zenith
				     * (integration.spread; 0: PLAN_AUTO_SPREAD; 1 and fixed θo: every point at the estimate) */
	double integ_hdr;           /* auto, timing only: the fraction of points needing an HDR exposure
				     * (integration.hdr_fraction; < 0: PLAN_AUTO_HDR) */
	int averages;
	size_t reciprocal_pairs;    /* number of reciprocal partners to add (0: none) */
	enum plan_blind_policy blind_policy;
	struct plan_adaptive *adaptive; /* kind: adaptive (the fields above are then its seed plan's); else NULL */
	int survey;                 /* points per incidence measured first (plan key survey:, plan_survey_apply; 0, the
				     * default: none); -1: PLAN_SURVEY_DEFAULT where the exposure prior lacks an incidence */
};

/* One bench configuration: axis positions in degrees. */
struct plan_pos {
	double laser_theta, det_theta, det_phi;
};

/* Why a requested point was dropped or moved (bit set). */
enum plan_reason {
	PLAN_R_BEAM = 1,       /* (a) the detector arm occludes the beam */
	PLAN_R_VIEW = 2,       /* (b) the laser arm hides the detector's view */
	PLAN_R_COLLISION = 4,  /* (c) the arms would collide */
	PLAN_R_LIMITS = 8,     /* an axis limit */
	PLAN_R_UNREACHABLE = 16, /* no collision-free move reaches it (dropped) */
	PLAN_R_NO_NEARBY = 32  /* policy move, but no visible point within the search radius (dropped) */
};

enum plan_status { PLAN_KEPT, PLAN_MOVED, PLAN_DROPPED, PLAN_DUPLICATE };
enum plan_role { PLAN_ROLE_GRID, PLAN_ROLE_RECIPROCAL };

/* A requested point and what became of it. */
struct plan_req {
	struct plan_pos req;        /* as requested (det_phi as written) */
	struct plan_pos pos;        /* where it is measured (moved or kept; det_phi in [0, 360)) */
	enum plan_status status;
	unsigned reason;            /* enum plan_reason bits when dropped or moved */
	double moved_deg;           /* great-circle distance of the move of ωo (status MOVED) */
	enum plan_role role;
	size_t partner;             /* reciprocal role: index of the grid point it mirrors */
	size_t same_as;             /* duplicate: index of the first request of the same configuration */
	double psi_deg;             /* ψ at pos */
};

/* One segment of a move: all axes go from the previous position to pos together. */
struct plan_wp {
	struct plan_pos pos;
	double duration_s;
};

/* One measurement in sweep order: reach pos through wps[first_wp .. first_wp+n_wp) (the last is pos). */
struct plan_step {
	size_t req;                 /* index into plan_result.req */
	struct plan_pos pos;        /* axis positions (det_phi is the chosen axis position, wrap included) */
	size_t first_wp, n_wp;
	double move_s, settle_s, dwell_s;
	double t_start_s;           /* when the move to this point starts (0 for the first) */
	double predicted_start_s;   /* the same in the executor's timeline (plan_time.c): overheads, darks, reference */
	double predicted_s;         /* this step's predicted duration (move to it, its darks and exposures) */
	bool detour;                /* the move is not a single straight segment */
};

struct plan_result {
	struct plan_req *req;
	size_t n_req;
	struct plan_step *steps;
	size_t n_steps;
	struct plan_wp *wps;
	size_t n_wps;
	size_t n_kept, n_moved, n_dropped, n_duplicate; /* kept counts unmoved measured points */
	double duration_s;          /* planned sweep */
	double raster_s;            /* the same points in request order (nested loops), safe moves, no wrap choice */
	double lower_bound_s;       /* no order and no path through these axis positions is faster (see plan.c) */
	double dwell_s, motion_s;   /* the planned duration split into dwell and motion (settle included) */
	double travel_deg[3];       /* planned axis travel: laser θ, detector θ, detector φ */
	size_t n_detours;
	size_t n_groups;            /* distinct incidences */
	double point_dwell_s;       /* averages × (integration + read-out) */
	/* What the sweep will take on the bench (plan_time.c): the ordering model above plus what the executor adds
	 * (controller polling and in-position checks, probe exposures, darks, the reference at the start). */
	double predicted_s;
	double reference_s;         /* of predicted_s: the reference phase and the move from it to the first point */
	double darks_s;             /* of predicted_s: dark spectra */
	double host_s;              /* of predicted_s: the host's time per point (point_overhead_s × time_scale each),
				     * load-dependent at high time scales: reported apart */
	/* predicted_s term by term (plan_time.c; they sum to it): each exposure term holds its shots' integration,
	 * read-out and round trip */
	double t_motion_s;          /* the points' moves (trapezoids), the ordering model's move_s */
	double t_settle_s;          /* their settling, polling for the end and in-position check, extra_settle_s */
	double t_probe_s;           /* auto: the probe exposures (one per point) */
	double t_first_s;           /* each point's first (base) exposure, the plan's averages */
	double t_hdr_s;             /* auto: the further (HDR) exposures */
	/* the survey (plan_survey_apply): steps[0 .. n_survey) are survey_k points of each incidence, then the route */
	size_t n_survey, survey_k;
	double survey_motion_s;     /* the motion (moves and settling) the survey adds to the route's */
};

/* The default integration.spread of auto plans: the range of times the bench chose at one viewing zenith on the
 * simulated green paint, quick plan: 41 to 81.9 ms at θo 60°, 57.9 ms at 30° off the specular plane (14.5 ms in
 * it): 1-4x, 2 typical; see plan_time.c. */
#define PLAN_AUTO_SPREAD 2.0
/* The default integration.hdr_fraction of auto plans: the points that needed a second (HDR) exposure on the
 * simulated green paint (paper plan 76 of 866, quick plan 2 of 15). */
#define PLAN_AUTO_HDR 0.09
/* Auto integration without a prior: the share of points whose probe (at the previous point's time) is one of their
 * first exposure's scans, as their time is the previous point's (executor_acq.c, exp_probe_reusable); measured on
 * the simulated green paint's paper plan (README "How long a sweep takes", session 17, probe: 363 of 866 points,
 * seed 1; its quick plan 3 of 15). */
#define PLAN_PROBE_POOL 0.42

/* An exposure prior: what the auto exposure chose in the previous completed auto sweep of the same sample (the
 * plan's sample: name), per incidence (exp_prior_build, daemon/exposure.c, from the database). With one, the
 * duration model times each point of an incidence with the prior's figures for the nearest incidence instead of the
 * band around the plan's estimate (plan_time.c). */
#define PLAN_PRIOR_MAX_INC 64
struct plan_prior_inc {
	double theta_i;             /* the incidence zenith, degrees (sample frame) */
	size_t points;              /* points done there */
	double median_ms, mean_ms;  /* each point's first exposure: median and mean integration time */
	double log_var;             /* the variance of ln(first exposure) over its points (n - 1 divisor; 0: one point) */
	double spread;              /* longest / shortest first exposure */
	double darks_per_clear;     /* darks taken at the incidence: the distinct times the cache needed */
	double dark_ms;             /* their mean integration time */
	double extra_per_point;     /* further (HDR) exposures per point */
	double extra_ms;            /* their mean integration time */
	uint64_t rungs;             /* the ladder rungs (plan_rung) its sample exposures used: the darks they need */
	double pooled_per_point;    /* points whose first exposure is at the previous point's first time: their probe
				     * was one of its scans (exp_probe_reusable; the exposure took one scan fewer) */
	double pooled_ms;           /* their mean first time (0: none; the scan each spared) */
};
struct plan_prior {
	long long sweep;            /* the sweep it comes from (0: no prior) */
	char sample[PLAN_SAMPLE_MAX];
	size_t points;              /* over all incidences: */
	double median_ms, spread, hdr_fraction; /* median first exposure, longest/shortest, points with an HDR exposure */
	double host_per_point_s;    /* the host's real seconds per point there (exp_prior_build), over host_points points */
	size_t host_points;         /* (0: not measured; point_overhead_s then) */
	size_t n_inc;
	struct plan_prior_inc inc[PLAN_PRIOR_MAX_INC];
};

/* The host's time per point a completed sweep of one plan kind measured (plan_kind_of names the kinds). */
#define PLAN_KIND_MAX 24
#define PLAN_HOST_KINDS 6 /* grid, fibonacci, adaptive × auto, fixed */
struct plan_host_kind {
	char kind[PLAN_KIND_MAX];
	double host_s;              /* real seconds per point (as point_overhead_s) */
	long long sweep;            /* the sweep that measured it */
};

/* The executor's costs the ordering model leaves out; plan_timing_defaults() gives the executor's and the
 * arm driver's defaults, the daemon fills it from its configuration (sweep, acquisition, devices). */
struct plan_timing {
	double axis_poll_s;         /* controllers' status polling: a move costs PLAN_MOVE_POLLS periods beyond its
				     * trapezoid and settling */
	double extra_settle_s;      /* sweep.extra_settle_s after every move */
	double probe_ms;            /* auto integration: one probe exposure per point */
	double min_ms, ladder_ratio; /* auto integration: times rounded down to min_ms · ladder_ratio^k (executor) */
	double exposure_overhead_s; /* per exposure beyond integration + read-out (start, polling, storage) */
	int dark_averages;          /* exposures per dark */
	int dark_every;             /* a dark every N points; 0: one per incidence; -1: none by schedule (age only) */
	double dark_max_age_s;      /* and a new dark when the last one is older than this (0: never) */
	int max_exposures;          /* auto: exposures per point at most (a second, HDR, one when the weak end is faint) */
	double hdr_ratio;           /* auto: the HDR exposure's time / the first's */
	bool reference;             /* a reference (the plan's averages) at the start, at ref_pose, then the move to
				     * the first point */
	struct plan_pos ref_pose;
	double point_overhead_s;    /* real seconds per point the host spends beyond the bench's own time
				     * (calibration, storage with fsync, protocol round trips) ... */
	double time_scale;          /* ... which cost time_scale times as much bench time on a simulated bench */
	long long host_sweep;       /* point_overhead_s is what this completed sweep measured (0: the default) */
	struct plan_host_kind host_kind[PLAN_HOST_KINDS]; /* by plan kind: used instead of point_overhead_s for a plan */
	int n_host_kind;            /* of that kind (when no exposure prior carries its own) */
	bool have_start;            /* the arms' position when the sweep starts is known (the daemon knows it) */
	struct plan_pos start;      /* then the move from there to ref_pose (or the first point) is counted */
	struct plan_prior prior;    /* auto integration: the exposure prior when prior.sweep > 0 (plan_time.c) */
	bool prior_trend;           /* an incidence beyond the prior's zeniths follows the three end rows' monotone trend
				     * at PLAN_TREND_WEIGHT (plan_time.c trend_row; default true, never for an adaptive
				     * spec); false: the nearest row */
	/* an adaptive batch appended to a running sweep (plan_timing_continue): the executor keeps its dark cache
	 * unless the batch starts at another incidence (executor_acq.c), so the first step clears it only then, and
	 * the rungs counted after cont_since_clear points there */
	bool cont;
	double cont_laser;          /* the last measured point's laser position */
	double cont_since_clear;    /* points measured there since the cache was last cleared */
};

/* Load and validate a plan file; errors name file:line:col. 0, or -1 with err (*out NULL). */
int plan_load(const char *path, struct plan_spec **out, struct acq_err *err);
/* Parse a plan from YAML text (name is the file name in messages). 0 or -1 with err. */
int plan_load_string(const char *name, const char *text, struct plan_spec **out, struct acq_err *err);
/* Parse the root mapping of a plan document into a new spec. 0 or -1 with err. */
int plan_parse(struct yc_node *root, struct plan_spec **out, struct acq_err *err);
/* Free a spec (NULL is fine). */
void plan_spec_free(struct plan_spec *spec);

/* Plan spec against bench g: classify, order, build safe moves, estimate. 0, or -1 with err. */
int plan_make(const struct plan_spec *spec, const struct bench_geom *g, struct plan_result **out,
	      struct acq_err *err);
/* Plan the given points (requested bench positions) with spec's integration and averages against g: blind ones
 * dropped (never moved), duplicates merged, ordered by incidence groups as plan_make does, the first move from
 * start when given (else the sweep starts at the first point). 0, or -1 with err. */
int plan_make_points(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_pos *pts, size_t n,
		     const struct plan_pos *start, struct plan_result **out, struct acq_err *err);
/* The polling periods (plan_timing.axis_poll_s) a move costs beyond its trapezoid and settling (the settle's
 * confirming read is at settle_s, in the settling). The driver (drivers/axis_modbus.c poll_at) reads a leg's status
 * first at its predicted end, then, the controller a little behind, when the distance left would be covered, at
 * least poll_s/10 later: 0.1. Before session 14 it polled every period from the start, seeing the end half a period
 * late on average, and the price was 1.5: at time scale 1 a period more than the bench took, which at time scale
 * 35 the host figure, measured against the price, hid. Measured with tests/bench/bench_duration.py (session 14,
 * load 2-4): the driver change alone took the paper plan at time scale 35 from 1907.6 to 1889.9 s (20 bench ms per
 * move, the half period); priced at 1.0 the quick plan at time scale 1 took 36.8-39.6 ms per point less than the
 * model's bench part (three sweeps), the paper plan at 35 5.23 ms real per point more: per move about 5 ms of
 * bench time (0.1 period) and 6.5 ms of real time (the host, plan_timing_defaults) solve both. */
#define PLAN_MOVE_POLLS 0.1

/* Straight-move time plus the settling of the axes that move: a lower bound of any move between a and b. */
double plan_straight_s(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b);
/* A straight move between two poses as the executor sees it (bench s): plan_straight_s, then PLAN_MOVE_POLLS polls and the
 * extra settling; 0 when nothing moves. */
double plan_move_time_s(const struct bench_geom *g, const struct plan_timing *t, const struct plan_pos *a,
			const struct plan_pos *b);
/* A pose [laser_theta, detector_theta, detector_phi] from a YAML sequence (what names it in messages). 0 or -1. */
int plan_pose_parse(const struct yc_node *n, const char *what, struct plan_pos *out, struct acq_err *err);
/* The executor's and drivers' default timing (see struct plan_timing). */
void plan_timing_defaults(struct plan_timing *t);
/* The kind of spec's plan for the host's time per point: "grid", "fibonacci" or "adaptive", then "/auto" or
 * "/fixed" (the integration); written into buf (PLAN_KIND_MAX bytes), returned. */
const char *plan_kind_of(const struct plan_spec *spec, char *buf);
/* The index (0 .. PLAN_HOST_KINDS-1) of spec's plan kind: plan_kind_name(plan_kind_index(spec)) is plan_kind_of. */
int plan_kind_index(const struct plan_spec *spec);
/* The name of plan kind i (0 .. PLAN_HOST_KINDS-1) written into buf (PLAN_KIND_MAX bytes) and returned; NULL for
 * any other i. Every kind plan_kind_of can name is one of these. */
const char *plan_kind_name(int i, char *buf);
/* The host's real seconds per point plan_time_apply uses for spec when no exposure prior carries its own: the
 * figure of spec's kind in t->host_kind (*own_kind true), else t->point_overhead_s; *sweep = the sweep that
 * measured it (0: the default). */
double plan_time_host(const struct plan_spec *spec, const struct plan_timing *t, long long *sweep, bool *own_kind);
/* The ladder rung of integration time ms on t's ladder: round(log(ms / min_ms) / log ladder_ratio) in [0, 63]. */
int plan_rung(const struct plan_timing *t, double ms);
/* Fill the predicted_* fields of r (made from spec against g) for an executor timed by t. */
void plan_time_apply(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_timing *t,
		     struct plan_result *r);
/* The interval of an auto sweep's duration where its exposures are unknown (plan_time.c): an incidence the exposure
 * prior has not measured (farther than PLAN_PRIOR_SAME_DEG from each of its rows) takes its nearest row's times
 * scaled by exp(-/+ g·Δθ), g = plan_prior_slope per degree, and its HDR share 0 at the low end, the measured
 * rows' most at the high end; with no prior at all, every exposure at the policy's
 * reach (min_ms; the plan's max_ms with the HDR share). The constants are the steepest changes measured on the
 * simulated samples (plan_time.c): the metal's quick plan 2.6x in 25° with one incidence known (ln 2 / 15° per
 * degree), the cloth-sheen's slow fall (0.4 %/° over 60°) below what adjacent rows show. */
#define PLAN_EXPO_SLOPE_ONE 0.0462 /* ln 2 / 15: per degree, fewer than two measured incidences */
#define PLAN_EXPO_SLOPE_MIN 0.01   /* per degree: the least g with two or more */
#define PLAN_PRIOR_SAME_DEG 0.5    /* a prior row within this (degrees) is the incidence itself */
#define PLAN_TREND_WEIGHT 0.5      /* of a monotone trend's slope, beyond the measured zeniths (plan_time.c) */
enum plan_interval {
	PLAN_IV_NONE,         /* fixed integration, adaptive, or every incidence measured: low = high = predicted */
	PLAN_IV_POLICY,       /* no exposure measured: the policy's reach */
	PLAN_IV_EXTRAPOLATED, /* some incidence extrapolated from the measured ones */
};
/* The steepest change of ln(mean first exposure) per degree of incidence between p's adjacent rows, at least
 * PLAN_EXPO_SLOPE_MIN (PLAN_EXPO_SLOPE_ONE with fewer than two rows). */
double plan_prior_slope(const struct plan_prior *p);
/* plan_time_apply, and the interval of its predicted_s: *lo_s, *hi_s (bench s), with each step's predicted start at
 * the two ends in lo_at, hi_at (n_steps + 1 each, the last the total; NULL: not wanted). r is left timed as
 * plan_time_apply times it. Returns the interval's kind (PLAN_IV_NONE: lo = hi = predicted_s). */
enum plan_interval plan_time_interval(const struct plan_spec *spec, const struct bench_geom *g,
				      const struct plan_timing *t, struct plan_result *r, double *lo_at, double *hi_at,
				      double *lo_s, double *hi_s);
/* One point's exposure costs as plan_time_apply counts them (bench seconds, no move). */
struct plan_point_cost {
	double point_s;             /* probe, exposure, HDR share, the host's time */
	double dark_s;              /* one dark */
	double rungs;               /* the distinct times the dark cache needs at an incidence: the j-th point after a
				     * clearing takes a dark with probability (1 - 1/rungs)^j (fixed integration: 1) */
};
/* The costs of one point at incidence theta_i (degrees) in a plan whose detector zeniths span cos ratio rho ≥ 1
 * (largest / smallest cos θ of the plan's points: the auto band widens with it; an exposure prior or fixed
 * integration does not), timed by t: plan_time_apply's per-point terms, for `brdf-recon select`'s price. */
void plan_time_point(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_timing *t,
		     double theta_i, double rho, struct plan_point_cost *out);
/* The survey (plan_order.c): a first auto sweep measures survey_k points of every incidence first, spread over its
 * viewing zeniths and azimuths, then the route without them (each point once), so that its re-timing (sweep_retime.c)
 * prices every incidence from the sample's own exposures after n_survey points (README "How long a sweep takes"). */
#define PLAN_SURVEY_DEFAULT 6
/* The survey's points per incidence for spec's plan r timed by t: spec->survey when ≥ 0, for -1 PLAN_SURVEY_DEFAULT
 * when t's exposure prior lacks one of r's incidences (else 0); 0 for fixed integration, adaptive plans
 * and a route whose first step has a move (a start position). */
size_t plan_survey_k(const struct plan_spec *spec, const struct plan_timing *t, const struct plan_result *r);
/* Reorder r (made by plan_make) for the survey (plan_survey_k points per incidence, at most an eighth of the
 * incidence's points, at least one): those points first, in their own shortest path (plan_order_group) walked from
 * its end so that it ends next to the route's first point, then the route's other points in its order; moves planned again, the ordering model's times recomputed (call plan_time_apply after), n_survey,
 * survey_k, survey_motion_s set. r unchanged when k is 0, when it has a survey already, or when a move of the new
 * order has no clear path. 0, or -1 with err (out of memory). */
int plan_survey_apply(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_timing *t,
		      struct plan_result *r, struct acq_err *err);
/* Free a result (NULL is fine). */
void plan_result_free(struct plan_result *res);

struct json_t;
/* The result as a JSON object (jansson; caller json_decref's it): counts, kept/dropped/moved, duration_s,
 * raster_s, lower_bound_s, motion summary, dropped and moved points, and with steps the sweep order with
 * waypoints. NULL when out of memory. */
struct json_t *plan_to_json(const struct plan_spec *spec, const struct plan_result *res, bool steps);

/* The dry run of spec planned into r against g for an executor timed by t: plan_time_apply, then plan_to_json,
 * with, for an adaptive plan, "kind": "adaptive" and "adaptive": {target, threshold, batch, budget_s,
 * budget_points, candidate counts, worst_case_s, worst_case_points} (the result r is its seed plan). */
struct json_t *plan_dry_run_json(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_timing *t,
				 struct plan_result *r, bool points);

/* ---- adaptive plans (plan_adaptive.c) */

/* One candidate measurement of an adaptive batch: reachable from the arms' position, visible, not measured yet. */
struct plan_cand {
	size_t id;                  /* its place among the spec's candidates (plan_adaptive_cand_pos) */
	struct plan_pos pos;        /* bench position (det_phi the axis position reached fastest) */
	double cost_s;              /* bench seconds to measure it from the arms' position: the safe move, its
				     * settling and polling, darks when the incidence changes, probe, exposures, host */
	double base_s;              /* of it: the point at an incidence the executor is at already, without a move */
	double open_s;              /* and the darks more at a new incidence (select charges each pick its increment
				     * to the batch's route: base_s, open_s when its incidence is new to the batch, and
				     * the motion of inserting it into the batch's route, plan_adaptive_route_spec) */
	/* select's price of the exposures (plan_time_point at the point alone, rho 1): the batch's j-th point at an
	 * incidence takes a dark with probability (1 - 1/rungs)^(since + j), and the batch's band (the spread of
	 * band_cos over its points) scales these terms as the route spec's band nodes say */
	double point_s;             /* probe, exposure, HDR share, host */
	double dark_s;              /* one dark at its incidence */
	double rungs;               /* the distinct times the dark cache needs there */
	double since;               /* points measured at its incidence since the cache was cleared (its incidence is the
				     * arms': the executor keeps the cache; else 0) */
	double band_cos;            /* cos of its detector zenith: what the auto band spans */
};
/* t continues a sweep whose points so far are at positions n_done (each stride bytes after the previous: an array of
 * struct plan_pos, or the pos member of struct plan_step): the cache state of its last incidence (cont fields). The
 * age rule (dark_max_age_s) is left to the new steps' own clock. n 0: no continuation. */
void plan_timing_continue(struct plan_timing *t, const struct plan_pos *done, size_t n, size_t stride);
/* The batch's route model as `brdf-recon select --route` takes it (comma-separated: the arms' position from (laser
 * θ, detector θ, detector φ), then per axis in that order speed °/s, acceleration °/s², settle s, then the executor's
 * seconds per move beyond the trapezoids and settling: PLAN_MOVE_POLLS polls + extra settle, plan_time.c; then spec's band nodes,
 * four numbers each: rho, then plan_time_point's point_s, dark_s, rungs at that band (rho 1 first, rising; one node
 * when the band does not change them: fixed integration, an exposure prior)) into buf (PLAN_ROUTE_SPEC_LEN). */
#define PLAN_ROUTE_SPEC_LEN 2048
void plan_adaptive_route_spec(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_timing *t,
			      const struct plan_pos *from, char *buf, size_t len);
/* The adaptive target as `brdf-recon select --target` takes it ("dhr:8,30,60:le=X", "lnf:le=X", "rgb:le=X") into buf. */
void plan_adaptive_target_spec(const struct plan_adaptive *a, char *buf, size_t len);
/* The candidates of spec's adaptive part from the arms at from (timed by t): every candidate incidence ×
 * direction that is visible, within the limits, reachable by a safe move, and not one of the n_done measured
 * positions. A new array in *out (free()), its length in *n. 0, or -1 with err. */
int plan_adaptive_candidates(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_timing *t,
			     const struct plan_pos *from, const struct plan_pos *done, size_t n_done,
			     struct plan_cand **out, size_t *n, struct acq_err *err);
/* The requested (canonical) position of candidate id of spec's adaptive part on bench g: ids below
 * incidences × per_incidence are the Fibonacci directions, then per incidence the mirror direction and its rings
 * (a ring direction the blind zones or limits hide is replaced by its reciprocal when that one is usable).
 * 0, or -1 when there is none. */
int plan_adaptive_cand_pos(const struct plan_spec *spec, const struct bench_geom *g, size_t id, struct plan_pos *out);
/* Which of select's picks (their costs cost[0..n-1], in choice order) a batch takes: each in turn when its cost fits
 * what the ones taken before it leave of left_s (INFINITY: no limit), a dearer pick skipped and a cheaper later one
 * still taken, at most max_k. Their indices, ascending, into keep[n]; their count. */
size_t plan_adaptive_fit_picks(const double *cost, size_t n, double left_s, size_t max_k, size_t *keep);
/* The threshold the select value of spec's target is compared with: le, or 1 for a combined target (whose value is
 * the larger of each part's value over its threshold). */
double plan_adaptive_threshold(const struct plan_adaptive *a);
/* Plan the points in the order given (no ordering, no classification: points already planned once, e.g. a stored
 * batch), each reached by a fresh safe move from the previous one (from start when given). 0, or -1 with err
 * (ACQ_E_RANGE: a point no safe move reaches). */
int plan_make_fixed(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_pos *pts, size_t n,
		    const struct plan_pos *start, struct plan_result **out, struct acq_err *err);
/* Append b's requests, steps and waypoints to r (indices, times and predictions shifted to follow r's). 0 or -1. */
int plan_result_append(struct plan_result *r, const struct plan_result *b, struct acq_err *err);
/* The worst case of an adaptive plan whose seed result is seed (timed by t): the budget's bench seconds and
 * points, each the stated limit or, when only the other is given, what it allows (points at the costliest
 * candidate's price from the seed's last point). */
void plan_adaptive_worst(const struct plan_spec *spec, const struct bench_geom *g, const struct plan_timing *t,
			 const struct plan_result *seed, double *worst_s, size_t *worst_points);

/* ---- geometry and kinematics (also for the executor and the daemon's manual moves; the simulator keeps its
 * own implementation of the same definitions: libsim links after libdaemon, and two codes check each other) */

/* Points within this of a blind-zone edge count as blind, and path checks need this much clearance to
 * prove a segment safe (so every visible point is reachable by the same test). */
#define PLAN_EDGE_DEG 1e-3

/* ψ at p, degrees. */
double plan_psi_deg(const struct bench_geom *g, const struct plan_pos *p);
/* The ψ below which the arms collide: laser_body + detector_body + safety margin. */
double plan_collision_deg(const struct bench_geom *g);
/* enum plan_reason bits that make p unusable as a measurement point (0: visible and reachable). */
unsigned plan_blind(const struct bench_geom *g, const struct plan_pos *p);
/* Duration of a rest-to-rest trapezoidal move of distance |d| on axis a. */
double plan_axis_time(const struct bench_axis *a, double d);
/* Position at time t (clamped to [0, duration]) of a trapezoidal move from x0 to x1 on axis a. */
double plan_axis_pos(const struct bench_axis *a, double x0, double x1, double t);
/* Duration of one segment from p to q (all axes together). */
double plan_seg_time(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q);
/* The ψ paths keep clear of: the largest blind-zone or collision half-angle that applies (margin included),
 * so no arm passes through the other, and no arm crosses the beam or the view while moving either. */
double plan_clearance_deg(const struct bench_geom *g);
/* True when the segment p → q (within the axis limits) keeps ψ ≥ plan_collision_deg + PLAN_EDGE_DEG at every
 * instant: the arms never collide (sound: never a false yes). For manual moves. */
bool plan_seg_safe(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q);
/* The same with plan_clearance_deg: no collision and no arm across the beam or the view; planned paths. */
bool plan_seg_clear(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q);
/* The same with any threshold: ψ ≥ psi_min + PLAN_EDGE_DEG at every instant (recovery moves: never closer). */
bool plan_seg_keeps(const struct bench_geom *g, const struct plan_pos *p, const struct plan_pos *q, double psi_min);
/* Fastest clear move a → b found (every segment passes plan_seg_clear; templates: straight, one arm then the
 * other, detector zenith detours, azimuth escapes, approach points, a parking pose): up to PLAN_MAX_WP
 * segments into wps (the last ends at b), their count in *n, and the move's time (segments + settle)
 * returned; -1 when no candidate path is clear. Executing: run each segment with all its axes started
 * together, wait in position, then the next; settle once at the end. */
#define PLAN_MAX_WP 13
double plan_move(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b,
		 struct plan_wp wps[PLAN_MAX_WP], size_t *n);
/* From a configuration inside the clearance (a move stopped part-way by one axis's alarm while the others went on),
 * a way out: one segment moving the detector straight away from the laser's direction that never brings the arms
 * closer than they are (ψ ≥ min(collision limit, ψ now) at every instant, plan_seg_keeps), ending clear, then
 * plan_move's path to b. Up to PLAN_MAX_WP + 1 segments into wps, their count in *n, the time returned; -1 when a
 * is not inside the clearance or no such way exists. */
double plan_escape(const struct bench_geom *g, const struct plan_pos *a, const struct plan_pos *b,
		   struct plan_wp wps[PLAN_MAX_WP + 1], size_t *n);
/* Readable name of the most telling reason bit set (limit, collision, beam, view, unreachable, none nearby). */
const char *plan_reason_name(unsigned reason);

#endif
