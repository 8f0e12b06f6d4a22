/* bigbuf: scratch arrays of megabytes on transparent huge pages (see bigbuf.h). Why: select's kernel and posterior
 * rows (J × n, Q × n per incidence: 8-25 MB each at 2000 candidates and 664 samples) are written once, soon after
 * they are allocated; with 4 KiB pages the first touch cost a page fault per page, 29 300 faults and ~17 % of a
 * decision's CPU in this project's VM (perf, session 13), and the arithmetic does not depend on where they live. */
#include "recon/bigbuf.h"

#include <stdlib.h>
#include <sys/mman.h>

void *recon_big_alloc(size_t bytes)
{
	if (bytes < RECON_BIG_PAGE)
		return malloc(bytes ? bytes : 1);
	size_t len = (bytes + RECON_BIG_PAGE - 1) / RECON_BIG_PAGE * RECON_BIG_PAGE;
	void *p = NULL;
	if (len < bytes || posix_memalign(&p, RECON_BIG_PAGE, len))
		return NULL;
#ifdef MADV_HUGEPAGE
	(void)madvise(p, len, MADV_HUGEPAGE); /* advice only: plain pages when declined (THP off, old kernel) */
#endif
	return p;
}
