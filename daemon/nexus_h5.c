/* nexus_h5: the HDF5 objects a NeXus file is made of, through libhdf5: groups with their NX_class, UTF-8 string
 * and numeric datasets (with units) and attributes, rows written one at a time (nexus.c lays out the sweep). */
#include "daemon/nexus_h5.h"

#include <string.h>

/* n UTF-8 strings as an attribute (attr) or a dataset of obj; a scalar when scalar is set (n = 1). Attribute
 * scalars are fixed-length (what NeXus readers expect of NX_class and units), the rest variable-length. */
static int put_strs(hid_t obj, const char *name, int attr, int scalar, size_t n, const char *const *vals)
{
	hsize_t dim = n;
	const char *one = n && vals[0] ? vals[0] : "";
	int fixed = attr && scalar;
	hid_t t = H5Tcopy(H5T_C_S1), s = scalar ? H5Screate(H5S_SCALAR) : H5Screate_simple(1, &dim, NULL), o = -1;
	int rc = -1;
	if (t < 0 || s < 0 || H5Tset_size(t, fixed ? (strlen(one) ? strlen(one) : 1) : H5T_VARIABLE) < 0 ||
	    H5Tset_cset(t, H5T_CSET_UTF8) < 0)
		goto out;
	const void *buf = fixed ? (const void *)one : scalar ? (const void *)&one : (const void *)vals;
	if (attr) {
		o = H5Acreate2(obj, name, t, s, H5P_DEFAULT, H5P_DEFAULT);
		rc = o >= 0 && H5Awrite(o, t, buf) >= 0 ? 0 : -1;
	} else {
		o = H5Dcreate2(obj, name, t, s, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
		rc = o >= 0 && (n == 0 || H5Dwrite(o, t, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf) >= 0) ? 0 : -1;
	}
out:
	if (o >= 0)
		(attr ? H5Aclose : H5Dclose)(o);
	if (s >= 0)
		H5Sclose(s);
	if (t >= 0)
		H5Tclose(t);
	return rc;
}

int nxh_attr_str(hid_t obj, const char *name, const char *val)
{
	return put_strs(obj, name, 1, 1, 1, &val);
}

int nxh_attr_strs(hid_t obj, const char *name, size_t n, const char *const *vals)
{
	return put_strs(obj, name, 1, 0, n, vals);
}

int nxh_attr_int(hid_t obj, const char *name, int v)
{
	hid_t s = H5Screate(H5S_SCALAR), a = s >= 0 ? H5Acreate2(obj, name, H5T_NATIVE_INT, s, H5P_DEFAULT, H5P_DEFAULT) : -1;
	int rc = a >= 0 && H5Awrite(a, H5T_NATIVE_INT, &v) >= 0 ? 0 : -1;
	if (a >= 0)
		H5Aclose(a);
	if (s >= 0)
		H5Sclose(s);
	return rc;
}

int nxh_dset_str(hid_t g, const char *name, const char *val)
{
	return put_strs(g, name, 0, 1, 1, &val);
}

int nxh_dset_strs(hid_t g, const char *name, size_t n, const char *const *vals)
{
	return put_strs(g, name, 0, 0, n, vals);
}

hid_t nxh_group(hid_t parent, const char *name, const char *nx_class)
{
	hid_t g = H5Gcreate2(parent, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
	if (g >= 0 && nxh_attr_str(g, "NX_class", nx_class)) {
		H5Gclose(g);
		return -1;
	}
	return g;
}

hid_t nxh_dset_num(hid_t g, const char *name, hid_t type, int rank, const hsize_t *dims, const void *data,
		      const char *units)
{
	hid_t s = H5Screate_simple(rank, dims, NULL), p = H5Pcreate(H5P_DATASET_CREATE), d = -1;
	if (s < 0 || p < 0)
		goto out;
	if (rank == 2 && dims[0] > 0 && dims[1] > 0) { /* rows written one by one: chunk by rows */
		hsize_t ch[2] = { dims[0] < 16 ? dims[0] : 16, dims[1] };
		H5Pset_chunk(p, 2, ch);
	}
	d = H5Dcreate2(g, name, type, s, H5P_DEFAULT, p, H5P_DEFAULT);
	if (d >= 0 && ((data && dims[0] > 0 && H5Dwrite(d, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0) ||
		       (units && nxh_attr_str(d, "units", units)))) {
		H5Dclose(d);
		d = -1;
	}
out:
	if (p >= 0)
		H5Pclose(p);
	if (s >= 0)
		H5Sclose(s);
	return d;
}

int nxh_close_ok(hid_t d)
{
	return d >= 0 && H5Dclose(d) >= 0 ? 0 : -1;
}

int nxh_write_row(hid_t d, hid_t type, hsize_t row, hsize_t ncol, const void *data)
{
	hid_t fs = H5Dget_space(d), ms = H5Screate_simple(1, &ncol, NULL);
	hsize_t start[2] = { row, 0 }, count[2] = { 1, ncol };
	int rc = fs >= 0 && ms >= 0 && H5Sselect_hyperslab(fs, H5S_SELECT_SET, start, NULL, count, NULL) >= 0 &&
			 H5Dwrite(d, type, ms, fs, H5P_DEFAULT, data) >= 0 ? 0 : -1;
	if (ms >= 0)
		H5Sclose(ms);
	if (fs >= 0)
		H5Sclose(fs);
	return rc;
}
