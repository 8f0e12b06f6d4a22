/* sweep_nyi: PLACEHOLDER weak definitions of the axis functions the sweep executor uses beyond those in
 * devices_nyi.c, until drivers/axis_modbus.c lands (then this file compiles to nothing: delete it). */
#if !__has_include("drivers/axis_modbus.c")
#include "drivers/axis.h"

#define NYI_AXIS "axis driver (drivers/axis_modbus.c): not implemented yet"
__attribute__((weak)) int axis_home_begin(struct axis *ax, double now, struct acq_err *err)
{
	(void)ax;
	(void)now;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
__attribute__((weak)) int axis_alarm_reset(struct axis *ax, struct acq_err *err)
{
	(void)ax;
	return acq_errf(err, ACQ_E_UNSUPPORTED, NYI_AXIS);
}
#endif

/* ISO C forbids an empty translation unit. */
typedef int sweep_nyi_nonempty;
