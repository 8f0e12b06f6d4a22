/* acq_num: the one range-checked number parser of the tree (device replies, control lines, arguments). */
#ifndef ACQ_NUM_H
#define ACQ_NUM_H

/* Parse the whole of s (no trailing text) as a finite decimal number within [lo, hi] into *out. 0, or -1 (out
 * untouched) for NULL, empty, trailing characters, overflow, NaN/Inf or out of range. */
int acq_num_parse(const char *s, double lo, double hi, double *out);

#endif
