/* bigbuf: scratch arrays of megabytes (kernel rows, posterior rows) on transparent huge pages. */
#ifndef RECON_BIGBUF_H
#define RECON_BIGBUF_H

#include <stddef.h>

/* Like malloc (release with free), but an array of at least RECON_BIG_PAGE bytes is aligned to that and advised
 * to the kernel as huge pages (MADV_HUGEPAGE: one page fault per 2 MiB instead of per 4 KiB on first touch;
 * plain pages where the kernel declines). NULL when out of memory. */
void *recon_big_alloc(size_t bytes);

#define RECON_BIG_PAGE ((size_t)2 << 20)

#endif
