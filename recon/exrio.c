/* exrio: OpenEXR in and out for the renderer (linear HDR preview, user environment maps). */
#include "recon/exrio.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <openexr.h>

#include "recon/pngio.h"

/* The library reports details through a callback (its default prints): keep the last message instead. When
 * writing, the file is encoded into memory (buf) and then written through pngio_write_bytes (config/acq_out):
 * the library's own temporary-file-and-rename would replace a device or FIFO given as the path (as root,
 * `--exr /dev/null` would turn /dev/null into a regular file). text must stay the first member: the error
 * handler reads the user data as struct exr_msg. */
struct exr_msg {
	char text[256];
	unsigned char *buf;
	size_t len, cap;
};

/* The library's write callback: the bytes at offset (it seeks back to fill the chunk table) into m->buf. */
static int64_t mem_write(exr_const_context_t c, void *ud, const void *data, uint64_t sz, uint64_t offset,
			 exr_stream_error_func_ptr_t error_cb)
{
	struct exr_msg *m = ud;
	if (offset > SIZE_MAX / 4 || sz > SIZE_MAX / 4) /* end <= SIZE_MAX / 2: the doubling below cannot wrap */
		return error_cb(c, EXR_ERR_OUT_OF_MEMORY, "exr: image too large"), -1;
	size_t end = (size_t)offset + (size_t)sz;
	if (end > m->cap) {
		size_t cap = m->cap ? m->cap : 65536;
		while (cap < end)
			cap *= 2;
		unsigned char *q = realloc(m->buf, cap);
		if (!q)
			return error_cb(c, EXR_ERR_OUT_OF_MEMORY, "exr: out of memory for %zu bytes", cap), -1;
		memset(q + m->cap, 0, cap - m->cap);
		m->buf = q;
		m->cap = cap;
	}
	memcpy(m->buf + offset, data, (size_t)sz);
	if (end > m->len)
		m->len = end;
	return (int64_t)sz;
}

static void on_error(exr_const_context_t ctxt, exr_result_t code, const char *msg)
{
	void *ud = NULL;
	if (exr_get_user_data(ctxt, &ud) == EXR_ERR_SUCCESS && ud)
		snprintf(((struct exr_msg *)ud)->text, sizeof ((struct exr_msg *)ud)->text, "%s (%s)", msg ? msg : "",
			 exr_get_error_code_as_string(code));
}

static int fail(struct acq_err *err, const char *what, const char *path, exr_result_t rc, const struct exr_msg *m)
{
	return acq_errf(err, ACQ_E_IO, "exr: %s %s: %s", what, path,
			m->text[0] ? m->text : exr_get_default_error_message(rc));
}

int exrio_write_rgb(const char *path, const float *rgb, int w, int h, const char *comments, struct acq_err *err)
{
	if (!path || !rgb || w < 1 || h < 1)
		return acq_errf(err, ACQ_E_INVAL, "exr: no path or image");
	for (size_t k = 0; k < (size_t)w * (size_t)h * 3; k++)
		if (!isfinite(rgb[k]))
			return acq_errf(err, ACQ_E_NUMERIC, "exr: %s: pixel (%zu, %zu) is not finite", path,
					(k / 3) % (size_t)w, (k / 3) / (size_t)w);
	struct exr_msg m = { "", NULL, 0, 0 };
	exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
	init.error_handler_fn = on_error;
	init.user_data = &m;
	init.write_fn = mem_write;
	exr_context_t c = NULL;
	exr_result_t rc = exr_start_write(&c, path, EXR_WRITE_FILE_DIRECTLY, &init);
	if (rc != EXR_ERR_SUCCESS) {
		free(m.buf);
		return fail(err, "cannot create", path, rc, &m);
	}
	int part = 0;
	exr_encode_pipeline_t enc;
	int enc_ok = 0, ret = -1;
	/* Rec. 709 primaries with the D65 white: what the pixel values mean (linear sRGB) */
	const exr_attr_chromaticities_t chroma = { 0.64f, 0.33f, 0.30f, 0.60f, 0.15f, 0.06f, 0.3127f, 0.3290f };
	if ((rc = exr_add_part(c, "rgba", EXR_STORAGE_SCANLINE, &part)) ||
	    (rc = exr_initialize_required_attr_simple(c, part, w, h, EXR_COMPRESSION_ZIP)) ||
	    (rc = exr_add_channel(c, part, "B", EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1)) ||
	    (rc = exr_add_channel(c, part, "G", EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1)) ||
	    (rc = exr_add_channel(c, part, "R", EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LOGARITHMIC, 1, 1)) ||
	    (rc = exr_attr_set_chromaticities(c, part, "chromaticities", &chroma)) ||
	    (comments && (rc = exr_attr_set_string(c, part, "comments", comments))) || (rc = exr_write_header(c))) {
		fail(err, "header of", path, rc, &m);
		goto out;
	}
	int32_t lines = 1;
	if ((rc = exr_get_scanlines_per_chunk(c, part, &lines)) || lines < 1) {
		fail(err, "chunking of", path, rc, &m);
		goto out;
	}
	for (int y = 0; y < h; y += lines) {
		exr_chunk_info_t ci;
		if ((rc = exr_write_scanline_chunk_info(c, part, y, &ci))) {
			fail(err, "chunk of", path, rc, &m);
			goto out;
		}
		rc = enc_ok ? exr_encoding_update(c, part, &ci, &enc) : exr_encoding_initialize(c, part, &ci, &enc);
		if (rc) {
			fail(err, "encoder for", path, rc, &m);
			goto out;
		}
		enc_ok = 1;
		for (int k = 0; k < enc.channel_count; k++) {
			exr_coding_channel_info_t *ch = &enc.channels[k];
			int comp = ch->channel_name[0] == 'R' ? 0 : ch->channel_name[0] == 'G' ? 1 : 2;
			ch->user_bytes_per_element = 4;
			ch->user_data_type = EXR_PIXEL_FLOAT;
			ch->user_pixel_stride = 12;
			ch->user_line_stride = 12 * w;
			ch->encode_from_ptr = (const uint8_t *)(rgb + ((size_t)y * (size_t)w) * 3 + comp);
		}
		if ((y == 0 && (rc = exr_encoding_choose_default_routines(c, part, &enc))) ||
		    (rc = exr_encoding_run(c, part, &enc))) {
			fail(err, "encoding", path, rc, &m);
			goto out;
		}
	}
	ret = 0;
out:
	if (enc_ok)
		exr_encoding_destroy(c, &enc);
	if (ret == 0) {
		rc = exr_finish(&c);
		if (rc != EXR_ERR_SUCCESS)
			ret = fail(err, "finishing", path, rc, &m);
		else if (pngio_write_bytes(path, m.buf, m.len, err))
			ret = acq_err_prefix(err, "exr: ");
	} else {
		exr_finish(&c); /* nothing was written to path */
	}
	free(m.buf);
	return ret;
}

int exrio_read_rgb(const char *path, float **rgb, int *w, int *h, struct acq_err *err)
{
	*rgb = NULL;
	struct exr_msg m = { "", NULL, 0, 0 };
	exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
	init.error_handler_fn = on_error;
	init.user_data = &m;
	exr_context_t c = NULL;
	exr_result_t rc = exr_start_read(&c, path, &init);
	if (rc != EXR_ERR_SUCCESS)
		return fail(err, "cannot read", path, rc, &m);
	int ret = -1, dec_ok = 0;
	float *img = NULL;
	exr_decode_pipeline_t dec;
	exr_storage_t st = EXR_STORAGE_SCANLINE;
	exr_attr_box2i_t dw;
	const exr_attr_chlist_t *chl = NULL;
	int32_t lines = 1;
	if ((rc = exr_get_storage(c, 0, &st)) || (rc = exr_get_data_window(c, 0, &dw)) ||
	    (rc = exr_get_channels(c, 0, &chl))) {
		fail(err, "header of", path, rc, &m);
		goto out;
	}
	if (st != EXR_STORAGE_SCANLINE || exr_get_scanlines_per_chunk(c, 0, &lines) || lines < 1) {
		acq_errf(err, ACQ_E_UNSUPPORTED, "exr: %s: only scanline images are read (this one is tiled or deep)", path);
		goto out;
	}
	long W = (long)dw.max.x - dw.min.x + 1, H = (long)dw.max.y - dw.min.y + 1;
	if (W < 2 || H < 2 || W > 16384 || H > 16384) {
		acq_errf(err, ACQ_E_RANGE, "exr: %s: image %ld x %ld (2..16384 per side)", path, W, H);
		goto out;
	}
	int have[3] = { 0, 0, 0 }, have_y = 0;
	for (int k = 0; k < chl->num_channels; k++) {
		const char *n = chl->entries[k].name.str;
		if (chl->entries[k].x_sampling != 1 || chl->entries[k].y_sampling != 1)
			continue;
		have[0] |= !strcmp(n, "R");
		have[1] |= !strcmp(n, "G");
		have[2] |= !strcmp(n, "B");
		have_y |= !strcmp(n, "Y");
	}
	int grey = !(have[0] && have[1] && have[2]);
	if (grey && !have_y) {
		acq_errf(err, ACQ_E_INVAL, "exr: %s: no full-resolution R, G, B (or Y) channels", path);
		goto out;
	}
	img = malloc((size_t)W * (size_t)H * 3 * sizeof *img);
	if (!img) {
		acq_errf(err, ACQ_E_NOMEM, "exr: %s: out of memory for %ld x %ld", path, W, H);
		goto out;
	}
	for (long y = dw.min.y; y <= dw.max.y; y += lines) {
		exr_chunk_info_t ci;
		if ((rc = exr_read_scanline_chunk_info(c, 0, (int)y, &ci))) {
			fail(err, "chunk of", path, rc, &m);
			goto out;
		}
		rc = dec_ok ? exr_decoding_update(c, 0, &ci, &dec) : exr_decoding_initialize(c, 0, &ci, &dec);
		if (rc) {
			fail(err, "decoder for", path, rc, &m);
			goto out;
		}
		dec_ok = 1;
		long row0 = ci.start_y - dw.min.y;
		for (int k = 0; k < dec.channel_count; k++) {
			exr_coding_channel_info_t *ch = &dec.channels[k];
			const char *n = ch->channel_name;
			int comp = grey ? (!strcmp(n, "Y") ? 0 : -1)
					: !strcmp(n, "R") ? 0 : !strcmp(n, "G") ? 1 : !strcmp(n, "B") ? 2 : -1;
			if (comp < 0 || ch->height == 0) {
				ch->decode_to_ptr = NULL;
				continue;
			}
			ch->user_bytes_per_element = 4;
			ch->user_data_type = EXR_PIXEL_FLOAT;
			ch->user_pixel_stride = 12;
			ch->user_line_stride = (int32_t)(12 * W);
			ch->decode_to_ptr = (uint8_t *)(img + (size_t)row0 * (size_t)W * 3 + comp);
		}
		if ((rc = exr_decoding_choose_default_routines(c, 0, &dec)) || (rc = exr_decoding_run(c, 0, &dec))) {
			fail(err, "decoding", path, rc, &m);
			goto out;
		}
	}
	for (size_t k = 0; k < (size_t)W * (size_t)H; k++) {
		if (grey)
			img[3 * k + 1] = img[3 * k + 2] = img[3 * k];
		for (int q = 0; q < 3; q++)
			if (!isfinite(img[3 * k + q]) || img[3 * k + q] < 0) {
				acq_errf(err, ACQ_E_INVAL, "exr: %s: pixel (%zu, %zu) channel %c is %g (needs finite >= 0)", path,
					 k % (size_t)W, k / (size_t)W, "RGB"[q], (double)img[3 * k + q]);
				goto out;
			}
	}
	*rgb = img;
	*w = (int)W;
	*h = (int)H;
	img = NULL;
	ret = 0;
out:
	if (dec_ok)
		exr_decoding_destroy(c, &dec);
	exr_finish(&c);
	free(img);
	return ret;
}
