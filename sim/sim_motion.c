/* sim_motion: kinematics of a simulated axis (trapezoid, limits, backlash, noise, scheduled halts). */
#include "sim/sim_motion.h"

#include <math.h>
#include <string.h>

void simmot_init(struct simmot *m, const struct bench_axis *k, double pos, uint64_t seed)
{
	memset(m, 0, sizeof *m);
	m->k = *k;
	m->motor = m->load = pos;
	acq_rng_seed(&m->rng, seed);
}

/* Phase durations of a profile over distance d (> 0) from speed v0 with max speed V. */
static void phases(double d, double v0, double V, double A, double D, double *ta, double *tc, double *td)
{
	if (v0 > V)
		V = v0;
	double da = (V * V - v0 * v0) / (2 * A), dd = V * V / (2 * D);
	if (da + dd <= d) {
		*ta = (V - v0) / A;
		*tc = (d - da - dd) / V;
		*td = V / D;
		return;
	}
	/* no cruise: peak vp with (vp² - v0²)/2A + vp²/2D = d */
	double vp2 = (d + v0 * v0 / (2 * A)) / (1 / (2 * A) + 1 / (2 * D));
	double vp = sqrt(vp2 > 0 ? vp2 : 0);
	if (vp < v0) /* cannot stop in d: decelerate as hard as allowed (overshoot not modelled) */
		vp = v0;
	*ta = (vp - v0) / A;
	*tc = 0;
	*td = vp / D;
}

double simmot_duration(double dist, double v0, double vmax, double acc, double dec)
{
	double ta, tc, td;
	if (fabs(dist) == 0)
		return 0;
	phases(fabs(dist), v0, vmax, acc, dec, &ta, &tc, &td);
	return ta + tc + td;
}

static double peak(const struct simmot *m)
{
	return m->v0 + m->acc * m->ta;
}

/* Profile position at bench time t (no limits, no noise). */
static double simmot_profile_pos(const struct simmot *m, double t)
{
	if (!m->moving)
		return m->motor;
	double s = t - m->t0, vp = peak(m), x;
	if (s <= 0)
		return m->p0;
	if (s < m->ta)
		x = m->v0 * s + 0.5 * m->acc * s * s;
	else if (s < m->ta + m->tc)
		x = m->v0 * m->ta + 0.5 * m->acc * m->ta * m->ta + vp * (s - m->ta);
	else if (s < m->ta + m->tc + m->td) {
		double u = s - m->ta - m->tc;
		x = m->v0 * m->ta + 0.5 * m->acc * m->ta * m->ta + vp * m->tc + vp * u - 0.5 * m->dec * u * u;
	} else
		return m->p1;
	return m->p0 + m->dir * x;
}

double simmot_speed(const struct simmot *m, double now)
{
	if (!m->moving)
		return 0;
	double s = now - m->t0, vp = peak(m), v;
	if (s <= 0)
		v = m->v0;
	else if (s < m->ta)
		v = m->v0 + m->acc * s;
	else if (s < m->ta + m->tc)
		v = vp;
	else if (s < m->ta + m->tc + m->td)
		v = vp - m->dec * (s - m->ta - m->tc);
	else
		v = 0;
	return m->dir * v;
}

static void begin(struct simmot *m, double target, double now, double v0, double V, double A, double D)
{
	m->t0 = now;
	m->p0 = m->motor;
	m->p1 = target;
	m->dir = target >= m->p0 ? 1 : -1;
	m->v0 = v0;
	m->vmax = V;
	m->acc = A;
	m->dec = D;
	phases(fabs(target - m->p0), v0, V, A, D, &m->ta, &m->tc, &m->td);
	m->moving = target != m->p0;
	m->halt_kind = SIMMOT_HALT_NONE;
}

void simmot_start(struct simmot *m, double target, double now, double speed, double accel, double decel)
{
	double V = speed > 0 && speed < m->k.speed_dps ? speed : m->k.speed_dps;
	double A = accel > 0 && accel < m->k.accel_dps2 ? accel : m->k.accel_dps2;
	double D = decel > 0 && decel < m->k.accel_dps2 ? decel : m->k.accel_dps2;
	/* A new target while moving restarts from standstill where the axis is (the model does not blend). */
	begin(m, target, now, 0, V, A, D);
	m->add_noise = true;
	if (!m->moving)
		m->add_noise = false;
}

void simmot_schedule_halt(struct simmot *m, int kind, double frac)
{
	m->halt_kind = kind;
	m->halt_frac = frac;
}

static void drag_load(struct simmot *m)
{
	double half = m->k.backlash_deg / 2;
	if (m->motor - m->load > half)
		m->load = m->motor - half;
	else if (m->load - m->motor > half)
		m->load = m->motor + half;
}

int simmot_advance(struct simmot *m, double now)
{
	if (!m->moving)
		return SIMMOT_NONE;
	int ev = SIMMOT_NONE;
	double p = simmot_profile_pos(m, now);
	double dist = fabs(m->p1 - m->p0);
	if (m->halt_kind != SIMMOT_HALT_NONE && dist > 0 && fabs(p - m->p0) >= m->halt_frac * dist) {
		p = m->p0 + m->dir * m->halt_frac * dist;
		ev = m->halt_kind == SIMMOT_HALT_ALARM ? SIMMOT_ALARMED : SIMMOT_STALL;
		m->halt_kind = SIMMOT_HALT_NONE;
		m->moving = false;
	} else if (now - m->t0 >= m->ta + m->tc + m->td) {
		p = m->p1;
		if (m->add_noise && m->k.noise_deg > 0)
			p += m->k.noise_deg * acq_rng_gauss(&m->rng);
		if (m->add_noise && m->bias_moves > 0) {
			m->bias_moves--;
			p += m->bias_deg;
		}
		m->moving = false;
		ev = SIMMOT_DONE;
	}
	if (p > m->k.max_deg) {
		p = m->k.max_deg;
		m->moving = false;
		ev = SIMMOT_LIMIT_POS;
	} else if (p < m->k.min_deg) {
		p = m->k.min_deg;
		m->moving = false;
		ev = SIMMOT_LIMIT_NEG;
	}
	m->motor = p;
	drag_load(m);
	return ev;
}

void simmot_stop(struct simmot *m, double now)
{
	if (!m->moving)
		return;
	double v = simmot_speed(m, now);
	double dir = v >= 0 ? 1 : -1, sp = fabs(v);
	if (sp <= 0) {
		m->moving = false;
		return;
	}
	double stopdist = sp * sp / (2 * m->dec);
	begin(m, m->motor + dir * stopdist, now, sp, sp, m->acc, m->dec);
	m->add_noise = false;
}

void simmot_halt(struct simmot *m)
{
	m->moving = false;
}

double simmot_arm_separation(double theta_l, double laser_phi, double theta_d, double phi_d)
{
	double pl = laser_phi;
	if (theta_l < 0) {
		theta_l = -theta_l;
		pl += 180;
	}
	double d2r = M_PI / 180;
	double c = cos(theta_l * d2r) * cos(theta_d * d2r) +
		   sin(theta_l * d2r) * sin(theta_d * d2r) * cos((pl - phi_d) * d2r);
	if (c > 1)
		c = 1;
	if (c < -1)
		c = -1;
	return acos(c) / d2r;
}
