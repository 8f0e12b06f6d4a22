/* devices_nyi: PLACEHOLDER definitions of the axis and laser drivers until drivers/axis_modbus.c and
 * drivers/laser_serial.c land (then this file compiles to nothing: delete it). They are weak, so a real
 * definition linked for any reason wins. Each says plainly that the driver is not implemented. */
#if !__has_include("drivers/axis_modbus.c") || !__has_include("drivers/laser_serial.c")
#include "drivers/axis.h"
#include "drivers/laser.h"
#endif

#if !__has_include("drivers/axis_modbus.c")
#define NYI_AXIS "axis driver (drivers/axis_modbus.c): not implemented yet"
__attribute__((weak)) int axis_cfg_parse(struct yc_node *node, struct yc_node *link, struct yc_node *maps,
					 const char *name, struct axis_cfg **out, struct acq_err *err)
{
	(void)link;
	(void)maps;
	*out = NULL;
	yc_errf(err, node, "%s: " NYI_AXIS, name);
	if (err)
		err->code = ACQ_E_UNSUPPORTED;
	return -1;
}
__attribute__((weak)) void axis_cfg_free(struct axis_cfg *cfg)
{
	(void)cfg;
}
__attribute__((weak)) void axis_cfg_limits(const struct axis_cfg *cfg, double *min_deg, double *max_deg)
{
	(void)cfg;
	*min_deg = 0;
	*max_deg = 0;
}
__attribute__((weak)) int axis_open(const struct axis_cfg *cfg, struct axis **out, struct acq_err *err)
{
	(void)cfg;
	*out = NULL;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
__attribute__((weak)) void axis_close(struct axis *ax)
{
	(void)ax;
}
__attribute__((weak)) int axis_read_status(struct axis *ax, struct axis_status *st, struct acq_err *err)
{
	(void)ax;
	(void)st;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
__attribute__((weak)) int axis_move_begin(struct axis *ax, double target_deg, double now, struct acq_err *err)
{
	(void)ax;
	(void)target_deg;
	(void)now;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
__attribute__((weak)) int axis_move_step(struct axis *ax, double now, struct acq_err *err)
{
	(void)ax;
	(void)now;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
__attribute__((weak)) double axis_next_poll(const struct axis *ax)
{
	(void)ax;
	return 0;
}
__attribute__((weak)) int axis_stop(struct axis *ax, struct acq_err *err)
{
	(void)ax;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
__attribute__((weak)) int axis_identity(struct axis *ax, struct axis_identity *id, struct acq_err *err)
{
	(void)ax;
	(void)id;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
__attribute__((weak)) bool axis_connected(const struct axis *ax)
{
	(void)ax;
	return false;
}
#endif

#if !__has_include("drivers/laser_serial.c")
#define NYI_LASER "laser driver (drivers/laser_serial.c): not implemented yet"
__attribute__((weak)) int laser_cfg_parse(struct yc_node *node, struct laser_cfg **out, struct acq_err *err)
{
	*out = NULL;
	yc_errf(err, node, NYI_LASER);
	if (err)
		err->code = ACQ_E_UNSUPPORTED;
	return -1;
}
__attribute__((weak)) void laser_cfg_free(struct laser_cfg *cfg)
{
	(void)cfg;
}
__attribute__((weak)) int laser_open(const struct laser_cfg *cfg, struct laser **out, struct acq_err *err)
{
	(void)cfg;
	*out = NULL;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_LASER);
}
__attribute__((weak)) void laser_close(struct laser *l)
{
	(void)l;
}
__attribute__((weak)) int laser_set_emission(struct laser *l, bool on, struct acq_err *err)
{
	(void)l;
	(void)on;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_LASER);
}
__attribute__((weak)) const struct laser_identity *laser_identity(const struct laser *l)
{
	(void)l;
	static const struct laser_identity none;
	return &none;
}
__attribute__((weak)) int laser_set_power(struct laser *l, double pct, struct acq_err *err)
{
	(void)l;
	(void)pct;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_LASER);
}
__attribute__((weak)) int laser_status(struct laser *l, struct laser_status *st, struct acq_err *err)
{
	(void)l;
	(void)st;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_LASER);
}
#endif

/* ISO C forbids an empty translation unit. */
typedef int devices_nyi_nonempty;
