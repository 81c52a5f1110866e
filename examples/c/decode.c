/* Decode a .gsi file to a binary PPM with the C API.
 * usage: decode FILE.gsi OUT.ppm [WIDTH HEIGHT]
 * Exit status: 0, or the gsi_status of the failing call (64 for usage/IO errors here). */
#include "gsi.h"

#include <stdio.h>
#include <stdlib.h>

static unsigned char *read_all(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    size_t cap = 1 << 16, n = 0;
    unsigned char *buf = malloc(cap);
    size_t got;
    while (buf && (got = fread(buf + n, 1, cap - n, f)) > 0) {
        n += got;
        if (n == cap) {
            unsigned char *bigger = realloc(buf, cap *= 2);
            if (!bigger) { free(buf); buf = NULL; }
            buf = bigger;
        }
    }
    fclose(f);
    *len = n;
    return buf;
}

int main(int argc, char **argv) {
    if (argc != 3 && argc != 5) {
        fprintf(stderr, "usage: %s FILE.gsi OUT.ppm [WIDTH HEIGHT]\n", argv[0]);
        return 64;
    }
    size_t len = 0;
    unsigned char *data = read_all(argv[1], &len);
    if (!data) { perror(argv[1]); return 64; }

    gsi_image *img = NULL;
    gsi_status st = gsi_open_memory(data, len, &img);
    free(data);
    if (st != GSI_OK) {
        fprintf(stderr, "gsi error %d: %s\n", st, gsi_last_error());
        return st;
    }
    uint32_t w, h, n;
    gsi_info(img, &w, &h, &n);
    if (argc == 5) { w = (uint32_t)strtoul(argv[3], NULL, 10); h = (uint32_t)strtoul(argv[4], NULL, 10); }

    /* API misuse is reported, not crashed on. */
    uint8_t small[4];
    if (gsi_render_rgba8(img, w, h, small, 0) != GSI_ERR_BUFFER_SIZE && (size_t)w * h > 0) {
        fprintf(stderr, "expected GSI_ERR_BUFFER_SIZE\n");
        return 65;
    }
    if (gsi_info(NULL, &w, &h, &n) != GSI_ERR_NULL_ARGUMENT) { fprintf(stderr, "expected NULL error\n"); return 65; }

    size_t size = (size_t)w * h * 4;
    uint8_t *rgba = malloc(size ? size : 1);
    st = gsi_render_rgba8(img, w, h, rgba, size);
    gsi_free(img);
    if (st != GSI_OK) {
        fprintf(stderr, "gsi error %d: %s\n", st, gsi_last_error());
        free(rgba);
        return st;
    }
    FILE *out = fopen(argv[2], "wb");
    if (!out) { perror(argv[2]); free(rgba); return 64; }
    fprintf(out, "P6\n%u %u\n255\n", w, h);
    for (size_t i = 0; i < (size_t)w * h; i++) fwrite(rgba + 4 * i, 1, 3, out);
    fclose(out);
    free(rgba);
    printf("%ux%u, %u Gaussians\n", w, h, n);
    return 0;
}
