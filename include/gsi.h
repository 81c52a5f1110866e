/* gsi: decode images stored as 2D Gaussians (.gsi files). C API of the gsi crate
 * (feature `capi`; link libgsi.a with -lpthread -ldl -lm, or libgsi.so).
 *
 * Every function returns a status; on failure gsi_last_error() gives a one-line message.
 * No Rust panic crosses this boundary: an internal failure returns GSI_ERR_INTERNAL.
 * Handles are not shared between threads by the library; a handle may be used from
 * one thread at a time. */
#ifndef GSI_H
#define GSI_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef int32_t gsi_status;

enum {
    GSI_OK = 0,
    /* The file was refused; one code per error kind of format-spec.md. */
    GSI_ERR_IO = 1,
    GSI_ERR_TRUNCATED = 2,
    GSI_ERR_BAD_SIGNATURE = 3,
    GSI_ERR_CRC_MISMATCH = 4,
    GSI_ERR_UNKNOWN_CRITICAL_CHUNK = 5,
    GSI_ERR_BAD_CHUNK_TYPE = 6,
    GSI_ERR_CHUNK_ORDER = 7,
    GSI_ERR_MISSING_CHUNK = 8,
    GSI_ERR_BAD_CHUNK_LENGTH = 9,
    GSI_ERR_UNSUPPORTED_VERSION = 10,
    GSI_ERR_INVALID_VALUE = 11,
    GSI_ERR_LIMIT_EXCEEDED = 12,
    GSI_ERR_DECOMPRESSION = 13,
    /* Misuse of the API. */
    GSI_ERR_NULL_ARGUMENT = 100,
    GSI_ERR_BUFFER_SIZE = 101,
    GSI_ERR_INTERNAL = 102
};

/* An opened file: header and Gaussians, ready to render at any size. */
typedef struct gsi_image gsi_image;

/* Parse a whole .gsi file held in memory. On success *out is a handle to free with
 * gsi_free; on failure *out is NULL. The bytes are not referenced after the call. */
gsi_status gsi_open_memory(const uint8_t *data, size_t len, gsi_image **out);

/* Free a handle (NULL is ignored). */
void gsi_free(gsi_image *image);

/* Stored size in pixels and number of Gaussians; any output pointer may be NULL. */
gsi_status gsi_info(const gsi_image *image, uint32_t *width, uint32_t *height, uint32_t *gaussians);

/* Render at width x height into out (at least width*height*4 bytes): RGBA8, rows top
 * to bottom, alpha 255. Any size is allowed up to the decoder's output limit. */
gsi_status gsi_render_rgba8(const gsi_image *image, uint32_t width, uint32_t height, uint8_t *out, size_t out_len);

/* Message of the last failed call on this thread ("" if none). Valid until the next
 * failing call on the same thread. */
const char *gsi_last_error(void);

#ifdef __cplusplus
}
#endif
#endif /* GSI_H */
