/* nexus_h5: the HDF5 objects of a NeXus file (nexus_h5.c): every group gets its NeXus class, every number its
 * units. Each returns 0 (or an open id) on success, -1 when libhdf5 failed. For nexus.c alone. */
#ifndef DAEMON_NEXUS_H5_H
#define DAEMON_NEXUS_H5_H

#include <hdf5.h>
#include <stddef.h>

/* A fixed-length UTF-8 string attribute name = val of obj (NX_class, units). */
int nxh_attr_str(hid_t obj, const char *name, const char *val);
/* An attribute holding n variable-length UTF-8 strings (NeXus `axes`). */
int nxh_attr_strs(hid_t obj, const char *name, size_t n, const char *const *vals);
/* A scalar int attribute. */
int nxh_attr_int(hid_t obj, const char *name, int v);
/* A scalar UTF-8 string dataset; NULL is written as "". */
int nxh_dset_str(hid_t g, const char *name, const char *val);
/* An array of n UTF-8 strings (n may be 0). */
int nxh_dset_strs(hid_t g, const char *name, size_t n, const char *const *vals);
/* A new group of parent with its NX_class attribute: its id (the caller closes it), or -1. */
hid_t nxh_group(hid_t parent, const char *name, const char *nx_class);
/* A numeric dataset of rank 1 or 2 (dims; rank 2 chunked by 16 rows), written whole from data (NULL: created only),
 * with units (NULL: none): its id (the caller closes it), or -1. */
hid_t nxh_dset_num(hid_t g, const char *name, hid_t type, int rank, const hsize_t *dims, const void *data,
		   const char *units);
/* Close dataset d: 0, or -1 when d is not valid or closing failed. */
int nxh_close_ok(hid_t d);
/* Write row `row` (ncol values of type from data) of the 2-D dataset d. */
int nxh_write_row(hid_t d, hid_t type, hsize_t row, hsize_t ncol, const void *data);

#endif
