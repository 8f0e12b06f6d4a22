/* devices_io: what a device request does on its port's thread (devices.c queues it, its completion returns to
 * the loop): the driver calls of open, close, status, move and homing, laser, measurement and stops. The only
 * place of the daemon that calls a driver. */
#include "daemon/devices_int.h"

#include <math.h>
#include <stdlib.h>

#include "daemon/loop.h"
#include "drivers/axis.h"
#include "drivers/laser.h"
#include "drivers/spectro.h"

/* ---- on the port's thread ------------------------------------------------------------------------------ */

static int no_handle(struct req *r)
{
	return acq_errf(&r->err, ACQ_E_DISCONNECTED, "%s unavailable", dname(r->d));
}

/* A move or homing from start to end on the thread: step at the driver's poll times; an interrupt stops it. */
static void run_motion(struct req *r, struct port *p, struct axis *ax)
{
	double now = port_now(p);
	r->rc = r->op == R_HOME ? axis_home_begin(ax, now, &r->err) : axis_move_begin(ax, r->target, now, &r->err);
	while (r->rc == 0) {
		now = port_now(p);
		int s = axis_move_step(ax, now, &r->err);
		if (s == AXIS_MOVE_DONE)
			break;
		if (s == AXIS_MOVE_FAILED) {
			r->rc = -1;
			break;
		}
		if (port_interrupted(p) || now > r->deadline) {
			struct acq_err e2;
			axis_stop(ax, &e2);
			if (port_interrupted(p))
				r->rc = acq_errf(&r->err, ACQ_E_STATE, "%s: move stopped by request", dname(r->d));
			else
				r->rc = acq_errf(&r->err, ACQ_E_TIMEOUT, "move not finished after %g s",
						 r->dv->c->sweep.move_timeout_s);
			break;
		}
		double wait = axis_next_poll(ax) - now;
		port_wait(p, wait > 0.5 ? 0.5 : wait, -1);
	}
	r->have_ast = axis_read_status(ax, &r->ast, NULL) == 0;
}

static void run_measure(struct req *r, struct port *p, struct spectro *sp)
{
	r->rc = spectro_start(sp, &r->meas, port_now(p), &r->err);
	while (r->rc == 0) {
		int f = spectro_fetch(sp, r->frame, port_now(p), &r->err);
		if (f == 1)
			break;
		if (f < 0) {
			r->rc = -1;
			break;
		}
		if (port_interrupted(p)) {
			spectro_stop(sp, NULL);
			r->rc = acq_errf(&r->err, ACQ_E_STATE, "spectrometer: measurement stopped by request");
			break;
		}
		port_wait_real(p, 0.005, spectro_pollfd(sp));
	}
}

static void req_run_op(struct req *r, struct port *p)
{
	struct dev_slot *s = &r->dv->slot[r->d];
	r->rc = 0;
	switch (r->op) {
	case R_OPEN:
		if (is_axis(r->d)) {
			if (!s->ax)
				r->rc = axis_open(r->cfg, &s->ax, &r->err);
			if (!r->rc) {
				axis_identity(s->ax, &r->aid, NULL);
				r->have_ast = axis_read_status(s->ax, &r->ast, NULL) == 0;
			}
		} else if (r->d == CONF_DEV_SPECTRO) {
			if (!s->sp)
				r->rc = spectro_open(r->cfg, &s->sp, &r->err);
			if (!r->rc) {
				r->info = *spectro_info(s->sp);
				r->have_info = true;
			}
		} else {
			if (!s->ls && !(r->rc = laser_open(r->cfg, &s->ls, &r->err)))
				devices_keepalive_armed(r->dv);
			if (!r->rc) {
				r->lid = *laser_identity(s->ls);
				r->have_lst = laser_status(s->ls, &r->lst, NULL) == 0;
			}
		}
		break;
	case R_CLOSE:
		axis_close(s->ax);
		spectro_close(s->sp);
		laser_close(s->ls);
		s->ax = NULL;
		s->sp = NULL;
		s->ls = NULL;
		break;
	case R_STATUS:
		if (is_axis(r->d))
			r->rc = !s->ax ? no_handle(r) : axis_read_status(s->ax, &r->ast, &r->err);
		else
			r->rc = !s->ls ? no_handle(r) : laser_status(s->ls, &r->lst, &r->err);
		r->have_ast = !r->rc && is_axis(r->d);
		r->have_lst = !r->rc && !is_axis(r->d);
		break;
	case R_MOVE:
	case R_HOME:
		if (!s->ax) {
			r->rc = no_handle(r);
			break;
		}
		if (r->op == R_HOME && r->on) { /* manual homing: an alarm is reset first */
			struct axis_status st;
			if (!axis_read_status(s->ax, &st, NULL) && st.alarm && axis_alarm_reset(s->ax, &r->err)) {
				r->rc = -1;
				acq_err_prefix(&r->err, "resetting its alarm: ");
				break;
			}
		}
		run_motion(r, p, s->ax);
		break;
	case R_STOP:
		r->rc = !s->ax ? 0 : axis_stop(s->ax, &r->err);
		break;
	case R_ALARM_RESET:
		r->rc = !s->ax ? no_handle(r) : axis_alarm_reset(s->ax, &r->err);
		break;
	case R_LASER:
		if (!s->ls) {
			r->rc = r->on ? no_handle(r) : 0;
			break;
		}
		if (r->on && !isnan(r->pct))
			r->rc = laser_set_power(s->ls, r->pct, &r->err);
		if (!r->rc)
			r->rc = laser_set_emission(s->ls, r->on, &r->err);
		r->have_lst = laser_status(s->ls, &r->lst, r->rc ? NULL : &r->err) == 0;
		if (!r->rc && !r->have_lst)
			r->rc = -1;
		break;
	case R_POWER:
		r->rc = !s->ls ? no_handle(r) : laser_set_power(s->ls, r->pct, &r->err);
		break;
	case R_MEASURE:
		if (!s->sp)
			r->rc = no_handle(r);
		else if (!r->frame)
			r->rc = acq_errf(&r->err, ACQ_E_NOMEM, "out of memory");
		else
			run_measure(r, p, s->sp);
		break;
	case R_SPECTRO_STOP:
		r->rc = !s->sp ? 0 : spectro_stop(s->sp, &r->err);
		break;
	}
}

/* The request's driver calls (the port times them: r->pr.took_s, on_cpu_s, cpu_wait_s). */
void devices_req_run(struct port_req *pr, struct port *p)
{
	req_run_op((struct req *)pr, p);
}
