/* cputime: a thread's time on a CPU and waiting for one, from /proc/thread-self/schedstat (cputime.h). */
#include "daemon/cputime.h"

#include <fcntl.h>
#include <stdio.h>
#include <unistd.h>

bool cputime_thread(struct cputime *out)
{
	out->on_cpu = out->waiting = 0;
	/* "<ns on the CPU> <ns waiting on a run queue> <timeslices>" (Documentation/scheduler/sched-stats.rst) */
	int fd = open("/proc/thread-self/schedstat", O_RDONLY | O_CLOEXEC);
	if (fd < 0)
		return false;
	char buf[128];
	ssize_t n = read(fd, buf, sizeof buf - 1);
	close(fd);
	if (n <= 0)
		return false;
	buf[n] = 0;
	unsigned long long run = 0, wait = 0;
	if (sscanf(buf, "%llu %llu", &run, &wait) != 2)
		return false;
	out->on_cpu = (double)run * 1e-9;
	out->waiting = (double)wait * 1e-9;
	return true;
}
